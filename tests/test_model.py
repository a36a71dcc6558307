"""Tests of mifaces.model: the value type, the built-in model, the SFM, meshes, export.

Reference values are computed independently of the code under test (numpy
algebra, trimesh, Mitsuba's own loaders).
"""

from __future__ import annotations

import json

from pathlib import Path

import mifaces  # noqa: F401  # isort: skip

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mifaces.model import MorphableModel, load_model
from mifaces.model.regions import REGIONS, region_map_from_landmarks
from mifaces.model.texture_space import rasterize

from conftest import JIT_VARIANTS, REPO

SFM_DIR = REPO.parent / "shared" / "models" / "sfm_3448"
SFM_NPZ = SFM_DIR / "sfm_shape_3448.npz"
needs_sfm = pytest.mark.skipif(not SFM_NPZ.is_file(), reason=f"Surrey Face Model not found at {SFM_DIR}")


@pytest.fixture(scope="session")
def builtin(tmp_path_factory):
    """The built-in model, from the user's cache (built there on first use)."""
    return load_model("builtin")


@pytest.fixture(scope="session")
def sfm():
    if not SFM_NPZ.is_file():
        pytest.skip(f"Surrey Face Model not found at {SFM_DIR}")
    return load_model(SFM_NPZ)


@pytest.fixture(params=["builtin", "sfm"])
def model(request):
    return request.getfixturevalue(request.param)


# ---- the linear model -----------------------------------------------------------------------
def test_bases_orthonormal_variances_positive(model):
    for basis, var in [(model.shape_basis, model.shape_variance)] + (
            [(model.color_basis, model.color_variance)] if model.has_texture else []):
        b = basis.astype(np.float64)
        np.testing.assert_allclose(b.T @ b, np.eye(b.shape[1]), atol=2e-4)
        assert np.all(var > 0)
        assert np.all(np.diff(var) <= 1e-3 * var[0]), "variances sorted, largest first"


def test_zero_coefficients_give_the_mean(model):
    np.testing.assert_array_equal(model.shape(np.zeros(model.shape_dim)), model.shape_mean)
    np.testing.assert_array_equal(model.shape(), model.shape_mean)
    if model.has_texture:
        np.testing.assert_array_equal(model.texture(np.zeros(model.color_dim)), model.color_mean)


def test_shape_is_the_linear_combination(model):
    rng = np.random.default_rng(3)
    a = rng.standard_normal(model.shape_dim)
    expected = model.shape_mean.ravel().astype(np.float64)
    for k in range(model.shape_dim):  # independent of the matrix product in shape()
        expected += a[k] * np.sqrt(float(model.shape_variance[k])) * model.shape_basis[:, k]
    np.testing.assert_allclose(model.shape(a).ravel(), expected, atol=1e-3)
    np.testing.assert_allclose(model.project(model.shape(a)), a, atol=1e-3)
    if model.has_expressions:
        d = np.zeros(model.expression_dim)
        d[0] = 1.0
        diff = model.shape(a, d) - model.shape(a)
        np.testing.assert_allclose(diff.ravel(), model.expression_basis[:, 0] * np.sqrt(model.expression_variance[0]),
                                   atol=1e-3)


def test_prior_is_squared_mahalanobis(model):
    a = np.random.default_rng(0).standard_normal(model.shape_dim)
    v = model.shape(a).ravel() - model.shape_mean.ravel()
    # Independent: project on the basis and divide by the variances.
    w = model.shape_basis.T.astype(np.float64) @ v
    assert model.prior(a) == pytest.approx(np.sum(w * w / model.shape_variance), rel=1e-3)


def test_random_faces_are_reproducible_and_differ(model):
    v1, t1 = model.random_face(7)
    v2, _ = model.random_face(7)
    v3, _ = model.random_face(8)
    np.testing.assert_array_equal(v1, v2)
    assert np.abs(v1 - v3).max() > 1.0  # mm
    assert np.all(np.isfinite(v1))
    if t1 is not None:
        assert t1.shape == (model.vertex_count, 3)


