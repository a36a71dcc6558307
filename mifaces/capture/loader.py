"""Loading and validating a capture folder: :func:`load_capture`.

The manifest's camera, white target and distances are read here, its lights by
:mod:`mifaces.capture.light_entries` and its measurements by
:mod:`mifaces.capture.measurement_entries`; then the lights are calibrated and
the feature points detected.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..io.image_files import check_image_size
from .detector import NoFaceError
from ..model.landmarks import FEATURE_POINTS
from .calibration import CalibrationError, calibrate_light
from .camera import Camera
from .feature_points import detect_feature_points
from .light_entries import read_lights
from .measurement_entries import read_measurements
from .problems import Problems
from ..io.paths import check_name
from .types import (AMBIENT_KINDS, DEFAULT_CAMERA, FEATURE_POINT_RANGE, FORMAT, MANIFEST, MIN_CAMERA_SEPARATION,
                    VERSION, Capture, CaptureError, Distance, Light, Measurement, WhiteTarget)


def _cameras(data: dict, problems: Problems) -> dict[str, Camera]:
    """The manifest's cameras by id: its one ``camera`` (id :data:`DEFAULT_CAMERA`), or its
    ``cameras`` list, each with an ``id``, calibrated (one head pose is shared by the cameras of a
    shot, so their intrinsics and poses are not fitted), no two at one place."""
    if "cameras" not in data:
        camera = _camera(data.get("camera"), problems)
        return {} if camera is None else {DEFAULT_CAMERA: camera}
    if "camera" in data:
        problems.append("camera, cameras: give one 'camera' or a list of 'cameras', not both")
    cameras = {}
    for i, entry, where in problems.objects(data, "cameras", " of cameras"):
        ident = problems.need(entry, "id", where, str)
        if ident is None:
            continue
        where = f"cameras[{i}] ({ident})"
        try:
            check_name(ident, f"{where}.id")
        except ValueError as error:
            problems.append(str(error))
        camera = _camera(entry, problems, where)
        if camera is not None and not camera.calibrated:
            problems.append(f"{where}: a camera of several must be calibrated (a shot's cameras share one head pose, "
                            "so their intrinsics are not fitted)")
        if camera is not None and ident not in cameras:
            cameras[ident] = camera
    problems.unique("cameras", [e.get("id") for e in data.get("cameras") or [] if isinstance(e, dict)])
    ids = list(cameras)
    for a in range(len(ids)):
        for b in range(a + 1, len(ids)):
            gap = float(np.linalg.norm(cameras[ids[a]].position - cameras[ids[b]].position))
            if gap < MIN_CAMERA_SEPARATION:
                problems.append(f"cameras {ids[a]!r} and {ids[b]!r} are at one place ({gap:.3g} mm apart; "
                                f"at least {MIN_CAMERA_SEPARATION:g} mm): one camera listed twice?")
    return cameras


def _camera(entry, problems: Problems, where: str = "camera") -> Camera | None:
    if not isinstance(entry, dict):
        problems.append(f"{where}: missing or not an object")
        return None
    n = len(problems)
    width = problems.need(entry, "width", where, int)
    height = problems.need(entry, "height", where, int)
    for name, v in (("width", width), ("height", height)):
        if v is not None and v <= 0:
            problems.append(f"{where}.{name}: must be positive, got {v}")
    if width is not None and height is not None and width > 0 and height > 0:
        try:
            check_image_size(width, height, where)
        except ValueError as e:
            problems.append(str(e))
    calibrated = entry.get("calibrated", True)
    if not isinstance(calibrated, bool):
        problems.append(f"{where}.calibrated: must be true or false, got {calibrated!r}")
    fx, fy, cx, cy = _intrinsics(entry, calibrated is not False, width, height, problems, where)
    distortion = entry.get("distortion", [])
    try:
        distortion = np.asarray(distortion, np.float64).ravel()
        if len(distortion) not in (0, 4, 5, 8) or not np.all(np.isfinite(distortion)):
            problems.append(f"{where}.distortion: must be 0, 4, 5 or 8 finite OpenCV coefficients "
                            f"(k1, k2, p1, p2[, k3[, k4, k5, k6]]), got {entry.get('distortion')!r}")
    except (TypeError, ValueError):
        problems.append(f"{where}.distortion: must be a list of numbers, got {entry.get('distortion')!r}")
    rotation = problems.vector(entry, "rotation", where, (3, 3), required=False, default=np.eye(3))
    if rotation is not None and not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-4):
        problems.append(f"{where}.rotation: must be a rotation matrix (orthonormal rows)")
    elif rotation is not None and np.linalg.det(rotation) < 0:
        problems.append(f"{where}.rotation: has determinant -1 (a reflection, not a rotation)")
    translation = problems.vector(entry, "translation", where, 3, required=False, default=np.zeros(3))
    if len(problems) > n:
        return None
    return Camera(width, height, fx, fy, cx, cy, distortion, rotation, translation, calibrated)


def _intrinsics(entry: dict, calibrated: bool, width, height, problems: Problems, where: str = "camera"):
    """``fx, fy, cx, cy`` of a manifest's camera. An uncalibrated camera's are a guess: one
    ``focal_guess_px`` may stand for both focal lengths, and ``cx, cy`` default to the image centre."""
    if "focal_guess_px" in entry:
        if calibrated:
            problems.append(f"{where}.focal_guess_px: only for an uncalibrated camera (\"calibrated\": false); "
                            "a calibrated one gives fx and fy")
        if "fx" in entry or "fy" in entry:
            problems.append(f"{where}: give either focal_guess_px or fx and fy, not both")
        fx = fy = problems.number(entry, "focal_guess_px", where, positive=True)
    else:
        fx = problems.number(entry, "fx", where, positive=True)
        fy = problems.number(entry, "fy", where, positive=True)
    centre = [None if v is None else (v - 1) / 2 for v in (width, height)]
    cx = problems.number(entry, "cx", where, default=centre[0], required=calibrated)
    cy = problems.number(entry, "cy", where, default=centre[1], required=calibrated)
    return fx, fy, cx, cy


def load_capture(path: str | os.PathLike | Capture, calibrate: bool = True, detect: bool = True,
                 allow_outside: bool = False) -> Capture:
    """Load and validate the capture in folder ``path`` (or its ``capture.json``).

    Parameters
    ----------
    path : path or Capture
        The capture folder, or its manifest file; a loaded :class:`Capture` is returned
        as it is, so a function may take either.
    calibrate : bool
        Compute the position of lights given by steel-sphere pictures
        (:func:`mifaces.capture.calibration.calibrate_light`). Without it such lights
        have ``position=None``.
    detect : bool
        Find the feature points of measurements whose manifest gives none
        with the landmark detector
        (:func:`mifaces.capture.feature_points.detect_feature_points`). Without
        it their ``feature_points`` stay empty.
    allow_outside : bool
        Accept image paths that leave the capture folder (absolute, ``../``,
        symbolic links resolving outside); by default they are problems.

    Returns
    -------
    Capture

    Raises
    ------
    CaptureError
        Naming every problem: a corrupted or incomplete manifest, missing or
        unreadable images, images of the wrong size, NaN or infinite pixels,
        malformed calibration or light directions, unknown feature points,
        lights that cannot be calibrated, faces the detector does not find.
    ImportError
        Where feature points are to be detected without the ``landmarks`` extra.

    Examples
    --------
    ``capture_folder`` is a capture folder (one :func:`mifaces.simulate` wrote, here):

    >>> from mifaces import load_capture
    >>> capture = load_capture(capture_folder)
    >>> [m.name for m in capture.measurements], capture.camera.width
    (['m00', 'm01'], 96)
    >>> capture.light(capture.measurements[0].light).directional
    False
    >>> load_capture(capture) is capture  # a loaded capture passes through
    True
    """
    if isinstance(path, Capture):
        return path
    root, data = _read_manifest(Path(path))
    problems = Problems()
    problems.allow_outside = allow_outside
    if data.get("format") != FORMAT:
        problems.append(f"format: must be {FORMAT!r}, got {data.get('format')!r}")
    if data.get("version") != VERSION:
        problems.append(f"version: this mifaces reads version {VERSION}, got {data.get('version')!r}")
    cameras = _cameras(data, problems)
    camera = next(iter(cameras.values()), None)
    white = _white_target(data.get("white_target"), problems)
    distances = _distances(data.get("distances"), problems)
    ambient = data.get("ambient", AMBIENT_KINDS[0])
    if ambient not in AMBIENT_KINDS:
        problems.append(f"ambient: must be one of {list(AMBIENT_KINDS)}, got {ambient!r}"[:300])
    lights = read_lights(data, root, camera, problems)
    measurements = read_measurements(data, root, cameras, [l.name for l in lights], problems)
    if problems:
        raise CaptureError(root, problems)
    if calibrate:
        lights = _calibrate(lights, camera, problems)
    if detect:
        measurements = _detect(measurements, root, problems)
    if problems:
        raise CaptureError(root, problems)
    metadata = data.get("metadata", {})
    return Capture(root, camera, tuple(lights), tuple(measurements), tuple(distances), white,
                   dict(metadata) if isinstance(metadata, dict) else {}, ambient, cameras)


def _read_manifest(path: Path) -> tuple[Path, dict]:
    """The capture folder and its manifest's JSON object; a :class:`CaptureError` when there is none."""
    manifest = path if path.is_file() else path / MANIFEST
    root = manifest.parent
    if not manifest.is_file():
        raise CaptureError(root, [f"no manifest: {manifest} does not exist"])
    try:
        data = json.loads(manifest.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CaptureError(root, [f"{MANIFEST} is not valid JSON: {e}"]) from None
    if not isinstance(data, dict):
        raise CaptureError(root, [f"{MANIFEST}: must hold a JSON object, got {type(data).__name__}"])
    return root, data


def _white_target(wt, problems: Problems) -> WhiteTarget | None:
    """The white target, or None where the manifest has none (reflectance then only relative)."""
    if wt is None:
        return None
    if not isinstance(wt, dict):
        problems.append(f"white_target: must be an object, got {wt!r}"[:300])
        return None
    n = len(problems)
    value = problems.vector(wt, "value", "white_target", 3, positive=True, scalar_ok=True)
    refl = problems.number(wt, "reflectance", "white_target", positive=True, default=1.0, required=False)
    dist = problems.number(wt, "distance_mm", "white_target", positive=True)
    inten = problems.vector(wt, "intensity", "white_target", 3, positive=True, scalar_ok=True)
    cos_i = problems.number(wt, "cos_incidence", "white_target", positive=True, default=1.0, required=False)
    if cos_i is not None and cos_i > 1:
        problems.append(f"white_target.cos_incidence: must be in (0, 1], got {cos_i}")
    return WhiteTarget(value, refl, dist, inten, cos_i) if len(problems) == n else None


def _distances(entries, problems: Problems) -> list[Distance]:
    """The metric distances: none (absent or empty: no absolute scale), or at least three."""
    distances = []
    if entries is None or entries == []:
        return distances
    if not isinstance(entries, list) or len(entries) < 3:
        problems.append(f"distances: need a list of at least three metric distances on the face, got {entries!r}"[:300])
        entries = entries if isinstance(entries, list) else []
    for i, d in enumerate(entries):
        where = f"distances[{i}]"
        a, b = problems.need(d, "from", where, str), problems.need(d, "to", where, str)
        mm = problems.number(d, "mm", where, positive=True)
        for name in (a, b):
            if name is not None and name not in FEATURE_POINTS:
                problems.append(f"{where}: unknown feature point {name!r}")
        if a is not None and b is not None and mm is not None:
            distances.append(Distance(a, b, mm))
    return distances


def _calibrate(lights: list[Light], camera: Camera, problems: Problems) -> list[Light]:
    """The lights with the positions their steel-sphere pictures give (paper sec. 3)."""
    calibrated = []
    for light in lights:
        try:
            light = light.calibrated(lambda spheres: calibrate_light(spheres, camera))
        except CalibrationError as e:
            problems.append(f"light {light.name!r}: steel-sphere calibration failed: {e}")
        calibrated.append(light)
    return calibrated


# --------------------------------------------------------------------------------------------
# Detecting feature points
# --------------------------------------------------------------------------------------------
def _detect(measurements: list[Measurement], root: Path, problems: Problems) -> list[Measurement]:
    """The measurements, those without feature points given the detected ones (on the diffuse
    companion, evenly lit, where there is one, else the photograph); each picture detected once."""
    found: dict[tuple, dict | None] = {}
    out = []
    for i, m in enumerate(measurements):
        if m.feature_points:
            out.append(m)
            continue
        picture = m.diffuse if m.diffuse is not None else m.image
        where = f"measurements[{i}] ({m.name})"
        rel = os.path.relpath(picture.path, root)
        key = (picture.path, m.face_box)
        if key not in found:
            try:
                found[key] = detect_feature_points(picture, m.face_box, rel)
            except NoFaceError:
                found[key] = None
        points = found[key]
        if points is None:
            problems.append(f"{where}: no feature points given and no face found in {rel}"
                            f"{'' if m.face_box else ' (give a face_box)'}")
        elif len(points) < FEATURE_POINT_RANGE[0]:
            problems.append(f"{where}: only {len(points)} detected feature points lie inside {rel}, "
                            f"a measurement needs {FEATURE_POINT_RANGE[0]}")
        else:
            m = replace(m, feature_points={k: v.copy() for k, v in points.items()})
        out.append(m)
    return out
