"""Per-texel specular maps, shrunk towards the region's fit (beyond the paper).

Real skin is not one gloss per region (pores, an oily T-zone). With each
region's glossy lobe g = π f_s(l̂, v̂; θ_R) fixed in shape, a texel's samples
are modelled as

    r_s = ρ_d + k g_s,

with its own diffuse albedo ρ_d (per channel) and a scale k of the region's
specular reflectance (the texel's ρ_s is k ρ_s,R; k = 1 is the region). The
weighted least squares (w = 1/σ², eq. 10) for one texel, ρ_d eliminated, is

    k̂ = Σ_c Σ_s w (r - r̄)(g - ḡ) / S,   S = Σ_c Σ_s w (g - ḡ)²,

with bars the texel's weighted means: only the variation of g over the
texel's samples (its highlight seen or not) tells k. A texel whose samples
all see the same g says nothing, and one seen twice says little; so, as for
the albedo (:mod:`mifaces.reflectance.maps.diffuse`), the texel scales of a region
are taken as drawn around 1 with variance τ², and k̂ as k plus noise of
variance s₀²/S: the posterior mean is

    k = (S k̂ + λ) / (S + λ),   λ = s₀² / τ²,

with s₀² the residual variance of the samples about their texel's fit and τ²
the scatter of k̂ beyond that noise (empirical Bayes, per region:
:func:`mifaces.reflectance.maps.shrinkage.empirical_bayes`). A texel
moves away from its region only as far as its samples justify. Roughness
stays the region's: one texel's few samples rarely pin a lobe's width.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..samples import ReflectanceSamples
from .diffuse import specular_reflectance_factor
from .shrinkage import empirical_bayes

#: Texels with fewer samples keep the region's specular reflectance.
MIN_SAMPLES = 3


@dataclass
class SpecularMap:
    """Per-texel specular reflectance.

    Attributes
    ----------
    scale : ndarray (R, R)
        k per texel (1: the region's ρ_s; also where not estimated).
    specular : ndarray (R, R, 3)
        ρ_s per texel, k times the region's (0 outside the face's regions).
    information : ndarray (R, R)
        S of the module docstring (0: not estimated).
    shrinkage : dict
        Region label -> λ.
    """

    scale: np.ndarray
    specular: np.ndarray
    information: np.ndarray
    shrinkage: dict


def refine_specular(model, params_by_region: dict[int, dict], samples: ReflectanceSamples,
                    region_map: np.ndarray) -> SpecularMap:
    """k per texel by shrunk least squares (module docstring).

    Parameters
    ----------
    model : BRDFModel or str
        A model with a ``specular_reflectance`` parameter.
    params_by_region : dict
        Region label -> fitted parameters (``RegionFit.params``).
    samples : ReflectanceSamples
        The samples, with their region labels (``label``).
    region_map : ndarray (R, R)

    Returns
    -------
    SpecularMap
    """
    size = np.asarray(region_map).size
    texel, region = np.asarray(samples.texel), samples.labels()
    g = specular_reflectance_factor(model, params_by_region, samples.light, samples.view, region,
                                    samples.footprint)
    r = np.asarray(samples.reflectance, np.float64)
    w = 1.0 / np.square(np.asarray(samples.sigma, np.float64))
    total = np.bincount(texel, weights=w, minlength=size)
    safe = np.maximum(total, 1e-300)
    mean_r = np.stack([np.bincount(texel, weights=w * r[:, c], minlength=size) for c in range(3)], 1) / safe[:, None]
    mean_g = np.stack([np.bincount(texel, weights=w * g[:, c], minlength=size) for c in range(3)], 1) / safe[:, None]
    dr, dg = r - mean_r[texel], g - mean_g[texel]
    information = np.bincount(texel, weights=w * np.sum(dg * dg, axis=1), minlength=size)
    cross = np.bincount(texel, weights=w * np.sum(dr * dg, axis=1), minlength=size)
    counts = np.bincount(texel, minlength=size)
    estimated = (counts >= MIN_SAMPLES) & (information > 0)
    k_hat = np.where(estimated, cross / np.maximum(information, 1e-300), 1.0)
    residual = dr - k_hat[texel, None] * dg
    texel_region = np.zeros(size, region.dtype)
    texel_region[texel] = region
    scale, lam = np.ones(size), {}
    for label in np.unique(region):
        t = np.flatnonzero(estimated & (texel_region == label))
        in_region = (region == label) & estimated[texel]
        dof = int(np.sum(3 * counts[t] - 4))  # three channels per sample; ρ_d (3) and k per texel
        if len(t) < 2 or dof < 2:
            continue
        squares = np.sum(w[in_region, None] * np.square(residual[in_region]))
        lam[int(label)] = float(empirical_bayes(squares, dof, k_hat[t], information[t], 1e-6)[0])
        scale[t] = (information[t] * k_hat[t] + lam[int(label)]) / (information[t] + lam[int(label)])
    scale = np.maximum(scale, 0.0)
    specular = np.zeros((size, 3))
    labels = np.asarray(region_map).ravel()
    for label, params in params_by_region.items():
        on = labels == label
        specular[on] = scale[on, None] * np.broadcast_to(np.asarray(params["specular_reflectance"], np.float64), 3)
    side = np.asarray(region_map).shape[0]
    return SpecularMap(scale=scale.reshape(side, side).astype(np.float32),
                       specular=specular.reshape(side, side, 3).astype(np.float32),
                       information=np.where(estimated, information, 0.0).reshape(side, side).astype(np.float32),
                       shrinkage=lam)


__all__ = ["MIN_SAMPLES", "SpecularMap", "refine_specular"]
