"""What the cameras tell of the fitted faces: each photograph's reprojection error in its own
camera, per camera, and, for a capture of one camera, how well its face's depth is known.

One camera sees a face ``s`` times larger and ``s`` times farther as the same picture: its depth
comes from what fixes the face's size, the capture's metric distances or, without them, the face
model's prior on size (``docs/shape_estimation.md``). :func:`depth_uncertainty` turns that size's
relative uncertainty into mm along the camera's axis. A second calibrated camera fixes the depth by
triangulation (``docs/capture.md``, "Several cameras").
"""

from __future__ import annotations

import numpy as np

from ..model.landmarks import FEATURE_POINTS
from .result import Weights

#: Identities drawn from the face model's prior to measure the spread of its size.
PRIOR_DRAWS = 500


def reprojection_errors(capture, shapes: dict, face_model) -> dict:
    """Per photograph with a fitted face (``shapes``: name -> world-frame vertices), the RMS distance
    (px) of its feature points from the face's landmarks projected through the photograph's own
    camera; and per camera (``"cameras"``: id -> mean over its photographs, and their count)."""
    ibug = face_model.ibug_landmarks
    per_photo, per_camera = {}, {}
    for m in capture.measurements:
        if m.name not in shapes or not m.feature_points:
            continue
        names = [n for n in m.feature_points if FEATURE_POINTS[n] in ibug]
        if not names:
            continue
        points = np.asarray(shapes[m.name], np.float64)[[ibug[FEATURE_POINTS[n]] for n in names]]
        clicked = np.array([m.feature_points[n] for n in names], np.float64)
        error = capture.camera_of(m).project(points) - clicked
        per_photo[m.name] = float(np.sqrt(np.mean(np.sum(error ** 2, axis=1))))
        per_camera.setdefault(m.camera, []).append(per_photo[m.name])
    return {"photographs": per_photo,
            "cameras": {camera: {"reprojection_px": float(np.mean(values)), "photographs": len(values)}
                        for camera, values in per_camera.items()}}


def relative_size_sd(capture, face_model, seed: int = 0) -> tuple[float, str]:
    """The relative standard deviation of the face's size as the fit knows it, and what fixes it:
    the capture's metric distances (:attr:`Weights.distance_sigma` over their mean length, over the
    root of their number), or, without them, the spread of the size (RMS distance of the landmarks
    from their centroid) over :data:`PRIOR_DRAWS` identities drawn from the face model's prior."""
    if capture.distances:
        lengths = np.array([d.mm for d in capture.distances])
        return float(Weights().distance_sigma / lengths.mean() / np.sqrt(len(lengths))), "metric distances"
    ibug = face_model.ibug_landmarks
    vertices = np.array(sorted({ibug[i] for i in FEATURE_POINTS.values() if i in ibug}))
    rows = (3 * vertices[:, None] + np.arange(3)).ravel()
    coefficients = np.random.default_rng(seed).standard_normal((face_model.shape_dim, PRIOR_DRAWS))
    drawn = face_model.shape_mean[vertices].astype(np.float64).ravel()[:, None] + (
        face_model.shape_basis[rows].astype(np.float64) * np.sqrt(face_model.shape_variance)) @ coefficients
    drawn = drawn.T.reshape(PRIOR_DRAWS, len(vertices), 3)
    sizes = np.sqrt(np.mean(np.sum((drawn - drawn.mean(axis=1, keepdims=True)) ** 2, axis=2), axis=1))
    return float(sizes.std() / sizes.mean()), "the face model's prior on size"


def depth_uncertainty(capture, shapes: dict, face_model) -> dict:
    """For a capture of one camera: the standard deviation (mm) of each fitted face's depth along the
    camera's axis that the size's uncertainty (:func:`relative_size_sd`) leaves, at the face's
    distance from the camera; with the reason. Empty for a capture of several cameras."""
    if capture.several_cameras or not shapes:
        return {}
    relative, source = relative_size_sd(capture, face_model)
    distance = float(np.mean([np.linalg.norm(np.mean(v, axis=0) - capture.camera.position) for v in shapes.values()]))
    return {"depth_sd_mm": relative * distance, "relative_size_sd": relative, "size_from": source,
            "camera_distance_mm": distance}
