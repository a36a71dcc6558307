"""Loading and validating a capture folder: :func:`load_capture`."""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..image_files import check_image_size, read_exr
from ..paths import check_name, resolve_inside
from .detector import NoFaceError
from ..model.landmarks import FEATURE_POINTS
from .calibration import CalibrationError, calibrate_light
from .camera import Camera
from .feature_points import detect_feature_points
from .images import read_image
from .problems import Problems
from .types import (ENVMAP_HEIGHTS, ENVMAP_SIZE, FEATURE_POINT_RANGE, FORMAT, GIVEN_ENVMAP_HEIGHTS, IMAGE_SUFFIXES,
                    LIGHT_KINDS, MANIFEST, RELATIVE_IRRADIANCE, TRANSFERS, VERSION, Capture, CaptureError, Distance,
                    Image, Light, Measurement, SpherePictures, WhiteTarget)


def _camera(entry, problems: Problems) -> Camera | None:
    where = "camera"
    if not isinstance(entry, dict):
        problems.append("camera: missing or not an object")
        return None
    n = len(problems)
    width = problems.need(entry, "width", where, int)
    height = problems.need(entry, "height", where, int)
    for name, v in (("width", width), ("height", height)):
        if v is not None and v <= 0:
            problems.append(f"camera.{name}: must be positive, got {v}")
    if width is not None and height is not None and width > 0 and height > 0:
        try:
            check_image_size(width, height, "camera")
        except ValueError as e:
            problems.append(str(e))
    calibrated = entry.get("calibrated", True)
    if not isinstance(calibrated, bool):
        problems.append(f"camera.calibrated: must be true or false, got {calibrated!r}")
    fx, fy, cx, cy = _intrinsics(entry, calibrated is not False, width, height, problems)
    distortion = entry.get("distortion", [])
    try:
        distortion = np.asarray(distortion, np.float64).ravel()
        if len(distortion) not in (0, 4, 5, 8) or not np.all(np.isfinite(distortion)):
            problems.append(f"camera.distortion: must be 0, 4, 5 or 8 finite OpenCV coefficients "
                            f"(k1, k2, p1, p2[, k3[, k4, k5, k6]]), got {entry.get('distortion')!r}")
    except (TypeError, ValueError):
        problems.append(f"camera.distortion: must be a list of numbers, got {entry.get('distortion')!r}")
    rotation = problems.vector(entry, "rotation", where, (3, 3), required=False, default=np.eye(3))
    if rotation is not None and not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-4):
        problems.append("camera.rotation: must be a rotation matrix (orthonormal rows)")
    elif rotation is not None and np.linalg.det(rotation) < 0:
        problems.append("camera.rotation: has determinant -1 (a reflection, not a rotation)")
    translation = problems.vector(entry, "translation", where, 3, required=False, default=np.zeros(3))
    if len(problems) > n:
        return None
    return Camera(width, height, fx, fy, cx, cy, distortion, rotation, translation, calibrated)


def _intrinsics(entry: dict, calibrated: bool, width, height, problems: Problems):
    """``fx, fy, cx, cy`` of a manifest's camera. An uncalibrated camera's are a guess: one
    ``focal_guess_px`` may stand for both focal lengths, and ``cx, cy`` default to the image centre."""
    where = "camera"
    if "focal_guess_px" in entry:
        if calibrated:
            problems.append("camera.focal_guess_px: only for an uncalibrated camera (\"calibrated\": false); "
                            "a calibrated one gives fx and fy")
        if "fx" in entry or "fy" in entry:
            problems.append("camera: give either focal_guess_px or fx and fy, not both")
        fx = fy = problems.number(entry, "focal_guess_px", where, positive=True)
    else:
        fx = problems.number(entry, "fx", where, positive=True)
        fy = problems.number(entry, "fy", where, positive=True)
    centre = [None if v is None else (v - 1) / 2 for v in (width, height)]
    cx = problems.number(entry, "cx", where, default=centre[0], required=calibrated)
    cy = problems.number(entry, "cy", where, default=centre[1], required=calibrated)
    return fx, fy, cx, cy


