"""Ground truths the fit cannot copy: Mitsuba's built-in BSDFs, spatially varying
parameter maps, and faces outside the model's span (mifaces.brdf.builtin,
mifaces.studio.varying, mifaces.studio.detail).

The simulations share a seed, so two captures differ only by their truth:
same face, lights, poses and noise draws."""

from __future__ import annotations

import json
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

import mifaces  # noqa: F401  # isort: skip
from mifaces.brdf import validate_brdf
from mifaces.brdf.builtin import fresnel_normal
from mifaces.capture import load_capture, read_ground_truth
from mifaces.model import load_model
from mifaces.model.regions import REGIONS, lookup
from mifaces.model.texture_space import rasterize
from mifaces.brdf.model import rgb
from mifaces.render import region_bsdf
from mifaces.studio.detail import span_residual
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate
from mifaces.studio.subsurface import SKIN1, dipole_albedo
from mifaces.studio.truth import COOK_TORRANCE_REGIONS, brdf_with_overrides, default_brdf
from mifaces.studio.varying import VARYING, texel_regions, zone_weights
from mifaces.reflectance import FitOptions

#: Small captures: one measurement, a face about 60 pixels high.
SMALL = dict(measurements=1, resolution=(128, 128), spp=4, companion="diffuse", albedo_resolution=128, seed=3)
_captures: dict[str, Path] = {}


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """name -> capture folder, simulated once: the default truth and each truth outside the fit."""
    mifaces.set_variant("llvm_ad_rgb")

    def make(name: str, **options) -> Path:
        if name not in _captures:
            out = tmp_path_factory.mktemp(name) / "capture"
            simulate(out, SimulationOptions(**SMALL, **options), progress=False)
            _captures[name] = out
        return _captures[name]

    return make


def _photo(path: Path) -> np.ndarray:
    return load_capture(path, calibrate=False).measurements[0].image.pixels


# --------------------------------------------------------------------------------------------
# Built-in BSDFs
# --------------------------------------------------------------------------------------------
def test_builtin_defaults_map_the_published_skin_values():
    rough, principled = default_brdf("roughplastic"), default_brdf("principled")
    for region, ct in COOK_TORRANCE_REGIONS.items():
        rp = rough["regions"][region]
        assert rp["alpha"] == ct["roughness"] and rp["int_ior"] == ct["eta"] and rp["ext_ior"] == 1.0
        assert rp["specular_reflectance"] == ct["specular_reflectance"]
        pr = principled["regions"][region]
        assert pr["roughness"] == pytest.approx(np.sqrt(ct["roughness"]), abs=1e-5)
        assert pr["specular"] == pytest.approx(ct["specular_reflectance"][0] * fresnel_normal(ct["eta"]) / 0.08,
                                               abs=1e-5)
    assert validate_brdf(rough) == rough and rough["options"] == {"distribution": "beckmann", "nonlinear": False}


@pytest.mark.parametrize("overrides, message", [
    ({"model": "roughplastic", "regions": {"skin": {"roughness": 0.3}}}, "roughplastic has no parameter 'roughness'"),
    ({"model": "roughplastic", "regions": {"skin": {"alpha": 3.0}}}, r"alpha = 3.0 is outside \[0.001, 1.0\]"),
    ({"model": "roughplastic", "regions": {"skin": {"diffuse_reflectance": 0.5}}}, "the albedo map"),
    ({"model": "principled", "regions": {"skin": {"base_color": 0.5}}}, "base_color is the albedo map"),
    ({"model": "principled", "regions": {"skin": {"metallic": -0.1}}}, "metallic = -0.1 is outside"),
    ({"model": "principled", "regions": {"skin": {"eta": 1.4, "specular": 0.3}}}, "eta or specular, not both"),
    ({"model": "roughplastic", "options": {"distribution": "phong"}}, "distribution = 'phong'; allowed"),
    ({"model": "roughplastic", "regions": {"chin": {"alpha": 0.3}}}, "unknown region 'chin'"),
])
def test_builtin_overrides_are_validated(overrides, message):
    with pytest.raises(ValueError, match=message):
        brdf_with_overrides("cooktorrance", overrides)


