"""The common parameterization: rasterizing a mesh into texture space.

Texture space is the unit square of ``(u, v)`` texture coordinates, sampled
by an image of ``height x width`` texels; texel ``(row, col)`` has its centre
at ``u = (col + 0.5) / width``, ``v = (row + 0.5) / height`` (``v = 0`` is
the top row, Mitsuba's convention). Rasterizing tells, for every texel, which
triangle of the face covers it and where (barycentric coordinates): the
correspondence that carries each image into the common domain (paper
section 4.2, 4.3) and that gives every region of the region map its
triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi

from ..runtime.memo import ContentCache
from .geometry import tangent_frames


@dataclass(frozen=True)
class TextureRaster:
    """Which triangle covers each texel of a texture-space image.

    Attributes
    ----------
    triangle : (H, W) int32
        Index of the covering triangle, -1 where none covers the texel.
    barycentric : (H, W, 3) float32
        Barycentric coordinates of the texel centre in that triangle (zero
        where uncovered).
    count : (H, W) int32
        How many triangles cover the texel centre: 1 inside a face whose
        parameterization is injective, more where triangles overlap in
        texture space.
    """

    triangle: np.ndarray
    barycentric: np.ndarray
    count: np.ndarray

    @property
    def covered(self) -> np.ndarray:
        """(H, W) bool: texels that some triangle covers."""
        return self.count > 0


#: How many rasterizations :func:`rasterize` keeps (the pipeline asks for the same few again and again:
#: every render's region textures, every set of samples).
RASTER_CACHE_SIZE = 8
_rasters = ContentCache(RASTER_CACHE_SIZE)


def rasterize(uv: np.ndarray, triangles: np.ndarray, shape: tuple[int, int], chunk: int = 4_000_000
              ) -> TextureRaster:
    """Rasterize the triangles of a mesh in texture space.

    The result is read-only and shared: the same ``uv``, ``triangles`` and ``shape`` (by content) give
    the same object, from a cache of the last :data:`RASTER_CACHE_SIZE`.

    A texel belongs to a triangle when its centre lies inside the triangle or
    on an edge shared in the top-left sense (the half-open rule of GPU
    rasterizers), so that two triangles meeting along an edge never both
    claim a texel on it and ``count`` counts true overlaps only.

    Parameters
    ----------
    uv : (N, 2) array
        Per-vertex texture coordinates.
    triangles : (T, 3) int array
        Vertex indices; both windings in texture space are accepted.
    shape : (int, int)
        ``(height, width)`` of the texture image.
    chunk : int
        Number of (triangle, texel) candidate pairs processed at once (memory).

    Returns
    -------
    TextureRaster
    """
    height, width = int(shape[0]), int(shape[1])
    if height < 1 or width < 1:
        raise ValueError(f"shape must be two positive ints (height, width), got {shape}")
    uv = np.asarray(uv, dtype=np.float64)
    tri = np.asarray(triangles).astype(np.int64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (N, 2), got {uv.shape}")
    return _rasters.get((uv, tri, (height, width)), lambda: _rasterize(uv, tri, height, width, chunk))


def _rasterize(uv: np.ndarray, tri: np.ndarray, height: int, width: int, chunk: int) -> TextureRaster:
    """:func:`rasterize`'s work, uncached."""
    # Texel-centre coordinates: x = u * W - 0.5, y = v * H - 0.5.
    px = uv[:, 0] * width - 0.5
    py = uv[:, 1] * height - 0.5
    x = px[tri]
    y = py[tri]
    area = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    keep = np.abs(area) > 1e-12
    # Orient every triangle counter-clockwise in (x, y) for the edge tests.
    flip = area < 0
    x[flip] = x[flip][:, [0, 2, 1]]
    y[flip] = y[flip][:, [0, 2, 1]]
    area = np.abs(area)
    x0 = np.clip(np.ceil(x.min(axis=1)), 0, width - 1).astype(np.int64)
    x1 = np.clip(np.floor(x.max(axis=1)), -1, width - 1).astype(np.int64)
    y0 = np.clip(np.ceil(y.min(axis=1)), 0, height - 1).astype(np.int64)
    y1 = np.clip(np.floor(y.max(axis=1)), -1, height - 1).astype(np.int64)
    nx = np.maximum(x1 - x0 + 1, 0)
    ny = np.maximum(y1 - y0 + 1, 0)
    n = np.where(keep, nx * ny, 0)

    triangle = np.full(height * width, -1, dtype=np.int32)
    bary = np.zeros((height * width, 3), dtype=np.float32)
    count = np.zeros(height * width, dtype=np.int64)
    # Split the triangles so that each batch has about `chunk` candidates.
    ends = np.cumsum(n)
    start_tri = 0
    while start_tri < len(tri):
        stop = int(np.searchsorted(ends, (ends[start_tri - 1] if start_tri else 0) + chunk, side="right"))
        stop = max(stop, start_tri + 1)
        sel = np.arange(start_tri, min(stop, len(tri)))
        start_tri = min(stop, len(tri))
        ns = n[sel]
        if ns.sum() == 0:
            continue
        t_id = np.repeat(sel, ns)
        offset = np.arange(ns.sum()) - np.repeat(np.cumsum(ns) - ns, ns)
        cx = x0[t_id] + offset % nx[t_id]
        cy = y0[t_id] + offset // nx[t_id]
        tx, ty = x[t_id], y[t_id]
        w = np.empty((len(t_id), 3))
        inside = np.ones(len(t_id), dtype=bool)
        for k in range(3):  # edge opposite vertex k: from a to b
            a, b = (k + 1) % 3, (k + 2) % 3
            ex, ey = tx[:, b] - tx[:, a], ty[:, b] - ty[:, a]
            e = ex * (cy - ty[:, a]) - ey * (cx - tx[:, a])
            # Top-left rule (y down, counter-clockwise in x-right/y-down means
            # positive e inside): include the edge only for top or left edges.
            top_left = (ey < 0) | ((ey == 0) & (ex > 0))
            inside &= (e > 0) | ((e == 0) & top_left)
            w[:, k] = e
        w /= area[t_id][:, None]
        w[flip[t_id]] = w[flip[t_id]][:, [0, 2, 1]]  # back to the mesh's vertex order
        texel = cy[inside] * width + cx[inside]
        np.add.at(count, texel, 1)
        triangle[texel] = t_id[inside]
        bary[texel] = w[inside]
    return TextureRaster(triangle.reshape(height, width), bary.reshape(height, width, 3),
                         count.reshape(height, width).astype(np.int32))


