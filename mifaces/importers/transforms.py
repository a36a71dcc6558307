"""Nerfstudio and instant-ngp ``transforms.json`` as mifaces cameras: :func:`read_transforms`,
:func:`write_transforms`.

The file (https://docs.nerf.studio/quickstart/data_conventions.html; instant-ngp's
``docs/nerf_dataset_tips.md``) holds intrinsics ``w h fl_x fl_y cx cy k1 k2 k3 k4 p1 p2``, at the top
level for every frame or in a frame for that frame alone, and ``frames``, each a ``file_path``
(relative to the file's folder) and a ``transform_matrix``. Its conventions against mifaces'
(:mod:`mifaces.capture`):

* **Pose**: ``transform_matrix`` is camera -> world (4x4, ``x_world = M [x_camera, 1]``) with
  OpenGL camera axes (x right, y up, z backwards, away from the scene); mifaces keeps world ->
  camera with OpenCV axes (x right, y down, z forward). With ``F = diag(1, -1, -1)`` (OpenGL <->
  OpenCV camera axes), ``R = F M[:3, :3]^T`` and ``t = -R M[:3, 3]``; back, ``M[:3, :3] = R^T F``
  and ``M[:3, 3]`` the camera's position ``-R^T t``.
* **Pixels**: Nerfstudio casts a pixel's ray through its centre at ``index + 0.5``
  (``Cameras.get_image_coords(pixel_offset=0.5)``, then ``(x - cx) / fx``), as COLMAP does, whose
  ``cx`` its converter copies unchanged: ``cx_mifaces = cx -``
  :data:`~mifaces.importers.colmap.PIXEL_CENTRE`. Without ``cx``, ``cy`` the principal point is the
  image centre, ``w / 2``, ``h / 2``, as instant-ngp takes it.
* **Distortion**: ``k1 k2 p1 p2`` and ``k3`` are OpenCV's; Nerfstudio's ``k4`` is an ``r^8`` term of
  the radial polynomial, which OpenCV's model (a rational one from ``k4`` on) has not: a nonzero one
  is an error, and so is a camera with ``k4`` to ``k6`` to write. Fisheye and equirectangular
  ``camera_model`` s are errors.
* **Focal length**: ``fl_x``, or instant-ngp's ``camera_angle_x`` (``fl_x = w / (2 tan(angle / 2))``);
  ``fl_y`` defaults to ``fl_x`` (or comes from ``camera_angle_y``).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from ..io.atomic import write_json
from ..capture.camera import Camera
from .colmap import PIXEL_CENTRE

#: OpenCV camera axes <-> OpenGL camera axes (its own inverse): flip y and z.
OPENGL_AXES = np.diag([1.0, -1.0, -1.0])
#: ``camera_model`` values read (absent: a pinhole camera with OpenCV distortion).
CAMERA_MODELS = ("OPENCV", "PINHOLE")
#: Distortion keys, in the order of :attr:`Camera.distortion`.
_DISTORTION_KEYS = ("k1", "k2", "p1", "p2", "k3")
#: The intrinsics a frame may give for itself, over the file's.
_INTRINSIC_KEYS = ("w", "h", "fl_x", "fl_y", "cx", "cy", "camera_angle_x", "camera_angle_y", "camera_model",
                   *_DISTORTION_KEYS, "k4")
#: Largest departure of a ``transform_matrix``'s rotation from orthonormal rows.
ORTHONORMAL_TOLERANCE = 1e-4


def _number(entry: dict, key: str, where: str, default=None) -> float | None:
    value = entry.get(key, default)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where}: {key} must be a finite number, got {value!r}"[:300])
    return float(value)


def _intrinsics(entry: dict, where: str) -> tuple:
    """``width, height, fx, fy, cx, cy, distortion`` of the merged top-level and frame intrinsics."""
    model = entry.get("camera_model", "OPENCV")
    if model not in CAMERA_MODELS:
        raise ValueError(f"{where}: camera_model {model!r} is not read by mifaces (it reads {list(CAMERA_MODELS)})")
    size = [_number(entry, key, where) for key in ("w", "h")]
    if None in size or min(size) <= 0 or any(v != int(v) for v in size):
        raise ValueError(f"{where}: needs the image size w and h in pixels, positive integers, got "
                         f"{entry.get('w')!r}, {entry.get('h')!r}")
    width, height = int(size[0]), int(size[1])
    focal = []
    for key, angle, extent in (("fl_x", "camera_angle_x", width), ("fl_y", "camera_angle_y", height)):
        value = _number(entry, key, where)
        if value is None and _number(entry, angle, where) is not None:
            value = extent / (2 * math.tan(_number(entry, angle, where) / 2))
        focal.append(value)
    fx, fy = focal[0], focal[1] if focal[1] is not None else focal[0]
    if fx is None or fx <= 0 or fy <= 0:
        raise ValueError(f"{where}: needs a positive focal length fl_x (or camera_angle_x), got {fx!r}")
    cx = _number(entry, "cx", where, width / 2) - PIXEL_CENTRE
    cy = _number(entry, "cy", where, height / 2) - PIXEL_CENTRE
    if _number(entry, "k4", where, 0.0) != 0:
        raise ValueError(f"{where}: k4 is Nerfstudio's r^8 radial term, which OpenCV's distortion model (and "
                         "mifaces') has not")
    distortion = np.array([_number(entry, key, where, 0.0) for key in _DISTORTION_KEYS])
    distortion = distortion[:4] if distortion[4] == 0 else distortion
    return width, height, fx, fy, cx, cy, distortion if np.any(distortion) else np.zeros(0)


def _pose(frame: dict, where: str) -> tuple[np.ndarray, np.ndarray]:
    """World -> camera ``R, t`` (OpenCV axes) of a frame's camera -> world OpenGL ``transform_matrix``."""
    try:
        matrix = np.asarray(frame.get("transform_matrix"), np.float64)
    except (TypeError, ValueError):
        matrix = np.zeros(0)
    if matrix.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(matrix)):
        raise ValueError(f"{where}: transform_matrix must be a 4x4 (or 3x4) matrix of finite numbers, got "
                         f"{frame.get('transform_matrix')!r}"[:300])
    if matrix.shape == (4, 4) and not np.allclose(matrix[3], [0, 0, 0, 1]):
        raise ValueError(f"{where}: transform_matrix's last row must be 0 0 0 1, got {matrix[3].tolist()}")
    rotation = OPENGL_AXES @ matrix[:3, :3].T
    if not np.allclose(rotation @ rotation.T, np.eye(3), atol=ORTHONORMAL_TOLERANCE) or np.linalg.det(rotation) < 0:
        raise ValueError(f"{where}: transform_matrix's 3x3 block must be a rotation (no scale, no mirror)")
    return rotation, -rotation @ matrix[:3, 3]