def test_builtin_overrides_replace_the_defaults():
    truth = brdf_with_overrides("roughplastic", {"regions": {"lips": {"alpha": 0.2}},
                                                 "options": {"distribution": "ggx"}})
    assert truth["regions"]["lips"]["alpha"] == 0.2 and truth["regions"]["lips"]["int_ior"] == 1.38
    assert truth["options"]["distribution"] == "ggx"
    # principled's eta replaces its specular default (Mitsuba takes one of the two)
    principled = brdf_with_overrides("principled", {"regions": {"skin": {"eta": 1.45}}})
    assert principled["regions"]["skin"]["eta"] == 1.45 and "specular" not in principled["regions"]["skin"]


@pytest.mark.parametrize("model, albedo", [("roughplastic", "diffuse_reflectance"), ("principled", "base_color")])
def test_region_bsdf_builds_builtins_over_any_albedo(model, albedo):
    """None, an rgb dict or a texture as the albedo; the result loads in Mitsuba
    and, lit and seen the same way, differs from the Cook–Torrance truth."""
    mifaces.set_variant("llvm_ad_rgb")
    truth = default_brdf(model)
    assert albedo not in region_bsdf(truth, "skin", None)
    d = region_bsdf(truth, "skin", rgb(0.5))
    assert d["type"] == model and d[albedo] == rgb(0.5)
    theta = np.radians(np.linspace(5, 75, 8))
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(np.sin(theta), 0 * theta, np.cos(theta))
    wo = mi.Vector3f(-np.sin(theta), 0 * theta, np.cos(theta))  # the mirror direction: the highlight
    values = {}
    for name, doc in (("builtin", truth), ("ct", default_brdf("cooktorrance"))):
        bsdf = mi.load_dict(region_bsdf(doc, "skin", rgb(0.5)))
        values[name] = np.array(bsdf.eval(mi.BSDFContext(), si, wo))[0]
    assert np.all(values["builtin"] > 0)
    assert np.max(np.abs(values["builtin"] / values["ct"] - 1)) > 0.05


def test_builtin_truth_photographs_differ_from_cook_torrance(captures):
    plain, rough = captures("plain"), captures("roughplastic", brdf="roughplastic")
    truth = read_ground_truth(rough)
    assert truth.brdf == default_brdf("roughplastic") and truth.description["brdf"] == "roughplastic"
    a, b = _photo(plain), _photo(rough)
    face = a.mean(axis=2) > 0.02 * a.max()
    # the same face under the same light and noise: only the BSDF differs
    assert np.mean(np.abs(a[face] - b[face])) / np.mean(a[face]) > 0.05


# --------------------------------------------------------------------------------------------
# Spatially varying truth
# --------------------------------------------------------------------------------------------
def test_varying_maps_make_the_tzone_shinier_and_smoother(captures):
    path = captures("varying", varying=True)
    truth = read_ground_truth(path)
    model = load_model("builtin")
    scale_name, width_name = VARYING["cooktorrance"]
    scale, width = truth.maps[scale_name], truth.maps[width_name]
    assert scale.shape == width.shape == (SMALL["albedo_resolution"],) * 2 and truth.description["varying"]
    tzone, cheeks = zone_weights(model, truth.neutral, rasterize(model.uv, model.triangles, scale.shape))
    labels = texel_regions(model, scale.shape[0])
    skin = labels == REGIONS["skin"]
    t, c = skin & (tzone > 0.8), skin & (cheeks > 0.8)
    assert t.sum() > 20 and c.sum() > 20
    assert scale[t].mean() > 1.5 * scale[c].mean() and width[t].mean() < 0.75 * width[c].mean()
    # brdf.json gives each region the mean of its texels; other regions keep their values
    assert truth.brdf["regions"]["skin"][width_name] == pytest.approx(width[skin].mean(), abs=1e-3)
    assert np.all(width[labels == REGIONS["eyes"]] == COOK_TORRANCE_REGIONS["eyes"]["roughness"])


