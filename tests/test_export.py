"""mifaces export: glTF, OBJ and USD of a measured face, the BRDF mapping onto glTF's model, bad result sets."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
from pathlib import Path

import mifaces  # isort: skip
from mifaces.reflectance import FitOptions

import numpy as np
import pytest

#: The glTF-Validator's folder (tools/web, npm install there).
WEB = Path(__file__).resolve().parents[1] / "tools" / "web"


@pytest.fixture(scope="module")
def measured(small_capture, tmp_path_factory):
    """A small default measure run (all four models, true shapes, 64² textures): its output folder."""
    from mifaces.pipeline.measure import measure

    capture = small_capture("export", measurements=2, resolution=(256, 256), spp=8, albedo_resolution=128, seed=4)
    out = tmp_path_factory.mktemp("export") / "m"
    mifaces.set_variant("llvm_ad_rgb")
    # the corrections off: two photographs hold no lobe for the bounced light's second fit to start from
    measure(out, capture, geometry="ground-truth", spp=2, progress=False,
            options=FitOptions(resolution=64, interreflection=False, balance_lights=False))
    return out


def _validate(*files: Path) -> list[dict]:
    """The Khronos glTF-Validator's reports, or a skip saying what is missing."""
    if shutil.which("node") is None:
        pytest.skip("node is not installed: the glTF-Validator cannot run (skipped)")
    if not (WEB / "node_modules" / "gltf-validator").is_dir():
        pytest.skip(f"gltf-validator is not installed: run `npm ci` in {WEB} (skipped)")
    run = subprocess.run(["node", str(WEB / "validate.js"), *map(str, files)], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


# --------------------------------------------------------------------------------------------
# The mapping onto glTF's model
# --------------------------------------------------------------------------------------------
def test_gltf_brdf_matches_mitsubas_principled_lobe():
    """glTF's specular layer (GGX, F0 from the index, f90 = 1) against Mitsuba's principled
    BSDF with the same roughness and index and no diffuse: an independent evaluation."""
    from mifaces.brdf.gltf_lobe import GltfLobe, gltf_brdf
    from mifaces.brdf.hemisphere import hemisphere_pairs
    from mifaces.validation.brdf_error import eval_bsdf

    mifaces.set_variant("llvm_ad_rgb")
    wi, wo = hemisphere_pairs(10)
    for roughness, eta in ((0.5, 1.4), (0.7, 1.5)):
        f0 = ((eta - 1) / (eta + 1)) ** 2
        ours = gltf_brdf(wi, wo, np.zeros(3), GltfLobe(roughness ** 2, np.full(3, f0), 1.0)) * wo[:, 2:3]
        principled = eval_bsdf({"type": "principled", "base_color": {"type": "rgb", "value": [0.0, 0.0, 0.0]},
                                "roughness": roughness, "eta": eta, "spec_tint": 0.0},
                               np.zeros((len(wi), 2)), wi, wo)
        near = (wi[:, 2] > 0.9) & (wo[:, 2] > 0.9)  # where Fresnel and masking are at their normal values
        np.testing.assert_allclose(ours[near], principled[near], rtol=0.01)
        error = np.sqrt(np.sum((ours - principled) ** 2) / np.sum(principled ** 2))
        assert error < 0.2, (roughness, eta, error)  # Schlick vs exact Fresnel, correlated vs separable Smith


def test_each_model_maps_onto_a_ggx_lobe():
    from mifaces.brdf import model
    from mifaces.brdf.builtin import fresnel_normal
    from mifaces.brdf.cosine_lobe import exponent_of_slope
    from mifaces.brdf.materials import REFRACTIVE_INDEX

    ct = model("cooktorrance").gltf_lobe({"specular_reflectance": [0.5, 0.4, 0.5], "roughness": 0.3, "eta": 1.4})
    assert ct.alpha == 0.3 and ct.f90 == 0.5
    np.testing.assert_allclose(ct.f0, np.array([0.5, 0.4, 0.5]) * fresnel_normal(1.4))
    # a region without its own η takes its published one (the value a fit holds there)
    lips = model("cooktorrance").region_values({"specular_reflectance": 0.5, "roughness": 0.3}, "lips")
    assert lips["eta"] == REFRACTIVE_INDEX["lips"]
    phong = model("phong").gltf_lobe({"specular_reflectance": 0.1, "exponent": 50.0})
    assert exponent_of_slope(phong.alpha) == pytest.approx(50.0)  # the inverse of the slope -> exponent map
    np.testing.assert_allclose(phong.f0, 0.1)
    assert phong.f90 == pytest.approx(0.1)
    ward = model("ward").gltf_lobe({"specular_reflectance": [0.05, 0.05, 0.05], "alpha": 0.2})
    assert ward.alpha == 0.2 and ward.f90 == pytest.approx(0.05)


def test_lafortune_lobe_is_the_least_squares_fit():
    """The fitted α has a smaller residual than its neighbours, and the fit is close to the lobe."""
    from mifaces.brdf import model
    from mifaces.brdf.gltf_lobe import ALPHA_GRID, FIT_GRID, GltfLobe, glossy_values, gltf_brdf
    from mifaces.brdf.hemisphere import hemisphere_pairs

    mifaces.set_variant("llvm_ad_rgb")
    params = {"cxy": -0.9, "cz": 0.9, "exponent": 20.0}
    lafortune = model("lafortune")
    lobe = lafortune.gltf_lobe(params)  # the default: the nearest GGX lobe
    wi, wo = hemisphere_pairs(FIT_GRID)
    target = glossy_values(lafortune, params, wi, wo) * wo[:, 2:3]

    def residual(alpha):
        basis = gltf_brdf(wi, wo, np.zeros(3), GltfLobe(alpha, np.ones(3), 1.0)) * wo[:, 2:3]
        return np.sum((target - basis * lobe.f0) ** 2)

    k = int(np.argmin(np.abs(ALPHA_GRID - lobe.alpha)))
    assert residual(lobe.alpha) < min(residual(ALPHA_GRID[k - 1]), residual(ALPHA_GRID[k + 1]))
    assert residual(lobe.alpha) < 0.5 * np.sum(target ** 2)
    assert 0.05 < lobe.alpha < 0.6 and 0 < lobe.f90 <= 1


def test_mapping_error_is_small_for_a_mapped_cook_torrance(measured):
    from mifaces.export.material import mapping_rmse
    from mifaces.reflectance.io import load_estimate

    document = load_estimate(measured / "brdf" / "cooktorrance")
    error = mapping_rmse(document, "skin", [0.5, 0.4, 0.3], grid=8)
    # the lobe alone: Beckmann m taken as GGX alpha leaves 0.4-0.6 of it (validation/results/export.json)
    assert 0 < error["rmse"] < 0.15 and 0 < error["rmse_specular"] < 0.7


# --------------------------------------------------------------------------------------------
# The files
# --------------------------------------------------------------------------------------------
def test_glb_loads_with_its_textures_and_passes_the_validator(measured, tmp_path):
    import trimesh

    from mifaces.export import export_face
    from mifaces.model import load_model
    from mifaces.model.regions import REGIONS, texel_regions
    from mifaces.reflectance.io import load_estimate

    result = measured / "brdf" / "cooktorrance"
    (glb,) = export_face(result, tmp_path / "face.glb")
    (gltf,) = export_face(result, tmp_path / "face.gltf")
    model = load_model("builtin")
    scene = trimesh.load(glb)
    (mesh,) = scene.geometry.values()
    assert len(mesh.vertices) == model.vertex_count and len(mesh.faces) == model.triangle_count
    np.testing.assert_allclose(np.asarray(mesh.vertices), model.shape_mean / 1000.0, atol=1e-6)  # metres, model frame
    assert 0.1 < np.ptp(mesh.vertices[:, 1]) < 0.5  # a head's height in metres, +y up
    material = mesh.visual.material
    albedo = load_estimate(result)["albedo"]
    assert material.baseColorTexture.size == albedo.shape[1::-1]
    assert material.metallicRoughnessTexture is not None
    # trimesh's uv is v-up: the texel row of v = 0 is the top of the image, as the albedo map's row 0
    base = np.asarray(material.baseColorTexture.convert("RGB"), np.float64) / 255
    skin = base
    encoded = np.where(albedo <= 0.0031308, 12.92 * albedo, 1.055 * np.clip(albedo, 0, None) ** (1 / 2.4) - 0.055)
    skin_texels = texel_regions(model.region_map, albedo.shape[0]) == REGIONS["skin"]  # one f0: one scale
    face = (albedo.mean(axis=2) > 0.05) & skin_texels
    assert np.corrcoef(skin[face].ravel(), encoded[face].ravel())[0, 1] > 0.98  # sRGB-encoded albedo (÷ 1 − f0)
    assert np.all(skin[face] >= np.clip(encoded[face], 0, 1) - 2 / 255)
    for report in _validate(glb, gltf):
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]
    document = json.loads(gltf.read_text())
    assert set(document["extensionsUsed"]) == {"KHR_materials_specular", "KHR_materials_ior"}
    assert document["materials"][0]["pbrMetallicRoughness"]["metallicFactor"] == 1.0  # × the texture's B = 0


