"""Fixed sets of directions over the hemisphere (local frame, z the normal),
on which BRDFs are compared and fitted to one another: the hemispherical mean
of the BRDF error (:mod:`mifaces.validation.brdf_error`) and the glTF lobe
nearest a model's (:func:`mifaces.brdf.gltf_lobe.nearest_lobe`)."""

from __future__ import annotations

import mitsuba as mi
import numpy as np


def hemisphere_grid(n: int) -> np.ndarray:
    """n² unit directions (local frame, z the normal), one per cell of an n x n
    grid of the unit square mapped by Mitsuba's cosine-weighted hemisphere
    warp (Shirley–Chiu concentric map): stratified, each with the same
    share of the projected solid angle."""
    u = (np.arange(n) + 0.5) / n
    x, y = np.meshgrid(u, u)
    d = mi.warp.square_to_cosine_hemisphere(mi.Point2f(x.ravel(), y.ravel()))
    return np.stack([np.asarray(d[i], np.float64) for i in range(3)], axis=1)


def hemisphere_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every (ωi, ωo) pair of :func:`hemisphere_grid` ``(n)``: two (n⁴, 3) arrays."""
    d = hemisphere_grid(n)
    i, o = np.meshgrid(np.arange(len(d)), np.arange(len(d)), indexing="ij")
    return d[i.ravel()], d[o.ravel()]


__all__ = ["hemisphere_grid", "hemisphere_pairs"]
