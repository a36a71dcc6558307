"""Lights nobody measured (mifaces.light_estimation.unknown): from fitted lights to the capture's, and their files.
The fitted lights here are written by hand (their fit is tested in tests/test_shape.py)."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from mifaces.capture import load_capture
from mifaces.capture.types import RELATIVE_IRRADIANCE
from mifaces.light_estimation.unknown import (LIGHTS_FILE, UnknownLightError, estimate_lights, sphere_shading,
                                              write_lights, write_lights_picture)
from mifaces.model.geometry import rotation_matrix
from mifaces.shape.targets import light_direction
from test_real_capture import write_directional


def _capture(tmp_path, lights=None):
    """test_real_capture's capture (m0 under 'top', m1 under 'side', 'known' given) with 'top' and
    'side' unknown; ``lights`` replaces them."""
    def change(data):
        data["lights"][:2] = lights or [{"name": "top", "unknown": True}, {"name": "side", "unknown": True}]
        data["measurements"].append(dict(data["measurements"][1], name="m2"))  # a second photograph under 'side'
    return load_capture(write_directional(tmp_path, change), detect=False)


def fitted(name, direction, color=1.0, gain=1.0, status="converged"):
    """A shape fit's result as estimate_lights reads it: a fitted point-image light (camera frame)."""
    return SimpleNamespace(measurement=name, converged=status == "converged", light={"point": {
        "direction": np.asarray(direction, np.float64), "color": np.full(3, color), "gain": np.full(3, gain)}})


