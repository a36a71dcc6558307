"""Skin's BRDF fitted on the true shape comes out at the truth (issue 48's regression test): a small
simulated capture with everything a capture has (light bounced off the face, the albedo's detail,
sensor noise, lamps placed by the steel spheres), a development truth (not the report's)."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import warnings

import numpy as np
import pytest

from mifaces.reflectance import FitOptions, fit_brdf

#: Skin's truth: inside the plausible range validation/reflectance_bias.py draws from, not its report
#: truth (ρs 0.55, roughness 0.31).
SKIN = {"specular_reflectance": [0.8] * 3, "roughness": 0.35}
CAPTURE = dict(measurements=8, resolution=(192, 192), spp=16, seed=11,
               brdf_params={"model": "cooktorrance", "regions": {"skin": SKIN}})
TEXTURE = 128
#: The largest relative error allowed on skin's ρs (each channel) and roughness.
TOLERANCE = 0.03


@pytest.fixture(scope="module")
def capture(small_capture):
    return small_capture("bias", **CAPTURE)


def _skin_errors(capture, options: FitOptions) -> tuple[np.ndarray, float]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted = fit_brdf(capture, "cooktorrance", "ground-truth", options=options, progress=False).fits["skin"].params
    rho = np.asarray(fitted["specular_reflectance"]) / np.asarray(SKIN["specular_reflectance"]) - 1
    return rho, float(fitted["roughness"]) / SKIN["roughness"] - 1


def test_bounced_light_out_and_lamps_balanced_recover_skin_within_3_percent(capture):
    """With the bounced light taken out and the lamps balanced against a quick fit, skin's ρs (every
    channel) and roughness are within 3 % of the truth (+0.3, +1.4, +1.1 % and +1.4 % when written)."""
    rho, roughness = _skin_errors(capture, FitOptions(resolution=TEXTURE, interreflection=True, balance_lights=True))
    assert np.all(np.abs(rho) <= TOLERANCE), rho
    assert abs(roughness) <= TOLERANCE, roughness


@pytest.mark.xfail(strict=True, reason="open defect (issue 48): the default fit leaves the bounced light and the "
                                       "lamps' calibration errors in skin's lobe (-15 % here when written); "
                                       "interreflection and balance_lights are not yet the defaults")
def test_the_default_fit_recovers_skin_within_3_percent(capture):
    """The defaults, as a user runs them: skin's ρs (every channel) and roughness within 3 %."""
    rho, roughness = _skin_errors(capture, FitOptions(resolution=TEXTURE))
    assert np.all(np.abs(rho) <= TOLERANCE), rho
    assert abs(roughness) <= TOLERANCE, roughness
