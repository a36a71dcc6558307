"""Captures with several calibrated cameras (issue 46): the manifest's ``cameras`` and each
photograph's ``camera`` and ``shot``, its errors, the simulated rig, and the shape fit that uses
every view of a shot, which fixes the face's depth."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from mifaces.capture import MANIFEST, CaptureError, load_capture, read_ground_truth
from mifaces.capture.camera import relative_pose
from mifaces.capture.types import DEFAULT_CAMERA
from mifaces.cli.commands import main
from mifaces.shape import ShapeSchedule, fit_shape, shapes_in_world
from mifaces.shape.io import load_fitted_shapes
from mifaces.shape.poses import seen_by
from mifaces.studio.scene import RIG_YAWS
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate
from test_simulate import copy_capture

#: The rig of these tests: two cameras, small pictures (the fit sees the features only).
RIG = dict(measurements=2, resolution=(96, 96), spp=2, companion="diffuse", albedo_resolution=64, seed=5, cameras=2)
#: Feature points only: the landmark stage of the shape fit, at its default length.
LANDMARKS = ShapeSchedule(levels=(), pose_iterations=ShapeSchedule().pose_iterations)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    return simulate(tmp_path_factory.mktemp("rig") / "capture", SimulationOptions(**RIG), progress=False).path


def _edited(rig, tmp_path, change):
    path = copy_capture(rig, tmp_path / "edited")
    data = json.loads((path / MANIFEST).read_text())
    change(data)
    (path / MANIFEST).unlink()
    (path / MANIFEST).write_text(json.dumps(data))
    return path


def test_a_rig_loads_with_its_cameras_and_shots(rig):
    capture = load_capture(rig)
    assert list(capture.cameras) == ["c0", "c1"] and capture.several_cameras
    assert capture.camera is capture.cameras["c0"]
    names = [(m.name, m.camera, m.pose) for m in capture.measurements]
    assert names == [("m00", "c0", "P000"), ("m00_c1", "c1", "P000"), ("m01", "c0", "P001"), ("m01_c1", "c1", "P001")]
    turned = capture.camera_of("m00_c1")
    assert turned is capture.cameras["c1"]
    head = read_ground_truth(capture).head_center
    a, b = (cam.position - head for cam in (capture.camera, turned))
    angle = np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))
    assert angle == pytest.approx(abs(RIG_YAWS[1]), abs=1e-6)
    truth = {m.name: m for m in read_ground_truth(capture).measurements}
    for m in capture.measurements:  # each photograph's clicks are where its own camera sees the face
        camera = capture.camera_of(m)
        for name, xy in m.feature_points.items():
            assert np.linalg.norm(xy - truth[m.name].feature_points[name]) < 1.0
        assert m.image.pixels.shape[:2] == (camera.height, camera.width)


def test_a_one_camera_manifest_is_its_only_camera(tmp_path):
    path = simulate(tmp_path / "one", SimulationOptions(**dict(RIG, cameras=1, measurements=1)), progress=False).path
    data = json.loads((path / MANIFEST).read_text())
    assert "camera" in data and "cameras" not in data
    capture = load_capture(path)
    assert list(capture.cameras) == [DEFAULT_CAMERA] and not capture.several_cameras
    assert capture.camera_of(capture.measurements[0]) is capture.camera


def _camera_entry(data, ident):
    return next(c for c in data["cameras"] if c["id"] == ident)


def _uncalibrated(entry):
    entry.update(calibrated=False, focal_guess_px=entry.pop("fx"))
    entry.pop("fy")


@pytest.mark.parametrize("change, message", [
    (lambda d: d["measurements"][1].update(camera="c7"), "no camera with id 'c7'"),
    (lambda d: d["measurements"][1].pop("camera"), "camera: missing; the capture has 2 cameras"),
    (lambda d: d["cameras"].append(dict(_camera_entry(d, "c1"), id="c2",
                                        translation=[0.0, 0.0, 900.0])), "camera 'c2' took no photograph"),
    (lambda d: _camera_entry(d, "c1").update(width=128), "the camera's images are 128x96"),
    (lambda d: _camera_entry(d, "c1").update(rotation=_camera_entry(d, "c0")["rotation"],
                                             translation=_camera_entry(d, "c0")["translation"]),
     "cameras 'c0' and 'c1' are at one place"),
    (lambda d: d.update(camera=d["cameras"][0]), "give one 'camera' or a list of 'cameras', not both"),
    (lambda d: _camera_entry(d, "c1").update(id="c0"), "cameras: name 'c0' used more than once"),
    (lambda d: _uncalibrated(_camera_entry(d, "c1")), "a camera of several must be calibrated"),
    (lambda d: d["measurements"][0].update(pose="elsewhere"), "pose 'elsewhere' and shot 'P000' differ"),
])
def test_bad_cameras_are_named(rig, tmp_path, change, message):
    with pytest.raises(CaptureError) as error:
        load_capture(_edited(rig, tmp_path, change))
    assert message in str(error.value)


def test_a_bad_camera_id_stops_measure_before_it_writes(rig, tmp_path):
    path = _edited(rig, tmp_path, lambda d: d["measurements"][1].update(camera="c7"))
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["measure", str(path), "--out", str(out)])
    assert result.exit_code != 0 and "no camera with id 'c7'" in result.output
    assert not out.exists() or not any(out.iterdir())


def test_seen_by_moves_a_fit_between_cameras(rig):
    capture = load_capture(rig)
    fits = fit_shape(capture, measurements=["m00", "m00_c1"], iterations=ShapeSchedule(levels=(), pose_iterations=20),
                     progress=False, one_identity=False)
    first, second = capture.camera, capture.cameras["c1"]
    moved = seen_by(fits[0], first, second)
    np.testing.assert_allclose(moved.vertices_camera, second.to_camera(fits[0].vertices_world), atol=1e-3)
    np.testing.assert_allclose(second.to_world(moved.vertices_camera), fits[0].vertices_world, atol=1e-3)
    A, _ = relative_pose(first, second)
    np.testing.assert_allclose(moved.rotation, A @ fits[0].rotation, atol=1e-12)
    # the shot's other photograph is that fit, seen from its own camera
    np.testing.assert_allclose(fits[1].vertices_camera, moved.vertices_camera, atol=1e-3)


def _depth_errors(capture, fits):
    """Per fit: the mean offset (mm) of the fitted face from the truth along its camera's axis."""
    truth = {m.name: m.vertices for m in read_ground_truth(capture).measurements}
    world = shapes_in_world(fits, capture)
    return {name: float(np.mean((world[name] - truth[name]) @ capture.camera_of(name).rotation[2]))
            for name in world}


def test_two_cameras_triangulate_the_depth(rig, tmp_path):
    """One camera cannot tell the face's distance from its size; a second calibrated camera, turned
    30 degrees, can: the feature points alone put the face at its true depth."""
    capture = load_capture(rig)
    both = fit_shape(capture, iterations=LANDMARKS, progress=False, out=tmp_path / "shapes")
    assert all(fit.converged for fit in both) and "scale" not in both[0].estimated
    two = _depth_errors(capture, both)
    assert max(abs(d) for d in two.values()) < 1.5, two  # (0.6-1.0 mm when written)
    one = _depth_errors(capture, fit_shape(capture, measurements=["m00", "m01"], iterations=LANDMARKS,
                                           progress=False))
    assert max(abs(d) for d in one.values()) > 2 * max(abs(d) for d in two.values()), (one, two)
    # the files hold each photograph in its own camera's frame, and read back into one world
    read = load_fitted_shapes(tmp_path / "shapes")
    for name, vertices in shapes_in_world(both, capture).items():
        np.testing.assert_allclose(read[name], vertices, atol=1e-3)
    np.testing.assert_allclose(read["m00"], read["m00_c1"], atol=1e-3)
