"""Environment lights in the texture-space stages (mifaces.reflectance.environment, mifaces.light_estimation.unknown):
given maps in the capture format, the light a map sends to a surface, a map estimated from
photographs, and the files an estimate writes."""

from __future__ import annotations

import json
from dataclasses import replace

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mifaces.capture import Camera, CaptureError, load_capture, read_ground_truth
from mifaces.capture.types import RELATIVE_IRRADIANCE
from mifaces.lights.environment import (LUMINANCE, dominant_direction, environment_emitter, irradiance, peak_irradiance,
                                        studio_environment, texel_directions, to_world)
from mifaces.io.image_files import read_exr, write_exr
from mifaces.light_estimation.unknown import LIGHTS_FILE, LIGHTS_FOLDER, write_lights, write_lights_picture
from mifaces.reflectance.environment import equivalent_lights, estimate_map, reduced_map
from mifaces.refine.environment import ENVMAP_FLOOR, padded_envmap
from mifaces.render import mitsuba_sensor
from mifaces.reflectance import FitOptions
from test_real_capture import write_directional

#: A camera 1 m along +z looking at the origin (the world's y up is the image's up).
CAMERA = Camera(32, 32, 200.0, 200.0, 15.5, 15.5, np.zeros(0), np.diag([1.0, -1.0, -1.0]), np.array([0, 0, 1000.0]))


def _with_map(tmp_path, envmap, **entry):
    """test_real_capture's capture with its first light replaced by a given environment map."""
    write_exr(tmp_path / "lights" / "room.exr", envmap)

    def change(data):
        data["lights"][0] = {"name": "room", "kind": "environment", "map": "lights/room.exr", **entry}
        for m in data["measurements"]:
            if m["light"] == "top":
                m["light"] = "room"
    return write_directional(tmp_path, change)


def test_a_given_map_loads_as_an_environment_light(tmp_path):
    envmap = studio_environment(16)
    capture = load_capture(_with_map(tmp_path, envmap, scale=2.0), detect=False)
    room = capture.light("room")
    assert room.environment and not room.unknown and not room.directional and room.position is None
    np.testing.assert_allclose(room.envmap, 2.0 * envmap, rtol=1e-3)  # the stated scale applied (EXR half floats)
    with pytest.raises(ValueError, match="'room' is an environment map: it has no one direction"):
        room.towards(np.zeros((1, 3)))


@pytest.mark.parametrize("entry, envmap, message", [
    ({"direction": [0, 0, -1]}, None, "light 'room' is an environment map: it takes no 'direction'"),
    ({"kind": "directional"}, None, "light 'room' has a 'map' but kind 'directional'"),
    ({}, np.ones((8, 8, 3), np.float32), "invalid envmap size 8x8"),
    ({}, -np.ones((8, 16, 3), np.float32), "has NaN, infinite or negative radiance"),
    ({"map": "lights/none.exr"}, None, "'lights/none.exr' is not an OpenEXR file in the capture"),
])
def test_a_bad_given_map_is_named(tmp_path, entry, envmap, message):
    with pytest.raises(CaptureError) as error:
        load_capture(_with_map(tmp_path, studio_environment(8) if envmap is None else envmap, **entry), detect=False)
    assert message in str(error.value), str(error.value)


def test_texel_directions_are_where_mitsuba_reads_the_map():
    """A map with one bright texel: Mitsuba's envmap is brightest in that texel's direction."""
    width, height = 16, 8
    image = np.zeros((height, width, 3), np.float32)
    image[2, 5] = 1.0
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(image)})
    d, solid = texel_directions(width, height)
    assert solid.sum() == pytest.approx(4 * np.pi)
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = mi.Vector3f(np.ascontiguousarray(-d.T, np.float32))
    value = np.array(emitter.eval(si))[0]
    assert np.argmax(value) == 2 * width + 5 and value.max() == pytest.approx(1.0, rel=1e-3)
    # and the refinement writes a map into Mitsuba's padded layout
    np.testing.assert_array_equal(np.array(padded_envmap(mi.TensorXf(image))), np.array(mi.traverse(emitter)["data"]))


