"""mifaces.importers.colmap.read_colmap on a real reconstruction: COLMAP's sparse model of 11 photographs
of the Château de Sceaux, in the text and the binary form COLMAP wrote.

**Where the model comes from.** Third-party data is not committed to this repository: it is read from
``../shared/data/colmap_real/`` (or the folder ``MIFACES_COLMAP_REAL`` names), as the other real data
(``../shared/data/README.md``), and these tests skip, saying so, where it is absent. The model is
``examples/colmap_example_model_{bin,txt}/`` of https://github.com/SBCV/Blender-Addon-Photogrammetry-Importer
(MIT, "Copyright (c) 2018 Sebastian Bullinger"; commit cd77c1698632a4aae028884760e73882813c8792): COLMAP's
reconstruction of openMVG's 11 "Sceaux Castle" photographs (2832 x 2128, one SIMPLE_RADIAL camera, 7862
points, 37123 observations; the photographs are not part of it). The folder holds ``text/`` and
``binary/``, each file compressed with ``xz`` (``<name>.xz``), checked against :data:`SHA256`. The two forms agree; every point projected through the cameras we
read lands on its observations as COLMAP's own bundle adjustment left it (against the per-point
errors COLMAP stored, and against pycolmap's projections where pycolmap is installed); and the
half-pixel shift between COLMAP's pixel convention and ours is needed for that."""

from __future__ import annotations

import hashlib
import lzma
import os
import struct
from pathlib import Path

import numpy as np
import pytest

from mifaces.importers.colmap import read_colmap

DATA = Path(os.environ.get("MIFACES_COLMAP_REAL",
                           Path(__file__).resolve().parents[2] / "shared" / "data" / "colmap_real"))
if not all((DATA / f"{form}/{name}.xz").is_file() for form, name in (("text", "cameras.txt"),
                                                                     ("binary", "cameras.bin"))):
    pytest.skip(f"the real COLMAP model is not at {DATA} (see this module's docstring for its source)",
                allow_module_level=True)
#: The files as COLMAP wrote them (decompressed), as README.md lists them.
SHA256 = {
    "binary/cameras.bin": "5f4e00f10f8c8f75f7e1c192f80807ac99c09155938bb58a0302797183ee0983",
    "binary/images.bin": "f3f84929dc54438da1a0d8c8eb119e270112a986bc4dfcba5cf58450d1206c41",
    "binary/points3D.bin": "4c5ce4204ddf4801db6f269201190c2b08dbbbb049fac018e2c156fed5dee703",
    "text/cameras.txt": "bf4d02789fed6c9743010166e508537efb9b287aaf383a41cc41047d5b24749c",
    "text/images.txt": "794c17e574e29e172a8e8eacf2ffe3e313d3c8252f438980ba2959aaeece7c96",
    "text/points3D.txt": "72720aea0df0028a3b2b656a47b37558ac8ccdafa84d11c66112978f0c1dd83a",
}
FORMS = ("text", "binary")
#: COLMAP's top-left pixel centre is (0.5, 0.5), ours (0, 0): stated here, not taken from the reader.
HALF = 0.5
#: How closely our per-point reprojection errors must equal the ERROR column COLMAP stored: the binary
#: form holds doubles (measured: 9e-13 px); the text form prints every number to 6 significant digits,
#: keypoints over 1000 px to 0.01 px among them (measured: 0.0058 px).
STORED_TOLERANCE = {"binary": 1e-6, "text": 0.02}


@pytest.fixture(scope="module")
def folders(tmp_path_factory) -> dict[str, Path]:
    """The two forms, decompressed into a temporary folder and checked against their hashes."""
    root = tmp_path_factory.mktemp("colmap_real")
    for name, digest in SHA256.items():
        raw = lzma.decompress((DATA / f"{name}.xz").read_bytes())
        assert hashlib.sha256(raw).hexdigest() == digest, name
        (root / name).parent.mkdir(exist_ok=True)
        (root / name).write_bytes(raw)
    return {form: root / form for form in FORMS}


@pytest.fixture(scope="module")
def models(folders):
    return {form: read_colmap(folders[form]) for form in FORMS}