# ---- geometry and parameterization ----------------------------------------------------------
def test_normals_point_outward(model):
    from scipy.spatial import ConvexHull

    v = model.shape_mean.astype(np.float64)
    n = model.vertex_normals()
    used = np.unique(model.triangles)
    np.testing.assert_allclose(np.linalg.norm(n[used], axis=1), 1.0, atol=1e-5)
    # Outward: at the vertices on the convex hull of the face, the normal points away from its inside.
    hull = ConvexHull(v[used])
    on_hull = used[hull.vertices]
    outward = np.sum(n[on_hull] * (v[on_hull] - v[used].mean(axis=0)), axis=1) > 0
    assert outward.mean() > 0.95
    # The nose tip's normal points forward (+z).
    tip = model.ibug_landmarks[31]
    assert n[tip, 2] > 0.7


def test_tangent_frames_orthonormal_and_follow_u(model):
    t, b, n = model.tangent_frames()
    for x, y in [(t, b), (t, n), (b, n)]:
        assert np.abs(np.sum(x * y, axis=1)).max() < 1e-4
    np.testing.assert_allclose(np.cross(t, b), n, atol=1e-4)
    # The tangent points along increasing u: compare with a finite difference
    # along a triangle edge whose u grows.
    tri = model.triangles
    start = tri.ravel()
    end = tri[:, [1, 2, 0]].ravel()
    du = model.uv[end, 0] - model.uv[start, 0]
    dv = model.uv[end, 1] - model.uv[start, 1]
    dp = model.shape_mean[end] - model.shape_mean[start]
    sel = (du > 0.3 * du.max()) & (np.abs(dv) < 0.3 * du)  # edges mostly along +u
    assert sel.sum() > 100
    agree = np.sum(t[start[sel]] * dp[sel], axis=1) > 0
    assert agree.mean() > 0.95


def test_uv_in_unit_square_and_injective(model):
    assert model.uv.min() >= 0.0 and model.uv.max() <= 1.0
    raster = rasterize(model.uv, model.triangles, (700, 700))
    # Texture-space area covered by the triangles equals the sum of their areas
    # only if none overlap; the rasterizer counts overlaps texel by texel.
    assert raster.count.max() == 1, f"{np.sum(raster.count > 1)} texels covered twice"
    uv = model.uv.astype(np.float64)
    e1 = uv[model.triangles[:, 1]] - uv[model.triangles[:, 0]]
    e2 = uv[model.triangles[:, 2]] - uv[model.triangles[:, 0]]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    assert raster.covered.mean() == pytest.approx(area, rel=0.02)


def test_rasterize_barycentrics_reproduce_uv(builtin):
    raster = rasterize(builtin.uv, builtin.triangles, (128, 96))
    rows, cols = np.nonzero(raster.covered)
    tri = builtin.triangles[raster.triangle[rows, cols]]
    uv = np.einsum("mk,mkc->mc", raster.barycentric[rows, cols], builtin.uv[tri])
    np.testing.assert_allclose(uv[:, 0], (cols + 0.5) / 96, atol=1e-5)
    np.testing.assert_allclose(uv[:, 1], (rows + 0.5) / 128, atol=1e-5)


def test_regions_used_and_cover_the_face(model):
    names = model.regions
    expected = {"skin", "lips", "eyes", "eyebrows", "nostrils"}
    if model.name == "builtin":
        expected |= {"beard", "hair"}
    assert expected <= set(names)
    for name in names:
        assert np.any(model.region_map == REGIONS[name])
    covered = rasterize(model.uv, model.triangles, model.region_map.shape).covered
    assert np.all(model.region_map[covered] != REGIONS["background"])
    # Each region covers vertices, and the eyes' vertices are where the eye landmarks are.
    labels = model.vertex_regions()
    for name in names:
        assert np.any(labels == REGIONS[name]), name