def bake(uv: np.ndarray, triangles: np.ndarray, values: np.ndarray, size: int,
         raster: TextureRaster | None = None) -> np.ndarray:
    """Per-vertex ``values`` (N, C) interpolated over the triangles into a ``size`` x ``size`` texture
    (float64, (size, size, C)); texels no triangle covers take the nearest covered texel's value, so
    that bilinear lookups at an island's border never see a gap. ``raster``: the mesh's
    :func:`rasterize` at that size, if at hand."""
    raster = rasterize(uv, triangles, (size, size)) if raster is None else raster
    covered = raster.covered
    values = np.asarray(values, np.float64)
    tri = np.asarray(triangles)[raster.triangle[covered]]
    image = np.zeros((size, size, values.shape[1]))
    image[covered] = np.einsum("nk,nkc->nc", raster.barycentric[covered], values[tri])
    _, (rows, cols) = ndi.distance_transform_edt(~covered, return_indices=True)
    return image[rows, cols]
@dataclass
class TexelGeometry:
    """Surface point and local frame of every covered texel of one mesh.

    ``texel`` are flat indices; ``position`` etc. are (M, 3) in the mesh's
    frame (world, mm); (tangent, bitangent, normal) is right-handed."""

    texel: np.ndarray
    position: np.ndarray
    tangent: np.ndarray
    bitangent: np.ndarray
    normal: np.ndarray


def texel_geometry(vertices, triangles, uv, raster) -> TexelGeometry:
    """Interpolate positions and the per-vertex shading frames of
    :func:`mifaces.model.geometry.tangent_frames` at the texel centres that
    ``raster`` (:func:`mifaces.model.texture_space.rasterize`) finds."""
    vertices = np.asarray(vertices, np.float64)
    triangles = np.asarray(triangles, np.int64)
    tangent, _, normal = (np.asarray(a, np.float64) for a in tangent_frames(vertices, triangles, uv))
    texel = np.flatnonzero(raster.triangle.ravel() >= 0)
    tri = triangles[raster.triangle.ravel()[texel]]
    bary = raster.barycentric.reshape(-1, 3)[texel].astype(np.float64)

    def interpolate(a):
        return np.einsum("mk,mkc->mc", bary, a[tri])

    n = interpolate(normal)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    t = interpolate(tangent)
    t -= n * np.sum(t * n, axis=1, keepdims=True)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-30)
    return TexelGeometry(texel=texel.astype(np.int32), position=interpolate(vertices), tangent=t,
                         bitangent=np.cross(n, t), normal=n)


