"""The BRDF error of a fitted region against the ground truth's, over the
hemisphere: the ``brdf_rmse`` of :meth:`mifaces.validation.validator.Validator.validate`.

The BRDF error over the hemisphere, for any truth that
:func:`mifaces.render.region_bsdf` builds (the four plugins, Mitsuba's
built-ins, spatially varying maps). Truth and fit are loaded as Mitsuba
BSDFs and evaluated by their ``eval``, which returns F = f(ωi, ωo) cos θo,
on every pair of a fixed set of directions (:func:`mifaces.brdf.hemisphere.hemisphere_grid`:
:data:`GRID` ² directions, stratified and cosine-weighted, so that a
sample mean is a cosine-weighted hemispherical mean) at
:data:`UV_SAMPLES` texels of the region (where the truth varies over
the face). The diffuse reflectance is the region's mean albedo, the
truth's for the truth and the fit's for the fit, so that a wrong albedo
level counts but texel noise does not::

    brdf_rmse = sqrt( Σ (F_fit − F_true)² / Σ F_true² )

summed over direction pairs, texels and RGB: the RMSE of f cos θo
relative to the truth's RMS (0 for a perfect fit, 1 for a fit that
returns nothing; None for a truth whose ``eval`` is zero, a delta BSDF).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..brdf.hemisphere import hemisphere_grid
from ..brdf.parameter import rgb
from ..render import region_bsdf

#: Directions per axis of the hemisphere grid: GRID² directions, GRID⁴ (ωi, ωo) pairs.
GRID = 12
#: Texels per region at which the BRDFs are compared.
UV_SAMPLES = 8


def eval_bsdf(bsdf: dict, uv: np.ndarray, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """f(ωi, ωo) cos θo of a Mitsuba BSDF dict (``mi.load_dict``'s layout) at
    texture coordinates ``uv`` (N, 2) and local directions ``wi``, ``wo``
    (N, 3, z the normal): ``BSDF.eval`` in one kernel. Returns (N, 3)."""
    loaded = mi.load_dict(bsdf)
    n = len(uv)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    normal = mi.Normal3f(0.0, 0.0, 1.0)
    si.n = normal
    si.sh_frame = mi.Frame3f(normal)
    si.uv = mi.Point2f(*(np.ascontiguousarray(uv[:, k], np.float32) for k in range(2)))
    si.wi = mi.Vector3f(*(np.ascontiguousarray(wi[:, k], np.float32) for k in range(3)))
    value = loaded.eval(mi.BSDFContext(), si, mi.Vector3f(*(np.ascontiguousarray(wo[:, k], np.float32)
                                                            for k in range(3))))
    return np.stack([np.asarray(value[c], np.float64) for c in range(3)], axis=1)


def region_texels(region_map: np.ndarray, label: int, count: int = UV_SAMPLES, seed: int = 0) -> np.ndarray:
    """(k, 2) texture coordinates of up to ``count`` texel centres of region
    ``label`` (row 0 at v = 0), drawn without replacement by a fixed seed."""
    rows, cols = np.nonzero(region_map == label)
    if rows.size == 0:
        return np.zeros((0, 2))
    r = region_map.shape[0]
    pick = np.random.default_rng(seed).choice(rows.size, min(count, rows.size), replace=False)
    return np.stack([(cols[pick] + 0.5) / r, (rows[pick] + 0.5) / r], axis=1)


def brdf_rmse(truth: dict, fit: dict, region: str, true_albedo, fit_albedo, uv: np.ndarray,
              grid: int = GRID, truth_maps: dict | None = None, scale: float = 1.0) -> float | None:
    """The relative BRDF error of one region (module docstring): truth and fit
    (``brdf.json`` documents) at texture coordinates ``uv`` (k, 2), with the
    diffuse reflectances ``true_albedo`` and ``fit_albedo`` (RGB). None where
    the truth's ``eval`` is zero everywhere (a delta BSDF, such as the smooth
    boundary of a subsurface truth). ``truth_maps``: a spatially varying
    truth's parameter textures (:func:`mifaces.studio.varying.map_textures`),
    read at ``uv``. ``scale`` multiplies the fit's BRDF (a relative estimate's, in the truth's
    units)."""
    d = hemisphere_grid(grid)
    i, o = np.meshgrid(np.arange(len(d)), np.arange(len(d)), indexing="ij")
    pairs = i.size
    wi, wo = np.tile(d[i.ravel()], (len(uv), 1)), np.tile(d[o.ravel()], (len(uv), 1))
    at = np.repeat(uv, pairs, axis=0)
    f_true = eval_bsdf(region_bsdf(truth, region, rgb(true_albedo), maps=truth_maps), at, wi, wo)
    f_fit = scale * eval_bsdf(region_bsdf(fit, region, rgb(fit_albedo)), at, wi, wo)
    energy = float(np.sum(f_true ** 2))
    if not energy > 0 or not np.isfinite(energy):
        return None  # a truth without a finite BRDF (a smooth boundary over a scattering medium): no BRDF error
    return float(np.sqrt(np.sum((f_fit - f_true) ** 2) / energy))


__all__ = ["GRID", "UV_SAMPLES", "eval_bsdf", "region_texels", "brdf_rmse"]
