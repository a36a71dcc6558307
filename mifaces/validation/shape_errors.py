"""Fitted shapes against a simulated capture's true ones, in the world frame (mm).

A fit can put the right shape at the wrong place: a face a few mm too far
from the camera looks almost the same in the photograph, yet every
reflectance sample then sits on the wrong surface. So the error is measured
several ways, over the front of the face (:func:`front_of_face`: the vertices
of the true face that look forward, from the chin up, hair left out; ears,
neck and the back of the head may stay coarse):

* ``world_mm``: the mean distance between each fitted vertex and the same
  vertex of the true face, in the world frame, without any alignment. A pose
  or depth error shows here.
* ``aligned_mm``: the same after the best rigid motion of the fitted face onto
  the true one (Kabsch): the shape's own error.
* ``depth_mm``: the mean signed offset along the camera's viewing axis
  (positive: the fit lies farther from the camera than the truth).
* ``scale_pct`` and ``scaled_mm``: the fitted face's size against the true
  one's (``s``, the ratio of their RMS distances from their centroids; in per
  cent, ``100 (s - 1)``), and the mean distance left after the true face is
  scaled by ``s`` about the camera's centre. A pinhole camera cannot tell a
  face from one ``s`` times larger and ``s`` times farther: every pixel is the
  same, and a fit that gets the size 0.1 % wrong places the face about 1.2 mm
  off in depth at 1.2 m. Where ``scaled_mm`` is far below ``world_mm``, the
  world error is that ambiguity; a face of the right size at the wrong depth
  leaves ``scaled_mm`` equal to ``world_mm`` (``docs/shape_estimation.md``).
* ``similarity_mm``: the mean distance over every vertex (the whole head) after
  the best similarity transform (rotation, translation and one scale) of the
  fitted face onto the true one: all that one camera can observe, since it
  cannot tell a face's distance from its size (:func:`similarity_error`).
* ``normal_deg``: the mean angle between the fitted and the true vertex
  normals, in the world frame: what shading sees. A face moved along its
  depth keeps it, a turned face or a bent surface does not. Vertex distances
  hide a surface that is bent by a fraction of a mm over a few mm: it shades
  wrong, as the shape refinement's displacement can (``docs/refine_shape.md``).
"""

from __future__ import annotations

import numpy as np
from skimage.transform import SimilarityTransform

from ..model.geometry import vertex_normals
from ..model.regions import REGIONS


def front_of_face(model, vertices=None) -> np.ndarray:
    """(V,) bool: vertices of the face that look forward (normal's z > 0.3 on ``vertices``, default the
    mean shape), at or above the chin (iBUG 9), outside the hair."""
    v = model.shape_mean if vertices is None else np.asarray(vertices)
    normals = model.vertex_normals(v)
    keep = (normals[:, 2] > 0.3) & (model.vertex_regions() != REGIONS["hair"])
    chin = model.ibug_landmarks.get(9)
    if chin is not None:
        keep &= v[:, 1] >= v[chin, 1]
    return keep


def rigid_alignment(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t minimising sum |R source + t - target|^2 (Kabsch)."""
    ms, mt = source.mean(axis=0), target.mean(axis=0)
    u, _, vt = np.linalg.svd((source - ms).T @ (target - mt))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, mt - rotation @ ms


def similarity_error(fitted: np.ndarray, true: np.ndarray) -> float:
    """Mean distance (mm) of ``fitted`` from ``true`` vertices after the similarity transform (rotation,
    translation, one scale) that brings them closest (Umeyama's, ``skimage``): what one camera can
    observe of a face, whose distance and size it cannot tell apart."""
    f, t = np.asarray(fitted, np.float64), np.asarray(true, np.float64)
    transform = SimilarityTransform.from_estimate(f, t)
    return float(np.linalg.norm(transform(f) - t, axis=1).mean())


def shape_errors(fitted: np.ndarray, true: np.ndarray, mask: np.ndarray, camera, triangles=None) -> dict:
    """World-frame errors of one fitted face against the true one (both (V, 3) world mm, the same
    model's vertices), over the vertices ``mask`` selects (``similarity_mm``: over every vertex, the
    whole head); ``camera`` gives the viewing axis; with the model's ``triangles``, the normals' error
    too."""
    out = {}
    if triangles is not None:
        cosine = np.sum(vertex_normals(fitted, triangles) * vertex_normals(true, triangles), axis=1)[mask]
        out["normal_deg"] = float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))).mean())
    f, t = np.asarray(fitted, np.float64)[mask], np.asarray(true, np.float64)[mask]
    rotation, translation = rigid_alignment(f, t)
    axis = np.asarray(camera.rotation, np.float64)[2]  # world direction of the camera's +z (forward)
    centre = np.asarray(camera.position, np.float64)
    scale = float(np.sqrt(np.sum((f - f.mean(axis=0)) ** 2) / np.sum((t - t.mean(axis=0)) ** 2)))  # sizes
    return {"world_mm": float(np.linalg.norm(f - t, axis=1).mean()),
            "aligned_mm": float(np.linalg.norm(f @ rotation.T + translation - t, axis=1).mean()),
            "depth_mm": float(np.mean((f - t) @ axis)),
            "scale_pct": 100.0 * (scale - 1.0),
            "scaled_mm": float(np.linalg.norm(f - centre - scale * (t - centre), axis=1).mean()),
            "similarity_mm": similarity_error(fitted, true),
            **out, "vertices": int(mask.sum())}


def capture_shape_errors(face_model, shapes: dict, true_shapes: dict, camera) -> dict:
    """:func:`shape_errors` per measurement (the true face's :func:`front_of_face`), and their
    largest and mean values under ``"summary"``."""
    out = {}
    for name, fitted in shapes.items():
        if name in true_shapes:
            mask = front_of_face(face_model, true_shapes[name] - true_shapes[name].mean(axis=0))
            out[name] = shape_errors(fitted, true_shapes[name], mask, camera, face_model.triangles)
    if out:
        out["summary"] = {f"{stat}_{key}": float(fn([e[key] for e in out.values()]))
                          for key in ("world_mm", "aligned_mm", "scaled_mm", "similarity_mm", "normal_deg")
                          for stat, fn in (("max", np.max), ("mean", np.mean))}
        out["summary"]["max_abs_depth_mm"] = float(max(abs(e["depth_mm"]) for k, e in out.items() if k != "summary"))
        out["summary"]["max_abs_scale_pct"] = float(max(abs(e["scale_pct"]) for k, e in out.items()
                                                        if k != "summary"))
    return out