def test_obj_and_usd_are_written_and_open(measured, tmp_path):
    import trimesh
    from pxr import Usd, UsdGeom, UsdShade

    from mifaces.export import export_face
    from mifaces.model import load_model

    model = load_model("builtin")
    result = measured / "brdf" / "ward"
    written = export_face(result, tmp_path / "face.obj")
    assert {p.name for p in written} == {"face.obj", "face.mtl", "face.png"}
    mesh = trimesh.load(tmp_path / "face.obj", process=False)
    assert len(mesh.faces) == model.triangle_count and mesh.visual.material.image is not None
    written = export_face(result, tmp_path / "face.usdc")
    assert written[-1].name == "face.usdc" and all(p.is_file() for p in written)
    stage = Usd.Stage.Open(str(tmp_path / "face.usdc"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    usd_mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh"))
    points = np.asarray(usd_mesh.GetPointsAttr().Get())
    np.testing.assert_allclose(points, model.shape_mean / 1000.0, atol=1e-6)
    st = np.asarray(UsdGeom.PrimvarsAPI(usd_mesh).GetPrimvar("st").Get())
    np.testing.assert_allclose(st[:, 1], 1.0 - model.uv[:, 1], atol=1e-6)  # USD counts v from the bottom
    material, _ = UsdShade.MaterialBindingAPI(usd_mesh.GetPrim()).ComputeBoundMaterial()
    assert material and material.GetPath() == "/Face/Material"
    texture = stage.GetPrimAtPath("/Face/Material/BaseColor").GetAttribute("inputs:file").Get()
    assert (tmp_path / texture.path).is_file()


def _srgb(linear):
    """The sRGB transfer function (IEC 61966-2-1), written out: linear [0, 1] -> encoded."""
    linear = np.clip(linear, 0.0, 1.0)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def _linear(encoded):
    """The inverse of :func:`_srgb`."""
    return np.where(encoded <= 0.04045, encoded / 12.92, ((encoded + 0.055) / 1.055) ** 2.4)


def _png(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)), np.float64) / 255.0