def test_the_maps_irradiance_matches_mitsubas_render():
    """A white Lambertian sphere under the studio map: the render reads E / pi where E is
    equivalent_lights' irradiance (the map reduced to 32 x 16 texels)."""
    radius = 50.0
    envmap = studio_environment(32)
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "direct"}, "sensor": mitsuba_sensor(CAMERA, 256),
                          "emitter": environment_emitter(envmap, CAMERA),
                          "ball": {"type": "sphere", "radius": radius,
                                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [1, 1, 1]}}}})
    image = np.array(mi.render(scene, spp=256))[..., :3].reshape(-1, 3)
    ys, xs = np.mgrid[0:CAMERA.height, 0:CAMERA.width]
    d = CAMERA.pixel_rays(np.stack([xs, ys], -1).reshape(-1, 2).astype(float)) @ CAMERA.rotation
    b = d @ CAMERA.position
    disc = b * b - (CAMERA.position @ CAMERA.position - radius ** 2)
    hit = disc > 0
    p = CAMERA.position + (-b[hit] - np.sqrt(disc[hit]))[:, None] * d[hit]
    n = p / radius
    inner = n[:, 2] > 0.5  # away from the silhouette's partly covered pixels
    occluder = mi.load_dict({"type": "scene", "ball": {"type": "sphere", "radius": radius}})
    direction, e = equivalent_lights(occluder, p[inner], n[inner], envmap, CAMERA, 1e-3, 1e4)
    ratio = image[hit][inner] @ LUMINANCE / (e @ LUMINANCE / np.pi)
    assert np.median(ratio) == pytest.approx(1.0, abs=0.02)
    assert np.percentile(np.abs(ratio - 1), 90) < 0.06
    # the equivalent light comes from the lit side: the key panel is on the image's left (+azimuth)
    key = dominant_direction(envmap, CAMERA)
    assert key @ CAMERA.direction(40.0, 30.0) > 0.8 and np.median(direction @ key) > 0.5


def _rotation(yaw, pitch):
    a, b = np.radians(yaw), np.radians(pitch)
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    tilt = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    return tilt @ turn


def test_estimate_map_recovers_the_light_with_one_albedo():
    """Texels of random albedo and normal seen in six head poses under the studio map: the
    estimated map gives every normal towards the camera the true irradiance (up to the stated
    scale), although no photograph alone tells the map from the albedo."""
    rng = np.random.default_rng(3)
    size = (16, 8)
    direction, radiance, _ = reduced_map(studio_environment(32), size)
    d, solid = texel_directions(*size)
    truth = radiance.reshape(size[1], size[0], 3)
    normals = rng.normal(size=(600, 3))
    normals[:, 2] = np.abs(normals[:, 2]) + 0.3
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    albedo = rng.uniform(0.2, 0.8, (len(normals), 3))
    parts = []
    for yaw, pitch in ((-30, 0), (-15, 12), (0, -12), (15, 15), (30, 0), (0, 0)):
        t = np.clip(normals @ _rotation(yaw, pitch).T @ d.T, 0, None) * solid
        pixels = albedo / np.pi * (t @ radiance) * (1 + 0.01 * rng.normal(size=(len(normals), 3)))
        parts.append((pixels, t, np.arange(len(normals))))
    estimate, info = estimate_map(*zip(*parts), size=size, rounds=20)
    assert estimate.shape == (8, 16, 3) and estimate.min() >= 0
    assert peak_irradiance(estimate) @ LUMINANCE == pytest.approx(RELATIVE_IRRADIANCE, rel=1e-6)
    front = d[:, 2] > 0.2
    e_true = irradiance(truth, d) * (RELATIVE_IRRADIANCE / (peak_irradiance(truth) @ LUMINANCE))
    e_fit = irradiance(estimate, d)
    def error(e):
        e = e * (np.mean(e_true[front]) / np.mean(e[front]))  # the shape of the light, not its scale
        return np.sqrt(np.mean((e - e_true)[front] ** 2) / np.mean(e_true[front] ** 2))

    assert error(e_fit) < 0.08, error(e_fit)
    assert error(irradiance(np.ones_like(truth), d)) > 0.3  # a uniform light would not pass
    assert info["residual"] < 0.03 and info["texels"] == len(normals)
    with pytest.raises(ValueError, match="too few usable texels"):
        estimate_map([p[0][:5] for p in parts], [p[1][:5] for p in parts], [p[2][:5] for p in parts], size)


def test_an_estimated_map_is_written_and_shown(tmp_path):
    capture = load_capture(_with_map(tmp_path / "c", studio_environment(8)), detect=False)
    estimated = replace(capture.light("room"), envmap=studio_environment(8), estimated=True, relative=True)
    capture = replace(capture, lights=(estimated, *capture.lights[1:]))
    document = json.loads(write_lights(tmp_path / "res", capture).read_text())
    entry = {e["name"]: e for e in document["lights"]}["room"]
    assert entry["kind"] == "environment" and entry["estimated"] and entry["map"] == f"{LIGHTS_FOLDER}/room.exr"
    np.testing.assert_allclose(read_exr(tmp_path / "res" / entry["map"])[..., :3], studio_environment(8), rtol=1e-3)
    assert "environment maps: latitude-longitude" in document["map"]
    assert (tmp_path / "res" / LIGHTS_FILE).is_file()
    write_lights_picture(tmp_path / "res" / "lights.png", capture)
    assert (tmp_path / "res" / "lights.png").stat().st_size > 1000


