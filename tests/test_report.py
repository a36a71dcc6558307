"""The report's validation against a simulated capture's ground truth: BRDF error over the hemisphere,
albedo error, held-out-light and environment-lit image errors in a novel pose (mifaces.validation.validator)."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import dataclasses
import warnings

import numpy as np
import pytest

from mifaces.capture import load_capture, read_ground_truth
from mifaces.shape.io import load_geometry
from mifaces.reflectance import FitOptions, fit_brdf
from mifaces.brdf.hemisphere import hemisphere_grid
from mifaces.validation.brdf_error import brdf_rmse
from mifaces.validation.held_out import held_out_lights, novel_rotation
from mifaces.validation.validator import Validator, relative_rmse

MIN_SEPARATION = 10.0  # degrees between anything held out and anything the fit saw


@pytest.fixture(scope="module")
def capture(small_capture):
    return load_capture(small_capture("report", measurements=3, resolution=(128, 128), spp=4, albedo_resolution=64,
                                      seed=6))


@pytest.fixture(scope="module")
def validator(capture):
    mifaces.set_variant("llvm_ad_rgb")
    face, shapes = load_geometry(capture, "ground-truth")
    first = capture.measurements[0].name
    return Validator(capture, face, shapes[first], first, size=40, spp=4)


@pytest.fixture(scope="module")
def estimate(capture):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit_brdf(capture, "cooktorrance", progress=False, options=FitOptions(resolution=64))


def with_params(estimate, change):
    """``estimate`` with every region's glossy parameters replaced by ``change(region)``."""
    fits = {name: dataclasses.replace(fit, params={**fit.params, **change(name)}) for name, fit in estimate.fits.items()}
    return dataclasses.replace(estimate, fits=fits)


def test_hemisphere_grid_is_stratified_and_cosine_weighted():
    d = hemisphere_grid(16)
    assert d.shape == (256, 3) and np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-5) and d[:, 2].min() > 0
    # under the cosine-weighted measure E[cos θ] = 2/3 and E[cos² θ] = 1/2
    assert d[:, 2].mean() == pytest.approx(2 / 3, abs=0.01)
    assert (d[:, 2] ** 2).mean() == pytest.approx(1 / 2, abs=0.01)


def test_brdf_rmse_is_zero_for_the_truth_and_grows_with_the_error(capture):
    truth = read_ground_truth(capture).brdf
    uv = np.array([[0.5, 0.5]])
    albedo = [0.5, 0.4, 0.3]
    assert brdf_rmse(truth, truth, "skin", albedo, albedo, uv) == 0.0
    skin = truth["regions"]["skin"]
    near = {**truth, "regions": {"skin": {**skin, "roughness": skin["roughness"] * 1.1}}}
    far = {**truth, "regions": {"skin": {**skin, "roughness": skin["roughness"] * 2.0}}}
    e_near, e_far = (brdf_rmse(truth, doc, "skin", albedo, albedo, uv) for doc in (near, far))
    assert 0 < e_near < e_far
    # a wrong albedo level counts: 20 % more diffuse reflectance
    assert brdf_rmse(truth, truth, "skin", albedo, np.multiply(albedo, 1.2), uv) > 0.05


def test_validation_keys_present_and_finite(validator, estimate):
    entry, images = validator.validate(estimate)
    assert set(entry) >= {"brdf_rmse", "albedo_rmse", "heldout_rmse", "environment_rmse", "per_condition"}
    assert "skin" in entry["brdf_rmse"]
    values = [*entry["brdf_rmse"].values(), entry["albedo_rmse"], entry["heldout_rmse"], entry["environment_rmse"],
              *entry["per_condition"].values()]
    assert all(np.isfinite(v) and v >= 0 for v in values)
    assert set(images) == set(validator.truth) == {"light_1", "light_2", "studio", "sky"}
    for name, image in images.items():
        assert image.shape == validator.truth[name].shape and validator.truth[name][validator.mask].mean() > 0
    # the true shape was used: the shape floor is exactly 0, and the reflectance's own error is the image error
    assert validator.summary["shape_floor"]["heldout_rmse"] == 0.0
    assert entry["heldout_rmse_true_shape"] == entry["heldout_rmse"]
    # the same errors with the random numbers drawn again: close (the renders' noise), not the same
    again = entry["replicate"]
    assert set(again) == {"heldout_rmse", "environment_rmse", "heldout_rmse_true_shape", "environment_rmse_true_shape"}
    assert again["heldout_rmse"] != entry["heldout_rmse"]
    assert again["heldout_rmse"] == pytest.approx(entry["heldout_rmse"], rel=0.5)


def test_noise_floor_is_the_renders_monte_carlo_noise(validator, capture):
    """The noise floor (the truth against itself with other random numbers) is positive under every
    condition and falls as the samples per pixel grow (about 1/sqrt(spp))."""
    face, shapes = load_geometry(capture, "ground-truth")
    first = capture.measurements[0].name
    noise = validator.summary["noise_floor"]
    assert all(v > 0 for v in noise["per_condition"].values())
    finer = Validator(capture, face, shapes[first], first, size=40, spp=16).summary["noise_floor"]
    assert finer["heldout_rmse"] < 0.75 * noise["heldout_rmse"]
    assert finer["environment_rmse"] < 0.75 * noise["environment_rmse"]


