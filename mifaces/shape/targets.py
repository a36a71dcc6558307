"""What a shape fit matches and where it starts (paper sec. 4.2): the clicked
feature points, the metric distances between them, the photographs
normalised and blurred, the frontal start of pose and light, and the
measurement whose texture starts the others.

Frames: model space (mm, y up, face along +z); camera space (OpenCV: x right,
y down, z forward; mm), ``x_camera = R0 R(yaw, pitch, roll) (x_model - c) + t``
with ``R0`` = :data:`FRONTAL` and ``c`` = :func:`rotation_centre`; pixels with
the centre of the top-left pixel at (0, 0).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.ndimage as ndi

from ..model.geometry import head_centre
from ..model.landmarks import FEATURE_POINTS
from .result import ShapeFitError

#: Model -> camera rotation of a frontal view (model y up, face along +z; camera y down, z forward).
FRONTAL = np.diag([1.0, -1.0, -1.0])


def light_direction(elevation: float, azimuth: float) -> np.ndarray:
    """Unit direction towards the light in camera space for two angles (radians):
    (0, 0) points at the camera, positive elevation up, positive azimuth to the image's right."""
    return np.array([math.cos(elevation) * math.sin(azimuth), -math.sin(elevation),
                     -math.cos(elevation) * math.cos(azimuth)])


def light_angles(direction) -> tuple[float, float]:
    """``(elevation, azimuth)`` in radians of a camera-space direction towards a light: the
    inverse of :func:`light_direction`."""
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    return math.asin(float(np.clip(-d[1], -1, 1))), math.atan2(d[0], -d[2])


def start_light_angles(light, camera, head_world) -> tuple[float, float] | None:
    """Start angles (:func:`light_angles`) of a capture's :class:`~mifaces.capture.Light` seen
    from the world point ``head_world`` (mm): a directional light's direction, a point light's
    direction from there, turned into the camera frame; None for a light with neither."""
    towards = None if light is None else light.direction_from(np.asarray(head_world, np.float64)[None])
    return None if towards is None else light_angles(camera.rotation @ towards[0])


def rotation_centre(model) -> np.ndarray:
    """The point ``c`` of the model the fitted rotation turns about: the mean shape's
    :func:`~mifaces.model.geometry.head_centre` (model space, mm)."""
    return head_centre(model.shape_mean, model.ibug_landmarks)


def metric_distances(distances, model) -> list[tuple[int, int, float]]:
    """The capture's metric distances as ``(vertex, vertex, mm)`` on ``model``.

    ``distances`` holds :class:`mifaces.capture.Distance` values (or ``(start, end, mm)``
    tuples) between named feature points; those whose points the model lacks are skipped.
    """
    ibug = model.ibug_landmarks
    out = []
    for d in distances or ():
        start, end, mm = (d.start, d.end, d.mm) if hasattr(d, "mm") else d
        for name in (start, end):
            if name not in FEATURE_POINTS:
                raise ShapeFitError(f"metric distance names unknown feature point {name!r}; "
                                    f"known names: {sorted(FEATURE_POINTS)}")
        if FEATURE_POINTS[start] in ibug and FEATURE_POINTS[end] in ibug and mm > 0:
            out.append((ibug[FEATURE_POINTS[start]], ibug[FEATURE_POINTS[end]], float(mm)))
    return out