#: Two regions' Cook-Torrance lobes: the specular scale large enough that the base colour's division by
#: 1 - f0 shows, roughness and index unlike each other.
CONVENTIONS = {"model": "cooktorrance", "options": {},
               "regions": {"skin": {"specular_reflectance": [4.0, 3.5, 3.0], "roughness": 0.3, "eta": 1.45},
                           "lips": {"specular_reflectance": [2.0, 1.5, 1.0], "roughness": 0.55, "eta": 1.38}}}


def test_each_format_writes_its_texture_conventions(tmp_path):
    """glTF, OBJ and USD of one face with known lobes, read back: base colour sRGB-encoded and divided
    by 1 - max f0, roughness √α linear in G (B, metallic, 0), glTF's F0(η_material) × specular colour ×
    f90 the lobe's f0, texture v = 0 the top row in glTF and counted from the bottom in OBJ and USD,
    USD's colour spaces and channels; every value from the lobe's parameters written out here."""
    import pygltflib
    from pxr import Usd, UsdShade

    from mifaces.brdf.materials import SKIN_REFRACTIVE_INDEX
    from mifaces.export.face import ExportedFace, material_textures
    from mifaces.export.gltf import write_gltf
    from mifaces.export.obj import write_obj
    from mifaces.export.usd import write_usd
    from mifaces.model import load_model
    from mifaces.model.regions import REGIONS, texel_regions_of_mesh

    model = load_model("builtin")
    r = 32
    rows, cols = np.mgrid[:r, :r]
    albedo = np.stack([0.1 + 0.6 * cols / r, 0.1 + 0.5 * rows / r, np.full((r, r), 0.3)], axis=2)
    labels = texel_regions_of_mesh(model.region_map, model.uv, model.triangles, r)
    textures, color_scale, _ = material_textures(CONVENTIONS, albedo, labels)
    tangent, _, normal = model.tangent_frames()
    face = ExportedFace(model.shape_mean / 1000, normal, np.concatenate([tangent, np.ones((len(tangent), 1))], 1),
                        model.uv, model.triangles.astype(np.uint32), textures, color_scale)
    expected = {}  # region -> (base colour (texels, 3) linear, roughness, f0 (3,))
    for name, params in CONVENTIONS["regions"].items():
        where = labels == REGIONS[name]
        f0 = np.array(params["specular_reflectance"]) * ((params["eta"] - 1) / (params["eta"] + 1)) ** 2
        expected[name] = (where, np.clip(albedo[where] / (1 - f0.max()), 0, 1), np.sqrt(params["roughness"]), f0)
    assert all(where.sum() > 5 for where, *_ in expected.values())

    def check_base_and_roughness(base, rough):
        for name, (where, colour, roughness, _) in expected.items():
            np.testing.assert_allclose(base[where][:, :3], _srgb(colour), atol=0.6 / 255, err_msg=name)
            np.testing.assert_allclose(rough[where][:, 1], roughness, atol=0.6 / 255, err_msg=name)
            assert not rough[where][:, [0, 2]].any()  # metallic 0 (B), R unused

    # glTF: images by their names, texture coordinates as the model's
    (path,) = write_gltf(face, tmp_path / "face.glb")
    document = pygltflib.GLTF2().load(str(path))
    blob = document.binary_blob()

    def view(index):
        v = document.bufferViews[index]
        return blob[v.byteOffset:v.byteOffset + v.byteLength]

    images = {image.name: _png(view(image.bufferView)) for image in document.images}
    check_base_and_roughness(images["base_color"], images["metallic_roughness"])
    material = document.materials[0]
    specular = material.extensions["KHR_materials_specular"]
    factor = np.asarray(specular["specularColorFactor"])
    eta = material.extensions["KHR_materials_ior"]["ior"]
    assert eta == SKIN_REFRACTIVE_INDEX
    for name, (where, _, _, f0) in expected.items():
        texels = images["specular"][where]
        f90 = texels[:, 3]  # linear
        # glTF: f0 = f90 · min(F0(ior) · specularColor, 1)
        rendered = f90[:, None] * np.minimum(((eta - 1) / (eta + 1)) ** 2 * _linear(texels[:, :3]) * factor, 1.0)
        np.testing.assert_allclose(rendered, np.broadcast_to(f0, rendered.shape), rtol=0.02, err_msg=name)
    accessor = document.accessors[document.meshes[0].primitives[0].attributes.TEXCOORD_0]
    uv = np.frombuffer(view(accessor.bufferView), np.float32).reshape(-1, 2)
    np.testing.assert_allclose(uv, model.uv, atol=1e-7)  # glTF: v = 0 the texture's top row
    # OBJ: vt counted from the bottom; its colour texture the sRGB base colour
    written = write_obj(face, tmp_path / "face.obj")
    vt = np.array([line.split()[1:3] for line in (tmp_path / "face.obj").read_text().splitlines()
                   if line.startswith("vt ")], np.float64)
    assert len(vt) == model.vertex_count
    np.testing.assert_allclose(vt, np.column_stack([model.uv[:, 0], 1 - model.uv[:, 1]]), atol=1e-6)
    assert {p.name for p in written} == {"face.obj", "face.mtl", "face.png"}
    np.testing.assert_allclose(_png((tmp_path / "face.png").read_bytes())[..., :3], images["base_color"][..., :3])
    # USD: st counted from the bottom, the base colour read as sRGB, roughness from G of a raw texture
    write_usd(face, tmp_path / "face.usda")
    stage = Usd.Stage.Open(str(tmp_path / "face.usda"))
    check_base_and_roughness(*(_png((tmp_path / f"face_{n}.png").read_bytes()) for n in ("base_color",
                                                                                       "metallic_roughness")))
    shaders = {name: UsdShade.Shader(stage.GetPrimAtPath(f"/Face/Material/{name}"))
               for name in ("Surface", "BaseColor", "MetallicRoughness")}
    assert shaders["BaseColor"].GetInput("sourceColorSpace").Get() == "sRGB"
    assert shaders["MetallicRoughness"].GetInput("sourceColorSpace").Get() == "raw"
    source, output, _ = shaders["Surface"].GetInput("roughness").GetConnectedSource()
    assert source.GetPath() == shaders["MetallicRoughness"].GetPath() and output == "g"
    source, output, _ = shaders["Surface"].GetInput("diffuseColor").GetConnectedSource()
    assert source.GetPath() == shaders["BaseColor"].GetPath() and output == "rgb"