def test_wrong_parameters_score_worse_than_true_ones(validator, estimate, capture):
    """The fit given the true glossy parameters scores better than the fit given wrong ones, in BRDF and image error."""
    truth = read_ground_truth(capture).brdf["regions"]
    right = with_params(estimate, lambda region: truth[region])
    wrong = with_params(estimate, lambda region: {"roughness": 0.9 * truth[region]["roughness"] + 0.5,
                                                  "specular_reflectance": [0.2] * 3})
    good, _ = validator.validate(right)
    bad, _ = validator.validate(wrong)
    assert good["brdf_rmse"]["skin"] < 0.5 * bad["brdf_rmse"]["skin"]
    assert good["heldout_rmse"] < bad["heldout_rmse"]
    assert good["environment_rmse"] < bad["environment_rmse"]
    assert good["albedo_rmse"] == bad["albedo_rmse"]  # the same albedo map


def test_held_out_lights_and_view_were_never_photographed(validator, capture):
    """Every held-out light is at least MIN_SEPARATION from every capture light, and the novel pose from every
    photographed pose: the fit never saw them."""
    summary = validator.summary
    centre = np.mean([m.vertices.mean(axis=0) for m in read_ground_truth(capture).measurements], axis=0)
    used = np.array([light.position for light in capture.lights]) - centre
    used /= np.linalg.norm(used, axis=1, keepdims=True)
    for light in summary["held_out_lights"]:
        assert light["angle_to_capture"] > MIN_SEPARATION
        towards = np.asarray(light["light_position"]) - centre
        angles = np.degrees(np.arccos(np.clip(used @ (towards / np.linalg.norm(towards)), -1, 1)))
        assert angles.min() > MIN_SEPARATION - 2  # measured from the mean head centre, not the validation's
    assert summary["novel_pose_angle_to_capture"] > MIN_SEPARATION
    assert held_out_lights(capture, centre, 1)[0][1] > MIN_SEPARATION
    assert np.allclose(novel_rotation(capture.camera, (0.0, 0.0)), np.eye(3))


def test_relative_rmse_and_bad_requests(capture):
    truth = np.ones((4, 4, 3))
    mask = np.zeros((4, 4), bool)
    mask[1:3, 1:3] = True
    assert relative_rmse(truth * 1.1, truth, mask) == pytest.approx(0.1)
    face, shapes = load_geometry(capture, "ground-truth")
    first = capture.measurements[0].name
    with pytest.raises(ValueError, match="at least one environment"):
        Validator(capture, face, shapes[first], first, environments={})


def test_a_fitted_shape_is_told_apart_from_the_reflectance(capture, estimate):
    """On a shape 3 mm off, the images carry the shape's error (the shape floor); the fitted reflectance rendered
    on the true shape still tells true parameters from wrong ones."""
    face, shapes = load_geometry(capture, "ground-truth")
    first = capture.measurements[0].name
    shifted = Validator(capture, face, shapes[first] + [3.0, 0.0, 0.0], first, size=40, spp=4)
    floor = shifted.summary["shape_floor"]
    assert floor["heldout_rmse"] > 0.02 and floor["environment_rmse"] > 0.02
    truth = read_ground_truth(capture).brdf["regions"]
    good, _ = shifted.validate(with_params(estimate, lambda region: truth[region]))
    bad, _ = shifted.validate(with_params(estimate, lambda region: {"roughness": 0.9 * truth[region]["roughness"] + 0.5,
                                                                    "specular_reflectance": [0.2] * 3}))
    assert good["heldout_rmse_true_shape"] < good["heldout_rmse"]
    assert good["heldout_rmse_true_shape"] < bad["heldout_rmse_true_shape"]
    assert good["environment_rmse_true_shape"] < bad["environment_rmse_true_shape"]


def test_report_names_every_fit_that_did_not_simply_converge(tmp_path):
    """report.md lists each region whose fit ended at a bound, at its start values, borrowed or at the
    defaults, with the reason; a converged region is not listed (issue 27)."""
    from mifaces.report.measurement import write_markdown

    statuses = {"skin": ("converged", "relative loss decrease below ftol"),
                "nostrils": ("at_start", "converged; the glossy parameters stayed at their start values"),
                "lips": ("at_bound", "converged; at the bound of its range: exponent"),
                "eyes": ("defaults", "0 samples, fewer than the 70 a phong fit needs: the model's defaults")}
    fit = {name: {"samples": 100, "status": status, "reason": reason, "loss": 0.1}
           for name, (status, reason) in statuses.items()}
    report = {"capture": "c", "measurements": 2, "geometry": "ground-truth", "resolution": 16,
              "models": {"phong": {"regions": {name: {"exponent": 30.0} for name in fit}, "fit": fit,
                                   "training_rmse": 0.1}},
              "seconds": {"fit_brdf_phong": 1.0}}
    write_markdown(tmp_path / "report.md", report, "m00")
    text = (tmp_path / "report.md").read_text()
    notes = text[text.index("did not simply converge"):].splitlines()
    for name, (status, reason) in statuses.items():
        listed = [line for line in notes if line.startswith(f"- phong / {name}:")]
        assert listed == ([] if status == "converged" else [f"- phong / {name}: **{status}**: {reason}"])