def test_landmarks_valid(model):
    ids, verts = model.landmarks[:, 0], model.landmarks[:, 1]
    assert np.all((ids >= 1) & (ids <= 68)) and len(np.unique(ids)) == len(ids)
    assert np.all((verts >= 0) & (verts < model.vertex_count))
    p = model.landmark_positions()
    # Anatomy, up to the model: eyes above the nose tip above the mouth above the chin;
    # the right eye's outer corner (37) on the -x side.
    assert p[38][1] > p[31][1] > p[52][1] > p[58][1]
    if 9 in p:
        assert p[58][1] > p[9][1]
    assert p[37][0] < p[40][0] < 0 < p[43][0] < p[46][0]
    # The nose tip is (nearly) the most forward vertex.
    assert p[31][2] > model.shape_mean[:, 2].max() - 3.0


def test_builtin_landmarks_on_their_regions(builtin):
    regions = builtin.vertex_regions()
    p = builtin.shape_mean
    lm = builtin.ibug_landmarks
    eyes = p[regions == REGIONS["eyes"]]
    for i in (38, 39, 41, 42, 44, 45, 47, 48):  # eyelid margins: within a few mm of the eyeball
        assert np.min(np.linalg.norm(eyes - p[lm[i]], axis=1)) < 4.0, i
    brows = p[regions == REGIONS["eyebrows"]]
    for i in (20, 25):  # on the brow's upper edge, where the detector puts them
        assert np.min(np.linalg.norm(brows - p[lm[i]], axis=1)) < 3.0, i
    for i in (62, 63, 64, 66, 67, 68):  # the inner lip line (the outer one is the region's border)
        assert regions[lm[i]] == REGIONS["lips"], i


def test_builtin_is_a_head(builtin):
    """The ICT Face Model Light: proportions of an adult (Farkas' anthropometry of North American
    young adults, men and women), a head with ears, neck and a closed skull, eyeballs in their sockets."""
    p = builtin.landmark_positions()
    assert 105 <= p[28][1] - p[9][1] <= 130  # n-gn, morphological face height (mm): 112.8 (f) - 121.3 (m)
    assert 45 <= np.linalg.norm(p[55] - p[49]) <= 60  # ch-ch, mouth width: 50.2 (f) - 54.5 (m)
    assert 80 <= np.linalg.norm(p[46] - p[37]) <= 100  # ex-ex, biocular width: 87.8 (f) - 91.2 (m)
    # eyes behind the brow ridge and the nose
    assert p[38][2] < p[20][2] and p[38][2] < p[31][2] - 15
    v = builtin.shape_mean
    width = np.ptp(v[:, 0])
    assert 140 <= width <= 260  # ears included (the face alone is about 140 mm)
    assert np.ptp(v[:, 1]) > 250  # from the neck to the crown
    # a closed skull: the mesh's open border lies below the chin (the neck's cut) or at the lips
    # (the mouth's opening, whose socket is left out)
    t = builtin.triangles
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    weld = {}
    key = [weld.setdefault(tuple(np.round(x, 4)), len(weld)) for x in v]  # seam copies are one vertex
    welded = np.sort(np.array(key)[edges], axis=1)
    unique, count = np.unique(welded, axis=0, return_counts=True)
    border = np.unique(unique[count == 1])
    first = {k: i for i, k in reversed(list(enumerate(key)))}
    border_points = v[[first[k] for k in border]]
    below_chin = border_points[:, 1] < p[9][1]
    at_mouth = np.linalg.norm(border_points - 0.5 * (p[49] + p[55]), axis=1) < 35
    eyeball = np.zeros(len(border_points), bool)
    labels = builtin.vertex_regions()[[first[k] for k in border]]
    eyeball[labels == REGIONS["eyes"]] = True  # the eyeballs are separate closed-off shells
    assert np.all(below_chin | at_mouth | eyeball)
    assert builtin.has_expressions and not builtin.has_texture
    assert builtin.shape_dim == 100 and builtin.fit_shape_modes == 50


def test_builtin_ships_with_its_licence_and_loads_fast(builtin):
    import subprocess
    import sys

    from mifaces.model.ict_convert import LICENSE_FILE, MODEL_FILE

    assert MODEL_FILE.stat().st_size <= 12e6
    assert "Permission is hereby granted" in LICENSE_FILE.read_text()
    assert builtin.metadata["licence"] == "MIT" and builtin.metadata["precision"]["max_mm"] <= 0.01
    code = ("import time, mifaces; t = time.perf_counter(); mifaces.load_model(); "
            "print(time.perf_counter() - t)")
    seconds = float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                   check=True).stdout.split()[-1])
    assert seconds < 2.0


