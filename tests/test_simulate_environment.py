"""Simulated captures lit by an environment (``SimulationOptions(environment=...)``): the capture
states its map as one given environment light, the photographs are rendered with exactly
that map, the sky's map is Mitsuba's sun and sky baked, and the CLI's ``--environment``."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import json
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest
from click.testing import CliRunner

from conftest import JIT_VARIANTS
from mifaces.capture import MANIFEST, load_capture, read_ground_truth
from mifaces.cli.commands import main
from mifaces.lights.environment import bake_environment, environment_emitter, irradiance, map_directions, sky_emitter
from mifaces.io.image_files import read_exr
from mifaces.studio import photograph
from mifaces.studio.environment_light import ENVIRONMENT_HEIGHT, ENVIRONMENTS
from mifaces.studio.scene import studio_camera
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate

#: A small environment-lit capture.
SMALL = dict(measurements=2, resolution=(48, 48), spp=4, albedo_resolution=64)


@pytest.fixture(scope="module")
def sky_capture(tmp_path_factory):
    """A sky-lit capture, and the scene dicts its renders were given."""
    mifaces.set_variant(JIT_VARIANTS[0])
    scenes = []
    original = photograph.render

    def recording(scene_dict, spp, seed, shown=None):
        scenes.append(scene_dict)
        return original(scene_dict, spp, seed, shown)

    photograph.render = recording
    try:
        path = tmp_path_factory.mktemp("sky") / "capture"
        simulate(path, SimulationOptions(environment="sky", seed=2, **SMALL), progress=False)
    finally:
        photograph.render = original
    return path, scenes


def test_capture_states_the_environment_its_photographs_were_rendered_with(sky_capture):
    path, scenes = sky_capture
    capture = load_capture(path)
    assert len(capture.lights) == 1
    light = capture.lights[0]
    assert (light.name, light.kind, light.environment) == ("sky", "environment", True)
    assert light.envmap.shape == (ENVIRONMENT_HEIGHT, 2 * ENVIRONMENT_HEIGHT, 3)
    assert json.loads((path / MANIFEST).read_text())["lights"] == [
        {"name": "sky", "kind": "environment", "map": "lights/sky.exr"}]
    # every face photograph (not the diffuse companions) was rendered with exactly the stated map, nothing else
    lit = [s for s in scenes if "environment" in s]
    assert len(lit) == SMALL["measurements"] and len(scenes) == 2 * SMALL["measurements"]
    for s in scenes:
        assert not any(key == "light" or key == "lamp" or key.startswith("steel_") for key in s)
    for s in lit:
        np.testing.assert_array_equal(np.array(s["environment"]["bitmap"]), light.envmap)
        emitter = environment_emitter(light.envmap, capture.camera)
        np.testing.assert_allclose(np.array(s["environment"]["to_world"].matrix),
                                   np.array(emitter["to_world"].matrix))
        assert s["environment"]["scale"] == 1.0
    # the map is the sun and sky, baked, times the exposure the ground truth records
    truth = read_ground_truth(path)
    exposure = truth.description["exposure"]
    baked = bake_environment(sky_emitter(capture.camera), capture.camera, ENVIRONMENT_HEIGHT)
    np.testing.assert_allclose(light.envmap, baked * exposure, rtol=1e-5, atol=1e-7)
    # the map is in pixel value: photographs have exposure 1, and no white target
    assert capture.white_target is None and not (path / "images" / "L00_spheres_point.exr").exists()
    assert all(m.light == "sky" and m.image.exposure == 1.0 for m in capture.measurements)


def test_environment_capture_turns_the_head_and_keeps_its_truth(sky_capture):
    path, _ = sky_capture
    capture, truth = load_capture(path), read_ground_truth(path)
    assert len({m.pose for m in capture.measurements}) == SMALL["measurements"]  # each its own head turn
    yaws = [m.yaw_pitch_roll[0] for m in truth.measurements]
    assert max(yaws) - min(yaws) > 20
    assert truth.lights == () and all(m.light == "sky" for m in truth.measurements)
    assert truth.description["environment"] == "sky" and truth.description["map"] == "lights/sky.exr"
    assert "none" in truth.description["point_lights"]
    assert all(m.diffuse is not None and m.feature_points for m in capture.measurements)
    # exposed from the map's physics: the brightest face pixels well under saturation, yet well exposed
    for m in capture.measurements:
        photo = read_exr(path / "images" / f"{m.name}_point.exr")
        face = m.diffuse.pixels.max(axis=2) < 0.7  # the diffuse companion's background is white
        assert 0.2 < np.percentile(photo[face], 99) < 0.8


def test_sky_bake_renders_as_the_sun_and_sky():
    """A white diffuse sphere under Mitsuba's sunsky and under its baked map: the same image."""
    mifaces.set_variant(JIT_VARIANTS[0])
    camera = studio_camera(32, 32, np.zeros(3))
    sky = sky_emitter(camera)
    baked = bake_environment(sky, camera, ENVIRONMENT_HEIGHT)

    def render(emitter):
        scene = mi.load_dict({
            "type": "scene", "integrator": {"type": "path", "max_depth": 2, "hide_emitters": True},
            "sensor": {"type": "perspective", "fov": 12.0, "film": {"type": "hdrfilm", "width": 32, "height": 32},
                       "to_world": mi.ScalarTransform4f().look_at([0, 0, 1200], [0, 0, 0], [0, 1, 0])},
            "ball": {"type": "sphere", "radius": 100.0,
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 1.0}}},
            "light": emitter})
        return np.array(mi.render(scene, spp=256, seed=1))[..., :3]

    direct, from_map = render(sky), render(environment_emitter(baked, camera))
    ball = direct.mean(axis=2) > 0
    assert ball.sum() > 100
    np.testing.assert_allclose(from_map[ball].mean(axis=0), direct[ball].mean(axis=0), rtol=0.03)
    # each half agrees: the sun (SKY_SUN_ANGLES, azimuth -35°, elevation 40°) lights the right and the
    # upper half; a map turned or upside down would not
    for half in (np.s_[:, :16], np.s_[:, 16:], np.s_[:16], np.s_[16:]):
        np.testing.assert_allclose(from_map[half][ball[half]].mean(), direct[half][ball[half]].mean(), rtol=0.04)


