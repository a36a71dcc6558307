"""Differential geometry of triangle meshes: vertex normals and tangent frames; rotations,
and vertices turned by them.

Conventions, held everywhere in :mod:`mifaces.model`: positions in model
space (millimetres for the shipped models, y up, the face looking along +z),
triangles counter-clockwise seen from outside, so the right-handed face
normal ``(p1 - p0) x (p2 - p0)`` points out of the head. Texture
coordinates ``(u, v)`` follow Mitsuba's convention: ``v = 0`` is the first
(top) row of a texture image.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def face_normals(vertices: np.ndarray, triangles: np.ndarray, normalize: bool = True) -> np.ndarray:
    """Normals of the triangles, ``(p1 - p0) x (p2 - p0)``.

    Parameters
    ----------
    vertices : (N, 3) array
    triangles : (T, 3) int array
    normalize : bool
        If False, return the cross products, whose length is twice the
        triangle's area (the weights of :func:`vertex_normals`).

    Returns
    -------
    (T, 3) float array
    """
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles)
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    if normalize:
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    return n


def _scatter_add(index: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """Sum (M, C) ``values`` into ``count`` rows by ``index`` (vectorised)."""
    return np.stack([np.bincount(index, weights=values[:, c], minlength=count)
                     for c in range(values.shape[1])], axis=1)


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit vertex normals, the area-weighted mean of the adjacent face normals.

    This is the weighting Mitsuba's ``Mesh.recompute_vertex_normals`` uses up to
    the angle factor, so the two agree closely on smooth meshes.

    Returns
    -------
    (N, 3) float32 array
        Unit vectors pointing out of the head; zero for unreferenced vertices.
    """
    vertices = np.asarray(vertices)
    t = np.asarray(triangles).astype(np.int64)
    fn = face_normals(vertices, t, normalize=False)
    n = _scatter_add(t.ravel(), np.repeat(fn, 3, axis=0), len(vertices))
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.maximum(length, 1e-30), 0.0).astype(np.float32)


def welded_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit vertex normals (V, 3) float64 of ``vertices`` with a mesh's seam
    copies (vertices at identical positions, split at texture seams) welded:
    every copy gets the normal of the whole neighbourhood, so that offsets
    along them keep the copies together."""
    v = np.asarray(vertices, np.float64)
    _, first, inverse = np.unique(v, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    normals = vertex_normals(v[first], inverse[np.asarray(triangles)]).astype(np.float64)
    return normals[inverse]


def tangent_frames(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-vertex orthonormal shading frames aligned with the texture parameterization.

    The tangent follows the direction of increasing ``u`` on the surface
    (``dp/du``, accumulated over the adjacent triangles as in Lengyel's method),
    made orthogonal to the vertex normal by Gram-Schmidt; the bitangent is
    ``normal x tangent``, so ``(tangent, bitangent, normal)`` is right-handed.
    This is the local frame in which reflectance samples give light and view
    directions (paper section 4.3).

    Returns
    -------
    tangent, bitangent, normal : (N, 3) float32 arrays
    """
    p = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles).astype(np.int64)
    uv = np.asarray(uv, dtype=np.float64)
    normal = vertex_normals(p, t).astype(np.float64)
    e1, e2 = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
    d1, d2 = uv[t[:, 1]] - uv[t[:, 0]], uv[t[:, 2]] - uv[t[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    # dp/du = (e1 dv2 - e2 dv1) / det; weighting by |det| * sign keeps flipped
    # or degenerate uv triangles from dominating.
    dpdu = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * np.sign(det)[:, None]
    tangent = _scatter_add(t.ravel(), np.repeat(dpdu, 3, axis=0), len(p))
    tangent -= normal * np.sum(tangent * normal, axis=1, keepdims=True)
    length = np.linalg.norm(tangent, axis=1, keepdims=True)
    # Where dp/du vanishes (unreferenced or degenerate), use any perpendicular.
    fallback = np.cross(normal, np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    fallback = np.cross(fallback, normal)
    tangent = np.where(length > 1e-12, tangent / np.maximum(length, 1e-30), fallback)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-30)
    bitangent = np.cross(normal, tangent)
    return tangent.astype(np.float32), bitangent.astype(np.float32), normal.astype(np.float32)


def rotation_matrix(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """R = R_y(yaw) R_x(pitch) R_z(roll), angles in degrees (world y up, face along +z)."""
    y, p, r = np.radians([yaw, pitch, roll])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    rz = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])
    return ry @ rx @ rz


def rotation_about(axis: np.ndarray, degrees: float) -> np.ndarray:
    """The rotation (3x3) by ``degrees`` about the unit ``axis``, right-handed (a rotation vector
    ``radians(degrees) * axis``)."""
    return Rotation.from_rotvec(np.radians(degrees) * np.asarray(axis, np.float64)).as_matrix()


def turned(vertices: np.ndarray, rotation: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``vertices`` (V, 3) turned by ``rotation`` (3x3) about the point ``centre`` (same frame, mm):
    ``(v - centre) R^T + centre``, float64."""
    return (np.asarray(vertices, np.float64) - centre) @ np.asarray(rotation).T + centre


def head_centre(vertices: np.ndarray, landmarks: dict[int, int] | None = None) -> np.ndarray:
    """The centre a head turns about and a camera frames: the centre of the bounding box of the
    vertices at or above the chin (iBUG landmark 9), so that a neck does not pull it down; of all
    vertices for a model without that landmark. Model or world space, mm."""
    v = np.asarray(vertices, dtype=np.float64)
    if landmarks and 9 in landmarks:
        above = v[v[:, 1] >= v[int(landmarks[9]), 1]]
        v = above if len(above) else v
    return 0.5 * (v.min(axis=0) + v.max(axis=0))


def grid_triangles(rows: int, cols: int) -> np.ndarray:
    """Two triangles per cell of a ``rows`` x ``cols`` vertex grid (row-major vertex order),
    counter-clockwise seen from the side the grid's normal ``d(col) x d(row)`` points to... seen
    with rows going down and columns to the right, as an image: ``(a, c, b)`` and ``(b, c, d)``."""
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (i * cols + j).ravel()
    b, c, d = a + 1, a + cols, a + cols + 1  # right, below, below-right
    return np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)]).astype(np.int32)


def camera_frame_direction(azimuth: float, elevation: float) -> np.ndarray:
    """:meth:`mifaces.capture.Camera.direction` in the camera frame (OpenCV: x right, y down,
    z forward, so towards the camera is -z)."""
    az, el = np.radians(azimuth), np.radians(elevation)
    return np.array([-np.cos(el) * np.sin(az), -np.sin(el), -np.cos(el) * np.cos(az)])