def test_cli_exports_the_fitted_shape_of_a_measurement(measured, tmp_path):
    from click.testing import CliRunner

    from mifaces.cli.commands import main
    from mifaces.model import load_model

    model = load_model("builtin")
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    coefficients = np.zeros(model.shape_dim)
    coefficients[:3] = [2.0, -1.0, 0.5]
    (shapes / "shapes.json").write_text(json.dumps({"model_source": "builtin",
                                                    "measurements": {"m00": {"status": "converged"}}}))
    (shapes / "m00.json").write_text(json.dumps({"coefficients": coefficients.tolist(), "expression": None}))
    run = CliRunner().invoke(main, ["export", str(measured / "brdf" / "phong"), "--out", str(tmp_path / "f.glb"),
                                    "--measurement", "m00", "--shapes", str(shapes)])
    assert run.exit_code == 0, run.output
    import trimesh

    (mesh,) = trimesh.load(tmp_path / "f.glb").geometry.values()
    np.testing.assert_allclose(mesh.vertices, model.shape(coefficients) / 1000.0, atol=1e-6)
    run = CliRunner().invoke(main, ["export", str(measured / "brdf" / "phong"), "--out", str(tmp_path / "g.glb"),
                                    "--measurement", "m07", "--shapes", str(shapes)])
    assert run.exit_code == 1 and "'m07' has no fitted shape" in run.output and not (tmp_path / "g.glb").exists()
    run = CliRunner().invoke(main, ["export", str(measured / "brdf" / "phong"), "--out", str(tmp_path / "f.ply")])
    assert run.exit_code == 1 and "suffix must be one of" in run.output


