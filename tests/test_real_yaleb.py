"""validation/real_yaleb.py's error measure: the pooled relative RMSE sqrt(Σ err² / Σ photo²) over the
face's unsaturated pixels of every held-out photograph, pooled over subjects, the best model picked by
its training error (:func:`mifaces.validation.validator.relative_rmse`), never by the held-out one;
each against sums written out here."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np
import pytest

from mifaces.validation.validator import relative_rmse

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def real_yaleb():
    spec = importlib.util.spec_from_file_location("real_yaleb", ROOT / "validation" / "real_yaleb.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _held_out(rng, count=3, shape=(12, 10)):
    """Photographs, predictions and valid masks; outside the mask the prediction is far off."""
    photos = [rng.uniform(0.1, 0.9, shape) for _ in range(count)]
    valid = [rng.uniform(size=shape) > 0.3 for _ in range(count)]
    predictions = [np.where(v, p + rng.normal(0, 0.05 * (k + 1), shape), 5.0) for k, (p, v) in
                   enumerate(zip(photos, valid))]
    return photos, predictions, valid


def test_relative_rmse_is_pooled_over_the_valid_pixels(real_yaleb):
    rng = np.random.default_rng(0)
    photos, predictions, valid = _held_out(rng)
    groups = ["small_shadows", "large_shadows", "large_shadows"]
    errors = real_yaleb.Errors()
    for prediction, photo, v, group in zip(predictions, photos, valid, groups):
        errors.add("model", group, prediction, photo, v)

    def pooled(indices):
        e = sum(np.sum((predictions[i][valid[i]] - photos[i][valid[i]]) ** 2) for i in indices)
        return np.sqrt(e / sum(np.sum(photos[i][valid[i]] ** 2) for i in indices))

    result = errors.relative_rmse()["model"]
    assert result["all"] == pytest.approx(pooled([0, 1, 2]), rel=1e-12)
    assert result["large_shadows"] == pytest.approx(pooled([1, 2]), rel=1e-12)
    assert result["small_shadows"] == pytest.approx(pooled([0]), rel=1e-12)
    # pooled, not the mean of the photographs' own ratios
    assert result["all"] != pytest.approx(np.mean([pooled([i]) for i in range(3)]), rel=1e-3)


def test_summary_pools_subjects_and_picks_the_best_model_by_its_training_error(real_yaleb):
    rng = np.random.default_rng(1)
    models = ["phong", "ward"]
    results, sums = [], {}
    # the first photograph's training_rmse favours ward; every training photograph pooled, phong
    for subject, training in (("a", {"phong": 0.12, "ward": 0.10}), ("b", {"phong": 0.12, "ward": 0.11})):
        photos, predictions, valid = _held_out(rng, count=2)
        errors, training_errors = real_yaleb.Errors(), real_yaleb.Errors()
        for key, scale in (("phong", 2.0), ("ward", 1.0), ("photometric_stereo", 1.5)):
            for prediction, photo, v in zip(predictions, photos, valid):
                prediction = photo + scale * (prediction - photo)  # phong's held-out error the largest
                errors.add(key, "small_shadows", prediction, photo, v)
                e, p = sums.get(key, (0.0, 0.0))
                sums[key] = (e + np.sum((prediction[v] - photo[v]) ** 2), p + np.sum(photo[v] ** 2))
                fitted = photo + (0.25 if key == "phong" else 1.0) * (prediction - photo)  # half ward's
                training_errors.add(key, "training", fitted, photo, v)
        detail = {"phong": 0.6 if subject == "a" else 0.8, "ward": float("nan")}  # ward's map constant per region
        results.append({"subject": subject, "errors": errors, "training_errors": training_errors,
                        "training_rmse": training,
                        "fitted_yaw_pitch_roll_deg": {}, "relative_rmse": errors.relative_rmse(),
                        "training_rmse_photometric_stereo": 0.05 if subject == "a" else 0.07,
                        "albedo_detail_r": detail})
    out = real_yaleb.summary(results, models)
    assert out["training_rmse_photometric_stereo"] == pytest.approx(0.06)
    assert out["albedo_detail_r"]["phong"] == pytest.approx({"mean": 0.7, "sd": np.sqrt(0.02), "min": 0.6, "max": 0.8,
                                                             "n": 2})
    assert out["albedo_detail_r"]["ward"]["n"] == 0 and out["albedo_detail_r"]["ward"]["mean"] is None
    per_subject = [r["relative_rmse"]["ward"]["all"] for r in results]
    assert out["per_subject"]["ward"]["mean"] == pytest.approx(np.mean(per_subject))
    assert out["per_subject"]["ward"]["sd"] == pytest.approx(np.std(per_subject, ddof=1))
    for key, (e, p) in sums.items():
        assert out["relative_rmse"][key]["all"] == pytest.approx(np.sqrt(e / p), rel=1e-12)
    assert out["best_model"] == "phong" and out["lowest_heldout_model"] == "ward"
    assert out["best_model_by_first_photograph"] == "ward"
    assert out["training_relative_rmse"]["phong"] == pytest.approx(0.5 * out["training_relative_rmse"]["ward"])
    assert out["best_vs_photometric_stereo"] == pytest.approx(np.sqrt(sums["phong"][0] / sums["phong"][1])
                                                             / np.sqrt(sums["photometric_stereo"][0]
                                                                       / sums["photometric_stereo"][1]))
    assert out["best_vs_photometric_stereo"] > 1


def test_albedo_detail_is_the_correlation_within_regions(real_yaleb):
    """Each region's mean removed from both: a map that is the reference plus an offset per region
    correlates perfectly; one constant per region has no detail (NaN); noise lowers r."""
    rng = np.random.default_rng(3)
    region_map = np.repeat(np.array([[1, 2], [3, 3]], np.uint8), 4, axis=0).repeat(4, axis=1)  # 8 x 8 texels
    uv = np.stack(np.meshgrid((np.arange(8) + 0.5) / 8, (np.arange(8) + 0.5) / 8), axis=-1)  # pixel = texel
    reference = rng.uniform(0.2, 0.8, (8, 8))
    offsets = np.take(np.array([0.0, 0.3, -0.1, 0.2]), region_map)
    valid = np.ones((8, 8), bool)
    same = (reference + offsets)[..., None].repeat(3, axis=2)
    assert real_yaleb.albedo_detail(same, reference, uv, region_map, valid) == pytest.approx(1.0)
    flat = offsets[..., None].repeat(3, axis=2)
    assert np.isnan(real_yaleb.albedo_detail(flat, reference, uv, region_map, valid))
    noisy = same + rng.normal(0, 0.2, same.shape)
    assert 0.2 < real_yaleb.albedo_detail(noisy, reference, uv, region_map, valid) < 0.95
    missed = uv.copy()
    missed[:4] = np.nan  # rays that miss the face do not count
    assert real_yaleb.albedo_detail(same, reference, missed, region_map, valid) == pytest.approx(1.0)


def test_only_the_largest_code_counts_as_saturated(real_yaleb):
    """The photographs are 8-bit codes / 255: 255 is saturated, 254 is not."""
    assert 254 / 255 < real_yaleb.SATURATED <= 255 / 255


def test_training_rmse_is_the_rms_error_over_the_mean_truth():
    rng = np.random.default_rng(2)
    truth = rng.uniform(0.2, 0.8, (9, 8, 3))
    mask = rng.uniform(size=(9, 8)) > 0.4
    image = truth + rng.normal(0.0, 0.1, truth.shape) * rng.uniform(0, 2, (9, 8, 1))
    image[~mask] = 7.0
    error = image[mask] - truth[mask]
    assert relative_rmse(image, truth, mask) == pytest.approx(np.sqrt(np.mean(error ** 2)) / truth[mask].mean())