def read_transforms(path: str | os.PathLike) -> dict[str, Camera]:
    """The cameras of a ``transforms.json``: ``file_path`` -> :class:`~mifaces.capture.Camera`
    (mifaces' conventions, see the module docstring), in the order of its frames.

    Raises
    ------
    FileNotFoundError
        Where there is no such file.
    ValueError
        Naming the file and the frame: invalid JSON, no frames, a missing or repeated
        ``file_path``, missing intrinsics, a ``transform_matrix`` that is not a rigid motion, a
        camera model or distortion term mifaces cannot express.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: not valid JSON: {error}") from None
    frames = data.get("frames") if isinstance(data, dict) else None
    if not isinstance(frames, list) or not frames:
        raise ValueError(f"{path}: needs a non-empty list 'frames'")
    shared = {key: data[key] for key in _INTRINSIC_KEYS if key in data}
    cameras = {}
    for i, frame in enumerate(frames):
        name = frame.get("file_path") if isinstance(frame, dict) else None
        where = f"{path}: frames[{i}]" + (f" ({name})" if isinstance(name, str) else "")
        if not isinstance(name, str) or not name:
            raise ValueError(f"{where}: needs a file_path")
        if name in cameras:
            raise ValueError(f"{where}: file_path {name!r} appears twice")
        width, height, fx, fy, cx, cy, distortion = _intrinsics({**shared, **frame}, where)
        rotation, translation = _pose(frame, where)
        cameras[name] = Camera(width, height, fx, fy, cx, cy, distortion, rotation, translation)
    return cameras


def transforms_intrinsics(camera: Camera) -> dict:
    """The ``transforms.json`` intrinsics of a camera (``k3`` only where nonzero)."""
    d = np.zeros(8)
    d[:len(camera.distortion)] = camera.distortion
    if np.any(d[5:]):
        raise ValueError(f"a camera with OpenCV's rational distortion terms k4-k6 ({d[5:].tolist()}) cannot be "
                         "written to transforms.json (its k4 is a polynomial term)")
    entry = {"camera_model": "OPENCV", "w": int(camera.width), "h": int(camera.height), "fl_x": float(camera.fx),
             "fl_y": float(camera.fy), "cx": float(camera.cx + PIXEL_CENTRE), "cy": float(camera.cy + PIXEL_CENTRE)}
    entry.update({key: float(d[k]) for k, key in enumerate(_DISTORTION_KEYS) if key != "k3" or d[4] != 0})
    return entry


def transform_matrix(camera: Camera) -> np.ndarray:
    """The camera -> world 4x4 matrix with OpenGL camera axes of a camera (module docstring)."""
    matrix = np.eye(4)
    matrix[:3, :3] = np.asarray(camera.rotation, np.float64).T @ OPENGL_AXES
    matrix[:3, 3] = camera.position
    return matrix


def write_transforms(cameras: dict[str, Camera] | list[Camera], path: str | os.PathLike,
                     image_paths: list[str] | None = None) -> Path:
    """Write a ``transforms.json`` that Nerfstudio and instant-ngp read.

    Parameters
    ----------
    cameras : dict or list
        ``file_path`` -> camera, or cameras in the order of ``image_paths``.
    path : path
        The file to write (atomically; its folder is created).
    image_paths : list of str, optional
        The frames' ``file_path`` s (relative to ``path``'s folder) where ``cameras`` is a list.

    Returns
    -------
    Path
        ``path``. The intrinsics are written once at the top level where every camera has the same,
        else in each frame.
    """
    if image_paths is not None:
        cameras = list(cameras.values()) if isinstance(cameras, dict) else list(cameras)
        if len(image_paths) != len(cameras):
            raise ValueError(f"image_paths: {len(image_paths)} paths for {len(cameras)} cameras")
        cameras = dict(zip(map(str, image_paths), cameras))
    elif not isinstance(cameras, dict):
        raise ValueError("image_paths: needed where cameras is a list")
    if not cameras:
        raise ValueError("cameras: nothing to write")
    intrinsics = {name: transforms_intrinsics(camera) for name, camera in cameras.items()}
    first = next(iter(intrinsics.values()))
    shared = all(entry == first for entry in intrinsics.values())
    frames = [{"file_path": name, **({} if shared else intrinsics[name]),
               "transform_matrix": transform_matrix(camera).tolist()} for name, camera in cameras.items()]
    write_json(path, {**(first if shared else {}), "frames": frames})
    return Path(path)
