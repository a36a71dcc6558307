"""The pixel's footprint in the fit: a photograph's pixel averages the surface over an area, and
where the surface curves inside that area (the lips, the nostrils' rims) it averages over a
spread of normals. A glossy lobe seen that way looks wider than the material's: fitted to point
evaluations, the lips' roughness came out 2–3 % high even on an ideal capture (and under 1 % at
twice the pixels; ``docs/reflectance.md``, "The lips' lobe and the pixel's footprint").

The fit therefore predicts what the pixel saw. Each sample carries the covariance of its
normal's tilt over the footprint (:func:`normal_spread`, radians², in the local frame), and the
model is averaged over five tilted normals that have that covariance (:func:`tilts`,
:func:`tilted`: the unscented transform's points), for every model alike,
inside the fit's kernels: in the region fit (:class:`~mifaces.reflectance.fit.problem.Problem`)
and in the normal step (:class:`~mifaces.reflectance.maps.observations.Observations`).

The footprint is the photograph's pixel filter (:data:`~mifaces.capture.camera.PIXEL_BLUR_STD`,
a Gaussian) and the bilinear read of :func:`~mifaces.reflectance.resampling.read_photograph` at the
sample's position (a tent whose variance per axis is f(1 - f), f the fractional pixel position).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..capture.camera import PIXEL_BLUR_STD
from ..runtime.memo import ContentCache

#: Tilted normals per sample (:func:`tilts`).
POINTS = 5
#: Texel neighbours further apart in the photograph (pixels), or whose normals differ by more
#: (radians), lie across a seam of the texture layout: no derivative is taken across them; and
#: no footprint's tilt has a standard deviation above MAX_TILT.
MAX_STEP_PX, MAX_TILT = 4.0, 0.3


def _grid_derivatives(values: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d values / d column and d values / d row on an (R, R, C) texel grid: central differences
    where both neighbours are ``valid``, one-sided where one is, 0 where neither."""
    out = []
    for axis in (1, 0):
        fwd, bwd = np.zeros_like(values), np.zeros_like(values)
        ok_f, ok_b = np.zeros(valid.shape, bool), np.zeros(valid.shape, bool)
        lead = [slice(None)] * 2
        trail = [slice(None)] * 2
        lead[axis], trail[axis] = slice(1, None), slice(None, -1)
        lead, trail = tuple(lead), tuple(trail)
        fwd[trail] = values[lead] - values[trail]
        ok_f[trail] = valid[lead] & valid[trail]
        bwd[lead] = values[lead] - values[trail]
        ok_b[lead] = valid[lead] & valid[trail]
        both = ok_f & ok_b
        d = np.where(both[..., None], 0.5 * (fwd + bwd), np.where(ok_f[..., None], fwd,
                                                                   np.where(ok_b[..., None], bwd, 0.0)))
        out.append(d)
    return out[0], out[1]


def normal_spread(xy: np.ndarray, normal: np.ndarray, tangent: np.ndarray, bitangent: np.ndarray,
                  texel: np.ndarray, resolution: int, blur_std: float = PIXEL_BLUR_STD) -> np.ndarray:
    """The covariance of the normal's tilt over each texel's pixel footprint, (M, 3): the entries
    tt, tb, bb in radians² along the texel's (tangent, bitangent).

    Parameters
    ----------
    xy : (M, 3) or (M, 2)
        The texels' projections in the photograph (pixels; pixel centres at integers).
    normal, tangent, bitangent : (M, 3)
        The texels' shading frames (world).
    texel : (M,)
        Flat texel indices on the R × R grid.
    resolution : int
        R.
    blur_std : float
        The photograph's pixel filter, a Gaussian's standard deviation in pixels.

    Returns
    -------
    (M, 3) read-only array, shared: the same inputs (by content) give it again (from a cache of the
    last :data:`SPREAD_CACHE_SIZE`; the samples of one shape are taken again for each round of the
    bounced light).
    """
    xy = np.asarray(xy, np.float64)[:, :2]
    return _spreads.get((xy, normal, tangent, bitangent, texel, resolution, blur_std),
                        lambda: _normal_spread(xy, normal, tangent, bitangent, texel, resolution, blur_std))


#: How many photographs' footprints :func:`normal_spread` keeps.
SPREAD_CACHE_SIZE = 16
_spreads = ContentCache(SPREAD_CACHE_SIZE)