def test_builtin_round_trip(builtin, tmp_path):
    path = builtin.save(tmp_path / "m.npz")
    again = load_model(path)
    for field in ("shape_mean", "shape_basis", "shape_variance", "triangles", "uv", "region_map", "landmarks",
                  "expression_basis"):
        np.testing.assert_array_equal(getattr(again, field), getattr(builtin, field))
    assert again.expression_names == builtin.expression_names
    assert again.metadata == builtin.metadata


def test_truncated_model_keeps_the_leading_modes(builtin):
    small = builtin.truncated(10)
    assert small.shape_dim == 10 and builtin.truncated(10) is small and builtin.truncated(None) is builtin
    c = np.random.default_rng(0).standard_normal(10)
    np.testing.assert_allclose(small.shape(c), builtin.shape(c), atol=1e-4)
    assert small.metadata["shape_modes_of"] == 100
    with pytest.raises(ValueError, match="at least 1"):
        builtin.truncated(0)


def test_converter_reproduces_the_packaged_model(tmp_path):
    """The repository's script turns the shared toolkit file into the packaged one, bit for bit."""
    from mifaces.model import ict_convert

    source = REPO.parent / "shared" / "models" / "ict_facekit"
    if not (source / "ict_facekit.npz").is_file():
        pytest.skip(f"the ICT FaceKit conversion source is not at {source}")
    out = tmp_path / "ict_face.npz"
    assert ict_convert.main([str(source), "--out", str(out)]) == 0
    with np.load(out) as fresh, np.load(ict_convert.MODEL_FILE) as packaged:
        assert set(fresh.files) == set(packaged.files)
        for key in fresh.files:
            a, b = fresh[key], packaged[key]
            if key in ("basis", "expressions"):  # int16: an SVD on other BLAS threads may move one step
                assert a.shape == b.shape and np.abs(a.astype(np.int32) - b).max() <= 1, key
            elif key == "metadata":
                assert json.loads(str(a))["parts"] == json.loads(str(b))["parts"]
            elif a.dtype.kind == "f":
                np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9, err_msg=key)
            else:
                np.testing.assert_array_equal(a, b, err_msg=key)


def test_painted_skin_looks_like_skin(builtin):
    """The simulator's albedo for a model without colour: lips redder than skin, brows and pupils
    dark, the sclera bright."""
    from mifaces.model.regions import texel_regions_of_mesh
    from mifaces.studio.skin import paint_skin

    image = paint_skin(builtin, np.random.default_rng(3), 256, male=True)
    labels = texel_regions_of_mesh(builtin.region_map, builtin.uv, builtin.triangles, 256)
    mean = {r: image[labels == REGIONS[r]].mean(axis=0) for r in ("skin", "lips", "eyebrows", "eyes", "beard")}
    assert mean["lips"][0] / mean["lips"][1] > 1.2 * mean["skin"][0] / mean["skin"][1]
    assert mean["eyebrows"].mean() < 0.6 * mean["skin"].mean()
    assert mean["beard"].mean() < mean["skin"].mean()
    eyes = image[labels == REGIONS["eyes"]].mean(axis=1)
    assert eyes.max() > 0.5 and eyes.min() < 0.05  # sclera and pupil
    assert image.min() >= 0 and image.max() <= 0.95


# ---- Mitsuba meshes ---------------------------------------------------------------------------
def test_mitsuba_mesh_equals_arrays(model, variant):
    a = np.random.default_rng(1).standard_normal(model.shape_dim)
    mesh = model.mitsuba_mesh(a)
    params = mi.traverse(mesh)
    v = model.shape(a)
    np.testing.assert_allclose(np.array(params["vertex_positions"]).reshape(-1, 3), v, atol=1e-4)
    np.testing.assert_array_equal(np.array(params["faces"]).reshape(-1, 3), model.triangles)
    np.testing.assert_allclose(np.array(params["vertex_texcoords"]).reshape(-1, 2), model.uv, atol=1e-7)
    n = np.array(params["vertex_normals"]).reshape(-1, 3)
    # Mitsuba weights face normals by angle, mifaces by area: close on a smooth mesh.
    cos = np.sum(n * model.vertex_normals(v), axis=1)
    assert np.median(cos) > 0.999 and np.mean(cos > 0.9) > 0.98