def _image(entry, where: str, root: Path, camera: Camera | None, problems: Problems) -> Image | None:
    """Read and check one image entry ``{"path", "transfer", "gamma", "exposure", "saturation"}``:
    a path inside the capture folder (:func:`mifaces.paths.resolve_inside`), finite, non-negative pixels."""
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
    >>> from mifaces import load_capture
    >>> capture = load_capture(SHARED / "data" / "yaleb_capture")  # doctest: +SKIP
    >>> capture = load_capture(tiny_capture)  # a folder mifaces.simulate wrote
    >>> [light.name for light in capture.lights][:2]
    ['L0', 'L1']
    >>> load_capture(capture) is capture
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
    camera = _camera(data.get("camera"), problems)
    white = _white_target(data.get("white_target"), problems)
    distances = _distances(data.get("distances"), problems)
    lights = _lights(data, root, camera, problems)
    measurements = _measurements(data, root, camera, [l.name for l in lights], problems)
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
                   dict(metadata) if isinstance(metadata, dict) else {})


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


def _lights(data: dict, root: Path, camera: Camera | None, problems: Problems) -> list[Light]:
    lights = []
    for i, e, where in problems.objects(data, "lights", " of light conditions"):
        name = problems.need(e, "name", where, str)
        where = f"lights[{i}] ({name})" if name else where
        relative = e.get("relative", False)
        if not isinstance(relative, bool):
            problems.append(f"{where}.relative: must be true or false, got {relative!r}")
        unknown = e.get("unknown", False)
        if not isinstance(unknown, bool):
            problems.append(f"{where}.unknown: must be true or false, got {unknown!r}")
        if unknown is True:
            light = _unknown_light(e, name, where, problems)
        elif e.get("kind") == "environment" or "map" in e:
            light = _environment_light(e, name, where, relative, root, problems)
        elif "direction" in e:
            light = _directional_light(e, name, where, relative, problems)
        else:
            light = _point_light(e, name, where, relative, root, camera, problems)
        if light is not None:
            lights.append(light)
    problems.unique("lights", [l.name for l in lights])
    return lights


def _directional_light(e: dict, name, where: str, relative, problems: Problems) -> Light | None:
    """A distant light: ``direction`` towards it (world frame), ``intensity`` optional (then
    :data:`~mifaces.capture.types.RELATIVE_IRRADIANCE`, relative)."""
    for key in ("position_mm", "spheres"):
        if key in e:
            problems.append(f"{where}: give 'direction' (a directional light) or '{key}' (a point light), not both")
    direction = problems.vector(e, "direction", where, 3)
    if direction is not None and np.linalg.norm(direction) < 1e-12:
        problems.append(f"{where}.direction: must be non-zero, got {e['direction']!r}")
        direction = None
    intensity = problems.vector(e, "intensity", where, 3, positive=True, scalar_ok=True, required=False)
    if "intensity" not in e:
        intensity, relative = np.full(3, RELATIVE_IRRADIANCE), True
    if name is None or direction is None or intensity is None:
        return None
    return Light(name, None, intensity, direction=direction / np.linalg.norm(direction), relative=relative is True)


#: Keys that give a light: none of them may come with ``"unknown": true``.
_GIVEN = ("direction", "position_mm", "spheres", "intensity", "map")


