"""Rendering only where something can show (:mod:`mifaces.render.crop`): the windows hold every
lit pixel, the cropped render has the whole render's mean, and scenes whose background can glow
are rendered whole."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import mitsuba as mi
import numpy as np

from mifaces.capture import Camera
from mifaces.render import mitsuba_sensor
from mifaces.render.crop import CROP_GRID, CROP_MARGIN, CroppedScene, box_corners, crop_window, dark_background

CAMERA = Camera(256, 192, 300.0, 300.0, 127.5, 95.5, np.zeros(5), np.diag([1.0, -1.0, -1.0]),
                np.array([0.0, 0.0, 1000.0]))
BALLS = [np.array([-150.0, 80.0, 0.0]), np.array([160.0, -90.0, 0.0])]
RADIUS = 30.0


def _scene(spp: int) -> dict:
    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
             "sensor": mitsuba_sensor(CAMERA, spp),
             "light": {"type": "point", "position": [0.0, 0.0, 800.0], "intensity": {"type": "rgb", "value": 4e5}}}
    for i, centre in enumerate(BALLS):
        scene[f"ball_{i}"] = {"type": "sphere", "center": centre.tolist(), "radius": RADIUS,
                              "bsdf": {"type": "diffuse"}}
    return scene


def test_a_window_holds_the_projection_snapped_to_the_grid():
    x, y, w, h = crop_window(CAMERA, box_corners(BALLS[0], RADIUS))
    assert x % CROP_GRID == 0 and y % CROP_GRID == 0
    assert (x + w) % CROP_GRID == 0 or x + w == CAMERA.width
    xy = CAMERA.project(box_corners(BALLS[0], RADIUS))
    assert x <= xy[:, 0].min() - CROP_MARGIN and x + w >= xy[:, 0].max() + CROP_MARGIN
    assert y <= xy[:, 1].min() - CROP_MARGIN and y + h >= xy[:, 1].max() + CROP_MARGIN
    assert w * h < CAMERA.width * CAMERA.height / 4
    # the whole image, straddling the camera's plane: render whole; behind it or outside: nothing
    assert crop_window(CAMERA, box_corners([0.0, 0.0, 0.0], 2000.0)) is None
    assert crop_window(CAMERA, box_corners([0.0, 0.0, 2000.0], 10.0)) == (0, 0, 0, 0)
    assert crop_window(CAMERA, box_corners([5000.0, 0.0, 0.0], 10.0)) == (0, 0, 0, 0)


def test_a_cropped_render_is_the_whole_render_within_its_noise():
    mifaces.set_variant("llvm_ad_rgb")
    scene = _scene(64)
    whole = np.array(mi.render(mi.load_dict(scene), spp=64, seed=3), np.float32)[..., :3]
    both = CroppedScene(scene, CAMERA, [box_corners(c, RADIUS) for c in BALLS])
    cropped, again = both.render(64, 3), both.render(64, 4)
    assert cropped.shape == whole.shape
    lit = whole.max(axis=-1) > 0
    assert np.all(cropped[~lit] == 0) and np.all(cropped.max(axis=-1)[lit] > 0)  # every lit pixel rendered
    np.testing.assert_allclose(cropped.sum(), whole.sum(), rtol=0.01)
    for ball in BALLS:  # each window its own noise: the two balls' pixels are not copies of one another
        x, y = np.round(CAMERA.project(ball)).astype(int)
        assert cropped[y, x, 0] > 0
    assert not np.array_equal(cropped, again)  # the seed reaches the windows
    # a window left out is dark: the render is what the windows hold, nothing else
    one = CroppedScene(scene, CAMERA, [box_corners(BALLS[0], RADIUS)]).render(64, 3)
    x, y = np.round(CAMERA.project(BALLS[1])).astype(int)
    assert one[y, x].max() == 0 and whole[y, x].max() > 0


def test_without_objects_or_with_a_glowing_background_the_scene_renders_whole():
    mifaces.set_variant("llvm_ad_rgb")
    scene = _scene(16)
    whole = np.array(mi.render(mi.load_dict(scene), spp=16, seed=2), np.float32)[..., :3]
    # the same samples as the whole render: equal to float32 rounding (the film's atomic splats)
    np.testing.assert_allclose(CroppedScene(scene, CAMERA).render(16, 2), whole, rtol=1e-5, atol=1e-7)
    straddling = box_corners([0.0, 0.0, 1000.0], 50.0)  # around the camera: no window holds it
    np.testing.assert_allclose(CroppedScene(scene, CAMERA, [straddling]).render(16, 2), whole, rtol=1e-5, atol=1e-7)


def test_only_a_scene_lit_by_delta_lights_has_a_dark_background():
    scene = _scene(4)
    assert dark_background(scene)
    assert not dark_background({**scene, "sky": {"type": "constant"}})
    assert not dark_background({**scene, "lamp": {"type": "sphere", "emitter": {"type": "area"}}})
    assert not dark_background({**scene, "map": mi.load_dict({"type": "constant"})})
    assert dark_background({**scene, "spot": mi.load_dict({"type": "point"})})
