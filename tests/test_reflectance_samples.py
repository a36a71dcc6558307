"""Eq. 4, 9 and 10, the sample mask and the samples' value on hand-made cases."""

from __future__ import annotations

import numpy as np
import pytest

from mifaces.reflectance.samples import (MIN_COSINE, ReflectanceSamples, confidence, confidence_with_distance,
                                         d_max, distance_to_missing, reflectance, unsaturated, valid_samples)


def test_white_lambertian_target_has_reflectance_one():
    # I = 2 W/sr at 0.5 m, lit at 60°: E = 2 · 0.5 / 0.25 = 4 W/m², white Lambertian R = E/π
    radiance = np.full(3, 4.0 / np.pi)
    np.testing.assert_allclose(reflectance(radiance, 0.5, 2.0, 0.5), [1.0, 1.0, 1.0])


def test_reflectance_grows_with_the_square_of_the_light_distance():
    """The physical reading: at twice the distance the same radiance means
    four times the reflectance (the printed eq. 4 would give a quarter)."""
    near = reflectance(np.ones(3), 1.0, 1.0, 1.0)
    far = reflectance(np.ones(3), 2.0, 1.0, 1.0)
    np.testing.assert_allclose(far / near, 4.0)


def test_reflectance_per_channel_intensity_and_invalid_cosine():
    r = reflectance(np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]), np.array([1.0, 1.0]), [1.0, 2.0, 4.0],
                    np.array([1.0, 0.0]), scale=1.0)
    np.testing.assert_allclose(r[0], [1.0, 0.5, 0.25])
    assert np.all(np.isnan(r[1]))


def test_confidence_eq9():
    np.testing.assert_allclose(confidence(1.0, 1.0), 1.0)
    np.testing.assert_allclose(confidence(0.5, 1.0), 4.0)
    np.testing.assert_allclose(confidence(1.0, 0.5), 2.0)
    np.testing.assert_allclose(confidence(np.array([0.5, 0.25]), np.array([0.5, 1.0])), [8.0, 16.0])


def test_confidence_eq10_and_dmax():
    assert d_max(1000) == 10.0 and d_max(512) == 5.12
    # far from any hole, eq. 10 equals eq. 9
    np.testing.assert_allclose(confidence_with_distance(0.5, 1.0, 50.0, 10.0), confidence(0.5, 1.0))
    # at distance 2 of d_max 10: five times less confident
    np.testing.assert_allclose(confidence_with_distance(0.5, 1.0, 2.0, 10.0), 5 * confidence(0.5, 1.0))


def test_distance_to_missing():
    valid = np.ones((7, 7), bool)
    valid[3, 3] = False
    d = distance_to_missing(valid)
    assert d[3, 3] == 0
    assert d[3, 4] == 1 and d[2, 2] == np.sqrt(2)
    # the image border counts as missing
    assert d[0, 0] == 1 and d[3, 0] == 1


def test_valid_samples_drop_shadow_grazing_and_borders():
    n = 21
    light_z = np.full((n, n), 0.9)
    view_z = np.full((n, n), 0.9)
    lit = np.ones((n, n), bool)
    visible = np.ones((n, n), bool)
    lit[:, :5] = False          # cast shadow on the left
    light_z[:, 16:] = 0.05      # grazing light on the right (cos < MIN_COSINE)
    visible[0, :] = False       # occluded top row
    assert 0.05 < MIN_COSINE < 0.9
    mask = valid_samples(light_z, view_z, lit, visible, erosion=1)
    assert not mask[:, :6].any()      # shadow plus one eroded column
    assert not mask[:, 15:].any()     # grazing plus one eroded column
    assert not mask[:2, :].any()      # occluded row plus one
    assert mask[5:15, 7:14].all()
    unchanged = valid_samples(light_z, view_z, lit, visible, erosion=0)
    assert unchanged[1:, 5].all() and not unchanged[:, 4].any()


def test_saturated_pixels_are_dropped():
    pixels = np.array([[0.2, 0.3, 0.4], [0.2, 0.99, 0.4], [1.0, 1.0, 1.0], [0.5, 0.97, 0.1]])
    np.testing.assert_array_equal(unsaturated(pixels, 1.0), [True, False, False, True])


def test_samples_round_trip_and_concatenate(tmp_path):
    rng = np.random.default_rng(0)

    def part(n, name):
        return ReflectanceSamples(rng.normal(size=(n, 3)).astype(np.float32), rng.normal(size=(n, 3)).astype(np.float32),
                                  rng.uniform(size=(n, 3)).astype(np.float32), rng.uniform(1, 2, n).astype(np.float32),
                                  rng.integers(0, 64, n).astype(np.int32), np.zeros(n, np.int16), 8, (name,))

    both = ReflectanceSamples.concatenate([part(5, "a"), part(7, "b")])
    assert len(both) == 12 and both.measurement_names == ("a", "b")
    assert both.measurement.tolist() == [0] * 5 + [1] * 7
    both.save(tmp_path / "s.npz")
    back = ReflectanceSamples.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(back.reflectance, both.reflectance)
    assert back.measurement_names == ("a", "b") and back.resolution == 8
    region_map = np.arange(64).reshape(8, 8)
    np.testing.assert_array_equal(both.region(region_map), both.texel)
    with pytest.raises(ValueError, match="does not match"):
        both.region(np.zeros((4, 4)))