def test_varying_truth_brightens_the_tzone_highlight(captures):
    """Against the uniform truth (same face, light and noise), the photograph is
    brighter over the T-zone (forehead, nose), darker over the cheeks: the mean
    difference over the pixels their vertices project to."""
    plain, varying = captures("plain"), captures("varying", varying=True)
    difference = _photo(varying).mean(axis=2) - _photo(plain).mean(axis=2)
    truth = read_ground_truth(varying)
    model = load_model("builtin")
    weights = zone_weights(model, truth.neutral, rasterize(model.uv, model.triangles, (256, 256)))
    on_skin = lookup(model.region_map, model.uv) == REGIONS["skin"]
    means = []
    for weight in weights:
        vertices = truth.measurements[0].vertices[on_skin & (lookup(weight, model.uv) > 0.8)]
        pixels = np.unique(np.round(truth.camera.project(vertices)).astype(int), axis=0)
        assert len(pixels) > 30
        means.append(float(difference[pixels[:, 1], pixels[:, 0]].mean()))
    tzone, cheeks = means
    assert tzone > 0 > cheeks, (tzone, cheeks)


def test_varying_needs_a_model_with_maps(tmp_path):
    with pytest.raises(ValueError, match="lobe scale and width maps"):
        simulate(tmp_path / "c", SimulationOptions(brdf="phong", varying=True, **SMALL), progress=False)
    assert not (tmp_path / "c").exists()


# --------------------------------------------------------------------------------------------
# Faces outside the model's span
# --------------------------------------------------------------------------------------------
def test_detailed_face_lies_outside_the_model_span(captures):
    plain, detailed = captures("plain"), captures("detail", detail=True)
    model = load_model("builtin")
    a, b = read_ground_truth(plain), read_ground_truth(detailed)
    assert span_residual(model, a.neutral) < 1e-3
    residual = span_residual(model, b.neutral)
    assert residual > 0.5 and b.description["span_residual_mm"] == pytest.approx(residual, abs=1e-3)
    # every measurement's true vertices carry the detail: they differ from the plain face's by it
    offset = np.linalg.norm(b.measurements[0].vertices - a.measurements[0].vertices, axis=1)
    assert 0.3 < np.sqrt(np.mean(offset ** 2)) < 3.0
    face = _photo(plain).mean(axis=2) > 0.02 * _photo(plain).max()
    assert np.mean(np.abs(_photo(plain) - _photo(detailed))[face]) > 0.01 * np.mean(_photo(plain)[face])


def test_measure_runs_on_a_truth_outside_the_fit(tmp_path):
    """The main job on a roughplastic, detailed face fitted with the default model:
    it runs, and reports the albedo error against the truth's map."""
    from mifaces.pipeline.measure import measure

    mifaces.set_variant("llvm_ad_rgb")
    capture = tmp_path / "capture"
    simulate(capture, SimulationOptions(brdf="roughplastic", detail=True, **dict(SMALL, measurements=2)), progress=False)
    report = measure(tmp_path / "m", capture, models=("cooktorrance",), spp=2, shape_iterations=0.2, progress=False,
                     options=FitOptions(resolution=64))
    entry = report["models"]["cooktorrance"]
    assert entry["ground_truth"]["truth_model"] == "roughplastic"
    assert np.isfinite(entry["ground_truth"]["albedo"]["rmse_sampled"])
    assert json.loads((tmp_path / "m" / "report.json").read_text())["measurements"] == 2


# --------------------------------------------------------------------------------------------
# Subsurface truth
# --------------------------------------------------------------------------------------------
def test_dipole_albedo_follows_the_single_scattering_albedo():
    lossless = dipole_albedo({"sigma_s_reduced": (1.0, 1.0, 1.0), "sigma_a": (0.0, 0.0, 0.0)})
    np.testing.assert_allclose(lossless, 1.0)  # nothing absorbed: everything comes back out
    skin = dipole_albedo(SKIN1)
    assert skin[0] > skin[1] > skin[2] > 0.05  # red travels furthest: skin is reddish
    assert 0.3 < skin[0] < 0.7