# --------------------------------------------------------------------------------------------
# The normal map's frame
# --------------------------------------------------------------------------------------------
def test_normal_map_is_converted_to_gltfs_tangent_frame(tmp_path):
    """A Mitsuba normal map of a known world normal field, exported, and read back
    with glTF's rule (interpolated vertex normal and tangent, bitangent n × t · w)
    from the file's own NORMAL and TANGENT: the same world normals."""
    import pygltflib

    from mifaces.export.face import ExportedFace, gltf_normals
    from mifaces.export.gltf import write_gltf
    from mifaces.model import load_model
    from mifaces.model.texture_space import rasterize
    from mifaces.reflectance.maps.normals import decode, encode, mitsuba_frames

    model = load_model("builtin")
    r = 64
    texel, mitsuba, _ = mitsuba_frames(model, model.shape_mean, r)
    tilted = np.array([0.35, -0.25, 1.0]) / np.linalg.norm([0.35, -0.25, 1.0])
    local = np.tile([0.0, 0.0, 1.0], (r * r, 1))
    local[texel] = tilted
    world_true = np.einsum("mji,j->mi", mitsuba, tilted)
    converted = gltf_normals(encode(local.reshape(r, r, 3)), model, model.shape_mean)
    tangent, _, normal = model.tangent_frames()
    face = ExportedFace(model.shape_mean / 1000, normal, np.concatenate([tangent, np.ones((len(tangent), 1))], 1),
                        model.uv, model.triangles.astype(np.uint32),
                        {"base_color": np.full((r, r, 3), 0.5), "metallic_roughness": np.full((r, r, 3), 0.5),
                         "specular": np.full((r, r, 4), 0.5), "normal": converted}, 1.0)
    (path,) = write_gltf(face, tmp_path / "n.glb")
    document = pygltflib.GLTF2().load(str(path))
    blob = document.binary_blob()

    def accessor(index, width):
        a = document.accessors[index]
        view = document.bufferViews[a.bufferView]
        return np.frombuffer(blob, np.float32, a.count * width, view.byteOffset).reshape(-1, width)

    attributes = document.meshes[0].primitives[0].attributes
    n_file, t_file = accessor(attributes.NORMAL, 3), accessor(attributes.TANGENT, 4)
    image = document.images[document.materials[0].normalTexture.index]
    view = document.bufferViews[image.bufferView]
    from PIL import Image

    png = np.asarray(Image.open(io.BytesIO(blob[view.byteOffset:view.byteOffset + view.byteLength])), np.float64)
    texture = decode(png / 255.0).reshape(-1, 3)
    raster = rasterize(model.uv, model.triangles, (r, r))
    tri = model.triangles[raster.triangle.ravel()[texel]]
    bary = raster.barycentric.reshape(-1, 3)[texel]
    n = np.einsum("mk,mkc->mc", bary, n_file[tri])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t = np.einsum("mk,mkc->mc", bary, t_file[tri][:, :, :3])
    t -= n * np.sum(n * t, axis=1, keepdims=True)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t) * t_file[tri][:, 0, 3:4]
    m = texture[texel]
    world = m[:, :1] * t + m[:, 1:2] * b + m[:, 2:3] * n
    world /= np.linalg.norm(world, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(np.sum(world * world_true, axis=1), -1, 1)))
    assert np.median(angle) < 1.0 and np.percentile(angle, 95) < 3.0, (np.median(angle), np.percentile(angle, 95))
    unconverted = m.copy()
    unconverted[:] = tilted  # had the Mitsuba normals been written as they are
    world_raw = unconverted[:, :1] * t + unconverted[:, 1:2] * b + unconverted[:, 2:3] * n
    world_raw /= np.linalg.norm(world_raw, axis=1, keepdims=True)
    raw = np.degrees(np.arccos(np.clip(np.sum(world_raw * world_true, axis=1), -1, 1)))
    assert np.percentile(angle, 99) <= np.percentile(raw, 99) + 0.5  # the conversion is no worse where frames differ


