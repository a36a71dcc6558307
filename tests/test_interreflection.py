"""Light bounced between parts of the face: rendered with the fit, taken out of the samples
(mifaces.reflectance.interreflection, FitOptions(interreflection=True))."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from mifaces.capture import Camera, load_capture, read_ground_truth
from mifaces.reflectance import FitOptions, capture_samples, fit_brdf
from mifaces.reflectance.interreflection import INDIRECT_ROUNDS, bounced_light, coarse_camera
from mifaces.shape.io import load_geometry

CAPTURE = dict(measurements=4, resolution=(160, 160), spp=16, albedo_resolution=256, seed=5)
TEXTURE = 96


def test_the_coarse_camera_sees_the_same_picture_smaller():
    camera = Camera(width=512, height=384, fx=900.0, fy=905.0, cx=250.3, cy=190.7,
                    translation=np.array([0.0, 0.0, 1200.0]))
    small = coarse_camera(camera, 128)
    assert (small.width, small.height) == (128, 96)
    points = np.random.default_rng(0).normal(0.0, 80.0, (20, 3))
    full, coarse = camera.project(points), small.project(points)
    np.testing.assert_allclose(coarse, (full + 0.5) / 4.0 - 0.5, atol=1e-9)  # pixel centres at integers
    assert coarse_camera(camera, 1024).width == 512  # never larger than the photograph
    assert coarse_camera(camera, None) is camera  # None: the photograph's own size


def test_the_rounds_are_those_the_study_chose():
    """The library's rounds are the variant validation/interreflection_rounds.py chose, and that variant
    brings the lips' ρs closest to the truth there (its largest error over seeds and channels)."""
    result = json.loads((Path(__file__).parents[1] / "validation/results/interreflection_rounds.json").read_text())
    assert [tuple(r) for r in result["variants"][result["chosen"]]] == [tuple(r) for r in INDIRECT_ROUNDS]
    worst = {v: row["lips.specular_reflectance"]["max_abs"] for v, row in result["summary"].items()}
    assert min(worst, key=worst.get) == result["chosen"], worst


def _paired(a, b):
    """Rows of samples ``a`` and ``b`` of the same measurement and texel."""
    ka = a.measurement.astype(np.int64) * 10 ** 7 + a.texel
    kb = b.measurement.astype(np.int64) * 10 ** 7 + b.texel
    common, ia, ib = np.intersect1d(ka, kb, return_indices=True)
    return ia, ib


@pytest.fixture(scope="module")
def captures(small_capture):
    """The same simulated face twice: path traced with bounces (the simulator's depth 4) and with
    direct light only (depth 2): same face, lights, poses and noise draws."""
    with_bounces = small_capture("bounces", **CAPTURE)
    direct = small_capture("direct", direct_only=True, **CAPTURE)
    return load_capture(with_bounces), load_capture(direct)


def test_the_rendered_bounced_light_is_the_light_the_simulator_bounced(captures):
    """On skin, the light bounced off the face that the fit's render predicts is, on average, the
    light the simulator's path tracer bounced (the difference of the two captures' samples), within
    30 % per channel (0.86-0.87 when written), and varies over the face as that light does."""
    mifaces.set_variant("llvm_ad_rgb")
    capture, direct = captures
    face, shapes = load_geometry(capture, "ground-truth")
    samples = capture_samples(capture, shapes, face, TEXTURE, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimate = fit_brdf(capture, "cooktorrance", shapes, face_model=face, samples=samples, progress=False,
                            options=FitOptions(resolution=TEXTURE, uncertainty=None))
    bounced = bounced_light(capture, shapes, face, estimate)
    assert set(bounced) == {m.name for m in capture.measurements}
    assert all(b.shape == (capture.camera.height, capture.camera.width, 3) and b.min() >= 0 for b in bounced.values())
    corrected = capture_samples(capture, shapes, face, TEXTURE, progress=False, indirect=bounced)
    plain = capture_samples(direct, shapes, face, TEXTURE, progress=False)
    ia, ib = _paired(samples, plain)
    ja, jc = _paired(samples, corrected)
    skin = samples.label[ia] == 1
    true = (samples.reflectance[ia] - plain.reflectance[ib])[skin]
    assert np.array_equal(ia, ja)
    predicted = (samples.reflectance[ja] - corrected.reflectance[jc])[skin]
    ratio = predicted.mean(axis=0) / true.mean(axis=0)
    assert np.all((ratio > 0.7) & (ratio < 1.3)), ratio
    # it varies over the face as the true bounced light does
    assert np.corrcoef(predicted[:, 0], true[:, 0])[0, 1] > 0.5


def test_taking_the_bounced_light_out_brings_skins_lobe_to_the_direct_light_fit(captures):
    """Skin's ρ_s fitted with ``interreflection=True`` is nearer the fit of the capture rendered
    without bounces (what a perfect removal gives) than the default fit is, by half the gap at least."""
    mifaces.set_variant("llvm_ad_rgb")
    capture, direct = captures
    face, shapes = load_geometry(capture, "ground-truth")
    truth = read_ground_truth(capture).brdf["regions"]["skin"]
    fits, records = {}, {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, c, inter in (("default", capture, False), ("corrected", capture, True), ("direct", direct, False)):
            estimate = fit_brdf(c, "cooktorrance", shapes, face_model=face, progress=False,
                                options=FitOptions(resolution=TEXTURE, interreflection=inter))
            fits[name], records[name] = estimate.fits["skin"].params, estimate.to_json().get("interreflection")
    # brdf.json says whether the bounced light was taken out, and how
    assert records["default"] is None and records["corrected"]["depth"] == 4 and records["corrected"]["seconds"] > 0
    rho = {k: float(np.mean(v["specular_reflectance"])) for k, v in fits.items()}
    assert rho["default"] < rho["direct"]  # the bounced light biases the lobe low
    assert abs(rho["corrected"] - rho["direct"]) < 0.5 * abs(rho["default"] - rho["direct"]), (rho, truth)


def test_samples_the_bounced_light_was_taken_out_of_are_shared_not_corrected_twice(captures):
    """``without_bounced_light`` takes the light out once: samples it already corrected come back as
    they are (``measure`` corrects once and every model shares them), and the record names the model
    whose fit rendered the light."""
    from mifaces import brdf as brdf_models
    from mifaces.reflectance.sample_stage import take_samples, without_bounced_light

    mifaces.set_variant("llvm_ad_rgb")
    capture, _ = captures
    face, shapes = load_geometry(capture, "ground-truth")
    options = FitOptions(resolution=TEXTURE, interreflection=True, uncertainty=None, normals=False)
    taken = take_samples(capture, shapes, face, options, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        corrected = without_bounced_light(taken, brdf_models.model("phong"), options, progress=False)
        again = without_bounced_light(corrected, brdf_models.model("cooktorrance"), options, progress=False)
    assert taken.interreflection is None and corrected.interreflection["fitted_with"] == "phong"
    assert again is corrected
    assert not np.array_equal(corrected.samples.reflectance, taken.samples.reflectance)