def test_subsurface_truth_renders_translucent_skin(tmp_path):
    """A tiny translucent capture: volumetric path tracer, the skin's albedo
    recorded as the medium's dipole albedo, and under the uniform light of
    the diffuse companion the skin shows about that albedo (not the opaque
    boundary's few percent of Fresnel reflection)."""
    mifaces.set_variant("llvm_ad_rgb")
    tiny = dict(SMALL, resolution=(64, 64), spp=4, albedo_resolution=64)
    simulate(tmp_path / "c", SimulationOptions(subsurface=True, **tiny), progress=False)
    truth = read_ground_truth(tmp_path / "c")
    model = load_model("builtin")
    assert truth.integrator["type"] == "volpath" and truth.description["subsurface"]["regions"][0] == "skin"
    labels = texel_regions(model, 64)
    expected = dipole_albedo(SKIN1, truth.brdf["regions"]["skin"]["eta"])
    np.testing.assert_allclose(truth.albedo[labels == REGIONS["skin"]].mean(axis=0), expected, rtol=1e-4)
    diffuse = load_capture(tmp_path / "c", calibrate=False).measurements[0].diffuse.pixels
    normals = model.vertex_normals(truth.measurements[0].vertices)
    facing = normals[:, 2] > 0.8  # the camera looks along -z
    on_skin = (lookup(model.region_map, model.uv) == REGIONS["skin"]) & facing
    pixels = np.unique(np.round(truth.camera.project(truth.measurements[0].vertices[on_skin])).astype(int), axis=0)
    pixels = pixels[np.all((pixels >= 0) & (pixels < [diffuse.shape[1], diffuse.shape[0]]), axis=1)]  # the neck leaves the frame
    seen = diffuse[pixels[:, 1], pixels[:, 0]].mean(axis=0)
    # about 1.3-1.6 measured: the boundary's glossy reflection (~0.05) on top, and light leaves the
    # index-matched boundary without total internal reflection; the boundary alone would show ~0.05
    ratio = seen / expected
    assert len(pixels) > 50 and np.all(ratio > 0.9) and np.all(ratio < 2.0), ratio
    with pytest.raises(ValueError, match="subsurface truth"):
        simulate(tmp_path / "d", SimulationOptions(subsurface=True, brdf="roughplastic", **tiny), progress=False)


def test_cli_simulate_offers_the_truths_and_names_bad_combinations(tmp_path):
    from click.testing import CliRunner

    from mifaces.cli.commands import main

    help_text = CliRunner().invoke(main, ["simulate", "--help"]).output
    for option in ("roughplastic", "principled", "--varying", "--detail", "--subsurface"):
        assert option in help_text
    for args, message in ((["--brdf", "roughplastic", "--varying"], "lobe scale and width maps"),
                          (["--brdf", "principled", "--subsurface"], "subsurface truth")):
        result = CliRunner().invoke(main, ["--variant", "llvm_ad_rgb", "simulate", str(tmp_path / "c"), *args])
        assert result.exit_code == 1 and message in result.output, result.output


def test_validation_judges_against_the_truth_with_its_maps(captures):
    """The report's validation renders and evaluates a spatially varying truth with its per-texel
    maps, as the simulator photographed it, not with the region means its brdf.json records: the
    means differ from the truth in images and in BRDF, and agree with a uniform truth exactly."""
    from mifaces.studio.varying import map_textures
    from mifaces.validation.brdf_error import brdf_rmse, region_texels
    from mifaces.validation.validator import SEED, Validator, relative_rmse

    path = captures("varying", varying=True)
    truth = read_ground_truth(path)
    model = load_model("builtin")
    first = truth.measurements[0]
    validator = Validator(load_capture(path), model, first.vertices, first.name, size=48, spp=4,
                          lights=1)
    means = validator.truth_scene.render(truth.brdf, truth.albedo, validator.camera, spp=validator.spp, seed=SEED,
                                         **validator.conditions["light_1"])
    assert relative_rmse(means, validator.truth["light_1"], validator.mask) > 0.01
    labels = texel_regions(model, 64)
    uv = region_texels(labels, REGIONS["skin"])
    albedo = [0.4, 0.3, 0.2]
    maps = map_textures(truth.maps)
    assert brdf_rmse(truth.brdf, truth.brdf, "skin", albedo, albedo, uv, truth_maps=maps) > 0.05
    assert brdf_rmse(truth.brdf, truth.brdf, "skin", albedo, albedo, uv) == 0.0