def test_report_gives_each_fitted_shape_its_errors_and_the_modes_used():
    """report.md's shape section: the identity modes of the fit and of the simulated truth, and per
    photograph the status, both convergence measures, its reprojection in its own camera and the errors
    in the world frame; per camera its reprojection error, and for one camera the depth it cannot fix."""
    from mifaces.report.measurement import shapes_markdown

    report = {"face_model": {"name": "builtin", "model_shape_modes": 100, "fit_shape_modes": 50,
                             "truth_shape_modes": 100, "truth_detail": True},
              "shapes": {"m00": {"status": "converged", "feature_rms_px": 0.81, "image_rms": 0.0312,
                                 "reprojection_px": 0.456,
                                 "errors": {"world_mm": 2.5, "aligned_mm": 1.2, "depth_mm": -2.25,
                                            "scale_pct": -0.19, "scaled_mm": 1.3, "similarity_mm": 0.777}},
                         "m01": {"status": "not_converged", "feature_rms_px": 0.7, "image_rms": 0.2}}}
    text = "\n".join(shapes_markdown(report))
    assert "leading 50 of its 100 identity modes" in text and "drew on 100 plus fine detail" in text
    assert "| m00 | converged | 0.81 | 0.46 | 0.031 | 2.50 | 1.20 | -2.25 | -0.19 | 1.30 | 0.78 |  |" in text
    assert "| m01 | not_converged | 0.70 |  | 0.200 |  |  |  |  |  |  |  |" in text
    assert "per camera" not in text and "One camera" not in text
    rig = dict(report, cameras={"c0": {"reprojection_px": 0.35, "photographs": 6},
                                "c1": {"reprojection_px": 0.41, "photographs": 6}})
    assert "c0 0.35 px (6 photographs), c1 0.41 px (6 photographs)" in "\n".join(shapes_markdown(rig))
    one = dict(report, depth={"depth_sd_mm": 12.34, "relative_size_sd": 0.0102, "size_from": "metric distances",
                              "camera_distance_mm": 1210.0})
    text = "\n".join(shapes_markdown(one))
    assert "not observable from one camera" in text and "metric distances, known to 1.0 %" in text
    assert "leaves 12.3 mm (1 sd) along the camera's axis at 1210 mm" in text
    assert shapes_markdown({"shapes": {}}) == []  # true shapes: nothing fitted, no section


def _validated(heldout: float, again: float) -> dict:
    return {"validation": {"heldout_rmse": heldout, "replicate": {"heldout_rmse": again}}}


def test_ranking_calls_a_tie_within_the_renders_noise():
    from mifaces.report.measurement import ranking, ranking_sentence, ties

    # a and b: 0.2 points apart, but the second draw of random numbers orders them the other way: a tie;
    # b and c: 3 points apart in both draws: c is worse
    models = {"a": _validated(0.140, 0.143), "b": _validated(0.142, 0.141), "c": _validated(0.172, 0.170)}
    order = ranking(models)
    assert order == {"heldout_rmse": ["a", "b", "c"]}
    pairs = ties(models, order)["heldout_rmse"]
    assert [(p["better"], p["worse"], p["tie"]) for p in pairs] == [("a", "b", True), ("b", "c", False)]
    assert pairs[0]["margin"] == pytest.approx(0.002) and pairs[0]["noise"] == pytest.approx(0.004)
    assert pairs[1]["noise"] == pytest.approx(0.001)
    sentence = ranking_sentence(models, order["heldout_rmse"], pairs, "heldout_rmse")
    assert sentence.startswith("a 14.00% ≈ b 14.20% < c 17.20%; a and b tie: 0.20 points apart")
    # the same margin measured alike twice is no tie, and the winner is named
    models["b"] = _validated(0.150, 0.151)
    pairs = ties(models, ranking(models))["heldout_rmse"]
    assert not pairs[0]["tie"]
    assert "a wins by 1.00 points" in ranking_sentence(models, ["a", "b", "c"], pairs, "heldout_rmse")
    # a report without replicates (written before them): no ties claimed, no noise made up
    old = {m: {"validation": {"heldout_rmse": e}} for m, e in (("a", 0.1), ("b", 0.2))}
    assert ties(old, ranking(old))["heldout_rmse"][0] == {"better": "a", "worse": "b", "margin": 0.1, "noise": None,
                                                          "tie": False}