def stored_points(folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points3D file read here, apart from mifaces' reader: per point in file order its
    coordinates (P, 3), its ERROR (P,) and its track length (P,)."""
    xyz, error, length = [], [], []
    if (folder / "points3D.bin").exists():
        data = (folder / "points3D.bin").read_bytes()
        offset = 8
        for _ in range(struct.unpack_from("<Q", data)[0]):
            _, x, y, z, _, _, _, e, n = struct.unpack_from("<Q3d3BdQ", data, offset)
            offset += 51 + 8 * n
            xyz.append((x, y, z))
            error.append(e)
            length.append(n)
        assert offset == len(data)
    else:
        for line in (folder / "points3D.txt").read_text().splitlines():
            if line.strip() and not line.startswith("#"):
                values = line.split()
                xyz.append(tuple(map(float, values[1:4])))
                error.append(float(values[7]))
                length.append((len(values) - 8) // 2)
    return np.array(xyz), np.array(error), np.array(length)


def residuals(model, shift=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Every observation's point row (N,) and its projection through the image's camera less the
    observed pixel, that moved by ``shift`` (N, 2)."""
    rows, res = [], []
    for name, (indices, xy) in model.observations.items():
        rows.append(indices)
        res.append(model.cameras[name].project(model.points[indices]) - (xy + np.asarray(shift)))
    return np.concatenate(rows), np.concatenate(res)


def point_errors(model, shift=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reprojection errors (px): per observation (N,), per point its mean over its track (P,), and
    the track lengths (P,)."""
    rows, res = residuals(model, shift)
    errors = np.linalg.norm(res, axis=1)
    counts = np.bincount(rows, minlength=len(model.points))
    return errors, np.bincount(rows, errors, minlength=len(model.points)) / counts, counts


def test_the_model_as_read(models):
    for model in models.values():
        assert sorted(model.cameras) == [f"100_{n}.JPG" for n in range(7100, 7111)]
        assert model.points.shape == (7862, 3)
        assert sum(len(indices) for indices, _ in model.observations.values()) == 37123
        for camera in model.cameras.values():
            assert (camera.width, camera.height) == (2832, 2128)
            assert len(camera.distortion) == 4 and not np.any(camera.distortion[1:])  # SIMPLE_RADIAL: k1 only
        # every camera sees its points in front of it
        assert all((model.cameras[n].to_camera(model.points[i])[:, 2] > 1).all()
                   for n, (i, _) in model.observations.items())


def test_text_and_binary_agree(models):
    """The same cameras, poses, keypoints and points, up to the text's 6 significant digits; every point
    in front of a camera and inside its image projects through the text's and the binary's camera to
    within 0.01 px (measured: 0.0035 px), and with each form's own points to within 0.02 px (measured:
    0.016 px; the points' rounding, up to 5e-5 scene units, moves them by that much)."""
    text, binary = models["text"], models["binary"]
    assert list(text.cameras) == list(binary.cameras)

    def rounding(x):  # half a unit in the 6th significant digit, with a little slack
        return 0.5 * 10.0 ** (np.floor(np.log10(np.maximum(np.abs(x), 1e-300))) - 5) + 1e-12

    assert np.all(np.abs(text.points - binary.points) <= rounding(binary.points))
    np.testing.assert_array_equal(text.colors, binary.colors)
    worst_camera = worst_full = 0.0
    for name, b in binary.cameras.items():
        t = text.cameras[name]
        assert (t.width, t.height, t.cx, t.cy) == (b.width, b.height, b.cx, b.cy) == (2832, 2128, 1415.5, 1063.5)
        assert abs(t.fx - b.fx) <= rounding(b.fx) and abs(t.fy - b.fy) <= rounding(b.fy)
        np.testing.assert_allclose(t.distortion, b.distortion, atol=1e-6)
        np.testing.assert_allclose(t.rotation, b.rotation, atol=2e-6)
        np.testing.assert_allclose(t.translation, b.translation, atol=1e-5)
        (ti, txy), (bi, bxy) = text.observations[name], binary.observations[name]
        np.testing.assert_array_equal(ti, bi)
        assert np.all(np.abs(txy - bxy) <= rounding(bxy + HALF))
        projected = b.project(binary.points)
        inside = ((b.to_camera(binary.points)[:, 2] > 0) & (projected[:, 0] > -0.5) & (projected[:, 1] > -0.5)
                  & (projected[:, 0] < b.width - 0.5) & (projected[:, 1] < b.height - 0.5))
        assert inside.sum() > 1000
        worst_camera = max(worst_camera, np.abs(t.project(binary.points[inside]) - projected[inside]).max())
        worst_full = max(worst_full, np.abs(t.project(text.points[inside]) - projected[inside]).max())
    assert worst_camera < 0.01
    assert worst_full < 0.02


@pytest.mark.parametrize("form", FORMS)
def test_reprojection_errors_are_colmaps(models, folders, form):
    """Our reprojection errors are those COLMAP stored: per point (its ERROR is the mean over its
    track), over all observations (the track-length weighted mean of ERROR: 0.62849 px) and over the
    points (COLMAP's "mean reprojection error": 0.60434 px), far closer than 0.2 px."""
    model = models[form]
    xyz, stored, length = stored_points(folders[form])
    np.testing.assert_array_equal(xyz, model.points)  # rows in file order
    errors, per_point, counts = point_errors(model)
    np.testing.assert_array_equal(counts, length)
    assert np.abs(per_point - stored).max() < STORED_TOLERANCE[form]
    assert errors.mean() == pytest.approx(np.average(stored, weights=length), abs=1e-4)
    assert per_point.mean() == pytest.approx(stored.mean(), abs=1e-4)
    assert stored.mean() == pytest.approx(0.604344, abs=1e-5)
    assert errors.mean() == pytest.approx(0.628492, abs=2e-5)


@pytest.mark.parametrize("form", FORMS)
def test_against_pycolmap(models, folders, form):
    """COLMAP's own projection (pycolmap, the same C++ code) of each observed point, less half a pixel,
    is ours; its keypoints less half a pixel are our observations; the mean reprojection error it
    computes, stored or recomputed, is our mean over points."""
    pycolmap = pytest.importorskip("pycolmap")
    model = models[form]
    reconstruction = pycolmap.Reconstruction(str(folders[form]))
    assert reconstruction.num_reg_images() == len(model.cameras) == 11
    projection_tolerance = 1e-6 if form == "binary" else 0.01  # text: pycolmap takes q unnormalised
    for image in reconstruction.images.values():
        indices, xy = model.observations[image.name]
        seen = [p for p in image.points2D if p.has_point3D()]
        xyz = np.array([reconstruction.points3D[p.point3D_id].xyz for p in seen])
        np.testing.assert_array_equal(model.points[indices], xyz)
        np.testing.assert_allclose(xy, np.array([p.xy for p in seen]) - HALF, rtol=0, atol=1e-9)
        pose = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
        colmap_pixels = image.camera.img_from_cam(pose * xyz)
        ours = model.cameras[image.name].project(xyz)
        assert np.abs(ours - (colmap_pixels - HALF)).max() < projection_tolerance
    _, per_point, _ = point_errors(model)
    tolerance = 1e-9 if form == "binary" else 1e-4
    assert reconstruction.compute_mean_reprojection_error() == pytest.approx(per_point.mean(), abs=tolerance)
    update = getattr(reconstruction, "update_point_3d_errors", None) or reconstruction.update_point_3D_errors
    update()
    assert reconstruction.compute_mean_reprojection_error() == pytest.approx(per_point.mean(), abs=tolerance)


def test_the_principal_point_is_the_image_centre(models):
    """COLMAP starts a camera's principal point at (W/2, H/2), the image's centre in its pixels, and
    kept it there (cameras: 1416 1064 for 2832 x 2128); the centre is ((W-1)/2, (H-1)/2) in ours.
    Fails if the reader dropped the half pixel from the intrinsics, or from everything at once (which
    leaves every reprojection error as it is)."""
    for model in models.values():
        for camera in model.cameras.values():
            assert (camera.cx, camera.cy) == ((camera.width - 1) / 2, (camera.height - 1) / 2)


@pytest.mark.parametrize("form", FORMS)
def test_half_a_pixel_on_either_side_would_show(models, folders, form):
    """Bundle adjustment leaves the residuals without a bias: their mean is 1e-4 px in each axis, so a
    reader that moved the keypoints and not the principal point (or the other way round) by half a
    pixel would be caught by a 0.02 px bound; it would raise the mean reprojection error by 0.31 px,
    and no point's error would match the one COLMAP stored any more."""
    model = models[form]
    _, res = residuals(model)
    assert np.all(np.abs(res.mean(axis=0)) < 0.02)
    _, stored, length = stored_points(folders[form])
    errors, per_point, _ = point_errors(model)
    assert np.abs(per_point - stored).max() < STORED_TOLERANCE[form]
    for shift in [(HALF, HALF), (-HALF, -HALF)]:
        _, shifted_res = residuals(model, shift)
        assert np.all(np.abs(shifted_res.mean(axis=0)) > 0.45)
        shifted_errors, shifted_per_point, _ = point_errors(model, shift)
        assert shifted_errors.mean() - errors.mean() > 0.25
        assert shifted_errors.mean() - np.average(stored, weights=length) > 0.25
        assert np.median(np.abs(shifted_per_point - stored)) > 0.1
