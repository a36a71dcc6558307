"""The pictures of a capture manifest: image entries (:func:`read_image_entry`) and the
measurements (:func:`read_measurements`) with their feature points and face boxes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.landmarks import FEATURE_POINTS
from ..io.paths import check_name, resolve_inside
from .camera import Camera
from .images import read_image
from .problems import Problems
from .types import DEFAULT_CAMERA, FEATURE_POINT_RANGE, IMAGE_SUFFIXES, TRANSFERS, Image, Measurement


def read_image_entry(entry, where: str, root: Path, camera: Camera | None, problems: Problems) -> Image | None:
    """Read and check one image entry ``{"path", "transfer", "gamma", "exposure", "saturation"}``:
    a path inside the capture folder (:func:`mifaces.io.paths.resolve_inside`), finite, non-negative pixels."""
    if isinstance(entry, str):
        entry = {"path": entry}
    if not isinstance(entry, dict):
        problems.append(f"{where}: must be an image entry (a path or an object with 'path'), got {entry!r}"[:300])
        return None
    rel = problems.need(entry, "path", where, str)
    if rel is None:
        return None
    n = len(problems)
    transfer = entry.get("transfer", "linear")
    if transfer not in TRANSFERS:
        problems.append(f"{where}.transfer: must be one of {TRANSFERS}, got {transfer!r}")
    gamma = problems.number(entry, "gamma", where, positive=True, default=2.2, required=False)
    exposure = problems.number(entry, "exposure", where, positive=True, default=1.0, required=False)
    saturation = problems.number(entry, "saturation", where, positive=True, default=None, required=False)
    try:
        path = resolve_inside(root, rel, problems.allow_outside)
    except (ValueError, OSError) as e:
        problems.append(f"{where}.path: {e}")
        return None
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        problems.append(f"{where}.path: {rel!r} is not an image file we read ({', '.join(IMAGE_SUFFIXES)})")
    elif not path.is_file():
        problems.append(f"{where}: image file missing: {rel}")
    if len(problems) > n:
        return None
    try:
        image = read_image(path, transfer, gamma, exposure, saturation)
    except Exception as e:  # noqa: BLE001 - any reader failure is a problem of this capture
        problems.append(f"{where}: cannot read {rel}: {e}")
        return None
    h, w = image.pixels.shape[:2]
    if camera is not None and (w, h) != (camera.width, camera.height):
        problems.append(f"{where}: {rel} is {w}x{h} pixels, the camera's images are "
                        f"{camera.width}x{camera.height}")
        return None
    bad = ~np.isfinite(image.pixels)
    if bad.any():
        rows, cols = np.nonzero(bad.any(axis=2))
        problems.append(f"{where}: {rel} has {int(bad.any(axis=2).sum())} pixels with NaN or infinite values "
                        f"(first at x={cols[0]}, y={rows[0]})")
        return None
    negative = image.pixels < 0
    if negative.any():
        rows, cols = np.nonzero(negative.any(axis=2))
        problems.append(f"{where}: {rel} has {len(rows)} pixels with negative values (first at x={cols[0]}, "
                        f"y={rows[0]}: {image.pixels[rows[0], cols[0]].tolist()}); light is not negative")
        return None
    return image


def _feature_points(entry, where: str, camera: Camera | None, problems: Problems) -> dict[str, np.ndarray]:
    if not isinstance(entry, dict):
        problems.append(f"{where}: must be an object mapping feature point names to [x, y] pixels")
        return {}
    out = {}
    lo, hi = FEATURE_POINT_RANGE
    if entry and not lo <= len(entry) <= hi:
        problems.append(f"{where}: has {len(entry)} feature points, a measurement needs {lo} to {hi}")
    for name, xy in entry.items():
        if name not in FEATURE_POINTS:
            problems.append(f"{where}: unknown feature point {name!r}; known: {', '.join(sorted(FEATURE_POINTS))}")
            continue
        p = problems.vector(entry, name, where, 2)
        if p is None:
            continue
        if camera is not None and not (-0.5 <= p[0] <= camera.width - 0.5 and -0.5 <= p[1] <= camera.height - 0.5):
            problems.append(f"{where}.{name}: {p.tolist()} lies outside the {camera.width}x{camera.height} image")
            continue
        out[name] = p
    return out


def _face_box(obj: dict, where: str, problems: Problems) -> tuple[float, ...] | None:
    """The optional ``face_box`` of ``obj``, ``[x0, y0, x1, y1]`` in pixels (``x1, y1`` the last inside)."""
    value = obj.get("face_box")
    if value is None:
        return None
    try:
        box = np.asarray(value, np.float64)
        valid = box.shape == (4,) and np.all(np.isfinite(box)) and box[2] > box[0] and box[3] > box[1]
    except (TypeError, ValueError):
        valid = False
    if not valid:
        problems.append(f"{where}: must be [x0, y0, x1, y1] in pixels with x1 > x0 and y1 > y0, got {value!r}"[:300])
        return None
    return tuple(float(v) for v in box)


def _camera_id(e: dict, where: str, cameras: dict, problems: Problems) -> str | None:
    """The id of the camera measurement entry ``e`` names: required where the capture has several
    cameras, else that one's (where it names one, it must be that one)."""
    ident = e.get("camera")
    if ident is None and len(cameras) == 1:
        return next(iter(cameras))
    if ident is None:
        if cameras:
            problems.append(f"{where}.camera: missing; the capture has {len(cameras)} cameras: {list(cameras)}")
        return None
    if ident not in cameras:
        if cameras:
            problems.append(f"{where}.camera: no camera with id {ident!r} (cameras: {list(cameras)})"[:300])
        return None
    return ident