def test_exported_tangents_are_the_frame_the_normal_map_is_written_in(measured):
    """The exported face's tangents are ∂p/∂u made orthogonal to the normal with w = +1, so glTF's
    bitangent n × t · w is the model's tangent frame's, the one :func:`gltf_normals` re-expresses the
    normal map in (the round trip above)."""
    from mifaces.export import exported_face
    from mifaces.model import load_model

    face = exported_face(measured / "brdf" / "cooktorrance")
    tangent, bitangent, normal = load_model("builtin").tangent_frames()
    np.testing.assert_allclose(face.tangents[:, :3], tangent, atol=1e-6)
    np.testing.assert_allclose(face.normals, normal, atol=1e-6)
    np.testing.assert_allclose(np.cross(face.normals, face.tangents[:, :3]) * face.tangents[:, 3:], bitangent,
                               atol=1e-5)


# --------------------------------------------------------------------------------------------
# One result type: the estimate in memory and the folder it was written to
# --------------------------------------------------------------------------------------------
def test_a_result_folder_reads_back_as_the_estimate_written(small_capture, tmp_path):
    """read_estimate(folder) of a fit is the estimate fit_brdf returned: its model, the region
    parameters and records, the albedo and specular maps (as written, float32); and the face
    exported from either is the same file."""
    from mifaces import brdf
    from mifaces.export import export_face
    from mifaces.reflectance import fit_brdf
    from mifaces.reflectance.io import read_estimate

    capture = small_capture("read_back", measurements=4, resolution=(192, 192), spp=4, albedo_resolution=64, seed=2)
    fitted = fit_brdf(capture, "cooktorrance", out=tmp_path / "ct", progress=False,
                      options=FitOptions(resolution=16, specular_maps=True, interreflection=False))
    read = read_estimate(tmp_path / "ct")
    assert (read.model, read.options, read.measurements) == (fitted.model, fitted.options, fitted.measurements)
    model = brdf.model(fitted.model, **fitted.options)  # values as brdf.json keeps them (RGB as three)
    assert read.regions() == model.validate_regions(fitted.regions())
    assert any(max(p["specular_reflectance"]) > 0 for p in read.regions().values())  # a lobe was measured
    for name, fit in fitted.fits.items():
        np.testing.assert_equal((read.fits[name].params, read.fits[name].status, read.fits[name].loss),
                                (model.validate(fit.params), fit.status, fit.loss))  # (a prior's loss: NaN)
    np.testing.assert_array_equal(read.albedo.albedo, fitted.albedo.albedo.astype(np.float32))
    np.testing.assert_array_equal(read.specular_texture(), fitted.specular_texture().astype(np.float32))
    assert fitted.normal_texture() is not None  # per-texel normals, the default: written and read back
    np.testing.assert_allclose(read.normal_texture(), fitted.normal_texture(), atol=1e-6)
    (memory,) = export_face(fitted, tmp_path / "memory.glb", source=str(tmp_path / "ct"))
    (folder,) = export_face(tmp_path / "ct", tmp_path / "folder.glb")
    assert memory.read_bytes() == folder.read_bytes()