def _environment_light(e: dict, name, where: str, relative, root: Path, problems: Problems) -> Light | None:
    """A given environment map: ``map``, a latitude-longitude OpenEXR file (width twice the height,
    linear RGB radiance in pixel value, times the optional ``scale``) in the frame of
    :func:`mifaces.environment.environment_emitter`."""
    n = len(problems)
    if e.get("kind", "environment") != "environment":
        problems.append(f"{where}: light {name!r} has a 'map' but kind {e['kind']!r}: a map is an environment light")
    for key in ("direction", "position_mm", "spheres", "intensity", "size", "guess"):
        if key in e:
            problems.append(f"{where}: light {name!r} is an environment map: it takes no '{key}'")
    rel = problems.need(e, "map", where, str)
    scale = problems.number(e, "scale", where, positive=True, default=1.0, required=False)
    if rel is None or len(problems) > n:
        return None
    try:
        path = resolve_inside(root, rel, problems.allow_outside)
    except (ValueError, OSError) as err:
        problems.append(f"{where}.map: {err}")
        return None
    if path.suffix.lower() != ".exr" or not path.is_file():
        problems.append(f"{where}.map: light {name!r}: {rel!r} is not an OpenEXR file in the capture")
        return None
    try:
        envmap = read_exr(path)
    except Exception as err:  # noqa: BLE001 - any reader failure is a problem of this capture
        problems.append(f"{where}.map: cannot read {rel}: {err}")
        return None
    if envmap.ndim != 3 or envmap.shape[2] < 3:
        problems.append(f"{where}.map: light {name!r}: {rel} must be an RGB image, got shape {envmap.shape}")
        return None
    envmap = envmap[..., :3]
    if _envmap_size([int(envmap.shape[1]), int(envmap.shape[0])], name, f"{where}.map", problems,
                    GIVEN_ENVMAP_HEIGHTS) is None:
        return None
    if not np.all(np.isfinite(envmap)) or envmap.min() < 0:
        problems.append(f"{where}.map: light {name!r}: {rel} has NaN, infinite or negative radiance")
        return None
    return Light(name, None, np.ones(3), relative=relative is True, kind="environment",
                 envmap=np.ascontiguousarray(envmap * np.float32(scale), np.float32))


def _unknown_light(e: dict, name, where: str, problems: Problems) -> Light | None:
    """A light nobody measured: its ``kind`` (:data:`LIGHT_KINDS`, default directional), for a
    directional one an optional ``guess`` (``{"direction": [x, y, z]}``), for an environment map an
    optional ``size`` ([width, height], width twice the height, height in :data:`ENVMAP_HEIGHTS`).
    Its intensity is relative (:data:`RELATIVE_IRRADIANCE` until estimated)."""
    n = len(problems)
    for key in _GIVEN:
        if key in e:
            problems.append(f"{where}: light {name!r} is both unknown and given ('{key}'): "
                            "drop 'unknown' or drop the measured values (a stated guess goes in 'guess')")
    kind = e.get("kind", LIGHT_KINDS[0])
    if kind not in LIGHT_KINDS:
        problems.append(f"{where}.kind: light {name!r} has unknown kind {kind!r}; kinds: {list(LIGHT_KINDS)}")
    guess = size = None
    if "guess" in e:
        if kind != "directional":
            problems.append(f"{where}.guess: light {name!r} of kind {kind!r} takes no guess (only a directional one)")
        elif not isinstance(e["guess"], dict) or set(e["guess"]) != {"direction"}:
            problems.append(f"{where}.guess: light {name!r}: must be {{\"direction\": [x, y, z]}}, "
                            f"got {e['guess']!r}"[:300])
        else:
            guess = problems.vector(e["guess"], "direction", f"{where}.guess", 3)
            if guess is not None and np.linalg.norm(guess) < 1e-12:
                problems.append(f"{where}.guess.direction: light {name!r}: must be non-zero, got {guess.tolist()}")
                guess = None
            elif guess is not None:
                guess = guess / np.linalg.norm(guess)
    if "size" in e and kind != "environment":
        problems.append(f"{where}.size: light {name!r} of kind {kind!r} has no map size (only an environment one)")
    elif kind == "environment":
        size = _envmap_size(e.get("size", list(ENVMAP_SIZE)), name, f"{where}.size", problems)
    if name is None or len(problems) > n:
        return None
    return Light(name, None, np.full(3, RELATIVE_IRRADIANCE), relative=True, unknown=True, kind=kind, guess=guess,
                 envmap_size=size)


