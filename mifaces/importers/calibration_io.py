"""Calibrations from other tools as captures, and captures' calibrations for other tools.

:func:`import_calibration` writes a capture (:mod:`mifaces.capture`) from cameras calibrated
elsewhere and their photographs (:func:`import_colmap` for a COLMAP sparse model,
:func:`import_transforms` for a Nerfstudio / instant-ngp ``transforms.json``);
:func:`export_calibration` writes a capture's camera in both formats for those tools.

The images that share intrinsics and pose (within :data:`POSE_TOLERANCE`) are one camera
(:func:`camera_groups`): a calibration whose images all share one becomes a one-camera capture (a
fixed camera photographing a subject under several lights), one with several a capture with a
``cameras`` list (docs/capture.md, "Several cameras"). A calibration is of a rigid scene, so every
image is of one head pose: one ``shot``.
"""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath

import numpy as np

from ..io.atomic import atomic_write, write_json
from ..capture.camera import Camera
from ..capture.images import read_image
from ..capture.loader import load_capture
from ..capture.types import DEFAULT_CAMERA, FORMAT, IMAGE_SUFFIXES, MANIFEST, TRANSFERS, VERSION, Capture
from ..io.paths import check_name, resolve_inside
from .colmap import read_colmap, write_colmap
from .transforms import read_transforms, write_transforms

#: Largest difference of two images' rotation entries, and of their translations relative to the
#: larger's length (at least 1), for them to count as one camera pose.
POSE_TOLERANCE = 1e-6
#: Pose (shot) label of every measurement of an imported calibration: one rigid scene, one unmoved subject
#: (``load_capture``'s pose grouping still fits apart a measurement of one camera whose feature points
#: disagree).
POSE = "P0"
#: Where :func:`export_calibration` writes the COLMAP model and the ``transforms.json`` in its folder.
SPARSE = Path("sparse") / "0"
TRANSFORMS = "transforms.json"


def _differences(a: Camera, b: Camera) -> list[str]:
    """What differs between two cameras: ``'intrinsics'``, ``'pose'``, both or neither."""
    da, db = np.zeros(8), np.zeros(8)
    da[:len(a.distortion)], db[:len(b.distortion)] = a.distortion, b.distortion
    same_intrinsics = (a.width, a.height) == (b.width, b.height) and np.allclose(
        [a.fx, a.fy, a.cx, a.cy, *da], [b.fx, b.fy, b.cx, b.cy, *db], rtol=1e-9, atol=1e-12)
    scale = max(1.0, np.linalg.norm(a.translation), np.linalg.norm(b.translation))
    same_pose = np.allclose(a.rotation, b.rotation, rtol=0, atol=POSE_TOLERANCE) and \
        np.linalg.norm(np.subtract(a.translation, b.translation)) <= POSE_TOLERANCE * scale
    return [what for what, same in (("intrinsics", same_intrinsics), ("pose", same_pose)) if not same]


def camera_groups(cameras: dict[str, Camera]) -> list[tuple[Camera, list[str]]]:
    """The distinct cameras of ``cameras`` (image name -> camera), in the order of their first image,
    each with the images it took (the same intrinsics and pose, :func:`_differences`)."""
    if not cameras:
        raise ValueError("the calibration has no images")
    groups: list[tuple[Camera, list[str]]] = []
    for name, camera in cameras.items():
        for first, images in groups:
            if not _differences(first, camera):
                images.append(name)
                break
        else:
            groups.append((camera, [name]))
    return groups


def _destinations(images) -> dict[str, PurePosixPath]:
    """Where each image goes under the capture's ``images/``: its path without ``.``, ``..`` and root
    parts, less the folders every image's path starts with."""
    parts = {image: [p for p in PurePosixPath(image).parts if p not in (".", "..", "/")] for image in images}
    common = os.path.commonprefix([p[:-1] for p in parts.values()])
    return {image: PurePosixPath(*p[len(common):]) for image, p in parts.items()}