@pytest.mark.parametrize("variant_name", JIT_VARIANTS)
def test_gradients_flow_to_shape_coefficients(builtin, variant_name):
    mifaces.set_variant(variant_name)
    from mifaces.model.mesh import FaceMesh

    model = builtin
    modes = 12
    face = FaceMesh(model, modes=modes)
    rng = np.random.default_rng(2)
    target = model.shape(rng.standard_normal(modes))
    c0 = rng.standard_normal(modes).astype(np.float32)
    c = mi.Float(c0)
    dr.enable_grad(c)
    face.update(c)
    positions = mi.traverse(face.mesh)["vertex_positions"]
    loss = dr.sum(dr.square(positions - mi.Float(target.ravel()))) / model.vertex_count
    dr.backward(loss)
    grad = dr.grad(c).numpy()
    # Independent: d/dc |mean + B S c - t|^2 / N = 2 S B^T (mean + B S c - t) / N.
    sigma = np.sqrt(model.shape_variance[:modes].astype(np.float64))
    b = model.shape_basis[:, :modes].astype(np.float64)
    r = model.shape_mean.ravel() + b @ (sigma * c0) - target.ravel()
    expected = 2 * sigma * (b.T @ r) / model.vertex_count
    np.testing.assert_allclose(grad, expected, rtol=2e-3, atol=1e-3 * np.abs(expected).max())
    # The prior is differentiable on the Dr.Jit side too: d/dc sum(c^2) = 2 c.
    dr.clear_grad(c)
    dr.backward(model.prior(c))
    np.testing.assert_allclose(dr.grad(c).numpy(), 2 * c0, rtol=1e-6)
    # The mesh holds the positions for c.
    np.testing.assert_allclose(np.array(positions).reshape(-1, 3), model.shape(c0), atol=1e-3)


def test_face_mesh_renders_and_updates(builtin):
    mifaces.set_variant(JIT_VARIANTS[0])
    from mifaces.model.mesh import FaceMesh

    face = FaceMesh(builtin, modes=4)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 600], target=[0, -10, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32}},
        "face": face.mesh, "light": {"type": "constant"}})
    before = np.array(mi.render(scene, spp=4))
    face.update(np.array([3.0, 0, 0, 0]))
    assert np.allclose(np.array(mi.traverse(face.mesh)["vertex_positions"]).reshape(-1, 3),
                       builtin.shape([3.0]), atol=1e-3)
    after = np.array(mi.render(scene, spp=4))
    assert before.mean() > 0.05 and np.abs(after - before).max() > 0.01


# ---- export ----------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", ["obj", "ply"])
def test_export_round_trip(sfm, tmp_path, suffix, variant):
    import trimesh

    v = sfm.shape(np.random.default_rng(4).standard_normal(5))
    path = sfm.export(tmp_path / f"face.{suffix}", np.random.default_rng(4).standard_normal(5))
    loaded = trimesh.load(path, process=False)
    np.testing.assert_allclose(loaded.vertices, v, atol=1e-4)
    np.testing.assert_array_equal(loaded.faces, sfm.triangles)
    # Mitsuba reads the texture coordinates back as the model's.
    mesh = mi.load_dict({"type": suffix, "filename": str(path)})
    params = mi.traverse(mesh)
    # Mitsuba may reorder vertices; compare corner by corner through the faces.
    faces = np.array(params["faces"]).reshape(-1, 3)
    assert len(faces) == sfm.triangle_count
    positions = np.array(params["vertex_positions"]).reshape(-1, 3)
    uv = np.array(params["vertex_texcoords"]).reshape(-1, 2)
    np.testing.assert_allclose(positions[faces], v[sfm.triangles], atol=1e-4)
    np.testing.assert_allclose(uv[faces], sfm.uv[sfm.triangles], atol=1e-5)