def _pose_label(e: dict, where: str, problems: Problems) -> str | None:
    """The pose label of measurement entry ``e``: its ``pose``, or its ``shot`` (the photographs
    taken at one instant by several cameras: one head pose); both must agree where both are given."""
    pose, shot = e.get("pose"), e.get("shot")
    if pose is not None and shot is not None and str(pose) != str(shot):
        problems.append(f"{where}: pose {pose!r} and shot {shot!r} differ; a shot is one head pose")
    label = shot if shot is not None else pose
    return None if label is None else str(label)


def read_measurements(data: dict, root: Path, cameras: dict[str, Camera], lights: list[str],
                      problems: Problems) -> list[Measurement]:
    """The manifest's ``measurements`` (each naming one of ``lights`` and, where the capture has
    several, one of ``cameras``: id -> Camera); the problems found go to ``problems``."""
    measurements = []
    capture_box = _face_box(data, "face_box", problems)
    for i, e, where in problems.objects(data, "measurements", ""):
        name = problems.need(e, "name", where, str) or f"#{i}"
        where = f"measurements[{i}] ({name})"
        if not name.startswith("#"):
            try:
                check_name(name, "name")
            except ValueError as error:
                problems.append(f"{where}: {error}")
        light = problems.need(e, "light", where, str)
        if light is not None and light not in lights:
            problems.append(f"{where}.light: no light condition named {light!r} (lights: {lights})")
        pose = _pose_label(e, where, problems)
        ident = _camera_id(e, where, cameras, problems)
        camera = cameras.get(ident)
        image = read_image_entry(e.get("image"), f"{where}.image", root, camera, problems) if "image" in e else \
            problems.need(e, "image", where)
        diffuse = (read_image_entry(e["diffuse"], f"{where}.diffuse", root, camera, problems) if "diffuse" in e
                   else None)
        series = e.get("exposures", [])
        if not isinstance(series, list):
            problems.append(f"{where}.exposures: must be a list of image entries")
            series = []
        exposures = [read_image_entry(x, f"{where}.exposures[{j}]", root, camera, problems)
                     for j, x in enumerate(series)]
        if "diffuse" not in e and not series:
            problems.append(f"{where}: needs a companion picture: 'diffuse' (diffuse light) or 'exposures' "
                            "(an exposure series)")
        if len(series) == 1:
            problems.append(f"{where}.exposures: an exposure series needs at least two pictures")
        points = _feature_points(e.get("feature_points") or {}, f"{where}.feature_points", camera, problems)
        box = _face_box(e, f"{where}.face_box", problems) if "face_box" in e else capture_box
        if isinstance(image, Image) and light is not None and None not in exposures:
            measurements.append(Measurement(name, light, pose, image, diffuse, tuple(exposures), points, box,
                                            ident if ident is not None else DEFAULT_CAMERA))
    problems.unique("measurements", [m.name for m in measurements])
    photographed = {e.get("camera") for e in data.get("measurements") or [] if isinstance(e, dict)}
    if len(cameras) > 1:
        for ident in cameras:
            if ident not in photographed:
                problems.append(f"cameras: camera {ident!r} took no photograph (no measurement names it)")
    return measurements