def feature_targets(measurement, model) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The measurement's feature points that the fit uses: ``(names, vertices, pixels)``.

    Raises
    ------
    ShapeFitError
        If the measurement has fewer than 6 feature points, names one outside
        :data:`~mifaces.model.landmarks.FEATURE_POINTS`, or one the model does not define.
    """
    points = dict(getattr(measurement, "feature_points", None) or {})
    name = getattr(measurement, "name", "?")
    unknown = [n for n in points if n not in FEATURE_POINTS]
    if unknown:
        raise ShapeFitError(f"measurement {name!r}: unknown feature point name(s) {sorted(unknown)}; "
                            f"known names: {sorted(FEATURE_POINTS)}")
    ibug = model.ibug_landmarks
    missing_on_model = [n for n in points if FEATURE_POINTS[n] not in ibug]
    usable = [n for n in points if FEATURE_POINTS[n] in ibug]
    if len(usable) < 6:
        raise ShapeFitError(
            f"measurement {name!r}: {len(usable)} usable feature point(s) {sorted(usable)}, the fit needs at "
            f"least 6 (paper sec. 4.2: 7-20)" + (f"; not defined on model {model.name!r}: "
                                                f"{sorted(missing_on_model)}" if missing_on_model else ""))
    pixels = np.array([np.asarray(points[n], np.float64).reshape(2) for n in usable])
    if not np.all(np.isfinite(pixels)):
        raise ShapeFitError(f"measurement {name!r}: non-finite feature point position(s)")
    vertices = np.array([ibug[FEATURE_POINTS[n]] for n in usable], np.int64)
    return usable, vertices, pixels


def normalised(pixels: np.ndarray) -> tuple[np.ndarray, float]:
    """Image divided by its 99th percentile (so E_I's sigma means the same for every image),
    non-finite pixels set to 0; and the percentile."""
    p = np.asarray(pixels, np.float32)
    scale = float(np.percentile(p, 99.0))
    scale = scale if scale > 0 and np.isfinite(scale) else 1.0
    return np.nan_to_num(p / scale), scale


def blurred(image: np.ndarray, sigma: float) -> np.ndarray:
    """``image`` (H, W, 3) blurred by a Gaussian of standard deviation ``sigma`` px (none below 0.05)."""
    if sigma <= 0.05:
        return image
    return ndi.gaussian_filter(image, (sigma, sigma, 0), mode="nearest")


def start_translation(model, camera, feature_vertices, feature_pixels, centre) -> np.ndarray:
    """Camera-space position (mm) of the rotation centre that places the frontal mean face on the
    feature points (paper: 'default values defining a frontal view'): depth from the spread of the
    points, x and y from their centroid."""
    lm = model.shape_mean[feature_vertices].astype(np.float64)
    lm_c = (lm - centre) @ FRONTAL.T
    px = feature_pixels
    spread_px = np.sqrt(np.mean(np.sum((px - px.mean(0)) ** 2, axis=1)))
    spread_mm = np.sqrt(np.mean(np.sum((lm_c[:, :2] - lm_c[:, :2].mean(0)) ** 2, axis=1)))
    z = camera.fy * spread_mm / max(spread_px, 1e-6)
    rays = camera.undistort(np.stack([(px[:, 0] - camera.cx) / camera.fx, (px[:, 1] - camera.cy) / camera.fy], -1))
    xy = rays.mean(0) * (z + lm_c[:, 2].mean()) - lm_c[:, :2].mean(0)
    return np.array([xy[0], xy[1], z])


def triangulated_translation(model, camera, feature_vertices, feature_pixels, centre, views) -> np.ndarray | None:
    """The start of :func:`start_translation` for a shot that other calibrated cameras saw too: the
    feature points both ``camera`` and a view see, triangulated (the midpoint of the two rays), and
    the frontal mean face moved onto their centroid; the face's depth then comes from the rays, not
    from the mean face's size. ``views``: ``(view, A, b, vertices, pixels)`` per other photograph,
    ``x_view = A x + b`` from ``camera``'s frame. None where no view shares three points."""
    own = {int(v): p for v, p in zip(feature_vertices, feature_pixels)}
    points, model_points = [], []
    for view, A, b, vertices, pixels in views:
        origin = -np.asarray(A).T @ np.asarray(b)
        for v, p in zip(vertices, pixels):
            if int(v) not in own:
                continue
            d0 = camera.pixel_rays(own[int(v)])
            d1 = np.asarray(A).T @ view.pixel_rays(p)
            (s, u), *_ = np.linalg.lstsq(np.stack([d0, -d1], axis=1), origin, rcond=None)
            points.append((s * d0 + origin + u * d1) / 2)
            model_points.append((model.shape_mean[int(v)].astype(np.float64) - centre) @ FRONTAL.T)
    if len(points) < 3:
        return None
    return np.mean(points, axis=0) - np.mean(model_points, axis=0)


def start_light(camera, translation, light_world) -> tuple[float, float, float]:
    """The calibrated lamp seen from the face at camera-space position ``translation`` (mm):
    ``(elevation, azimuth, distance)``, angles in radians as in :func:`light_direction`,
    distance in mm."""
    head = camera.to_world(translation)
    d = camera.rotation @ (light_world - head)
    return (*light_angles(d), float(np.linalg.norm(d)))


def eye_distance_px(vertices_camera, model, focal_px: float) -> float:
    """The face's size in the image: the distance between the outer eye corners (iBUG 37, 46) of
    camera-space ``vertices_camera`` (mm), in 3-D, at the eyes' depth, in px for a focal length of
    ``focal_px``. Independent of head rotation and of the face's overall scale (a model without
    those landmarks: the RMS spread of its feature points about their centroid, likewise)."""
    v = np.asarray(vertices_camera, np.float64)
    ibug = model.ibug_landmarks
    if 37 in ibug and 46 in ibug:
        a, b = v[ibug[37]], v[ibug[46]]
        return focal_px * float(np.linalg.norm(a - b)) / max(0.5 * (a[2] + b[2]), 1e-9)
    p = v[[ibug[i] for i in FEATURE_POINTS.values() if i in ibug]]
    return focal_px * float(np.sqrt(np.mean(np.sum((p - p.mean(0)) ** 2, axis=1)))) / max(p[:, 2].mean(), 1e-9)


def light_axis_angle(capture, measurement) -> float:
    """Angle (degrees) between a measurement's light and the camera's viewing axis, seen from the
    feature points' centroid at the camera's distance; 0 for a measurement without a light or with
    an unknown light without a stated guess (its estimate starts frontal)."""
    if not measurement.light:
        return 0.0
    light, cam = capture.light(measurement.light), capture.camera_of(measurement)
    fp = np.array(list(measurement.feature_points.values()))
    distance = max(float(np.linalg.norm(cam.translation)), 1.0)
    centre = cam.to_world(cam.pixel_rays(fp.mean(0)) * distance)
    towards = light.first_seen_from(centre[None])  # a guess as the fit starts from it; None: no one axis
    if towards is None:
        return 0.0
    d2 = (cam.position - centre) / np.linalg.norm(cam.position - centre)
    return math.degrees(math.acos(float(np.clip(towards[0] @ d2, -1, 1))))


def reference_measurement(capture, measurements=None) -> str:
    """Among ``measurements`` (default: all of the capture's), the one to take the starting
    texture from, or to fit a pose's shared shape on: the one whose light (point or directional)
    is closest to the camera's viewing axis and whose feature points are most left-right
    symmetric (a frontal view at frontal illumination, paper sec. 4.2)."""
    best, best_score = None, np.inf
    for m in capture.measurements if measurements is None else measurements:
        pts = m.feature_points
        asym = 0.0
        if "nose_tip" in pts and "right_eye_outer" in pts and "left_eye_outer" in pts:
            a = np.linalg.norm(np.asarray(pts["right_eye_outer"]) - pts["nose_tip"])
            b = np.linalg.norm(np.asarray(pts["left_eye_outer"]) - pts["nose_tip"])
            asym = abs(math.log(max(a, 1e-6) / max(b, 1e-6))) * 100.0
        score = light_axis_angle(capture, m) + asym
        if best is None or score < best_score:
            best, best_score = m.name, score
    return best
