"""COLMAP sparse models (mifaces.importers.colmap, mifaces.importers.colmap_records): a hand-written
model read against values computed by hand, every supported camera model against COLMAP's own
projection formulas written here, text and binary round trips, pycolmap reading what we write
(and we what it writes), and the errors."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from mifaces.capture import Camera
from mifaces.importers.colmap import (PIXEL_CENTRE, ColmapModel, quaternion_from_rotation, read_colmap,
                                      rotation_from_quaternion, write_colmap)
from mifaces.importers.colmap_records import CameraRecord, ImageRecord, write_records

S = 0.5 ** 0.5  # cos 45° = sin 45°: the quaternion (S, 0, 0, S) turns 90° about z


def write_text_model(folder: Path, cameras: str, images: str, points: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in (("cameras", cameras), ("images", images), ("points3D", points)):
        (folder / f"{name}.txt").write_text(text)
    return folder


HAND_CAMERAS = "# Camera list\n1 PINHOLE 640 480 500 400 320 240\n"
#: Image 1 turned 90° about z, t = (1, 2, 10); its keypoints: point 7 at COLMAP pixel (370, 360), point 9 at
#: (320, 293.33...), one keypoint without a point. Image 2 (a name with a space) sees nothing: an empty line.
HAND_IMAGES = (f"# Image list\n1 {S!r} 0 0 {S!r} 1 2 10 1 front.png\n"
               f"370 360 7 320 {880 / 3!r} 9 100 100 -1\n"
               "2 1 0 0 0 0 0 0 1 side view.png\n\n")
HAND_POINTS = "# 3D points\n9 0 1 5 10 20 30 0.5 1 1\n7 1 0 0 255 0 0 0.1 1 0\n"


def test_hand_written_text_model(tmp_path):
    model = read_colmap(write_text_model(tmp_path, HAND_CAMERAS, HAND_IMAGES, HAND_POINTS))
    assert list(model.cameras) == ["front.png", "side view.png"]
    front = model.cameras["front.png"]
    # intrinsics: COLMAP's principal point less half a pixel
    assert (front.width, front.height, front.fx, front.fy, front.cx, front.cy) == (640, 480, 500, 400, 319.5, 239.5)
    assert len(front.distortion) == 0
    # R_z(90°) by hand; the camera's centre -R^T t = -(2, -1, 10)
    np.testing.assert_allclose(front.rotation, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(front.translation, [1, 2, 10])
    np.testing.assert_allclose(front.position, [-2, 1, -10], atol=1e-14)
    # points in file order (rows), not by id: id 9 is row 0, id 7 row 1
    np.testing.assert_array_equal(model.points, [[0, 1, 5], [1, 0, 0]])
    np.testing.assert_array_equal(model.colors, [[10, 20, 30], [255, 0, 0]])
    indices, xy = model.observations["front.png"]
    np.testing.assert_array_equal(indices, [1, 0])
    # by hand: (1, 0, 0) -> R -> (0, 1, 0) + t = (1, 3, 10) -> (500/10 + 320, 400 * 3/10 + 240) = (370, 360) in
    # COLMAP's pixels; (0, 1, 5) -> (-1, 0, 5) + t = (0, 2, 15) -> (320, 240 + 800/15); mifaces' half a pixel less
    np.testing.assert_allclose(xy, [[369.5, 359.5], [319.5, 240 + 800 / 15 - 0.5]], atol=1e-12)
    # the pixel convention, proven: each point projected through the returned camera lands on its observation
    np.testing.assert_allclose(front.project(model.points[indices]), xy, atol=1e-9)
    assert len(model.observations["side view.png"][0]) == 0
    np.testing.assert_allclose(model.cameras["side view.png"].rotation, np.eye(3))


def test_pixel_centre_convention(tmp_path):
    """The top-left pixel's centre is (0.5, 0.5) in COLMAP and (0, 0) in mifaces: a point on the optical
    axis lands on COLMAP's principal point, which is mifaces' plus 0.5."""
    cameras = "1 SIMPLE_PINHOLE 4 4 10 0.5 0.5\n"  # principal point on the top-left pixel's centre
    images = "1 1 0 0 0 0 0 0 1 a.png\n0.5 0.5 1\n"
    model = read_colmap(write_text_model(tmp_path, cameras, images, "1 0 0 3 0 0 0 0 1 0\n"))
    camera = model.cameras["a.png"]
    assert (camera.cx, camera.cy) == (0.0, 0.0)
    np.testing.assert_allclose(camera.project([[0, 0, 3]]), [[0.0, 0.0]])
    np.testing.assert_allclose(model.observations["a.png"][1], [[0.0, 0.0]])
    assert PIXEL_CENTRE == 0.5


def colmap_distort(model: str, extra, u, v):
    """COLMAP's distortion of normalised coordinates (``src/colmap/sensor/models.h``), written out per
    model; ``extra`` are the parameters after the focal lengths and the principal point."""
    r2 = u * u + v * v
    if model in ("SIMPLE_PINHOLE", "PINHOLE"):
        return u, v
    if model in ("SIMPLE_RADIAL", "RADIAL"):
        radial = 1 + extra[0] * r2 + (extra[1] * r2 ** 2 if model == "RADIAL" else 0)
        return u * radial, v * radial
    k1, k2, p1, p2 = extra[:4]
    k3, k4, k5, k6 = extra[4:8] if model == "FULL_OPENCV" else (0, 0, 0, 0)
    radial = (1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3) / (1 + k4 * r2 + k5 * r2 ** 2 + k6 * r2 ** 3)
    return (u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u),
            v * radial + 2 * p2 * u * v + p1 * (r2 + 2 * v * v))


MODELS = {"SIMPLE_PINHOLE": [300, 31, 22], "PINHOLE": [300, 320, 31, 22],
          "SIMPLE_RADIAL": [300, 31, 22, -0.2], "RADIAL": [300, 31, 22, -0.2, 0.05],
          "OPENCV": [300, 320, 31, 22, -0.2, 0.05, 0.001, -0.002],
          "FULL_OPENCV": [300, 320, 31, 22, -0.2, 0.05, 0.001, -0.002, 0.01, 0.02, -0.01, 0.003]}


@pytest.mark.parametrize("model", sorted(MODELS))
def test_every_supported_camera_model(tmp_path, model):
    params = MODELS[model]
    cameras = f"3 {model} 64 48 {' '.join(map(str, params))}\n"
    read = read_colmap(write_text_model(tmp_path, cameras, "5 1 0 0 0 0 0 0 3 a.png\n\n", "")).cameras["a.png"]
    n = 3 if model.startswith("SIMPLE") or model == "RADIAL" else 4  # one focal length or two
    f, c, extra = (params[0], params[n - 3]), params[n - 2:n], params[n:]
    assert (read.fx, read.fy) == f
    assert (read.cx, read.cy) == (30.5, 21.5)
    points = np.array([[0.1, -0.05, 1.0], [-0.08, 0.07, 1.3], [0.0, 0.0, 2.0]])
    distorted = [colmap_distort(model, extra, x / z, y / z) for x, y, z in points]
    expected = [[f[0] * du + c[0], f[1] * dv + c[1]] for du, dv in distorted]
    np.testing.assert_allclose(read.project(points) + PIXEL_CENTRE, expected, rtol=0, atol=1e-9)


def random_model(seed: int = 0, images: int = 4, points: int = 30) -> ColmapModel:
    """Cameras of three kinds of intrinsics (none, four and eight OpenCV coefficients, two images sharing
    one), random poses, points and what each image sees of them."""
    rng = np.random.default_rng(seed)
    intrinsics = [(64, 48, 70.0, 72.0, 31.2, 23.9, np.zeros(0)),
                  (80, 60, 90.0, 90.0, 40.1, 29.7, np.array([-0.1, 0.02, 0.001, -0.003])),
                  (80, 60, 90.0, 95.0, 39.0, 30.2, np.array([-0.1, 0.02, 0.001, -0.003, 0.01, 0.02, 0.001, 0.0]))]
    cameras = {}
    for i in range(images):
        q = rng.normal(size=4)
        cameras[f"img/{i:03d}.png"] = Camera(*intrinsics[min(i, 2)], rotation_from_quaternion(q),
                                             rng.normal(size=3) + [0, 0, 6])
    xyz = rng.normal(size=(points, 3))
    observations = {}
    for name, camera in cameras.items():
        seen = np.sort(rng.choice(points, size=points // 2, replace=False))
        observations[name] = (seen, camera.project(xyz[seen]) + rng.normal(0, 0.3, size=(len(seen), 2)))
    return ColmapModel(cameras, xyz, observations, rng.integers(0, 256, size=(points, 3)).astype(np.uint8))


def assert_models_equal(a: ColmapModel, b: ColmapModel, atol: float = 0.0):
    assert list(a.cameras) == list(b.cameras)
    for name, ca in a.cameras.items():
        cb = b.cameras[name]
        assert (ca.width, ca.height) == (cb.width, cb.height)
        np.testing.assert_allclose([ca.fx, ca.fy, ca.cx, ca.cy], [cb.fx, cb.fy, cb.cx, cb.cy], rtol=0, atol=atol)
        np.testing.assert_allclose(ca._coefficients(), cb._coefficients(), rtol=0, atol=atol)
        np.testing.assert_allclose(ca.rotation, cb.rotation, rtol=0, atol=max(atol, 1e-14))
        np.testing.assert_allclose(ca.translation, cb.translation, rtol=0, atol=atol)
        np.testing.assert_array_equal(a.observations[name][0], b.observations[name][0])
        np.testing.assert_allclose(a.observations[name][1], b.observations[name][1], rtol=0, atol=max(atol, 1e-12))
    np.testing.assert_allclose(a.points, b.points, rtol=0, atol=atol)
    np.testing.assert_array_equal(a.colors, b.colors)


def test_text_binary_round_trip(tmp_path):
    model = random_model()
    read_text = read_colmap(write_colmap(model, tmp_path / "text"))
    read_binary = read_colmap(write_colmap(model, tmp_path / "binary", binary=True))
    assert sorted(p.name for p in (tmp_path / "binary").iterdir()) == ["cameras.bin", "images.bin", "points3D.bin"]
    assert_models_equal(model, read_text, atol=1e-13)  # the half-pixel shift and the quaternion cost a few ulps
    assert_models_equal(read_text, read_binary)  # text keeps every digit of a float64: exactly equal
    again = read_colmap(write_colmap(read_binary, tmp_path / "again"))
    assert_models_equal(read_text, again, atol=1e-13)
    # images with the same intrinsics share one COLMAP camera
    lines = [line for line in (tmp_path / "text" / "cameras.txt").read_text().splitlines() if line[0] != "#"]
    assert [line.split()[1] for line in lines] == ["PINHOLE", "OPENCV", "FULL_OPENCV"]


def test_quaternions_round_trip():
    rng = np.random.default_rng(3)
    for q in [*rng.normal(size=(200, 4)), [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [S, 0, S, 0]]:
        q = np.asarray(q, float) / np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        rotation = rotation_from_quaternion(q)
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(quaternion_from_rotation(rotation), q, atol=1e-12)


def test_pycolmap_reads_what_we_write_and_we_what_it_writes(tmp_path):
    """pycolmap (COLMAP's own reader and projection) on a binary model we wrote: the same cameras, poses,
    points and tracks, its projection half a pixel off mifaces'; and the model as pycolmap writes it back
    (binary and text) reads as ours."""
    import pycolmap

    model = random_model(seed=1)
    reconstruction = pycolmap.Reconstruction(str(write_colmap(model, tmp_path / "ours", binary=True)))
    assert reconstruction.num_images() == len(model.cameras) and reconstruction.num_points3D() == len(model.points)
    for image in reconstruction.images.values():
        camera = model.cameras[image.name]
        pose = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
        np.testing.assert_allclose(pose.rotation.matrix(), camera.rotation, atol=1e-12)
        np.testing.assert_allclose(pose.translation, camera.translation, atol=1e-12)
        theirs = np.array([image.project_point(xyz) for xyz in model.points])
        np.testing.assert_allclose(theirs, camera.project(model.points) + PIXEL_CENTRE, rtol=0, atol=1e-8)
        indices, xy = model.observations[image.name]
        keypoints = np.array([p.xy for p in image.points2D])
        np.testing.assert_allclose(keypoints, xy + PIXEL_CENTRE, atol=1e-12)
        np.testing.assert_array_equal([p.point3D_id for p in image.points2D], indices + 1)
    for point_id, point in reconstruction.points3D.items():
        np.testing.assert_allclose(point.xyz, model.points[point_id - 1], atol=1e-15)
        np.testing.assert_array_equal(point.color, model.colors[point_id - 1])
    (tmp_path / "theirs_bin").mkdir()
    (tmp_path / "theirs_txt").mkdir()
    reconstruction.write_binary(str(tmp_path / "theirs_bin"))
    reconstruction.write_text(str(tmp_path / "theirs_txt"))
    for folder in ("theirs_bin", "theirs_txt"):
        read = read_colmap(tmp_path / folder)
        order = {name: i for i, name in enumerate(model.cameras)}
        read = ColmapModel(dict(sorted(read.cameras.items(), key=lambda item: order[item[0]])), read.points,
                           read.observations, read.colors)
        assert_models_equal(model, read, atol=1e-9)


# --------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("binary", [False, True])
def test_unsupported_camera_model_names_model_and_camera(tmp_path, binary):
    if binary:
        write_records(tmp_path, [CameraRecord(3, "OPENCV_FISHEYE", 64, 48, (60, 60, 32, 24, 0.1, 0, 0, 0))],
                      [ImageRecord(1, np.array([1.0, 0, 0, 0]), np.zeros(3), 3, "a.png", np.zeros((0, 2)),
                                   np.zeros(0, np.int64))], [], binary=True)
    else:
        write_text_model(tmp_path, "3 OPENCV_FISHEYE 64 48 60 60 32 24 0.1 0 0 0\n", "1 1 0 0 0 0 0 0 3 a.png\n\n", "")
    with pytest.raises(ValueError, match=r"cameras\.(txt, line 1|bin, record 1): camera 3 uses the camera model "
                                         r"OPENCV_FISHEYE.*reads SIMPLE_PINHOLE, PINHOLE"):
        read_colmap(tmp_path)


GOOD_IMAGES = "1 1 0 0 0 0 0 0 1 a.png\n10 10 1\n"
GOOD_POINTS = "1 0 0 1 0 0 0 0 1 0\n"


@pytest.mark.parametrize("cameras, images, points, message", [
    (HAND_CAMERAS, "1 1 0 0 0 0 0 0 5 a.png\n\n", "", r"images\.txt, line 1: image 1 \(a\.png\) refers to camera 5"),
    ("1 PINHOLE 640 480 500 400 320 240\n", GOOD_IMAGES, "1 0 0 1 0 0 0 0 42 0\n",
     r"points3D\.txt, line 1: 3D point 1's track refers to image 42"),
    (HAND_CAMERAS, GOOD_IMAGES, "1 0 0 1 0 0 0 0 1 3\n", r"points3D\.txt, line 1: .*keypoint 3 of image 1"),
    (HAND_CAMERAS, "1 1 0 0 0 0 0 0 1 a.png\n10 10 8\n", GOOD_POINTS, r"images\.txt, line 1: .*sees 3D point 8"),
    ("# c\n1 PINHOLE 640 abc 500 400 320 240\n", GOOD_IMAGES, GOOD_POINTS, r"cameras\.txt, line 2: malformed"),
    ("1 PINHOLE 640 480 500 400 320\n", GOOD_IMAGES, GOOD_POINTS, r"line 1: camera 1: PINHOLE takes 4 parameters"),
    ("1 PINHOLE 640 480 -5 400 320 240\n", GOOD_IMAGES, GOOD_POINTS, r"camera 1: focal lengths must be positive"),
    (HAND_CAMERAS, "1 1 0 0 0 0 0 1 a.png\n10 10 1\n", GOOD_POINTS, r"images\.txt, line 1: malformed"),
    (HAND_CAMERAS, "1 1 0 0 0 0 0 0 1 a.png\n10 10\n", GOOD_POINTS, r"images\.txt, line 2: malformed keypoints"),
    (HAND_CAMERAS, GOOD_IMAGES, "1 0 0 1 0 0 0 0 1\n", r"points3D\.txt, line 1: malformed"),
    (HAND_CAMERAS, GOOD_IMAGES + "1 1 0 0 0 0 0 0 1 b.png\n\n", GOOD_POINTS, r"line 3: image id 1 appears twice"),
    (HAND_CAMERAS, GOOD_IMAGES + "2 0 0 0 0 0 0 0 1 b.png\n\n", GOOD_POINTS, r"image 2 \(b\.png\): the pose needs"),
])
def test_bad_text_models_name_file_and_line(tmp_path, cameras, images, points, message):
    write_text_model(tmp_path, cameras, images, points)
    with pytest.raises(ValueError, match=message):
        read_colmap(tmp_path)


def test_missing_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="is not a folder"):
        read_colmap(tmp_path / "nowhere")
    write_text_model(tmp_path, HAND_CAMERAS, GOOD_IMAGES, GOOD_POINTS)
    (tmp_path / "points3D.txt").unlink()
    with pytest.raises(FileNotFoundError, match=r"needs cameras, images and points3D.*\['cameras.txt', 'images.txt'\]"):
        read_colmap(tmp_path)


def test_truncated_and_overlong_binary_files(tmp_path):
    folder = write_colmap(random_model(images=2, points=4), tmp_path, binary=True)
    data = (folder / "images.bin").read_bytes()
    (folder / "images.bin").write_bytes(data[:-5])
    with pytest.raises(ValueError, match=r"images\.bin, record 2: the file ends inside this record"):
        read_colmap(folder)
    (folder / "images.bin").write_bytes(data + b"\0")
    with pytest.raises(ValueError, match=r"images\.bin: 1 bytes after its 2 records"):
        read_colmap(folder)
    (folder / "images.bin").write_bytes(data)
    cameras = (folder / "cameras.bin").read_bytes()
    (folder / "cameras.bin").write_bytes(cameras[:12] + struct.pack("<i", 99) + cameras[16:])
    with pytest.raises(ValueError, match=r"cameras\.bin, record 1: camera \d+ has the unknown camera model id 99"):
        read_colmap(folder)