def test_a_new_brdf_model_is_exported_without_export_knowing_it(monkeypatch, tmp_path):
    """A model class defined here (a Blinn lobe), registered for the test only: exported through
    the base class's mapping (the nearest GGX lobe), export/ never told its name."""
    import drjit as dr
    import mitsuba as mi
    import pygltflib

    from mifaces import brdf
    from mifaces.brdf.model import BRDFModel, Parameter, power
    from mifaces.export import export_face
    from mifaces.reflectance.fit.region_fit import RegionFit
    from mifaces.reflectance.maps.diffuse import DiffuseMap
    from mifaces.reflectance.result import BRDFEstimate

    class Blinn(BRDFModel):
        name, title = "blinn_test", "Blinn (test)"

        def specular_parameters(self):
            return (Parameter("specular_reflectance", "rgb", 0.1, 0.0, 1.0, "scale"),
                    Parameter("exponent", "float", 40.0, 1.0, 1e4, "Blinn exponent"))

        def specular(self, wi, wo, params):
            h = dr.normalize(wi + wo)
            n = params["exponent"]
            return mi.Color3f(params["specular_reflectance"]) * (n + 8.0) / (8.0 * dr.pi) * power(h.z, n)

    mifaces.set_variant("llvm_ad_rgb")
    monkeypatch.setitem(brdf.MODELS, Blinn.name, Blinn)
    params = {"specular_reflectance": [0.2, 0.15, 0.1], "exponent": 60.0}
    fit = RegionFit(Blinn.name, {}, dict(params, diffuse_reflectance=[0.5, 0.4, 0.3]), 0.0, 1, 0.0, "converged", "",
                    1)
    albedo = np.full((16, 16, 3), 0.4, np.float32)
    estimate = BRDFEstimate(Blinn.name, {}, {"skin": fit}, DiffuseMap(albedo, None, None), None, 1, ("m",))
    (glb,) = export_face(estimate, tmp_path / "face.glb")
    lobe = Blinn().gltf_lobe(params)
    assert 0.02 < lobe.alpha < 0.5 and np.all(np.diff(lobe.f0) < 0) and 0 < lobe.f90 <= 1
    document = pygltflib.GLTF2().load(str(glb))
    assert document.extras["mifaces"]["model"] == Blinn.name


