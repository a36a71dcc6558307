"""Nerfstudio / instant-ngp transforms.json (mifaces.importers.transforms): a hand-written file read
against values computed by hand, points projected through the file's OpenGL camera -> world matrices by
a formula written here against mifaces' OpenCV cameras, round trips, and the errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mifaces.capture import Camera
from mifaces.importers.colmap import rotation_from_quaternion
from mifaces.importers.transforms import read_transforms, write_transforms


def project_opengl(entry: dict, frame: dict, points) -> np.ndarray:
    """Pixels of world points through a transforms.json frame without distortion, as Nerfstudio casts
    rays: camera -> world ``M`` with x right, y up, z backwards, pixel centres at index + 0.5; so mifaces'
    pixel (centres at integers) is half a pixel less."""
    merged = {**entry, **frame}
    m = np.asarray(frame["transform_matrix"], float)
    local = (np.asarray(points, float) - m[:3, 3]) @ m[:3, :3]  # M^-1 x for a rigid M
    depth = -local[:, 2]  # in front of the camera is -z
    u = merged["fl_x"] * local[:, 0] / depth + merged["cx"]
    v = -merged["fl_y"] * local[:, 1] / depth + merged["cy"]  # image rows grow downwards, y up
    return np.stack([u, v], axis=-1) - 0.5


HAND = {"w": 640, "h": 480, "fl_x": 500.0, "fl_y": 400.0, "cx": 320.0, "cy": 240.0,
        "frames": [
            # at (0, 0, 10), looking down the world's -z, its up the world's +y
            {"file_path": "images/front.png", "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 10],
                                                                   [0, 0, 0, 1]]},
            # at (10, 0, 0), turned 90° about the world's y so that it looks down the world's -x; its own focal
            {"file_path": "images/side.png", "fl_x": 250.0, "fl_y": 250.0,
             "transform_matrix": [[0, 0, 1, 10], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]]},
        ]}


def test_hand_written_file(tmp_path):
    path = tmp_path / "transforms.json"
    path.write_text(json.dumps(HAND))
    cameras = read_transforms(path)
    assert list(cameras) == ["images/front.png", "images/side.png"]
    front, side = cameras.values()
    assert (front.width, front.height, front.fx, front.fy, front.cx, front.cy) == (640, 480, 500, 400, 319.5, 239.5)
    assert (side.fx, side.fy, side.cx) == (250, 250, 319.5)
    # OpenCV axes of the front camera: x right, y down (the world's -y), z forward (the world's -z)
    np.testing.assert_allclose(front.rotation, np.diag([1, -1, -1]))
    np.testing.assert_allclose(front.translation, [0, 0, 10])
    np.testing.assert_allclose(front.position, [0, 0, 10])
    np.testing.assert_allclose(side.position, [10, 0, 0])
    # by hand: (1, 2, 0) is 10 in front of the front camera, 1 right and 2 up: (320 + 50, 240 - 80) in
    # Nerfstudio's pixels, half a pixel less in mifaces'
    np.testing.assert_allclose(front.project([[1, 2, 0]]), [[369.5, 159.5]])
    # (0, 2, -1) is 10 in front of the side camera, its right the world's -z: 1 right, 2 up
    np.testing.assert_allclose(side.project([[0, 2, -1]]), [[320 + 25 - 0.5, 240 - 50 - 0.5]])


def test_projection_agrees_with_the_opengl_formula(tmp_path):
    rng = np.random.default_rng(5)
    cameras = {}
    for i in range(5):
        rotation = rotation_from_quaternion(rng.normal(size=4))
        cameras[f"f{i}.png"] = Camera(64, 48, 60.0 + i, 62.0, 31.0 + 0.1 * i, 24.2, np.zeros(0), rotation,
                                      rng.normal(size=3) + [0, 0, 8])
    path = write_transforms(cameras, tmp_path / "transforms.json")
    data = json.loads(path.read_text())
    assert "fl_x" not in data and all("fl_x" in frame for frame in data["frames"])  # intrinsics differ: per frame
    for frame, camera in zip(data["frames"], cameras.values()):
        points = camera.to_world(np.c_[rng.uniform(-2, 2, size=(10, 2)), rng.uniform(3, 9, size=10)])
        np.testing.assert_allclose(project_opengl(data, frame, points), camera.project(points), rtol=0, atol=1e-9)
    np.testing.assert_allclose(project_opengl(HAND, HAND["frames"][0], [[1, 2, 0]]), [[369.5, 159.5]])


@pytest.mark.parametrize("distortion", [np.zeros(0), np.array([-0.1, 0.02, 0.001, -0.002]),
                                        np.array([-0.1, 0.02, 0.001, -0.002, 0.01])])
def test_round_trip_shared_intrinsics(tmp_path, distortion):
    rng = np.random.default_rng(2)
    cameras = [Camera(80, 60, 90.0, 91.0, 40.3, 29.1, distortion, rotation_from_quaternion(rng.normal(size=4)),
                      rng.normal(size=3)) for _ in range(3)]
    path = write_transforms(cameras, tmp_path / "t.json", ["a.png", "b/c.png", "d.jpg"])
    data = json.loads(path.read_text())
    assert data["camera_model"] == "OPENCV" and (data["w"], data["h"], data["cx"]) == (80, 60, 40.8)
    assert ("k3" in data) == (len(distortion) == 5)
    assert all(set(frame) == {"file_path", "transform_matrix"} for frame in data["frames"])  # intrinsics shared
    read = read_transforms(path)
    assert list(read) == ["a.png", "b/c.png", "d.jpg"]
    for camera, back in zip(cameras, read.values()):
        assert (back.width, back.height, back.fx, back.fy) == (80, 60, 90.0, 91.0)
        np.testing.assert_allclose([back.cx, back.cy], [40.3, 29.1], rtol=0, atol=1e-12)
        np.testing.assert_array_equal(back.distortion, distortion)
        np.testing.assert_allclose(back.rotation, camera.rotation, rtol=0, atol=1e-14)
        np.testing.assert_allclose(back.translation, camera.translation, rtol=0, atol=1e-14)


def test_instant_ngp_camera_angle_and_default_centre(tmp_path):
    angle = 0.6911112070083618  # NeRF synthetic's camera_angle_x
    path = tmp_path / "transforms.json"
    path.write_text(json.dumps({"camera_angle_x": angle, "w": 800, "h": 800,
                                "frames": [{"file_path": "r_0.png", "transform_matrix": np.eye(4).tolist()}]}))
    camera = read_transforms(path)["r_0.png"]
    assert camera.fx == camera.fy == pytest.approx(400 / math.tan(angle / 2))
    assert (camera.cx, camera.cy) == (399.5, 399.5)  # the image centre, (w - 1) / 2 with centres at integers


def _file(tmp_path, top=None, frame=None, frames=None):
    """A transforms.json of one frame, the top level's ``top`` (a None value leaves a key out) and the frame's
    ``frame`` given, or ``frames`` instead."""
    base = {k: v for k, v in {"w": 64, "h": 48, "fl_x": 60.0, "cx": 32.0, "cy": 24.0, **(top or {})}.items()
            if v is not None}
    base["frames"] = frames if frames is not None else \
        [{"file_path": "a.png", "transform_matrix": np.eye(4).tolist(), **(frame or {})}]
    path = tmp_path / "transforms.json"
    path.write_text(json.dumps(base))
    return path


@pytest.mark.parametrize("top, frame, frames, message", [
    ({"k4": 0.01}, None, None, r"frames\[0\] \(a\.png\): k4 is Nerfstudio's r\^8 radial term"),
    ({"camera_model": "OPENCV_FISHEYE"}, None, None, r"frames\[0\] \(a\.png\): camera_model 'OPENCV_FISHEYE'"),
    (None, {"transform_matrix": np.diag([2.0, 2, 2, 1]).tolist()}, None, r"frames\[0\].*must be a rotation"),
    (None, {"transform_matrix": np.diag([1.0, 1, -1, 1]).tolist()}, None, r"must be a rotation \(no scale, no mirror"),
    (None, {"transform_matrix": [[1, 0, 0]]}, None, r"transform_matrix must be a 4x4"),
    (None, None, [{"transform_matrix": np.eye(4).tolist()}], r"frames\[0\]: needs a file_path"),
    (None, None, [{"file_path": "a.png", "transform_matrix": np.eye(4).tolist()}] * 2, r"frames\[1\].*appears twice"),
    ({"w": None}, None, None, r"needs the image size w and h"),
    ({"fl_x": None}, None, None, r"needs a positive focal length"),
    ({"fl_x": "60"}, None, None, r"fl_x must be a finite number"),
    (None, None, [], r"needs a non-empty list 'frames'"),
])
def test_bad_files_name_the_frame(tmp_path, top, frame, frames, message):
    path = _file(tmp_path, top, frame, frames)
    with pytest.raises(ValueError, match=message):
        read_transforms(path)


def test_invalid_json_and_unwritable_cameras(tmp_path):
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ValueError, match="bad.json: not valid JSON"):
        read_transforms(tmp_path / "bad.json")
    with pytest.raises(FileNotFoundError):
        read_transforms(tmp_path / "missing.json")
    rational = Camera(8, 8, 10, 10, 3.5, 3.5, np.array([0.1, 0, 0, 0, 0, 0.2, 0, 0]))
    with pytest.raises(ValueError, match="k4-k6"):
        write_transforms({"a.png": rational}, tmp_path / "t.json")
    with pytest.raises(ValueError, match="2 paths for 1 cameras"):
        write_transforms([rational], tmp_path / "t.json", ["a.png", "b.png"])