# ---- the Surrey Face Model -------------------------------------------------------------------
def test_sfm_landmarks_on_features(sfm):
    assert len(sfm.landmarks) == 50
    p = sfm.landmark_positions()
    v = sfm.shape_mean
    # Nose tip (31) is the most forward vertex, within 1 mm.
    assert v[:, 2].max() - p[31][2] < 1.0
    # Chin (9) is the lowest landmark, on the midline.
    assert p[9][1] == min(q[1] for q in p.values()) and abs(p[9][0]) < 2.0
    # Eyes symmetric about the midline, eye corners at the eye line, mouth corners below the nose.
    np.testing.assert_allclose(p[37][[1, 2]], p[46][[1, 2]], atol=1.5)
    assert p[37][0] == pytest.approx(-p[46][0], abs=1.5)
    assert p[49][1] < p[34][1] < p[31][1] < p[40][1]
    # Landmarks sit on their regions in the derived region map.
    regions = sfm.vertex_regions()
    lm = sfm.ibug_landmarks
    from mifaces.model.regions import lookup

    upper_lip = 0.5 * (sfm.uv[lm[52]] + sfm.uv[lm[63]])
    lower_lip = 0.5 * (sfm.uv[lm[58]] + sfm.uv[lm[67]])
    assert list(lookup(sfm.region_map, np.stack([upper_lip, lower_lip]))) == [REGIONS["lips"]] * 2
    brow = sfm.uv[lm[20]]
    assert lookup(sfm.region_map, brow[None])[0] == REGIONS["eyebrows"]
    eye = 0.5 * (sfm.uv[lm[38]] + sfm.uv[lm[42]])
    assert lookup(sfm.region_map, eye[None])[0] == REGIONS["eyes"]
    assert regions[lm[31]] == REGIONS["skin"]


def test_region_map_from_landmarks_polygons():
    """A flat square face with landmarks placed by hand: regions land where placed."""
    g = np.linspace(0, 1, 41)
    uu, vv = np.meshgrid(g, g)
    uv = np.stack([uu.ravel(), vv.ravel()], 1)
    from mifaces.model.geometry import grid_triangles

    tri = grid_triangles(41, 41)

    def vid(u, v):
        return int(round(v * 40)) * 41 + int(round(u * 40))

    lm = {}
    for k, ang in enumerate(np.linspace(0, 2 * np.pi, 12, endpoint=False)):
        lm[49 + k] = vid(0.5 + 0.2 * np.cos(ang), 0.75 + 0.08 * np.sin(ang))
    rmap = region_map_from_landmarks(uv, tri, lm, (97, 97))
    assert rmap[73, 48] == REGIONS["lips"] and rmap[73, 20] == REGIONS["skin"]
    assert rmap[20, 48] == REGIONS["skin"]
    assert set(np.unique(rmap)) == {REGIONS["skin"], REGIONS["lips"]}


def test_value_type_validates():
    with pytest.raises(ValueError, match="shape_basis must have shape"):
        MorphableModel("x", np.zeros((4, 3)), np.zeros((11, 2)), np.ones(2), np.zeros((1, 3)), np.zeros((4, 2)),
                       np.zeros((4, 4)))
    with pytest.raises(ValueError, match="shape_variance must be positive"):
        MorphableModel("x", np.zeros((4, 3)), np.zeros((12, 2)), np.array([1.0, 0.0]), np.zeros((1, 3)),
                       np.zeros((4, 2)), np.zeros((4, 4)))


def test_load_model_unknown(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.npz"):
        load_model(tmp_path / "nothere.npz")
    bad = tmp_path / "model.xyz"
    bad.write_text("")
    with pytest.raises(ValueError, match="unknown model format"):
        load_model(bad)


def test_package_exports():
    assert mifaces.load_model is load_model
    assert mifaces.MorphableModel is MorphableModel
    assert Path(mifaces.__file__).parent == REPO / "mifaces"
