"""COLMAP sparse models as mifaces cameras and points: :func:`read_colmap`, :func:`write_colmap`.

COLMAP (Schönberger and Frahm, "Structure-from-Motion Revisited", CVPR 2016) stores a
reconstruction as cameras (intrinsics), images (a pose and a camera each, and the keypoints seen in
them) and 3D points (https://colmap.github.io/format.html; the files themselves are read and written
by :mod:`mifaces.importers.colmap_records`). Its conventions against mifaces' (:mod:`mifaces.capture`):

* **Pose**: the same. An image's quaternion ``qw qx qy qz`` and ``t`` give world -> camera,
  ``x_camera = R(q) x_world + t``, camera axes as OpenCV's (x right, y down, z forward).
* **Pixels**: COLMAP puts the top-left pixel's centre at (0.5, 0.5), mifaces at (0, 0), so
  ``cx_mifaces = cx_colmap -`` :data:`PIXEL_CENTRE` and likewise every keypoint.
* **Camera models**: ``SIMPLE_PINHOLE`` (f, cx, cy), ``PINHOLE`` (fx, fy, cx, cy),
  ``SIMPLE_RADIAL`` (f, cx, cy, k), ``RADIAL`` (f, cx, cy, k1, k2), ``OPENCV`` (fx, fy, cx, cy, k1,
  k2, p1, p2) and ``FULL_OPENCV`` (... k3, k4, k5, k6): COLMAP's distortion of these is OpenCV's,
  so the coefficients go into :attr:`Camera.distortion` as they are. Fisheye and the other models
  are an error naming the model and the camera.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..capture.camera import Camera
from .colmap_records import NO_POINT, CameraRecord, ImageRecord, PointRecord, read_records, write_records

#: Coordinate of the top-left pixel's centre in COLMAP's (and Nerfstudio's) pixel convention; mifaces'
#: is 0 (pixel centres at integers), so a pixel coordinate there is this much more than here.
PIXEL_CENTRE = 0.5
#: The camera models read: name -> OpenCV distortion coefficients ``k1, k2, p1, p2[, k3, k4, k5, k6]``
#: as indices into the parameters after the intrinsics (None: zero), and whether one focal length.
_DISTORTION = {"SIMPLE_PINHOLE": ((), True), "PINHOLE": ((), False), "SIMPLE_RADIAL": ((0, None, None, None), True),
               "RADIAL": ((0, 1, None, None), True), "OPENCV": ((0, 1, 2, 3), False),
               "FULL_OPENCV": (tuple(range(8)), False)}
SUPPORTED_MODELS = tuple(_DISTORTION)


@dataclass(frozen=True, eq=False)
class ColmapModel:
    """A COLMAP sparse model in mifaces' conventions.

    Attributes
    ----------
    cameras : dict
        Image name -> its :class:`~mifaces.capture.Camera` (intrinsics and pose; pixel centres at integers).
    points : (P, 3) float64
        The 3D points, world frame (COLMAP's units).
    observations : dict
        Image name -> ``(point_indices, xy)``: rows of ``points`` (N,) int64 and where the image sees
        them, (N, 2) float64 pixels in its camera's convention (keypoints without a 3D point are left out).
    colors : (P, 3) uint8
        The points' RGB colours.
    """

    cameras: dict[str, Camera]
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    observations: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    colors: np.ndarray | None = None

    def __post_init__(self):
        if self.colors is None:
            object.__setattr__(self, "colors", np.zeros((len(self.points), 3), np.uint8))


def rotation_from_quaternion(q) -> np.ndarray:
    """The rotation matrix of a quaternion ``(w, x, y, z)`` (normalised first), as COLMAP's ``qvec2rotmat``."""
    w, x, y, z = np.asarray(q, np.float64)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def quaternion_from_rotation(rotation) -> np.ndarray:
    """The unit quaternion ``(w, x, y, z)`` with ``w >= 0`` of a rotation matrix."""
    x, y, z, w = Rotation.from_matrix(np.asarray(rotation, np.float64)).as_quat()
    q = np.array([w, x, y, z])
    return -q if q[0] < 0 else q


def camera_from_record(record: CameraRecord, rotation=None, translation=None) -> Camera:
    """The mifaces camera of a COLMAP camera (one of :data:`SUPPORTED_MODELS`) with a pose (default: identity)."""
    where = f"{record.where}: camera {record.camera_id}"
    if record.model not in _DISTORTION:
        raise ValueError(f"{where} uses the camera model {record.model}, which mifaces does not read "
                         f"(it reads {', '.join(SUPPORTED_MODELS)})")
    indices, single = _DISTORTION[record.model]
    params = np.asarray(record.params, np.float64)
    needed = (3 if single else 4) + len([i for i in indices if i is not None])
    if len(params) != needed:
        raise ValueError(f"{where}: {record.model} takes {needed} parameters, got {len(params)}")
    if not np.all(np.isfinite(params)) or record.width <= 0 or record.height <= 0:
        raise ValueError(f"{where}: size {record.width}x{record.height} and parameters {params.tolist()} must be "
                         "positive and finite")
    fx, fy = (params[0], params[0]) if single else (params[0], params[1])
    if fx <= 0 or fy <= 0:
        raise ValueError(f"{where}: focal lengths must be positive, got {fx}, {fy}")
    cx, cy = params[1 if single else 2: 3 if single else 4]
    rest = params[3 if single else 4:]
    distortion = np.array([0.0 if i is None else rest[i] for i in indices])
    rotation = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
    translation = np.zeros(3) if translation is None else np.asarray(translation, np.float64)
    return Camera(int(record.width), int(record.height), float(fx), float(fy), float(cx - PIXEL_CENTRE),
                  float(cy - PIXEL_CENTRE), distortion, rotation, translation)


def colmap_camera(camera: Camera) -> tuple[str, tuple[float, ...]]:
    """The COLMAP model and parameters of a mifaces camera's intrinsics: ``PINHOLE`` without
    distortion, ``OPENCV`` for ``k1, k2, p1, p2``, ``FULL_OPENCV`` where ``k3`` to ``k6`` are not all zero."""
    d = np.zeros(8)
    d[:len(camera.distortion)] = camera.distortion
    intrinsics = (camera.fx, camera.fy, camera.cx + PIXEL_CENTRE, camera.cy + PIXEL_CENTRE)
    model = "PINHOLE" if not np.any(d) else "OPENCV" if not np.any(d[4:]) else "FULL_OPENCV"
    count = {"PINHOLE": 0, "OPENCV": 4, "FULL_OPENCV": 8}[model]
    return model, tuple(float(v) for v in (*intrinsics, *d[:count]))


def _unique(records, key: str, what: str, path_of: str) -> dict:
    by_id = {}
    for record in records:
        value = getattr(record, key)
        if value in by_id:
            raise ValueError(f"{record.where}: {what} {value!r} appears twice in {path_of} "
                             f"(first at {by_id[value].where})")
        by_id[value] = record
    return by_id


def read_colmap(sparse_dir: str | os.PathLike) -> ColmapModel:
    """Read the COLMAP sparse model in ``sparse_dir`` (``cameras``, ``images``, ``points3D``, text or
    binary), without the images.

    Returns
    -------
    ColmapModel
        Per image name its camera (intrinsics and pose, in mifaces' pixel convention: COLMAP's
        coordinates minus :data:`PIXEL_CENTRE`), the points and what each image sees of them.

    Raises
    ------
    FileNotFoundError
        Where the folder lacks one of the three files.
    ValueError
        Naming the file and line (or record): a malformed line or truncated binary file, a camera
        model other than :data:`SUPPORTED_MODELS`, an image naming a camera the model does not
        have, a keypoint or track naming an unknown point or image, repeated ids or names.
    """
    camera_records, image_records, point_records = read_records(Path(sparse_dir))
    cameras_by_id = _unique(camera_records, "camera_id", "camera id", "cameras")
    images_by_id = _unique(image_records, "image_id", "image id", "images")
    _unique(image_records, "name", "image name", "images")
    points_by_id = _unique(point_records, "point3d_id", "3D point id", "points3D")
    for record in cameras_by_id.values():
        camera_from_record(record)  # every camera checked, used or not
    rows = {point_id: row for row, point_id in enumerate(points_by_id)}
    cameras, observations = {}, {}
    for image in image_records:
        label = f"{image.where}: image {image.image_id} ({image.name})"
        if image.camera_id not in cameras_by_id:
            raise ValueError(f"{label} refers to camera {image.camera_id}, which the model's cameras file does "
                             f"not have (cameras: {sorted(cameras_by_id)[:20]})")
        if not np.all(np.isfinite(image.qvec)) or not np.all(np.isfinite(image.tvec)) \
                or np.linalg.norm(image.qvec) < 1e-12:
            raise ValueError(f"{label}: the pose needs a nonzero quaternion and finite numbers, got "
                             f"q={image.qvec.tolist()}, t={image.tvec.tolist()}")
        cameras[image.name] = camera_from_record(cameras_by_id[image.camera_id],
                                                 rotation_from_quaternion(image.qvec), image.tvec)
        seen = image.point3d_ids != NO_POINT
        unknown = [int(p) for p in image.point3d_ids[seen] if int(p) not in rows]
        if unknown:
            raise ValueError(f"{label} sees 3D point {unknown[0]}, which the model's points3D file does not have "
                             f"({len(unknown)} unknown points)")
        indices = np.array([rows[int(p)] for p in image.point3d_ids[seen]], np.int64)
        observations[image.name] = (indices, image.xys[seen] - PIXEL_CENTRE)
    for point in point_records:
        for image_id, index in zip(point.image_ids, point.point2d_idxs):
            image = images_by_id.get(int(image_id))
            if image is None:
                raise ValueError(f"{point.where}: 3D point {point.point3d_id}'s track refers to image {image_id}, "
                                 "which the model's images file does not have")
            if not 0 <= index < len(image.xys):
                raise ValueError(f"{point.where}: 3D point {point.point3d_id}'s track refers to keypoint {index} of "
                                 f"image {image_id} ({image.name}), which has {len(image.xys)}")
    points = np.array([p.xyz for p in point_records], np.float64).reshape(-1, 3)
    colors = np.array([p.rgb for p in point_records], np.uint8).reshape(-1, 3)
    return ColmapModel(cameras, points, observations, colors)


def write_colmap(model: ColmapModel | dict[str, Camera], sparse_dir: str | os.PathLike, binary: bool = False) -> Path:
    """Write a sparse model that COLMAP (and :func:`read_colmap`) reads: ``cameras``, ``images`` and
    ``points3D`` (``.txt``, or ``.bin`` with ``binary``) in ``sparse_dir``, created.

    Parameters
    ----------
    model : ColmapModel or dict
        A model, or image name -> :class:`~mifaces.capture.Camera` (then no points).
    sparse_dir : path
    binary : bool
        COLMAP's binary files instead of its text files.

    Returns
    -------
    Path
        ``sparse_dir``.

    Notes
    -----
    Images whose cameras have the same intrinsics share one COLMAP camera (:func:`colmap_camera`).
    Image ids are 1, 2, ... in the order of ``model.cameras``, 3D point ids the points' rows plus one;
    the points' errors are written as -1 (unknown).
    """
    if not isinstance(model, ColmapModel):
        model = ColmapModel(dict(model))
    camera_ids: dict[tuple, int] = {}
    images = []
    tracks: list[list[tuple[int, int]]] = [[] for _ in range(len(model.points))]
    for image_id, (name, camera) in enumerate(model.cameras.items(), start=1):
        key = (int(camera.width), int(camera.height), *colmap_camera(camera))
        camera_id = camera_ids.setdefault(key, len(camera_ids) + 1)
        indices, xy = model.observations.get(name, (np.zeros(0, np.int64), np.zeros((0, 2))))
        indices = np.asarray(indices, np.int64)
        if np.any((indices < 0) | (indices >= len(model.points))):
            raise ValueError(f"observations of image {name!r}: point indices must be rows of the "
                             f"{len(model.points)} points")
        for keypoint, row in enumerate(indices):
            tracks[row].append((image_id, keypoint))
        images.append(ImageRecord(image_id, quaternion_from_rotation(camera.rotation),
                                  np.asarray(camera.translation, np.float64), camera_id, name,
                                  np.asarray(xy, np.float64).reshape(-1, 2) + PIXEL_CENTRE, indices + 1))
    cameras = [CameraRecord(camera_id, model_name, width, height, params)
               for (width, height, model_name, params), camera_id in camera_ids.items()]
    points = [PointRecord(row + 1, xyz, rgb, -1.0, np.array([t[0] for t in track], np.int64),
                          np.array([t[1] for t in track], np.int64))
              for row, (xyz, rgb, track) in enumerate(zip(model.points, model.colors, tracks))]
    write_records(Path(sparse_dir), cameras, images, points, binary)
    return Path(sparse_dir)