def _envmap_size(value, name, where: str, problems: Problems, heights=ENVMAP_HEIGHTS) -> tuple[int, int] | None:
    """An environment map's (width, height): two integers, width = 2 x height (latitude-longitude),
    height in ``heights`` (low, high): :data:`ENVMAP_HEIGHTS` for a map to estimate,
    :data:`GIVEN_ENVMAP_HEIGHTS` for a given one."""
    low, high = heights
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
        problems.append(f"{where}: light {name!r}: invalid envmap size {value!r}: "
                        "must be [width, height] in texels"[:300])
        return None
    width, height = value
    if width != 2 * height or not low <= height <= high:
        problems.append(f"{where}: light {name!r}: invalid envmap size {width}x{height}: the width must be twice the "
                        f"height (a latitude-longitude map) and the height between {low} and {high}")
        return None
    return width, height


def _point_light(e: dict, name, where: str, relative, root: Path, camera: Camera | None,
                 problems: Problems) -> Light | None:
    """A point light: ``intensity`` and ``position_mm`` or the steel-sphere pictures to calibrate it from."""
    intensity = problems.vector(e, "intensity", where, 3, positive=True, scalar_ok=True)
    position = problems.vector(e, "position_mm", where, 3, required=False)
    spheres = None
    if "spheres" in e:
        s = e["spheres"]
        sw = f"{where}.spheres"
        radius = problems.number(s, "radius_mm", sw, positive=True)
        hl = _image(s.get("highlight") if isinstance(s, dict) else None, f"{sw}.highlight", root, camera, problems)
        ol = _image(s.get("outline") if isinstance(s, dict) else None, f"{sw}.outline", root, camera, problems)
        if radius is not None and hl is not None and ol is not None:
            spheres = SpherePictures(radius, hl, ol)
    elif position is None and "position_mm" not in e:
        problems.append(f"{where}: needs 'position_mm' or 'spheres' (the steel-sphere pictures), "
                        "or 'direction' for a directional light")
    if name is None or intensity is None:
        return None
    return Light(name, position, intensity, spheres, relative=relative is True)


def _measurements(data: dict, root: Path, camera: Camera | None, lights: list[str],
                  problems: Problems) -> list[Measurement]:
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
        pose = e.get("pose")
        image = _image(e.get("image"), f"{where}.image", root, camera, problems) if "image" in e else \
            problems.need(e, "image", where)
        diffuse = _image(e["diffuse"], f"{where}.diffuse", root, camera, problems) if "diffuse" in e else None
        series = e.get("exposures", [])
        if not isinstance(series, list):
            problems.append(f"{where}.exposures: must be a list of image entries")
            series = []
        exposures = [_image(x, f"{where}.exposures[{j}]", root, camera, problems) for j, x in enumerate(series)]
        if "diffuse" not in e and not series:
            problems.append(f"{where}: needs a companion picture: 'diffuse' (diffuse light) or 'exposures' "
                            "(an exposure series)")
        if len(series) == 1:
            problems.append(f"{where}.exposures: an exposure series needs at least two pictures")
        points = _feature_points(e.get("feature_points") or {}, f"{where}.feature_points", camera, problems)
        box = _face_box(e, f"{where}.face_box", problems) if "face_box" in e else capture_box
        if isinstance(image, Image) and light is not None and None not in exposures:
            measurements.append(Measurement(name, light, None if pose is None else str(pose), image, diffuse,
                                            tuple(exposures), points, box))
    problems.unique("measurements", [m.name for m in measurements])
    return measurements


def _calibrate(lights: list[Light], camera: Camera, problems: Problems) -> list[Light]:
    """The lights with the positions their steel-sphere pictures give (paper sec. 3)."""
    calibrated = []
    for light in lights:
        if light.position is None and light.spheres is not None:
            try:
                cal = calibrate_light(light.spheres, camera)
            except CalibrationError as e:
                problems.append(f"light {light.name!r}: steel-sphere calibration failed: {e}")
                calibrated.append(light)
                continue
            light = replace(light, position=cal.position, calibration=cal)
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