def test_irradiance_of_a_uniform_map_is_pi_radiance():
    normals = map_directions(np.array([0.1, 0.4, 0.9]), np.array([0.2, 0.5, 0.7]))
    np.testing.assert_allclose(irradiance(np.full((64, 128, 3), 2.0), normals), 2 * np.pi, rtol=2e-3)


def test_a_bad_environment_is_named(tmp_path):
    with pytest.raises(ValueError, match="'moon'") as error:
        simulate(tmp_path / "out", SimulationOptions(environment="moon", **SMALL), progress=False)
    assert all(name in str(error.value) for name in ENVIRONMENTS)
    assert not (tmp_path / "out" / MANIFEST).exists()


def test_cli_simulate_environment(tmp_path):
    out = tmp_path / "capture"
    result = CliRunner().invoke(main, ["--variant", JIT_VARIANTS[0], "simulate", str(out), "--environment", "studio",
                                       "--measurements", "2", "--resolution", "48x48", "--spp", "4"])
    assert result.exit_code == 0, result.output
    assert "studio environment" in result.output
    capture = load_capture(out)
    assert [(light.name, light.kind) for light in capture.lights] == [("studio", "environment")]
    assert read_ground_truth(out).description["environment"] == "studio"
    bad = CliRunner().invoke(main, ["simulate", str(tmp_path / "bad"), "--environment", "moon"])
    assert bad.exit_code != 0 and "moon" in bad.output
    assert not Path(tmp_path / "bad" / MANIFEST).exists()
