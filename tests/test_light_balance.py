"""The given lights' balance against the glossy part of a quick fit (FitOptions(balance_lights=True),
mifaces.reflectance.sample_stage.with_balanced_lights)."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import warnings
from dataclasses import replace

import numpy as np
import pytest

from mifaces import brdf as brdf_models
from mifaces.capture import load_capture, with_true_lights
from mifaces.reflectance import FitOptions, fit_brdf
from mifaces.reflectance.sample_stage import take_samples, with_balanced_lights
from mifaces.shape.io import load_geometry

#: A glossy, rough skin (its lobe's tails reach the samples the balance reads), no bounced light.
RHO_S = 1.2
CAPTURE = dict(measurements=6, resolution=(160, 160), spp=16, albedo_resolution=256, seed=7,
               brdf_params={"model": "cooktorrance", "regions": {"skin": {"specular_reflectance": [RHO_S] * 3,
                                                                          "roughness": 0.5}}})
TEXTURE = 96
#: How much farther than it is the capture says the moved lamp stands.
FARTHER = 1.01


#: The fit without the balance (the default balances), and without the bounced light's correction: the
#: capture is direct light only, so there is none to take out.
UNBALANCED = {"balance_lights": False, "interreflection": False}


@pytest.fixture(scope="module")
def lamp_off(small_capture):
    """The capture with the simulator's true light positions, and the same with its first lamp
    stated 1 % farther from the face than it is (2 % too little light where the face is)."""
    folder = small_capture("balance", direct_only=True, **CAPTURE)
    true = with_true_lights(load_capture(folder))
    face, shapes = load_geometry(true, "ground-truth")
    centre = np.mean([np.asarray(v).mean(axis=0) for v in shapes.values()], axis=0)
    lamp = true.lights[0]
    moved = lamp.moved_to(centre + FARTHER * (np.asarray(lamp.position) - centre))
    return true, replace(true, lights=(moved, *true.lights[1:])), face, shapes


def _skin_rho(capture, face, shapes, **options) -> tuple[float, object]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimate = fit_brdf(capture, "cooktorrance", shapes, face_model=face, progress=False,
                            options=FitOptions(resolution=TEXTURE, uncertainty=None,
                                               **{**UNBALANCED, **options}))
    return float(np.mean(estimate.fits["skin"].params["specular_reflectance"])), estimate


def test_the_balance_finds_a_lamp_stated_too_far_and_gives_back_the_true_lights_lobe(lamp_off):
    """The moved lamp's factor is the light it lacks (1 / 1.01², against the others' mean), within
    0.5 %; skin's ρ_s with the balance is within half the error the moved lamp causes of the fit with
    the true positions, and within 2 % of the truth (1.0 % when written, the moved lamp 5.9 % off);
    ``brdf.json`` records the factors. With the true positions it finds nothing to correct: ρ_s moves
    by less than 1 % (0.3 % when written; 1.9 % where the lobe's tails are read as light, without the
    quick fit's glossy part)."""
    true, off, face, shapes = lamp_off
    assert len(true.lights) >= 2
    rho_true, _ = _skin_rho(true, face, shapes)
    rho_off, _ = _skin_rho(off, face, shapes)
    rho_balanced, estimate = _skin_rho(off, face, shapes, balance_lights=True)
    factor = estimate.light_balance
    moved = true.lights[0].name
    others = np.mean([np.log(v) for k, v in factor.items() if k != moved])
    assert np.exp(np.log(factor[moved]) - others) == pytest.approx(1 / FARTHER ** 2, rel=0.005), factor
    assert abs(rho_off - rho_true) > 0.02 * rho_true  # the lamp matters to the lobe
    assert abs(rho_balanced - rho_true) < 0.5 * abs(rho_off - rho_true), (rho_true, rho_off, rho_balanced)
    assert abs(rho_balanced / RHO_S - 1) < 0.02, (rho_true, rho_off, rho_balanced)
    assert estimate.to_json()["light_balance"] == pytest.approx(factor)
    rho_kept, kept = _skin_rho(true, face, shapes, balance_lights=True)
    assert max(abs(np.log(v)) for v in kept.light_balance.values()) < 0.002, kept.light_balance
    assert rho_kept == pytest.approx(rho_true, rel=0.01)


def test_samples_balanced_once_are_shared_not_balanced_again(lamp_off):
    """``with_balanced_lights`` balances once: what it balanced comes back as it is (``measure``
    balances with its first model and every model shares the samples), and nothing without the option."""
    _, off, face, shapes = lamp_off
    options = FitOptions(resolution=TEXTURE, uncertainty=None, balance_lights=True, interreflection=False)
    taken = take_samples(off, shapes, face, options, progress=False)
    assert with_balanced_lights(taken, brdf_models.model("phong"), replace(options, balance_lights=False)) is taken
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        balanced = with_balanced_lights(taken, brdf_models.model("phong"), options)
    assert taken.light_balance is None and set(balanced.light_balance) == {light.name for light in off.lights}
    assert with_balanced_lights(balanced, brdf_models.model("cooktorrance"), options) is balanced
    assert not np.array_equal(balanced.samples.reflectance, taken.samples.reflectance)
    assert balanced.capture.lights[0].intensity[0] != off.lights[0].intensity[0]
