"""The whole pipeline: capture -> fitted shapes -> BRDFs -> report, from the API and the CLI."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import skimage.io
from mifaces.options.measure import MeasureOptions
from mifaces.reflectance import FitOptions


@pytest.fixture(scope="module")
def capture_dir(small_capture):
    return small_capture("pipeline", measurements=2, resolution=(256, 256), spp=8, albedo_resolution=128, seed=4)


def test_measure_writes_a_report(capture_dir, tmp_path):
    import mifaces
    from mifaces.pipeline.measure import measure
    from mifaces.runtime.status import BRDF_STATUSES

    mifaces.set_variant("llvm_ad_rgb")
    report = measure(tmp_path / "m", capture_dir, models=("cooktorrance", "phong"), geometry="ground-truth", spp=4,
                     progress=False, options=FitOptions(resolution=128))
    for name in ("report.json", "report.md", "report.png", "report_training.png", "brdf/cooktorrance/brdf.json",
                 "brdf/phong/scene.xml", "report_uncertainty.png", "brdf/cooktorrance/albedo_std.exr"):
        assert (tmp_path / "m" / name).is_file(), name
    saved = json.loads((tmp_path / "m" / "report.json").read_text())
    assert saved == json.loads(json.dumps(report))  # the file is the report returned
    assert set(saved["models"]) == {"cooktorrance", "phong"}
    # the options recorded whole, as they ran (the keywords made them) and as the fits' plan resolved them
    ran = MeasureOptions(models=("cooktorrance", "phong"), geometry="ground-truth", spp=4,
                         fit=FitOptions(resolution=128))
    assert MeasureOptions.from_record(saved["options"]["requested"]) == ran
    assert MeasureOptions.from_record(saved["options"]["effective"]) == ran.resolved()
    brdf = json.loads((tmp_path / "m" / "brdf" / "phong" / "brdf.json").read_text())
    assert FitOptions.from_record(brdf["fit_options"]["requested"]) == ran.fit
    assert saved["models"]["phong"]["fit_options"] == brdf["fit_options"]
    for model, entry in saved["models"].items():
        assert set(entry["regions"]) == set(entry["fit"])
        assert {fit["status"] for fit in entry["fit"].values()} <= set(BRDF_STATUSES)
        assert entry["fit"]["skin"]["samples"] > 1000 and entry["fit"]["skin"]["status"] != "prior"
        # the fitted face rendered under the photograph's light reproduces it, not just anything
        assert 0 < entry["training_rmse"] < 0.5
        # a simulated capture: the measures that separate the models, against the ground truth
        validation = entry["validation"]
        assert set(validation["brdf_rmse"]) >= {"skin"} and validation["heldout_rmse"] > 0
        assert all(np.isfinite(validation[k]) for k in ("albedo_rmse", "heldout_rmse", "environment_rmse"))
    assert saved["validation"]["truth_model"] == "cooktorrance" and saved["validation"]["environments"] == ["studio",
                                                                                                            "sky"]
    for key in ("heldout_rmse", "environment_rmse"):
        order = saved["ranking"][key]
        assert sorted(order) == ["cooktorrance", "phong"]
        assert saved["models"][order[0]]["validation"][key] <= saved["models"][order[1]]["validation"][key]
        # each pair of the ranking measured twice, with other random numbers the second time: a tie or not
        (pair,) = saved["ties"][key]
        again = [saved["models"][m]["validation"]["replicate"][key] for m in order]
        assert pair["noise"] == pytest.approx(abs(pair["margin"] - (again[1] - again[0])))
        assert pair["tie"] == (pair["margin"] + again[1] - again[0] <= 2 * pair["noise"])
    # every fitted parameter's uncertainty, in report.json and brdf.json alike
    skin_fit = saved["models"]["cooktorrance"]["regions"]["skin"]
    skin_unc = saved["models"]["cooktorrance"]["uncertainty"]["skin"]
    lo, hi = skin_unc["diffuse_reflectance"]["interval95"]
    albedo = saved["models"]["cooktorrance"]["fit"]["skin"]["diffuse_reflectance"]
    assert all(a < v < b for a, v, b in zip(lo, albedo, hi)) and min(skin_unc["diffuse_reflectance"]["std"]) > 0
    # a parameter at its bound is flagged, with no interval made up; one inside its range has an interval
    # around its value; the fixed eta says so
    if skin_fit["roughness"] == pytest.approx(1.0, rel=1e-3):
        assert skin_unc["roughness"] == {"status": "at_bound"}
    else:
        lo, hi = skin_unc["roughness"]["interval95"]
        assert lo < skin_fit["roughness"] < hi and skin_unc["roughness"]["std"] > 0
    assert skin_unc["eta"] == {"status": "fixed"}
    written = json.loads((tmp_path / "m" / "brdf" / "cooktorrance" / "brdf.json").read_text())
    assert written["uncertainty"] == saved["models"]["cooktorrance"]["uncertainty"]
    markdown = (tmp_path / "m" / "report.md").read_text()
    assert "specular_reflectance [" in markdown and " ± " in markdown
    assert "eta 1.38 (fixed)" in markdown
    skin = saved["models"]["cooktorrance"]["ground_truth"]["regions"]["skin"]
    assert skin["roughness"] < 0.3  # a 2-photograph, 128² fit: in the right range, not exact
    assert saved["models"]["phong"]["ground_truth"]["regions"] == {}  # another family: no parameter errors
    assert saved["models"]["phong"]["ground_truth"]["albedo"]["rmse_sampled"] < 0.1
    stages = report["seconds"]
    assert set(stages) >= {"reflectance_samples", "fit_brdf_cooktorrance", "fit_brdf_phong", "total"}
    assert stages["total"] >= sum(v for k, v in stages.items() if k != "total") * 0.99
    assert "| cooktorrance | skin |" in markdown and "| phong | skin |" in markdown
    assert "- Ranked by held-out lights:" in markdown and "- Ranked by environments:" in markdown
    picture = skimage.io.imread(tmp_path / "m" / "report_training.png")
    assert picture.shape[0] / picture.shape[1] == pytest.approx(2 / 4, rel=0.1)  # a row of four panels per model
    picture = skimage.io.imread(tmp_path / "m" / "report.png")  # truth and two fits, four conditions
    assert picture.shape[0] / picture.shape[1] == pytest.approx(4 * 2.5 / (3 * 2.6), rel=0.1)
    with pytest.raises(ValueError, match="models must be one or more of"):
        measure(tmp_path / "x", capture_dir, models=("blinn",))
    with pytest.raises(ValueError, match="geometry must be"):
        measure(tmp_path / "x", capture_dir, geometry="guess")


def test_two_photographs_too_few_for_the_texel_fit_keep_the_region_fit(capture_dir, tmp_path):
    """Two photographs at texture 64²: most texels are seen once, and the fit with an albedo per texel
    (the default) finds no lobe on skin. The fit then says so and keeps the region fit, whose skin lobe it
    reports with intervals, and brdf.json says no texel albedo was used."""
    import mifaces
    from mifaces.capture import load_capture
    from mifaces.reflectance import fit_brdf
    from mifaces.shape.io import load_geometry

    mifaces.set_variant("llvm_ad_rgb")
    capture = load_capture(capture_dir)
    face, shapes = load_geometry(capture, "ground-truth")
    with pytest.warns(UserWarning, match="measured no lobe on skin"):
        default = fit_brdf(capture, "ward", shapes, face_model=face, progress=False, out=tmp_path / "w",
                           options=FitOptions(resolution=64))
    region = fit_brdf(capture, "ward", shapes, face_model=face, progress=False,
                      options=FitOptions(resolution=64, texel_albedo=False))
    skin = default.fits["skin"]
    np.testing.assert_allclose(skin.params["specular_reflectance"], region.fits["skin"].params["specular_reflectance"],
                               rtol=1e-3, atol=1e-4)  # refitted from it
    assert np.max(skin.params["specular_reflectance"]) > 0 and "alpha" in skin.uncertainty
    written = json.loads((tmp_path / "w" / "brdf.json").read_text())
    assert written["texel_albedo"] is False
    # asked for, and left out: brdf.json records both
    assert FitOptions.from_record(written["fit_options"]["requested"]) == FitOptions(resolution=64)
    # (per-texel normals, the default, need three samples of a texel: left out too)
    assert FitOptions.from_record(written["fit_options"]["effective"]) == FitOptions(resolution=64, texel_albedo=False,
                                                                                     normals=False)


def test_cli_measure_prints_skin_and_errors(capture_dir, tmp_path):
    """The main job's command line: each model's skin parameters with their ground-truth error, and the report."""
    from click.testing import CliRunner

    from mifaces.cli.commands import main

    out = tmp_path / "cli"
    result = CliRunner().invoke(main, ["--variant", "llvm_ad_rgb", "measure", str(capture_dir), "--out", str(out),
                                       "--brdf", "ward", "--geometry", "ground-truth", "--resolution", "64"])
    assert result.exit_code == 0, result.output
    line = next(line for line in result.output.splitlines() if line.startswith("ward"))
    assert "skin:" in line and "alpha=" in line and "specular_reflectance=[" in line
    assert "vs ground truth" not in line  # the truth is Cook-Torrance: no parameter errors for Ward
    assert f"report: {out}/report.md" in result.output
    recorded = json.loads((out / "report.json").read_text())["options"]["requested"]
    assert MeasureOptions.from_record(recorded) == MeasureOptions(models=("ward",), geometry="ground-truth",
                                                                  fit=FitOptions(resolution=64))
    assert ("ranked by held-out lights (novel pose, relative image RMSE; ≈: within the renders' noise): ward "
            in result.output)
    assert json.loads((out / "report.json").read_text())["models"].keys() == {"ward"}


def test_novel_light_is_not_a_capture_light(capture_dir):
    from mifaces.capture import load_capture
    from mifaces.validation.held_out import novel_light

    capture = load_capture(capture_dir)
    centre = np.zeros(3)
    novel = novel_light(capture, centre)
    light = novel.position
    np.testing.assert_array_equal(novel.intensity, capture.lights[0].intensity)
    for lamp in capture.lights:
        cos = light @ lamp.position / (np.linalg.norm(light) * np.linalg.norm(lamp.position))
        assert cos < np.cos(np.radians(10))
    distances = [np.linalg.norm(lamp.position) for lamp in capture.lights]
    assert np.linalg.norm(light) == pytest.approx(np.mean(distances), rel=0.3)


def test_novel_direction_for_directional_lights(capture_dir):
    """A capture lit by directional lights gets a novel direction, unit, away from every capture light."""
    import dataclasses

    from mifaces.capture import load_capture
    from mifaces.lights.emitters import light_record
    from mifaces.validation.held_out import novel_light

    capture = load_capture(capture_dir)
    lights = tuple(dataclasses.replace(lamp, position=None, direction=lamp.position / np.linalg.norm(lamp.position))
                   for lamp in capture.lights)
    capture = dataclasses.replace(capture, lights=lights)
    novel = novel_light(capture, np.zeros(3))
    assert set(light_record(novel)) == {"light_direction", "intensity"}
    direction = novel.direction
    assert np.linalg.norm(direction) == pytest.approx(1.0)
    for lamp in lights:
        assert direction @ lamp.direction < np.cos(np.radians(10))


def test_cli_fit_shape_then_fit_brdf_on_the_fitted_shape(capture_dir, tmp_path):
    """fit-shape writes a shape that fit-brdf samples reflectance on."""
    from click.testing import CliRunner

    from mifaces.cli.commands import main

    runner = CliRunner()
    shapes = tmp_path / "shapes"
    result = runner.invoke(main, ["--variant", "llvm_ad_rgb", "fit-shape", str(capture_dir), "--out", str(shapes),
                                  "--measurements", "m00", "--iterations", "0.25"])
    assert result.exit_code == 0, result.output
    assert "m00: converged" in result.output
    index = json.loads((shapes / "shapes.json").read_text())
    assert index["model_source"] == "builtin"
    result = runner.invoke(main, ["--variant", "llvm_ad_rgb", "fit-brdf", str(capture_dir), "--brdf", "ward",
                                  "--geometry", str(shapes), "--out", str(tmp_path / "brdf"), "--resolution", "48"])
    assert result.exit_code == 0, result.output
    data = json.loads((tmp_path / "brdf" / "brdf.json").read_text())
    assert data["measurements"] == ["m00"] and data["fit"]["skin"]["samples"] > 100
    missing = runner.invoke(main, ["fit-brdf", str(capture_dir), "--geometry", str(tmp_path), "--out",
                                   str(tmp_path / "x")])
    assert missing.exit_code == 1 and "no fitted shapes" in missing.output and "Traceback" not in missing.output


def test_measure_names_the_failed_shape_fits(capture_dir, tmp_path, monkeypatch):
    """Without one usable shape fit, measure stops with a message naming each fit's status and reason,
    before any reflectance stage runs."""
    import mifaces.pipeline.measure as pipeline
    from mifaces.shape import ShapeFit

    def failing(capture, model, **options):
        return [ShapeFit(measurement=m.name, status="not_converged", vertices_world=None, vertices_camera=None,
                         coefficients=np.zeros(1), expression=np.zeros(0), color=None, albedo=None,
                         rotation=np.eye(3), translation=np.zeros(3), yaw_pitch_roll=np.zeros(3),
                         focal_length=np.ones(2), light={}, loss={}, iterations=1, seconds=0.0,
                         message="feature points end 2.6 px RMS from their targets")
                for m in capture.measurements]

    def never(*args, **kwargs):
        raise AssertionError("reflectance sampled without geometry")

    monkeypatch.setattr(pipeline, "fit_shape", failing)
    monkeypatch.setattr(pipeline, "capture_samples", never)
    with pytest.raises(pipeline.NoUsableShapeError, match=r"m00: not_converged \(feature points end 2.6 px"):
        pipeline.measure(tmp_path / "m", capture_dir, models=("ward",), progress=False)


def test_measure_refines_the_shapes_when_asked(capture_dir, tmp_path, monkeypatch):
    """measure(refine_shape=True): a first fit lights the faces, the refinement runs against the
    photographs and the report says whether it was kept and why (a short schedule here)."""
    import mifaces
    import mifaces.pipeline.measure as pipeline
    from mifaces.refine.shape import ShapeRefineSchedule
    from mifaces.refine.shape_lit import refine_lit

    mifaces.set_variant("llvm_ad_rgb")
    calls = []

    def short(capture, shapes, face, samples, model, resolution, schedule=None, **kw):
        calls.append((model, schedule))
        return refine_lit(capture, shapes, face, samples, model, resolution,
                          dataclasses.replace(schedule, iterations=2, downsample=4), **kw)

    monkeypatch.setattr(pipeline, "refine_lit", short)
    asked = ShapeRefineSchedule(judged=1)  # as --refine-shape-judged 1 asks
    report = pipeline.measure(tmp_path / "m", capture_dir, models=("phong",), geometry="ground-truth", spp=2,
                              progress=False, refine_shape=asked, options=FitOptions(resolution=64))
    assert calls == [("phong", asked)]
    refinement = report["shape_refinement"]
    assert refinement["judged_photographs"] == []  # two photographs: none to spare for judging
    assert isinstance(refinement["accepted"], bool) and refinement["reason"] and refinement["model"] == "phong"
    assert report["seconds"]["refine_shape"] > 0
    if refinement["accepted"]:
        assert "shape_errors_refined" in report


def test_measure_writes_the_refined_shapes_it_fits_on(capture_dir, tmp_path, monkeypatch):
    """measure(refine_shape=True) on fitted shapes: an accepted refinement's faces are written to
    RES/shapes_refined (the layout of RES/shapes, loadable as --geometry), the model fit stays in
    RES/shapes; a refinement not accepted writes none."""
    import mifaces
    import mifaces.pipeline.measure as pipeline
    from mifaces.capture import load_capture
    from mifaces.shape.io import load_geometry
    from mifaces.refine.shape import ShapeRefinement

    mifaces.set_variant("llvm_ad_rgb")
    lift = np.array([0.0, 0.5, 0.0])

    def lifted(capture, shapes, face, samples, model, resolution, **kw):
        return ShapeRefinement({k: np.asarray(v, np.float32) + lift for k, v in shapes.items()},
                               np.zeros(face.vertex_count, np.float32), True, "the held-out loss fell (test)")

    monkeypatch.setattr(pipeline, "refine_lit", lifted)
    out = tmp_path / "m"
    report = pipeline.measure(out, capture_dir, models=("phong",), spp=2, progress=False, refine_shape=True,
                              shape_iterations=0.25, options=FitOptions(resolution=48))
    assert report["shape_refinement"]["shapes"] == pipeline.REFINED_SHAPES
    capture = load_capture(capture_dir, detect=False)
    _, fitted = load_geometry(capture, out / pipeline.SHAPES)
    _, refined = load_geometry(capture, out / pipeline.REFINED_SHAPES)
    assert set(refined) == set(fitted) and fitted
    for name in fitted:
        np.testing.assert_allclose(refined[name] - fitted[name], np.broadcast_to(lift, fitted[name].shape), atol=1e-3)

    def refused(capture, shapes, face, samples, model, resolution, **kw):
        return ShapeRefinement(dict(shapes), np.zeros(face.vertex_count, np.float32), False, "no gain (test)")

    monkeypatch.setattr(pipeline, "refine_lit", refused)
    again = pipeline.measure(tmp_path / "n", capture_dir, models=("phong",), spp=2, progress=False, refine_shape=True,
                             shape_iterations=0.25, options=FitOptions(resolution=48))
    assert not again["shape_refinement"]["accepted"] and not (tmp_path / "n" / pipeline.REFINED_SHAPES).exists()


def test_measure_with_unknown_lights_checks_before_fitting(capture_dir, tmp_path, monkeypatch):
    """Unknown lights are estimated with the fitted faces: measure refuses the true geometry, and a
    light it cannot estimate (an environment map seen in one pose), naming the lights, before any fit runs."""
    import shutil

    import mifaces.pipeline.measure as pipeline
    from mifaces.capture import MANIFEST
    from mifaces.light_estimation.unknown import UnknownLightError

    def never(*args, **kwargs):
        raise AssertionError("fitted before the lights were checked")

    monkeypatch.setattr(pipeline, "fit_shape", never)
    copy = tmp_path / "capture"
    shutil.copytree(capture_dir, copy)
    data = json.loads((copy / MANIFEST).read_text())
    names = [light["name"] for light in data["lights"]]
    data["lights"] = [{"name": name, "unknown": True} for name in names]
    (copy / MANIFEST).write_text(json.dumps(data))
    with pytest.raises(ValueError, match=rf"lights \['{names[0]}'.*are unknown: .* geometry must be 'fitted'"):
        pipeline.measure(tmp_path / "m", copy, models=("phong",), geometry="ground-truth", progress=False)
    data["lights"][0]["kind"] = "environment"
    for m in data["measurements"]:  # the environment's photographs all of one pose: its map is not estimable
        if m["light"] == names[0]:
            m["pose"] = "one"
    (copy / MANIFEST).write_text(json.dumps(data))
    with pytest.raises(UnknownLightError, match=rf"\['{names[0]}'\]: their photographs show one pose"):
        pipeline.measure(tmp_path / "m", copy, models=("phong",), progress=False)