def _measurement_name(destination: PurePosixPath, image: str) -> str:
    """The measurement name of an image: its destination without suffix, folders joined by ``_``."""
    return check_name("_".join(destination.with_suffix("").parts), f"the measurement name of image {image!r}")


def _transfer(image: str, transfer: str) -> str:
    """The transfer curve of an image: ``transfer`` for an integer file, linear for an EXR one."""
    return "linear" if PurePosixPath(image).suffix.lower() == ".exr" else transfer


def import_calibration(cameras: dict[str, Camera], image_dir: str | os.PathLike, out: str | os.PathLike,
                       source: str, force: bool = False, diffuse: str | None = None, transfer: str = "srgb",
                       scale: float = 1.0) -> Path:
    """Write the images of a calibration as a capture at ``out`` (``capture.json``, ``images/``).

    * **Cameras**: the distinct cameras of the images (:func:`camera_groups`): one ``camera``, or a
      ``cameras`` list with ids ``cam0``, ``cam1``, ... where there are several; calibrated, their
      translations multiplied by ``scale``: the world frame is the calibration's, in its units times
      ``scale`` (mm per unit).
    * **Lights**: one per image, named like its measurement, ``"unknown": true`` (no calibration
      tool knows the lights): estimated with the face by ``mifaces measure``.
    * **Measurements**: one per image, all of pose (shot) :data:`POSE`, the file copied into ``images/``
      under its path (relative to ``image_dir``) less the folders all images' paths start with and
      any ``..``, and named by that path without suffix, folders joined by ``_``; decoded with
      ``transfer`` (an integer file; EXR files are linear); the ``diffuse`` companion of every one
      is the image named ``diffuse`` (default: the first) where its camera took it, else its
      camera's first image, for the landmark detector.
    * ``metadata``: ``source`` and each measurement's image name.

    Raises
    ------
    FileExistsError
        Where ``out`` holds a capture already and ``force`` is False.
    FileNotFoundError
        For a missing image.
    ValueError
        For an image name that cannot name a measurement,
        an image of another size than the camera's or a format mifaces does not read, an unknown
        ``diffuse`` or ``transfer``, a ``scale`` that is not positive.
    """
    out, image_dir = Path(out), Path(image_dir)
    if (out / MANIFEST).exists() and not force:
        raise FileExistsError(f"{out} holds a capture already ({MANIFEST}); use force=True (--force) to replace it")
    if transfer not in TRANSFERS:
        raise ValueError(f"transfer: must be one of {TRANSFERS}, got {transfer!r}")
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale: must be a positive number of mm per unit, got {scale!r}")
    groups = camera_groups(cameras)
    ids = {image: (f"cam{k}" if len(groups) > 1 else DEFAULT_CAMERA)
           for k, (_, images) in enumerate(groups) for image in images}
    diffuse = next(iter(cameras)) if diffuse is None else diffuse
    if diffuse not in cameras:
        raise ValueError(f"diffuse: no image {diffuse!r} in the calibration (images: {list(cameras)[:10]})")
    destinations = _destinations(cameras)
    names = {image: _measurement_name(destinations[image], image) for image in cameras}
    if len(set(names.values())) < len(names):
        raise ValueError("two images would get the same measurement name (their paths without suffix)")
    for image in cameras:
        source_path = image_dir / image
        if source_path.suffix.lower() not in IMAGE_SUFFIXES:
            raise ValueError(f"image {image!r}: not a format mifaces reads ({', '.join(IMAGE_SUFFIXES)})")
        if not source_path.is_file():
            raise FileNotFoundError(f"image {image!r}: no file {source_path}")
        height, width = read_image(source_path, _transfer(image, transfer)).pixels.shape[:2]
        camera = cameras[image]
        if (width, height) != (camera.width, camera.height):
            raise ValueError(f"image {image!r} is {width}x{height} pixels, its camera's images {camera.width}x"
                             f"{camera.height}")
        with atomic_write(resolve_inside(out / "images", str(destinations[image]))) as f:
            f.write(source_path.read_bytes())
    entries = []
    for camera, images in groups:
        entry = camera.to_json()
        entry["translation"] = (np.asarray(camera.translation, np.float64) * scale).tolist()
        entries.append({"id": ids[images[0]], **entry})
    companion = {image: diffuse if ids[diffuse] == ids[image] else next(i for i in cameras if ids[i] == ids[image])
                 for image in cameras}

    def picture(image: str) -> dict:
        return {"path": f"images/{destinations[image]}", "transfer": _transfer(image, transfer)}

    def measurement(image: str, name: str) -> dict:
        entry = {"name": name, "light": name, "image": picture(image), "diffuse": picture(companion[image])}
        return dict(entry, camera=ids[image], shot=POSE) if len(groups) > 1 else dict(entry, pose=POSE)

    layout = ({"cameras": entries} if len(groups) > 1 else
              {"camera": {k: v for k, v in entries[0].items() if k != "id"}})
    write_json(out / MANIFEST, {
        "format": FORMAT, "version": VERSION, **layout,
        "lights": [{"name": name, "unknown": True} for name in names.values()],
        "measurements": [measurement(image, name) for image, name in names.items()],
        "metadata": {"source": source, "scale_mm_per_unit": scale, "images": {n: i for i, n in names.items()}},
    })
    return out


