"""High dynamic range: sRGB decoding, exposure merging, scaling to the white target.

The simulated exposure series of the shared capture (:func:`test_simulate.studio`)
is merged and compared with the point-light photograph of the same render,
whose noise is independent, in units of the noise both should have under the
simulator's sensor model (:attr:`mifaces.capture.GroundTruth.noise`).
"""

from __future__ import annotations

import numpy as np
import pytest

from mifaces.capture import load_capture, read_ground_truth
from mifaces.capture.hdr import decode_srgb, merge_exposures, merge_series, scale_to_white
from test_simulate import studio  # noqa: F401  (the shared session fixture)


def _srgb_curve(v):
    """IEC 61966-2-1 decoding, written out."""
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_decode_srgb_integer_codes(dtype):
    import colour

    top = np.iinfo(dtype).max
    codes = np.unique(np.linspace(0, top, 1000).round().astype(dtype))
    np.testing.assert_allclose(decode_srgb(codes), _srgb_curve(codes / top), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(decode_srgb(codes), colour.cctf_decoding(codes / top, function="sRGB"), rtol=1e-6)
    image = codes[:60].reshape(3, 4, 5)
    assert decode_srgb(image).shape == image.shape and decode_srgb(image).dtype == np.float32


def test_decode_srgb_floats_are_clipped_to_the_unit_range():
    np.testing.assert_allclose(decode_srgb(np.array([-0.2, 0.02, 0.5, 1.0, 1.3])),
                               _srgb_curve([0.0, 0.02, 0.5, 1.0, 1.0]), rtol=1e-6)
    with pytest.raises(ValueError, match="8 or 16 bit"):
        decode_srgb(np.array([1, 2], np.int32))


def test_merge_recovers_radiance_over_a_wide_range():
    """Radiance over four decades, three exposures 16x apart, photon and read noise, clipping at 1."""
    rng = np.random.default_rng(2)
    radiance = np.exp(rng.uniform(np.log(0.01), np.log(100.0), (64, 64, 3)))
    exposures = [1 / 64, 1 / 4, 4.0]
    sigma = [1e-4 + 0.003 * np.sqrt(t * radiance) for t in exposures]
    pictures = [np.clip(t * radiance + rng.normal(0, s), 0, 1) for t, s in zip(exposures, sigma)]
    merged = merge_exposures(pictures, exposures)
    assert merged.valid[(radiance < 60).all(axis=2)].all()  # 60 / 64: below saturation in the shortest
    # no worse than the best single picture that is neither dark nor near clipping
    best = np.min([np.where((t * radiance > 2 / 255) & (t * radiance < 0.85), s / t, np.inf)
                   for t, s in zip(exposures, sigma)], axis=0)
    z = ((merged.radiance - radiance) / best)[merged.valid]
    assert np.abs(z).max() < 5 and z.std() < 1.0
    # a pixel too bright for every exposure takes the shortest's (clipped) value and is invalid
    hot = np.clip(radiance * 0 + 1e4, 0, None)
    merged = merge_exposures([np.clip(t * hot, 0, 1) for t in exposures], exposures)
    assert not merged.valid.any()
    np.testing.assert_allclose(merged.radiance, 64.0)


def test_merge_ignores_pictures_marked_saturated():
    values = [np.full((2, 2, 3), 0.5), np.full((2, 2, 3), 0.6)]
    saturated = [np.zeros((2, 2), bool), np.ones((2, 2), bool)]
    merged = merge_exposures(values, [1.0, 2.0], saturated)
    np.testing.assert_allclose(merged.radiance, 0.5)
    np.testing.assert_allclose(merge_exposures(values, [1.0, 2.0]).radiance, (1 * 0.5 + 2 * 0.3) / 3)


@pytest.mark.parametrize("args, message", [
    (([], []), "non-empty and of equal length"),
    (([np.zeros((2, 2, 3))], [1.0, 2.0]), "non-empty and of equal length"),
    (([np.zeros((2, 2, 3))] * 2, [1.0, 0.0]), "exposures must be positive"),
    (([np.zeros((2, 2, 3))] * 2, [1.0, 2.0], [np.zeros((3, 3), bool)] * 2), "saturated masks must have shape"),
])
def test_merge_names_bad_input(args, message):
    with pytest.raises(ValueError, match=message):
        merge_exposures(*args)


def test_merge_of_a_simulated_series_is_the_radiance_within_noise(studio):
    capture = load_capture(studio, calibrate=False)
    noise = read_ground_truth(studio).noise
    full_well, read_noise = noise["full_well"], noise["read_noise"]
    codes = decode_srgb(np.arange(256, dtype=np.uint8)).astype(np.float64)
    code_step = np.gradient(codes)  # linear value per 8-bit code

    def variance(radiance, t, quantisation=0.0):  # of one picture's estimate v / t of the radiance
        return (t * radiance / full_well + read_noise ** 2 + quantisation) / t ** 2

    for m in capture.measurements:
        merged = merge_series(m.exposures)
        reference = m.image.pixels.astype(np.float64)  # same render, independent noise, linear EXR
        radiance = np.clip(reference, 1e-4, None)
        # the merge's variance: the inverse-variance combination of the usable pictures (8-bit steps included)
        precision = np.zeros_like(reference)
        for e in m.exposures:
            v = e.pixels.astype(np.float64) * e.exposure
            usable = (v >= 2 / 255) & (v < 0.98) & ~e.saturated[..., None]
            quantisation = np.interp(v, codes, code_step) ** 2 / 12
            precision += np.where(usable, 1 / variance(radiance, e.exposure, quantisation), 0)
        face = merged.valid & (reference.mean(axis=2) > 0.02)
        assert face.mean() > 0.1
        total = variance(radiance, m.image.exposure)[face] + 1 / precision[face]
        z = (merged.radiance - reference)[face] / np.sqrt(total)
        assert abs(z.mean()) < 0.05 and 0.9 < z.std() < 1.1, (m.name, z.mean(), z.std())
        assert np.mean(np.abs(z) > 4) < 1e-3
        # no bias: the merged face is as bright as the photograph
        assert merged.radiance[face].mean() == pytest.approx(reference[face].mean(), rel=0.002)


def test_merge_series_needs_two_pictures(studio):
    capture = load_capture(studio, calibrate=False)
    with pytest.raises(ValueError, match="at least two pictures, got 1"):
        merge_series(capture.measurements[0].exposures[:1])


def test_scale_to_white():
    image = np.array([[[0.2, 0.4, 0.6]]])
    np.testing.assert_allclose(scale_to_white(image, [0.4, 0.4, 1.2]), [[[0.5, 1.0, 0.5]]])
    np.testing.assert_allclose(scale_to_white(image, 0.4, reflectance=0.9), image / 0.4 * 0.9, rtol=1e-6)
    with pytest.raises(ValueError, match="white_value must be positive"):
        scale_to_white(image, [0.4, 0.0, 1.0])