def test_to_world_places_the_maps_centre_towards_the_camera():
    centre = np.array([[0.0, 0.0, 1.0]])  # the map frame's +z: u = 1/2, the centre column
    np.testing.assert_allclose(to_world(centre, CAMERA)[0], CAMERA.position / np.linalg.norm(CAMERA.position))


@pytest.fixture(scope="module")
def studio_capture(tmp_path_factory):
    """A small capture of three head turns under the generated studio map."""
    from mifaces.studio import SimulationOptions, simulate

    out = tmp_path_factory.mktemp("studio") / "capture"
    simulate(out, SimulationOptions(environment="studio", measurements=3, resolution=(96, 96), spp=8,
                                    albedo_resolution=128, seed=4), progress=False)
    return out


def test_measure_estimates_a_hidden_map_with_the_face(studio_capture, tmp_path):
    """The studio's map hidden: measure estimates it, writes it, refines it with the BRDF, and says
    that the reflectance is relative."""
    import shutil

    from mifaces.capture import MANIFEST
    from mifaces.pipeline.measure import measure

    hidden = tmp_path / "hidden"
    shutil.copytree(studio_capture, hidden)
    data = json.loads((hidden / MANIFEST).read_text())
    true_map = load_capture(studio_capture, detect=False).lights[0].envmap
    data["lights"] = [{"name": "studio", "unknown": True, "kind": "environment", "size": [16, 8]}]
    (hidden / MANIFEST).write_text(json.dumps(data))
    # the bounced light left in: the subject is the map (the correction's own tests: test_interreflection.py)
    report = measure(tmp_path / "m", hidden, models=("phong",), spp=4, refine=True, progress=False,
                     options=FitOptions(resolution=64, interreflection=False))
    estimate = report["lights"]["estimates"][0]
    assert estimate["kind"] == "environment" and estimate["size"] == [16, 8] and estimate["photographs"] == [
        "m00", "m01", "m02"]
    envmap = read_exr(tmp_path / "m" / estimate["map"])[..., :3]
    assert envmap.shape == (8, 16, 3)
    # the estimate lights the face from where the studio's key light is
    key = dominant_direction(true_map, load_capture(hidden, detect=False).camera)
    camera = load_capture(hidden, detect=False).camera
    assert dominant_direction(envmap, camera) @ key > 0.7
    brdf = json.loads((tmp_path / "m" / "brdf" / "phong" / "brdf.json").read_text())
    assert brdf["lighting"]["reflectance"] == "relative"
    assert brdf["refinement"]["restarted"] is True  # under a map the glossy part starts afresh
    assert brdf["refinement"]["lights"] == ["environment"]
    assert "| environment light | map |" in (tmp_path / "m" / "report.md").read_text()
    # the fitted face's scene is lit as the BRDF was fitted: by the refined map where the refinement
    # was kept (it moved from its floored start), else by the estimate; beside the scene
    scene_map = read_exr(tmp_path / "m" / "brdf" / "phong" / "environment.exr")[..., :3]
    assert 'value="environment.exr"' in (tmp_path / "m" / "brdf" / "phong" / "scene.xml").read_text()
    if brdf["refinement"]["accepted"]:
        refined = np.asarray(brdf["refinement"]["environment_maps"]["studio"])
        start = np.maximum(envmap, ENVMAP_FLOOR * envmap.mean())
        assert refined.shape == (8, 16, 3) and np.abs(np.log(refined) - np.log(start)).max() > 1e-2
        np.testing.assert_allclose(scene_map, refined, rtol=1e-3)
    else:
        assert brdf["refinement"]["environment_maps"] == {}
        np.testing.assert_allclose(scene_map, envmap, rtol=1e-3)