# --------------------------------------------------------------------------------------------
# Bad result sets: a clear error, nothing written
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("damage", ["changed", "missing", "no manifest"])
def test_incomplete_or_mixed_result_is_refused(measured, tmp_path, damage):
    from mifaces.export import export_face
    from mifaces.io.result_set import SET_MANIFEST, ResultSetError

    result = tmp_path / "cooktorrance"
    shutil.copytree(measured / "brdf" / "cooktorrance", result)
    if damage == "changed":
        shutil.copy(measured / "brdf" / "phong" / "albedo.exr", result / "albedo.exr")  # another run's map
        match = "albedo.exr is not the file written with the rest"
    elif damage == "missing":
        next((result / "meshes").glob("*.ply")).unlink()
        match = "of the result set is missing"
    else:
        (result / SET_MANIFEST).unlink()
        match = "no result-set manifest"
    if damage == "changed" and json.loads((result / SET_MANIFEST).read_text())["files"]["albedo.exr"] == \
            json.loads((measured / "brdf" / "phong" / SET_MANIFEST).read_text())["files"]["albedo.exr"]:
        pytest.fail("the two models' albedo maps are identical: the test cannot mix them")
    for suffix in (".glb", ".obj", ".usdc"):
        with pytest.raises(ResultSetError, match=match):
            export_face(result, tmp_path / "out" / f"face{suffix}")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


# --------------------------------------------------------------------------------------------
# report.html in a real browser
# --------------------------------------------------------------------------------------------
#: Window of the headless browser, and the square (x0, y0, x1, y1, CSS px) where the page's 3D view shows the face.
WINDOW = (900, 900)
FACE_BOX = (270, 360, 450, 540)


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if shutil.which(name):
            return shutil.which(name)
    pytest.skip("no chromium: report.html is not opened in a browser (skipped; apt-get install chromium)")


def test_report_html_shows_the_face_in_3d_in_a_browser(measured, tmp_path):
    """measure writes report.html and face.glb; headless Chromium opens the page from disk, renders the
    face in <model-viewer> (WebGL on SwiftShader) and logs no console error; nothing comes from the internet."""
    import re

    import skimage.io

    page = measured / "report.html"
    text = page.read_text()
    assert (measured / "face.glb").is_file() and (measured / "model-viewer-umd.min.js").is_file()
    assert "<model-viewer" in text and "camera-controls" in text and "data:model/gltf-binary;base64," in text
    assert "<table>" in text and 'src="report.png"' in text
    assert not re.search(r"""(src|href)=["']https?:""", text)  # nothing loaded from the internet
    browser = _chromium()
    shot = tmp_path / "report_html.png"
    run = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                          "--enable-unsafe-swiftshader", "--enable-logging=stderr", "--v=0", "--hide-scrollbars",
                          f"--window-size={WINDOW[0]},{WINDOW[1]}", "--virtual-time-budget=20000",
                          f"--screenshot={shot}", page.as_uri()], capture_output=True, text=True, timeout=180)
    assert shot.is_file(), run.stderr[-2000:]
    console = [line for line in run.stderr.splitlines() if ":CONSOLE" in line and "GL Driver Message" not in line]
    problems = [line for line in console if re.search(r"error|uncaught|failed|refused", line, re.I)]
    assert not problems, problems
    image = skimage.io.imread(shot)[:, :, :3].astype(np.float64)
    x0, y0, x1, y1 = FACE_BOX
    face = image[y0:y1, x0:x1]
    shaded = np.mean(np.min(face, axis=2) < 235)  # not the white page: the face is drawn there
    assert shaded > 0.8, shaded
    assert face.std(axis=(0, 1)).mean() > 3  # shading and texture, not a flat fill
    assert np.mean(np.min(image[:, 700:], axis=2) > 250) > 0.6  # the page beside the view stays background
