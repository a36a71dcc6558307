"""Fine geometric detail a face model's PCA cannot express.

A morphable model spans smooth, symmetric-on-average faces: a few dozen
principal components of shape. Real faces carry wrinkles, pores and
asymmetries that no combination of those components reproduces.
:func:`fine_detail` adds them to a simulated face as offsets along its
vertex normals (and, for the asymmetry, across), in the model frame
(x across the face, y up, z out of it; mm):

* wrinkles: horizontal forehead lines (sinusoidal in height above the
  eyebrows, :data:`DETAIL` ``forehead_mm`` deep, period ``forehead_period_mm``),
  crow's feet fanning out of the outer eye corners, and the nasolabial
  folds, grooves from the nose wings to the mouth corners;
* pores: independent per-vertex depth noise (the mesh's ~1.3 mm spacing is
  the finest scale it can hold);
* asymmetry: one side of the face raised and pushed out relative to the
  other, and the nose tip turned sideways, by a few mm with random signs.

The simulated photographs and the ground truth's vertices are the detailed
face; the fit uses the model, which can only approximate it. How far the
detailed face lies outside the model's span is the residual of its
least-squares projection onto the model (:func:`span_residual`).
"""

from __future__ import annotations

import numpy as np

from ..model.geometry import welded_normals
from ..model.landmarks import FEATURE_POINTS

#: Sizes of the detail (mm).
DETAIL = {"forehead_mm": 0.35, "forehead_period_mm": 9.0, "crows_feet_mm": 0.25, "fold_mm": 1.0,
          "fold_width_mm": 3.5, "pores_mm": 0.06, "asymmetry_mm": 2.0, "nose_turn_mm": 1.5}


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance in the (x, y) plane from each point to the segment a-b."""
    d = b[:2] - a[:2]
    t = np.clip(((points[:, :2] - a[:2]) @ d) / max(float(d @ d), 1e-12), 0.0, 1.0)
    return np.linalg.norm(points[:, :2] - (a[:2] + t[:, None] * d), axis=1)


def fine_detail(face_model, neutral: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Offsets (V, 3) float64, mm, model frame, to add to ``neutral`` (and
    to the face in every expression): wrinkles, pores and asymmetry as the
    module docstring describes."""
    v = np.asarray(neutral, np.float64)
    normals = face_model.vertex_normals(neutral.astype(np.float32)).astype(np.float64)
    lm = {name: np.asarray(v[face_model.ibug_landmarks[index]]) for name, index in FEATURE_POINTS.items()
          if index in face_model.ibug_landmarks}
    x, y = v[:, 0] - lm["nose_bridge"][0], v[:, 1]
    brows = np.mean([lm[n][1] for n in ("right_eyebrow_inner", "left_eyebrow_inner")])
    half_width = 0.5 * abs(lm["left_eye_outer"][0] - lm["right_eye_outer"][0])
    depth = np.zeros(len(v))
    # forehead lines: above the brows, fading out sideways and upwards
    above = y - brows - 8.0
    forehead = (above > 0) * np.exp(-(x / (1.1 * half_width)) ** 4) * np.exp(-(np.maximum(above, 0) / 45.0) ** 2)
    phase = rng.uniform(0, 2 * np.pi)
    depth -= DETAIL["forehead_mm"] * forehead * np.sin(2 * np.pi * above / DETAIL["forehead_period_mm"] + phase) ** 2
    # crow's feet: rays out of each outer eye corner, within 18 mm of it, on its outer side
    for corner, side in (("right_eye_outer", -1.0), ("left_eye_outer", 1.0)):
        c = lm[corner]
        r = np.hypot(v[:, 0] - c[0], v[:, 1] - c[1])
        angle = np.arctan2(v[:, 1] - c[1], side * (v[:, 0] - c[0]))
        outer = (side * (v[:, 0] - c[0]) > 2.0) * np.exp(-(r / 18.0) ** 2)
        depth -= DETAIL["crows_feet_mm"] * outer * np.cos(7 * angle) ** 8
    # nasolabial folds: nose wing to mouth corner
    for wing, mouth in (("right_nostril", "mouth_right"), ("left_nostril", "mouth_left")):
        a = lm[wing] + np.array([np.sign(lm[wing][0] - lm["nose_bridge"][0]) * 6.0, 0.0, 0.0])
        b = lm[mouth] + np.array([np.sign(lm[mouth][0] - lm["nose_bridge"][0]) * 4.0, -3.0, 0.0])
        depth -= DETAIL["fold_mm"] * np.exp(-(_segment_distance(v, a, b) / DETAIL["fold_width_mm"]) ** 2)
    depth += rng.normal(0.0, DETAIL["pores_mm"], len(v))
    offsets = depth[:, None] * normals
    # asymmetry: one side raised and pushed out, the nose tip turned
    side = np.tanh(x / 25.0) * rng.choice([-1.0, 1.0])
    offsets[:, 1] += 0.5 * DETAIL["asymmetry_mm"] * side
    offsets += 0.5 * DETAIL["asymmetry_mm"] * (np.maximum(side, 0))[:, None] * normals
    tip = np.exp(-np.sum((v[:, :2] - lm["nose_tip"][:2]) ** 2, axis=1) / (2 * 12.0 ** 2))
    offsets[:, 0] += DETAIL["nose_turn_mm"] * rng.choice([-1.0, 1.0]) * tip
    return offsets


def span_residual(face_model, vertices: np.ndarray) -> float:
    """RMS distance (mm) from ``vertices`` (model frame) to their least-squares
    projection onto ``face_model``'s shape space (mean + principal components):
    0 for a face the model can express exactly."""
    projected = face_model.shape(face_model.project(vertices))
    return float(np.sqrt(np.mean(np.sum((np.asarray(vertices, np.float64) - projected) ** 2, axis=1))))


def cheek_bump(face_model, neutral: np.ndarray, amplitude_mm: float = 3.5, sigma_mm: float = 8.0,
               side: str = "right") -> np.ndarray:
    """A Gaussian bump on one cheek, along the welded normals: offsets (V, 3)
    float64, mm, model frame, ``amplitude_mm · exp(-d² / 2σ²)`` with ``d`` the
    3D distance from the cheek's centre (the front-most vertex below the outer
    eye corner, halfway down to the mouth corner's height, a third of the way
    in towards the mouth corner). Outside the span of a morphable model's few
    dozen components: a test of shape refinement beyond the model
    (:mod:`mifaces.refine.shape`)."""
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    v = np.asarray(neutral, np.float64)
    eye = v[face_model.ibug_landmarks[FEATURE_POINTS[f"{side}_eye_outer"]]]
    mouth = v[face_model.ibug_landmarks[FEATURE_POINTS[f"mouth_{side}"]]]
    target = eye[:2] + np.array([(mouth[0] - eye[0]) / 3.0, (mouth[1] - eye[1]) / 2.0])
    near = np.linalg.norm(v[:, :2] - target, axis=1) < 3.0
    if not near.any():
        raise ValueError("the face has no vertex at its cheek's centre")
    centre = v[np.flatnonzero(near)[np.argmax(v[near, 2])]]
    height = amplitude_mm * np.exp(-np.sum((v - centre) ** 2, axis=1) / (2 * sigma_mm ** 2))
    return height[:, None] * welded_normals(v, face_model.triangles)