def _normal_spread(xy, normal, tangent, bitangent, texel, resolution, blur_std) -> np.ndarray:
    """:func:`normal_spread`'s work, uncached."""
    m = len(texel)
    if m == 0:
        return np.zeros((0, 3))
    grid = np.zeros((resolution * resolution, 5))
    valid = np.zeros(resolution * resolution, bool)
    grid[texel, :2] = xy
    grid[texel, 2:] = normal
    valid[texel] = True
    grid, valid = grid.reshape(resolution, resolution, 5), valid.reshape(resolution, resolution)
    du, dv = (d.reshape(-1, 5)[texel] for d in _grid_derivatives(grid, valid))
    # neighbours across a seam of the texture layout, or a fold, are no neighbours on the surface
    for d in (du, dv):
        d[(np.linalg.norm(d[:, :2], axis=1) > MAX_STEP_PX) | (np.linalg.norm(d[:, 2:], axis=1) > MAX_TILT)] = 0.0
    # d(xy)/d(uv) (M, 2, 2) and the normal's tilt per texel step along the tangent and bitangent (M, 2, 2)
    j_xy = np.stack([du[:, :2], dv[:, :2]], axis=2)
    j_tilt = np.stack([np.stack([np.sum(du[:, 2:] * tangent, 1), np.sum(dv[:, 2:] * tangent, 1)], 1),
                       np.stack([np.sum(du[:, 2:] * bitangent, 1), np.sum(dv[:, 2:] * bitangent, 1)], 1)], 1)
    det = j_xy[:, 0, 0] * j_xy[:, 1, 1] - j_xy[:, 0, 1] * j_xy[:, 1, 0]
    ok = np.abs(det) > 1e-12
    inv = np.zeros_like(j_xy)
    safe = np.where(ok, det, 1.0)
    inv[:, 0, 0], inv[:, 1, 1] = j_xy[:, 1, 1] / safe, j_xy[:, 0, 0] / safe
    inv[:, 0, 1], inv[:, 1, 0] = -j_xy[:, 0, 1] / safe, -j_xy[:, 1, 0] / safe
    g = np.einsum("mij,mjk->mik", j_tilt, inv)  # tilt per pixel (M, 2, 2)
    frac = xy - np.floor(xy)
    footprint = blur_std ** 2 + frac * (1.0 - frac)  # (M, 2): the filter, then the bilinear read's tent
    cov = np.einsum("mij,mj,mkj->mik", g, footprint, g)
    cov[~ok] = 0.0
    # a tilt beyond MAX_TILT within one pixel is a crease or a silhouette the mesh does not resolve
    scale = np.minimum(1.0, MAX_TILT ** 2 / np.maximum(np.trace(cov, axis1=1, axis2=2), 1e-30))
    cov *= scale[:, None, None]
    return np.stack([cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]], axis=1)


def tilts(spread) -> list:
    """The :data:`POINTS` tilts (x, y) of the normal, along the frame's tangent and bitangent
    (radians, Dr.Jit arrays), with their weights, that stand for each sample's Gaussian ``spread``
    (tt, tb, bb; three Dr.Jit arrays): the untilted normal (weight 1/3) and ± √3 times the columns of
    the spread's Cholesky factor (1/6 each): the unscented transform with κ = 1, whose points have
    the Gaussian's covariance and fourth moments. The centre point matters: a lobe narrower than the
    footprint (the eyes' m of 0.05 under a tilt of 0.05 rad) falls between the four outer points, and
    without it their mean took the eyes' peak for a third of what it is."""
    tt, tb, bb = spread
    l11 = dr.sqrt(dr.maximum(tt, 0.0))
    l21 = dr.select(l11 > 0, tb / dr.maximum(l11, 1e-30), 0.0)
    l22 = dr.sqrt(dr.maximum(bb - l21 * l21, 0.0))
    r, zero = float(np.sqrt(3.0)), 0.0 * l11
    return [(zero, zero, 1.0 / 3.0), (r * l11, r * l21, 1.0 / 6.0), (-r * l11, -r * l21, 1.0 / 6.0),
            (zero, r * l22, 1.0 / 6.0), (zero, -r * l22, 1.0 / 6.0)]


def tilted(wi, wo, spread) -> list:
    """``wi`` and ``wo`` (Dr.Jit vectors in the local frame, z the normal) in the frames of the
    normals tilted by :func:`tilts` of ``spread``, each frame the local frame turned by the smallest
    rotation taking z onto its normal, with each one's weight w cos θl' / cos θl in what the pixel
    saw (w its weight in :func:`tilts`): the pixel sums f cos θl' over its normals, and eq. 4 divided
    by the cosine of the sample's own normal. A list of (wi', wo', weight)."""
    out = []
    for x, y, w in tilts(spread):
        n = dr.normalize(mi.Vector3f(x, y, 1.0))
        axis = mi.Vector3f(-n.y, n.x, 0.0)  # z × n: sin θ times the rotation's axis

        def turned(w):  # the inverse rotation: w cos θ - a × w + a (a·w) / (1 + cos θ)
            return w * n.z - dr.cross(axis, w) + axis * (dr.dot(axis, w) / (1.0 + n.z))

        a, b = turned(wi), turned(wo)
        out.append((a, b, w * dr.maximum(a.z, 0.0) / wi.z))
    return out


def seen_by_pixel(evaluate, wi, wo, spread):
    """What each sample's pixel saw of a BRDF: ``evaluate(wi', wo')`` summed over the normals
    tilted by :func:`tilted` of ``spread``, weighted; ``evaluate(wi, wo)`` itself where ``spread``
    is empty (points). The one average of the footprint that the region fit
    (:class:`~mifaces.reflectance.fit.problem.Problem`) and the glossy part taken out of the
    albedo map (:func:`~mifaces.reflectance.maps.diffuse.specular_reflectance_factor`) share."""
    if not spread:
        return evaluate(wi, wo)
    f = None
    for a, b, weight in tilted(wi, wo, spread):
        term = evaluate(a, b) * weight
        f = term if f is None else f + term
    return f


def spread_arrays(footprint, samples: int) -> tuple:
    """Each sample's footprint (``samples``, 3) (tt, tb, bb; :func:`normal_spread`) as the three
    Dr.Jit arrays :func:`tilts` takes; a footprint of another shape is refused, naming both."""
    if np.shape(footprint) != (samples, 3):
        raise ValueError(f"footprint must have shape ({samples}, 3), got {np.shape(footprint)}")
    return tuple(mi.Float(np.ascontiguousarray(c)) for c in np.asarray(footprint, np.float32).T)


__all__ = ["POINTS", "MAX_STEP_PX", "MAX_TILT", "normal_spread", "tilts", "tilted", "seen_by_pixel",
           "spread_arrays"]