def import_colmap(sparse_dir: str | os.PathLike, image_dir: str | os.PathLike, out: str | os.PathLike,
                  **options) -> Path:
    """:func:`import_calibration` of a COLMAP sparse model (:func:`~mifaces.importers.colmap.read_colmap`)
    whose image names are paths relative to ``image_dir``; its 3D points are not kept."""
    cameras = read_colmap(sparse_dir).cameras
    return import_calibration(cameras, image_dir, out, f"COLMAP sparse model {Path(sparse_dir).resolve()}", **options)


def import_transforms(path: str | os.PathLike, out: str | os.PathLike, **options) -> Path:
    """:func:`import_calibration` of a ``transforms.json``
    (:func:`~mifaces.importers.transforms.read_transforms`), its ``file_path`` s relative to its folder."""
    cameras = read_transforms(path)
    return import_calibration(cameras, Path(path).parent, out, f"transforms.json {Path(path).resolve()}", **options)


def photographs(capture: Capture) -> dict[str, Camera]:
    """Every picture the capture's cameras took (photographs, companions, steel-sphere pictures), once
    each, as paths relative to the capture folder (``/``-separated), with the camera that took it
    (the steel spheres' is the first camera)."""
    images = []
    for m in capture.measurements:
        camera = capture.camera_of(m)
        images += [(image, camera) for image in (m.image, *([m.diffuse] if m.diffuse is not None else []),
                                                 *m.exposures)]
    for light in capture.lights:
        images += [(image, capture.camera) for image in light.pictures]
    out: dict[str, Camera] = {}
    for image, camera in images:
        out.setdefault(Path(os.path.relpath(image.path, capture.path)).as_posix(), camera)
    return out


def export_calibration(capture: Capture | str | os.PathLike, out_dir: str | os.PathLike) -> Path:
    """Write a capture's cameras for other tools: a COLMAP sparse model ``out_dir/sparse/0/``
    (``cameras.txt``, ``images.txt``, ``points3D.txt``, no points) whose image names are relative
    to the capture folder, and ``out_dir/transforms.json`` whose ``file_path`` s are relative to
    ``out_dir``: for each of the capture's pictures the camera that took it (:func:`photographs`).

    ``capture`` is a loaded capture or its folder (loaded without calibrating lights or detecting
    feature points). An uncalibrated camera (``Camera.calibrated`` False) is written with its guessed
    intrinsics. Returns ``out_dir``.
    """
    capture = load_capture(capture, calibrate=False, detect=False)
    out_dir = Path(out_dir)
    taken = photographs(capture)
    write_colmap(taken, out_dir / SPARSE)
    relative = [Path(os.path.relpath(os.path.abspath(capture.path / name), os.path.abspath(out_dir))).as_posix()
                for name in taken]
    write_transforms(list(taken.values()), out_dir / TRANSFORMS, relative)
    return out_dir