def test_the_refinement_differentiates_an_estimated_map(studio_capture):
    """An estimated map is a variable of the refinement: its log radiance gets a gradient from the
    photographs, its mean is held, and a given map stays fixed."""
    from mifaces.shape.io import load_geometry
    from mifaces.reflectance import fit_brdf
    from mifaces.refine.problem import RefineProblem
    from mifaces.refine.schedule import RefineSchedule, environment_variable

    capture = load_capture(studio_capture)
    face, shapes = load_geometry(capture, "ground-truth")
    estimate = fit_brdf(capture, "phong", "ground-truth", progress=False, options=FitOptions(resolution=32))
    schedule = RefineSchedule(spp=2, evaluation_spp=2)
    given = RefineProblem(estimate, capture, shapes, face, schedule)
    assert given.restarted and given.environments == {} and not any(k.startswith("environment") for k in given.variables)
    light = capture.lights[0]
    estimated = replace(capture, lights=(replace(light, estimated=True, relative=True),))
    problem = RefineProblem(estimate, estimated, shapes, face, schedule)
    name = environment_variable(light.name)
    assert name in problem.variables and problem.variables[name].shape == light.envmap.shape
    variables = {k: mi.TensorXf(np.asarray(v, np.float32)) if np.ndim(v) == 3 else mi.Float(np.asarray(v, np.float32))
                 for k, v in problem.variables.items()}
    dr.enable_grad(variables[name])
    loss = problem.loss(problem.photographs[0], variables, spp=2, seed=1)
    dr.backward(loss)
    gradient = np.asarray(dr.grad(variables[name]))
    assert np.all(np.isfinite(gradient)) and np.abs(gradient).max() > 0
    # the mean log radiance is held: a uniform shift of the variable changes no texel
    shifted = dict(variables, **{name: variables[name] + 1.0})
    np.testing.assert_allclose(np.asarray(problem.environment_map(light.name, shifted)),
                               np.asarray(problem.environment_map(light.name, variables)), rtol=1e-4)


def test_held_out_lights_avoid_the_maps_light(studio_capture):
    """Held-out lights of a capture lit by a map alone are directional, of irradiance pi, and none
    comes from where most of the map's light does; beside point lights, the map's direction is
    avoided too."""
    from mifaces.validation.held_out import held_out_lights

    capture = load_capture(studio_capture)
    key = dominant_direction(capture.lights[0].envmap, capture.camera)
    lights = held_out_lights(capture, np.zeros(3), count=3)
    assert all(light.directional and np.allclose(light.intensity, RELATIVE_IRRADIANCE) for light, _ in lights)
    assert all(np.degrees(np.arccos(np.clip(light.direction @ key, -1, 1))) >= angle - 1e-6
               and angle > 20 for light, angle in lights)
    from mifaces.capture.types import Light
    lamp = Light("lamp", capture.camera.position * 1.5, np.full(3, 1e6))
    mixed = replace(capture, lights=(capture.lights[0], lamp))
    for light, angle in held_out_lights(mixed, np.zeros(3), count=3):
        assert light.position is not None and np.allclose(light.intensity, 1e6)
        towards = light.position / np.linalg.norm(light.position)
        assert np.degrees(np.arccos(np.clip(towards @ key, -1, 1))) >= angle - 1e-6


def test_a_map_without_the_refinement_is_flagged(studio_capture, tmp_path):
    """A capture lit by a map, measured without --refine: the report and a warning say that the
    glossy parameters need the refinement."""
    from mifaces.pipeline.measure import MAP_WITHOUT_REFINE, measure

    with pytest.warns(UserWarning, match="read as lit from one direction per texel"):
        report = measure(tmp_path / "m", studio_capture, models=("phong",), geometry="ground-truth", spp=2,
                         progress=False, options=FitOptions(resolution=32))
    assert report["environment_note"] == MAP_WITHOUT_REFINE
    assert f"Note: {MAP_WITHOUT_REFINE}." in (tmp_path / "m" / "report.md").read_text()


def test_held_out_lights_of_an_estimated_map_are_the_given_maps(studio_capture):
    """The held-out lights avoid the map the simulator rendered with, not the estimate: a run that
    estimated its map is judged under the same lights as one given the map."""
    from mifaces.validation.held_out import held_out_lights, true_lights

    capture = load_capture(studio_capture)
    truth = read_ground_truth(capture)
    light = capture.lights[0]
    turned = np.roll(light.envmap, light.envmap.shape[1] // 4, axis=1)  # an estimate a quarter turn off
    estimated = replace(capture, lights=(replace(light, envmap=turned, estimated=True, relative=True),))
    restored = true_lights(estimated, truth)
    np.testing.assert_array_equal(restored.lights[0].envmap, light.envmap)
    assert not restored.lights[0].estimated and true_lights(capture, truth).lights == capture.lights
    given = held_out_lights(true_lights(capture, truth), np.zeros(3), count=3)
    for (a, _), (b, _) in zip(held_out_lights(restored, np.zeros(3), count=3), given):
        np.testing.assert_array_equal(a.direction, b.direction)
    # the estimate itself would have moved them
    assert any(not np.allclose(a.direction, b.direction)
               for (a, _), (b, _) in zip(held_out_lights(estimated, np.zeros(3), count=3), given))
    from mifaces.capture import with_true_lights
    with pytest.raises(ValueError, match=r"placed no point light for light\(s\) \['studio'\]"):
        with_true_lights(capture)
