"""COLMAP's sparse model files as records, in its text and binary encodings.

A sparse model is three files, ``cameras``, ``images`` and ``points3D``, each ``.txt`` or ``.bin``
(https://colmap.github.io/format.html; the reference reader and writer is COLMAP's
``scripts/python/read_write_model.py``, whose binary layouts, all little-endian, these follow):

* ``cameras``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`` (binary: int32 id, int32 model id,
  uint64 width, uint64 height, the model's number of float64 parameters);
* ``images``: ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` and, on the next line (empty for
  none), ``POINTS2D[]`` as ``(X, Y, POINT3D_ID)``, -1 for a keypoint with no 3D point (binary: int32
  id, 7 float64, int32 camera id, the name ending in a zero byte, uint64 count, then float64 x,
  float64 y, int64 point id each);
* ``points3D``: ``POINT3D_ID X Y Z R G B ERROR TRACK[]`` as ``(IMAGE_ID, POINT2D_IDX)`` (binary:
  uint64 id, 3 float64, 3 uint8, float64 error, uint64 track length, then int32 image id and int32
  keypoint index each).

The records keep COLMAP's own numbers: its ids, its quaternion and its pixel coordinates (the
top-left pixel's centre at (0.5, 0.5)); :mod:`mifaces.importers.colmap` gives them their meaning.
Each record says where it was read (``where``: the file and line, or the file and record), for the
errors about it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write

#: COLMAP's camera models: name -> (model id, number of parameters) (``src/colmap/sensor/models.h``).
MODELS = {"SIMPLE_PINHOLE": (0, 3), "PINHOLE": (1, 4), "SIMPLE_RADIAL": (2, 4), "RADIAL": (3, 5),
          "OPENCV": (4, 8), "OPENCV_FISHEYE": (5, 8), "FULL_OPENCV": (6, 12), "FOV": (7, 5),
          "SIMPLE_RADIAL_FISHEYE": (8, 4), "RADIAL_FISHEYE": (9, 5), "THIN_PRISM_FISHEYE": (10, 12),
          "RAD_TAN_THIN_PRISM_FISHEYE": (11, 16)}
_MODEL_NAMES = {model_id: name for name, (model_id, _) in MODELS.items()}
#: The three files of a sparse model, without their suffix.
FILES = ("cameras", "images", "points3D")
#: Point id of a keypoint that has no 3D point.
NO_POINT = -1


@dataclass(frozen=True)
class CameraRecord:
    camera_id: int
    model: str
    width: int
    height: int
    params: tuple[float, ...]
    where: str = ""


@dataclass(frozen=True, eq=False)
class ImageRecord:
    """``qvec`` (w, x, y, z) and ``tvec`` of ``x_camera = R(q) x_world + t``; ``xys`` (N, 2) and
    ``point3d_ids`` (N,) the keypoints and their 3D points (:data:`NO_POINT` for none)."""

    image_id: int
    qvec: np.ndarray
    tvec: np.ndarray
    camera_id: int
    name: str
    xys: np.ndarray
    point3d_ids: np.ndarray
    where: str = ""


@dataclass(frozen=True, eq=False)
class PointRecord:
    """``image_ids`` and ``point2d_idxs`` (T,): the track, the keypoints that see the point."""

    point3d_id: int
    xyz: np.ndarray
    rgb: np.ndarray
    error: float
    image_ids: np.ndarray
    point2d_idxs: np.ndarray
    where: str = ""


def model_files(sparse_dir: Path) -> tuple[Path, Path, Path, bool]:
    """The three files of the model in ``sparse_dir`` and whether they are binary (the binary
    ones where all three are there, as ``read_write_model.py`` does, else the text ones)."""
    for suffix, binary in ((".bin", True), (".txt", False)):
        paths = [sparse_dir / f"{name}{suffix}" for name in FILES]
        if all(p.is_file() for p in paths):
            return (*paths, binary)
    if not sparse_dir.is_dir():
        raise FileNotFoundError(f"no COLMAP sparse model: {sparse_dir} is not a folder")
    found = sorted(p.name for p in sparse_dir.iterdir() if p.stem in FILES)
    raise FileNotFoundError(f"no COLMAP sparse model in {sparse_dir}: it needs cameras, images and points3D, "
                            f"all .txt or all .bin; found {found or 'none of them'}")


def read_records(sparse_dir: Path) -> tuple[list[CameraRecord], list[ImageRecord], list[PointRecord]]:
    """The cameras, images and points of the sparse model in ``sparse_dir``, in file order."""
    *paths, binary = model_files(sparse_dir)
    readers = (_read_cameras_bin, _read_images_bin, _read_points_bin) if binary else \
        (_read_cameras_txt, _read_images_txt, _read_points_txt)
    return tuple(read(path) for read, path in zip(readers, paths))


def write_records(sparse_dir: Path, cameras: list[CameraRecord], images: list[ImageRecord],
                  points: list[PointRecord], binary: bool = False) -> None:
    """Write the three files of a sparse model into ``sparse_dir`` (created), atomically."""
    suffix = ".bin" if binary else ".txt"
    writers = (_cameras_bin, _images_bin, _points_bin) if binary else (_cameras_txt, _images_txt, _points_txt)
    for name, write, records in zip(FILES, writers, (cameras, images, points)):
        with atomic_write(sparse_dir / f"{name}{suffix}", "wb") as f:
            f.write(write(records))


# --------------------------------------------------------------------------------------------
# Text
# --------------------------------------------------------------------------------------------
def _data_lines(path: Path):
    """``(line number, stripped line)`` of the lines that are not blank or comments."""
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        line = line.strip()
        if line and not line.startswith("#"):
            yield number, line


def _parse(fields: list[str], types, where: str, layout: str) -> list:
    try:
        return [kind(value) for kind, value in zip(types, fields)]
    except ValueError:
        raise ValueError(f"{where}: malformed, expected {layout}, got {' '.join(fields)[:200]!r}") from None


def _read_cameras_txt(path: Path) -> list[CameraRecord]:
    layout = "CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]"
    records = []
    for number, line in _data_lines(path):
        where = f"{path}, line {number}"
        fields = line.split()
        if len(fields) < 4:
            raise ValueError(f"{where}: malformed, expected {layout}, got {line[:200]!r}")
        camera_id, model, width, height = _parse(fields[:4], (int, str, int, int), where, layout)
        params = _parse(fields[4:], [float] * len(fields[4:]), where, layout)
        records.append(CameraRecord(camera_id, model, width, height, tuple(params), where))
    return records


def _read_images_txt(path: Path) -> list[ImageRecord]:
    layout = "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then a line of X Y POINT3D_ID triples"
    lines = path.read_text().splitlines()
    records, i = [], 0
    while i < len(lines):
        line = lines[i].strip()
        i += 1
        if not line or line.startswith("#"):
            continue
        where = f"{path}, line {i}"
        fields = line.split(maxsplit=9)
        if len(fields) < 10:
            raise ValueError(f"{where}: malformed, expected {layout}, got {line[:200]!r}")
        values = _parse(fields[:9], [int] + [float] * 7 + [int], where, layout)
        keypoints = lines[i].split() if i < len(lines) else []  # the next line, empty for none
        i += 1
        if len(keypoints) % 3:
            raise ValueError(f"{path}, line {i}: malformed keypoints of image {values[0]}: {len(keypoints)} "
                             "numbers, not X Y POINT3D_ID triples")
        triples = _parse(keypoints, [float, float, int] * (len(keypoints) // 3), f"{path}, line {i}", layout)
        xys = np.array([triples[0::3], triples[1::3]], np.float64).T.reshape(-1, 2)
        ids = np.array(triples[2::3], np.int64)
        records.append(ImageRecord(values[0], np.array(values[1:5]), np.array(values[5:8]), values[8],
                                   fields[9], xys, ids, where))
    return records


def _read_points_txt(path: Path) -> list[PointRecord]:
    layout = "POINT3D_ID X Y Z R G B ERROR then IMAGE_ID POINT2D_IDX pairs"
    records = []
    for number, line in _data_lines(path):
        where = f"{path}, line {number}"
        fields = line.split()
        if len(fields) < 8 or len(fields) % 2:
            raise ValueError(f"{where}: malformed, expected {layout}, got {line[:200]!r}")
        values = _parse(fields, [int] + [float] * 3 + [int] * 3 + [float] + [int] * (len(fields) - 8), where, layout)
        if not all(0 <= c <= 255 for c in values[4:7]):
            raise ValueError(f"{where}: colour {values[4:7]} is not three values 0-255")
        track = np.array(values[8:], np.int64).reshape(-1, 2)
        records.append(PointRecord(values[0], np.array(values[1:4], np.float64), np.array(values[4:7], np.uint8),
                                   values[7], track[:, 0], track[:, 1], where))
    return records


def _cameras_txt(records: list[CameraRecord]) -> bytes:
    lines = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
             f"# Number of cameras: {len(records)}"]
    lines += [" ".join([str(c.camera_id), c.model, str(c.width), str(c.height), *map(repr, map(float, c.params))])
              for c in records]
    return ("\n".join(lines) + "\n").encode()


def _images_txt(records: list[ImageRecord]) -> bytes:
    observations = sum(int(np.sum(r.point3d_ids != NO_POINT)) for r in records)
    mean = observations / len(records) if records else 0
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)",
             f"# Number of images: {len(records)}, mean observations per image: {mean}"]
    for r in records:
        numbers = [repr(float(v)) for v in (*r.qvec, *r.tvec)]
        lines.append(" ".join([str(r.image_id), *numbers, str(r.camera_id), r.name]))
        lines.append(" ".join(f"{float(x)!r} {float(y)!r} {int(p)}" for (x, y), p in zip(r.xys, r.point3d_ids)))
    return ("\n".join(lines) + "\n").encode()


def _points_txt(records: list[PointRecord]) -> bytes:
    length = sum(len(p.image_ids) for p in records) / len(records) if records else 0
    lines = ["# 3D point list with one line of data per point:",
             "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
             f"# Number of points: {len(records)}, mean track length: {length}"]
    for p in records:
        track = [f"{int(i)} {int(k)}" for i, k in zip(p.image_ids, p.point2d_idxs)]
        lines.append(" ".join([str(p.point3d_id), *(repr(float(v)) for v in p.xyz), *(str(int(c)) for c in p.rgb),
                               repr(float(p.error)), *track]))
    return ("\n".join(lines) + "\n").encode()


# --------------------------------------------------------------------------------------------
# Binary
# --------------------------------------------------------------------------------------------
class _Reader:
    """Little-endian values read from a binary file, a truncated file named with its record."""

    def __init__(self, path: Path):
        self.path, self.data, self.offset, self.where = path, path.read_bytes(), 0, f"{path}"

    def read(self, fmt: str) -> tuple:
        size = struct.calcsize("<" + fmt)
        if self.offset + size > len(self.data):
            raise ValueError(f"{self.where}: the file ends inside this record (truncated or not a COLMAP "
                             f"{self.path.stem} file)")
        values = struct.unpack_from("<" + fmt, self.data, self.offset)
        self.offset += size
        return values

    def array(self, dtype: str, count: int) -> np.ndarray:
        size = np.dtype(dtype).itemsize * count
        if count < 0 or self.offset + size > len(self.data):
            raise ValueError(f"{self.where}: the file ends inside this record (it claims {count} entries)")
        values = np.frombuffer(self.data, dtype, count, self.offset)
        self.offset += size
        return values

    def name(self) -> str:
        end = self.data.find(b"\0", self.offset)
        if end < 0:
            raise ValueError(f"{self.where}: the image name has no terminating zero byte (truncated file)")
        name = self.data[self.offset:end].decode("utf-8", "replace")
        self.offset = end + 1
        return name

    def records(self):
        """Record numbers 1..count, ``where`` naming each; a file longer than its records is an error."""
        (count,) = self.read("Q")
        for number in range(1, count + 1):
            self.where = f"{self.path}, record {number}"
            yield number
        if self.offset != len(self.data):
            raise ValueError(f"{self.path}: {len(self.data) - self.offset} bytes after its {count} records")


def _read_cameras_bin(path: Path) -> list[CameraRecord]:
    f, records = _Reader(path), []
    for _ in f.records():
        camera_id, model_id, width, height = f.read("iiQQ")
        if model_id not in _MODEL_NAMES:
            raise ValueError(f"{f.where}: camera {camera_id} has the unknown camera model id {model_id}")
        model = _MODEL_NAMES[model_id]
        params = f.read("d" * MODELS[model][1])
        records.append(CameraRecord(camera_id, model, width, height, tuple(params), f.where))
    return records


def _read_images_bin(path: Path) -> list[ImageRecord]:
    f, records = _Reader(path), []
    for _ in f.records():
        image_id, *pose, camera_id = f.read("i7di")
        name = f.name()
        (count,) = f.read("Q")
        keypoints = f.array("<f8,<f8,<i8", count) if count else np.zeros(0, "<f8,<f8,<i8")
        xys = np.stack([keypoints["f0"], keypoints["f1"]], axis=-1).astype(np.float64)
        records.append(ImageRecord(image_id, np.array(pose[:4]), np.array(pose[4:]), camera_id, name, xys,
                                   keypoints["f2"].astype(np.int64), f.where))
    return records


def _read_points_bin(path: Path) -> list[PointRecord]:
    f, records = _Reader(path), []
    for _ in f.records():
        point_id, x, y, z, r, g, b, error, length = f.read("Q3d3BdQ")
        track = f.array("<i4", 2 * length).reshape(-1, 2).astype(np.int64) if length else np.zeros((0, 2), np.int64)
        records.append(PointRecord(point_id, np.array([x, y, z]), np.array([r, g, b], np.uint8), error,
                                   track[:, 0], track[:, 1], f.where))
    return records


def _cameras_bin(records: list[CameraRecord]) -> bytes:
    out = [struct.pack("<Q", len(records))]
    for c in records:
        out.append(struct.pack("<iiQQ", c.camera_id, MODELS[c.model][0], c.width, c.height))
        out.append(struct.pack(f"<{len(c.params)}d", *c.params))
    return b"".join(out)


def _images_bin(records: list[ImageRecord]) -> bytes:
    out = [struct.pack("<Q", len(records))]
    for r in records:
        out.append(struct.pack("<i7di", r.image_id, *map(float, r.qvec), *map(float, r.tvec), r.camera_id))
        out.append(r.name.encode() + b"\0" + struct.pack("<Q", len(r.xys)))
        keypoints = np.zeros(len(r.xys), "<f8,<f8,<i8")
        keypoints["f0"], keypoints["f1"], keypoints["f2"] = r.xys[:, 0], r.xys[:, 1], r.point3d_ids
        out.append(keypoints.tobytes())
    return b"".join(out)


def _points_bin(records: list[PointRecord]) -> bytes:
    out = [struct.pack("<Q", len(records))]
    for p in records:
        out.append(struct.pack("<Q3d3BdQ", p.point3d_id, *map(float, p.xyz), *map(int, p.rgb), float(p.error),
                               len(p.image_ids)))
        out.append(np.stack([p.image_ids, p.point2d_idxs], axis=-1).astype("<i4").tobytes())
    return b"".join(out)