def angle(a, b):
    return np.degrees(np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def test_estimate_lights_shares_and_turns_into_the_world_frame(tmp_path):
    capture = _capture(tmp_path)
    rotation = rotation_matrix(20.0, -10.0, 5.0)
    capture = replace(capture, camera=replace(capture.camera, rotation=rotation))
    top, side_a, side_b = light_direction(0.3, 0.1), light_direction(0.0, 0.6), light_direction(0.1, 0.5)
    fits = [fitted("m0", top, 0.5, 2.0), fitted("m1", side_a, 1.0, 2.0), fitted("m2", side_b, 1.0, 4.0)]
    result = estimate_lights(capture, fits)
    top_l, side_l, known = result.lights
    assert known is capture.lights[2]  # a given light stays as it was
    np.testing.assert_allclose(top_l.direction, rotation.T @ top, atol=1e-12)  # camera -> world frame
    mean = side_a + side_b
    np.testing.assert_allclose(side_l.direction, rotation.T @ (mean / np.linalg.norm(mean)), atol=1e-12)
    assert all(l.estimated and l.relative and not l.unknown and l.directional for l in (top_l, side_l))
    # intensities: colour x gain (1, and the mean of 2 and 4 = 3), scaled to mean pi
    np.testing.assert_allclose([top_l.intensity[0], side_l.intensity[0]],
                               np.array([1.0, 3.0]) * RELATIVE_IRRADIANCE / 2)
    info = result.metadata["estimated_lights"]
    assert info["side"]["photographs"] == ["m1", "m2"]
    assert info["side"]["spread_deg"] == pytest.approx(angle(side_a, side_b) / 2, abs=1e-6)
    # lights.json: the capture format's frame and convention, given lights too
    document = json.loads(write_lights(tmp_path / "res", result).read_text())
    assert (tmp_path / "res" / LIGHTS_FILE).is_file()
    entries = {e["name"]: e for e in document["lights"]}
    assert entries["top"]["kind"] == "directional" and entries["top"]["estimated"] is True
    np.testing.assert_allclose(entries["top"]["direction"], top_l.direction)
    assert entries["known"]["estimated"] is False and entries["known"]["direction"] == [0.0, 0.0, -1.0]
    assert document["ambient"] == "unknown"  # the capture's: the shape fit fitted an ambient term
    assert json.loads(write_lights(tmp_path / "dark", replace(result, ambient="none")).read_text())["ambient"] == "none"
    write_lights_picture(tmp_path / "res" / "lights.png", result)
    assert (tmp_path / "res" / "lights.png").stat().st_size > 1000


def test_unestimable_lights_are_named(tmp_path):
    capture = _capture(tmp_path)
    with pytest.raises(UnknownLightError, match=r"unknown light\(s\) \['side'\]: no photograph"):
        estimate_lights(capture, [fitted("m0", (0, 0, -1)), fitted("m1", (0, 0, -1), status="not_converged")])
    environment = _capture(tmp_path, [{"name": "top", "unknown": True, "kind": "environment"},
                                      {"name": "side", "unknown": True}])
    with pytest.raises(UnknownLightError, match=r"\['top'\]: their photographs show one pose"):
        estimate_lights(environment, [])


def test_sphere_shading_is_brightest_towards_the_light():
    d = light_direction(0.4, -0.7)  # above, towards the image's left
    shade = sphere_shading(d, 65)
    row, col = np.unravel_index(np.nanargmax(shade), shade.shape)
    normal = np.array([(col + 0.5) / 65 * 2 - 1, (row + 0.5) / 65 * 2 - 1])
    assert np.linalg.norm(normal - d[:2]) < 0.05
    assert np.isnan(shade[0, 0]) and np.nanmin(shade) == 0.0


def test_balance_intensities_gives_one_albedo(tmp_path):
    """Samples of one face under two estimated lights whose intensities are off by known factors
    (with highlights and grazing samples as outliers): the factors are found and undone."""
    from mifaces.light_estimation.unknown import balance_intensities
    from mifaces.reflectance.samples import ReflectanceSamples

    capture = estimate_lights(_capture(tmp_path), [fitted("m0", (0, 0, -1)), fitted("m1", (0.5, 0, -0.8)),
                                                   fitted("m2", (0.5, 0, -0.8))])
    rng = np.random.default_rng(0)
    texels = np.repeat(np.arange(400), 3)
    photo = np.tile([0, 1, 2], 400)  # m0 (top), m1 and m2 (side)
    albedo = rng.uniform(0.2, 0.8, 400)
    wrong = {"top": 1.6, "side": 0.8}  # the estimated intensity is this many times the true one
    light_of = {0: "top", 1: "side", 2: "side"}
    r = albedo[texels] / np.array([wrong[light_of[k]] for k in photo]) * rng.lognormal(0, 0.05, len(photo))
    r[::17] *= 5.0  # highlights
    cosines = np.full(len(photo), 0.8)
    cosines[::23] = 0.1  # grazing: left out
    unit = np.stack([np.zeros_like(cosines), np.sqrt(1 - cosines ** 2), cosines], axis=1).astype(np.float32)
    samples = ReflectanceSamples(unit, unit, np.repeat(r[:, None], 3, axis=1).astype(np.float32),
                                 np.ones(len(photo), np.float32), texels.astype(np.int32), photo.astype(np.int16), 32,
                                 ("m0", "m1", "m2"))
    before = {l.name: l.intensity.mean() for l in capture.lights}
    # an estimated map's entry (estimate_environments runs before the balance) is kept
    capture = replace(capture, metadata=dict(capture.metadata, estimated_lights=dict(
        capture.metadata["estimated_lights"], sky={"photographs": ["m9"], "residual": 0.1})))
    balanced = balance_intensities(capture, samples)
    after = {l.name: l.intensity.mean() for l in balanced.lights}
    ratio = (after["top"] / after["side"]) / (before["top"] / before["side"])
    assert ratio == pytest.approx(wrong["side"] / wrong["top"], rel=0.03)
    assert np.mean([after["top"], after["side"]]) == pytest.approx(RELATIVE_IRRADIANCE)
    assert balanced.lights[2] is capture.lights[2]  # the given light stays
    assert balanced.metadata["estimated_lights"]["top"]["photographs"] == ["m0"]
    assert balanced.metadata["estimated_lights"]["sky"] == {"photographs": ["m9"], "residual": 0.1}


def test_a_stated_guess_is_the_lights_angle_to_the_camera(tmp_path):
    """The pose's face is fitted on the photograph lit nearest the camera's axis: an unknown light counts
    by its stated guess, frontal without one."""
    from mifaces.shape.targets import light_axis_angle

    capture = _capture(tmp_path, [{"name": "top", "unknown": True, "guess": {"direction": [0, -3, -4]}},
                                  {"name": "side", "unknown": True}])
    m0 = capture.measurements[0]
    pixels_to_axis = angle(capture.camera.pixel_rays(np.mean(list(m0.feature_points.values()), axis=0)), [0, 0, 1])
    assert light_axis_angle(capture, m0) == pytest.approx(np.degrees(np.arccos(0.8)), abs=pixels_to_axis + 0.1)
    no_guess = _capture(tmp_path / "no_guess")
    assert light_axis_angle(no_guess, no_guess.measurements[0]) == 0.0


def _samples(wrong: dict, light_of: dict, seed: int = 0):
    """Samples of 400 texels seen in m0, m1 and m2, the reflectance 1/``wrong[light]`` of the albedo."""
    from mifaces.reflectance.samples import ReflectanceSamples

    rng = np.random.default_rng(seed)
    texels = np.repeat(np.arange(400), 3)
    photo = np.tile([0, 1, 2], 400)
    r = rng.uniform(0.2, 0.8, 400)[texels] / np.array([wrong[light_of[k]] for k in photo])
    unit = np.tile(np.array([[0.0, 0.6, 0.8]], np.float32), (len(photo), 1))
    return ReflectanceSamples(unit, unit, np.repeat(r[:, None], 3, axis=1).astype(np.float32),
                              np.ones(len(photo), np.float32), texels.astype(np.int32), photo.astype(np.int16), 32,
                              ("m0", "m1", "m2"))


def test_given_lights_anchor_the_estimated_intensities(tmp_path):
    """A capture mixing a given light with an unknown one: the given light keeps its intensity and the
    estimated one is expressed in its units; a capture whose lights are all estimated has no use for
    the white target (its units tie to no estimated light)."""
    from mifaces.light_estimation.unknown import balance_intensities

    capture = estimate_lights(_capture(tmp_path, [{"name": "top", "unknown": True},
                                                  {"name": "side", "direction": [3, 0, -4], "intensity": 2.0}]),
                              [fitted("m0", (0, 0, -1))])
    top = capture.lights[0].intensity.mean()
    balanced = balance_intensities(capture, _samples({"top": 1.6, "side": 1.0}, {0: "top", 1: "side", 2: "side"}))
    assert balanced.lights[1] is capture.lights[1]  # the given light holds
    assert balanced.lights[0].intensity.mean() == pytest.approx(top / 1.6, rel=1e-6)

    def with_white_target(data):
        data["lights"] = [{"name": n, "unknown": True} for n in ("top", "side", "known")]
        data["measurements"].append(dict(data["measurements"][1], name="m2", light="known"))
        data["white_target"] = {"value": 0.5, "distance_mm": 1000, "intensity": 1e6}

    every = load_capture(write_directional(tmp_path / "w", with_white_target), detect=False)
    assert every.white_target is not None
    estimated = estimate_lights(every, [fitted(m, (0, 0, -1)) for m in ("m0", "m1", "m2")])
    assert estimated.white_target is None and estimated.relative_reflectance
    partly = estimate_lights(replace(every, lights=every.lights[:2] + (replace(capture.lights[1], name="known"),)),
                             [fitted(m, (0, 0, -1)) for m in ("m0", "m1")])
    assert partly.white_target is every.white_target


def test_samples_under_an_unknown_light_are_refused(tmp_path):
    """The reflectance stage names an unknown light instead of reading it as an uncalibrated one."""
    from mifaces.model import load_model
    from mifaces.reflectance import capture_samples

    capture = _capture(tmp_path)
    face = load_model("builtin")
    shapes = {m.name: face.shape_mean for m in capture.measurements}
    with pytest.raises(ValueError, match="measurement 'm0': light 'top' is unknown: estimate it with the face first"):
        capture_samples(capture, shapes, face, 16, progress=False)


def test_report_page_shows_the_lights_picture_when_there_is_one(tmp_path):
    from mifaces.light_estimation.unknown import LIGHTS_PICTURE
    from mifaces.report.html import write_html

    report = {"capture": "c", "measurements": 1, "geometry": "fitted", "resolution": 8, "models": {},
              "seconds": {"total": 1.0}}
    assert LIGHTS_PICTURE not in write_html(tmp_path / "report.html", report).read_text()
    (tmp_path / LIGHTS_PICTURE).write_bytes(b"png")
    assert f'<img src="{LIGHTS_PICTURE}"' in write_html(tmp_path / "report.html", report).read_text()


def _two_light_samples(reflectance):
    """Samples of the same n texels under 'top' (measurement m0) then 'side' (m1), ``reflectance``
    (2n, 3): light and view 50 degrees from the normal in planes at right angles, so the half vector
    is 40 degrees off and the balance reads them."""
    from mifaces.reflectance.samples import ReflectanceSamples

    n = len(reflectance) // 2
    a = np.radians(50.0)
    light = np.tile(np.array([[np.sin(a), 0.0, np.cos(a)]], np.float32), (2 * n, 1))
    view = np.tile(np.array([[0.0, np.sin(a), np.cos(a)]], np.float32), (2 * n, 1))
    return ReflectanceSamples(light=light, view=view, reflectance=np.asarray(reflectance, np.float32),
                              sigma=np.ones(2 * n, np.float32), texel=np.tile(np.arange(n, dtype=np.int32), 2),
                              measurement=np.repeat(np.arange(2, dtype=np.int16), n), resolution=32,
                              measurement_names=("m0", "m1"))


def test_balance_given_lights_finds_a_lamp_that_is_off(tmp_path):
    """Two given lights over the same texels, 'side' stated 6 % too strong: its samples read 6 %
    too dark. The balance finds the factor (the two lights' mean kept), corrects the intensities
    and the samples, and leaves a capture of one given light alone."""
    from mifaces.reflectance.light_balance import balance_given_lights

    capture = load_capture(write_directional(tmp_path), detect=False)
    rng = np.random.default_rng(0)
    n = 400
    albedo = rng.uniform(0.2, 0.6, (n, 1)) * np.ones(3)
    highlight = np.where(rng.random((n, 1)) < 0.1, 0.5, 0.0)  # a few highlights under 'top' only
    reflectance = np.concatenate([albedo + highlight, albedo / 1.06]).astype(np.float32)
    samples = _two_light_samples(reflectance)
    balanced, corrected = balance_given_lights(capture, samples)
    factor = balanced.metadata["light_balance"]
    assert factor["side"] / factor["top"] == pytest.approx(1.06, rel=1e-3)
    assert factor["side"] * factor["top"] == pytest.approx(1.0, rel=1e-9)  # the mean kept
    np.testing.assert_allclose(balanced.light("side").intensity, capture.light("side").intensity / factor["side"])
    plain = highlight[:, 0] == 0  # after the balance both lights read one albedo
    np.testing.assert_allclose(np.median(corrected.reflectance[n:] / albedo, axis=0),
                               np.median(corrected.reflectance[:n][plain] / albedo[plain], axis=0), rtol=1e-3)
    assert balanced.light("known") is capture.light("known")  # no samples under it: unchanged
    # highlights seen in the mirror direction under 'side' are not read: the factor stays
    up = np.tile(np.array([[0.0, 0.0, 1.0]], np.float32), (n, 1))
    shiny = replace(samples, light=np.concatenate([samples.light, up]), view=np.concatenate([samples.view, up]),
                    reflectance=np.concatenate([reflectance, (3 * albedo).astype(np.float32)]),
                    sigma=np.ones(3 * n, np.float32), texel=np.tile(np.arange(n, dtype=np.int32), 3),
                    measurement=np.repeat(np.array([0, 1, 1], np.int16), n))
    assert balance_given_lights(capture, shiny)[0].metadata["light_balance"] == pytest.approx(factor, rel=1e-9)
    one = replace(capture, lights=(capture.lights[0], replace(capture.lights[1], unknown=True), capture.lights[2]))
    assert balance_given_lights(one, replace(samples, measurement_names=("m0", "m0")))[0] is one


def test_balance_given_lights_reads_the_albedo_less_the_glossy_part_a_fit_predicts(tmp_path):
    """A rough lobe's tail reaches the samples the balance reads, under 'top' only (5 % of the
    albedo's level), and 'side' is stated 6 % too strong. Read as they are, the tail is taken for
    light: the factor comes out wrong. With the glossy part a fit predicts taken out, it is exact; a
    second balance from there changes nothing, and the record stays the product of both."""
    from mifaces.reflectance.light_balance import balance_given_lights

    capture = load_capture(write_directional(tmp_path), detect=False)
    rng = np.random.default_rng(1)
    n = 400
    albedo = rng.uniform(0.2, 0.6, (n, 1)) * np.ones(3)
    tail = np.concatenate([np.full((n, 3), 0.02), np.zeros((n, 3))]).astype(np.float32)
    reflectance = (np.concatenate([albedo, albedo / 1.06]) + tail).astype(np.float32)
    samples = _two_light_samples(reflectance)
    blind = balance_given_lights(capture, samples)[0].metadata["light_balance"]
    assert abs(blind["side"] / blind["top"] - 1.06) > 0.02  # the tail read as light
    balanced, corrected = balance_given_lights(capture, samples, tail)
    factor = balanced.metadata["light_balance"]
    assert factor["side"] / factor["top"] == pytest.approx(1.06, rel=1e-4)
    np.testing.assert_allclose(balanced.light("side").intensity, capture.light("side").intensity / factor["side"])
    again, twice = balance_given_lights(balanced, corrected, tail * np.float32(factor["top"]))
    assert again.metadata["light_balance"] == pytest.approx(factor, rel=1e-5)
    np.testing.assert_allclose(twice.reflectance, corrected.reflectance, rtol=1e-5)
