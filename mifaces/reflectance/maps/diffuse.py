"""Per-texel refinement of the diffuse albedo (paper sec. 5.3).

With each region's glossy part fixed at its fitted value, the model predicts
r̂ = ρ_d + π f_s(l̂, v̂) for a sample (r is scaled so a white Lambertian target
is 1, so the Lambertian term ρ_d/π contributes ρ_d). Minimising eq. 8 over
the samples of one texel alone is then linear in ρ_d, with the closed form

    ρ_d(texel) = Σ_s w_s (r_s - π f_s) / Σ_s w_s,   w_s = 1/σ_s²,

computed per colour channel for all texels at once. Texels without samples
take the local mean of their region's sampled texels (:data:`FILL_TEXELS`:
the band along a region border whose samples were dropped), else their
region's fitted albedo.

**Shrinkage** (on by default; not in the paper). A texel seen once, at a
grazing angle, gets an albedo as noisy as that one sample. Treating the
texel albedos of a region as drawn around the region's albedo ρ_R with
variance τ², and a sample's residual x_s = r_s - π f_s as the texel's albedo
plus noise of variance s₀² σ_s², the posterior mean is

    ρ_d(texel) = (Σ_s w_s x_s + λ ρ_R) / (Σ_s w_s + λ),   λ = s₀² / τ²,

with s₀² estimated from the scatter of the samples within texels and τ² from
the scatter of the texel means beyond that noise (empirical Bayes, per region
and channel: :func:`mifaces.reflectance.maps.shrinkage.empirical_bayes`).
Well-sampled texels keep their own value (Σ w ≫ λ); with noise-free samples
s₀ = 0 and the closed form above is unchanged.

**Posterior standard deviation** (:attr:`DiffuseMap.std`). Under the same
model the texel's posterior variance is

    s₀² / (Σ_s w_s + λ)

(the prior's precision 1/τ² plus the samples' Σ w_s / s₀²); without
shrinkage, s₀² / Σ_s w_s. A texel without samples has its region's spread τ;
a region whose noise cannot be estimated (fewer than two texels with two
samples) has NaN; texels outside the face 0. It leaves out the uncertainty of
the region's glossy part and of ρ_R, which are shared by all texels of a
region (:attr:`mifaces.reflectance.fit.region_fit.RegionFit.uncertainty`).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np
import scipy.ndimage as ndi

from ... import brdf as brdf_models
from ..footprint import seen_by_pixel, spread_arrays
from ..samples import ReflectanceSamples
from .shrinkage import empirical_bayes


@dataclass
class DiffuseMap:
    """Refined diffuse albedo in texture space.

    Attributes
    ----------
    albedo : ndarray (R, R, 3)
        ρ_d per texel, row 0 at v = 0.
    weight : ndarray (R, R)
        Σ 1/σ² of the samples behind each texel (0: filled from the region).
    samples : ndarray (R, R)
        Number of samples per texel.
    std : ndarray (R, R, 3) or None
        Posterior standard deviation of ρ_d per texel (module docstring);
        None where it is not known (an albedo refined by rendering).
    shrinkage : dict or None
        Region label -> λ = s₀²/τ² per channel (3,), the prior weight each
        texel's albedo was shrunk with (0: none); None where not known.
    """

    albedo: np.ndarray
    weight: np.ndarray
    samples: np.ndarray
    std: np.ndarray | None = None
    shrinkage: dict | None = None


@dataclass
class AlbedoOffsets:
    """Per-texel albedo offsets a region fit's reflectance was corrected by
    (``fit_brdf(..., options=FitOptions(albedo_rounds=k))``), with what their uncertainty needs.

    Each offset o_i = a_t - ā is its texel t's refined albedo (the posterior mean
    of the module docstring, shrunk with λ) less its region's mean over the
    samples: a function of the samples of texel t and of the glossy fit.
    :func:`mifaces.reflectance.fit.offset_uncertainty.offset_sums` uses that to make the
    intervals of the fit re-estimate the offsets when a tile is left out.

    Attributes
    ----------
    offsets : ndarray (N, 3)
        o_i, subtracted from the reflectance (:func:`albedo_offsets`).
    texel : ndarray (N,)
        Flat texel index of each sample.
    shrinkage : ndarray (N, 3)
        λ of each sample's region per channel (:attr:`DiffuseMap.shrinkage`; 0: none).
    """

    offsets: np.ndarray
    texel: np.ndarray
    shrinkage: np.ndarray

    def __getitem__(self, mask) -> "AlbedoOffsets":
        """The offsets of the samples ``mask`` selects."""
        return AlbedoOffsets(self.offsets[mask], self.texel[mask], self.shrinkage[mask])

    @classmethod
    def of(cls, diffuse: DiffuseMap, texel, label) -> "AlbedoOffsets":
        """The offsets of ``diffuse``'s texel albedos for samples at ``texel`` of region ``label``."""
        texel, label = np.asarray(texel), np.asarray(label)
        shrinkage = np.zeros((len(texel), 3))
        for lab, lam in (diffuse.shrinkage or {}).items():
            shrinkage[label == lab] = lam
        return cls(albedo_offsets(diffuse.albedo.reshape(-1, 3), texel, label), texel, shrinkage)


def specular_reflectance_factor(model, params_by_region: dict[int, dict], light, view, region,
                                footprint=None) -> np.ndarray:
    """π f_s(l̂, v̂) of each sample's region, without the diffuse term, (N, 3); with each sample's
    ``footprint`` (N, 3) (:attr:`ReflectanceSamples.footprint`), what its pixel saw: f_s averaged over
    the tilted normals of :func:`~mifaces.reflectance.footprint.tilted`, as the region fit predicts it.
    (A lobe the fit sharpened against the footprint, read at the sample's normal alone, would take
    its peak for the pixel's: the eyes' albedo came out 0.15 too dark where the highlights lay.)

    All samples are evaluated in one Dr.Jit call, with each region's
    parameters gathered per sample.
    """
    model = brdf_models.model(model) if isinstance(model, str) else model
    labels = sorted(params_by_region)
    region = np.asarray(region)
    missing = sorted(set(np.unique(region).tolist()) - set(labels))
    if missing:
        raise ValueError(f"samples of region label(s) {missing} have no fitted parameters")
    lookup = np.full(int(max(labels)) + 1, -1)
    lookup[labels] = np.arange(len(labels))
    index = lookup[region]
    idx = mi.UInt32(index.astype(np.uint32))
    params = {}
    for p in model.specular_parameters():
        table = np.array([np.broadcast_to(np.asarray(params_by_region[l][p.name], dtype=np.float32),
                                          (3,) if p.kind == "rgb" else ()) for l in labels])
        if p.kind == "rgb":
            params[p.name] = mi.Color3f([dr.gather(mi.Float, mi.Float(table[:, c]), idx) for c in range(3)])
        else:
            params[p.name] = dr.gather(mi.Float, mi.Float(table), idx)
    wi = mi.Vector3f(np.ascontiguousarray(np.asarray(light, np.float32).T))
    wo = mi.Vector3f(np.ascontiguousarray(np.asarray(view, np.float32).T))
    spread = () if footprint is None else spread_arrays(footprint, len(index))
    return np.pi * np.array(seen_by_pixel(lambda a, b: model.eval(a, b, params, diffuse=False), wi, wo, spread)).T


def noise_and_spread(residual, w, texel, region, mean, total, counts, labels) -> dict:
    """Per region label, (λ, s₀², τ²) per channel (module docstring;
    :func:`~mifaces.reflectance.maps.shrinkage.empirical_bayes`); s₀² and τ² NaN where they cannot
    be estimated (λ = 0).

    ``residual`` (N, 3) are the samples' x_s, ``mean`` (T, 3) the texels' weighted means,
    ``total`` (T,) their Σ w, ``counts`` (T,) their sample counts; all texel arrays are flat
    over the texture."""
    out = {}
    deviation = residual - mean[texel]
    for label in labels:
        in_region = region == label
        texels = np.unique(texel[in_region])
        dof = int(np.sum(counts[texels] - 1))
        multi = texels[counts[texels] >= 2]
        if dof < 2 or len(multi) < 2:
            out[label] = (np.zeros(3), np.full(3, np.nan), np.full(3, np.nan))  # no noise estimate: no shrinkage
            continue
        squares = np.sum(w[in_region, None] * np.square(deviation[in_region]), axis=0)
        floor = 1e-6 * np.maximum(np.mean(mean[multi], axis=0) ** 2, 1e-12)
        out[label] = empirical_bayes(squares, dof, mean[multi], total[multi], floor)
    return out


def albedo_offsets(albedo, texel, label, where=None) -> np.ndarray:
    """ρ_p - ρ̄ per sample (N, 3): its texel's albedo (``albedo``, flat (R², 3)) less its region's mean
    over the samples' texels (weighted by samples), for the samples ``where`` is True (default all);
    0 for the others. Subtracted from the reflectance, it lets a region fit's one albedo ρ̄ stand
    for all its texels, so the albedo's texture is not read as noise (or as gloss) of the glossy part."""
    texel, label = np.asarray(texel), np.asarray(label)
    offsets = np.zeros((len(texel), 3))
    on = np.ones(len(texel), bool) if where is None else np.asarray(where, bool)
    for lab in np.unique(label[on]):
        chosen = on & (label == lab)
        values = albedo[texel[chosen]]
        offsets[chosen] = values - values.mean(axis=0)
    return offsets.astype(np.float32)


#: A texel without samples takes the mean of its region's sampled texels around
#: it, Gaussian-weighted with this σ (texels), where they are near (a thin band
#: along a region border, whose samples mixed in the neighbour's light:
#: :func:`mifaces.reflectance.mixed_pixels.region_mixed`); further away, its region's albedo.
FILL_TEXELS = 2.0


def _local_mean(albedo: np.ndarray, seen: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The Gaussian-weighted mean (σ :data:`FILL_TEXELS`) of ``albedo`` (size², 3) over the
    flat mask ``seen`` around every texel, and the weight of ``seen`` there (1 inside it)."""
    mask = seen.reshape(size, size).astype(np.float64)
    weight = ndi.gaussian_filter(mask, FILL_TEXELS, mode="constant")
    image = albedo.reshape(size, size, 3) * mask[..., None]
    total = np.stack([ndi.gaussian_filter(image[..., c], FILL_TEXELS, mode="constant") for c in range(3)], -1)
    return (total / np.maximum(weight, 1e-12)[..., None]).reshape(-1, 3), weight.ravel()


def refine_diffuse(model, params_by_region: dict[int, dict], samples: ReflectanceSamples, region_map: np.ndarray,
                   shrinkage: bool = True) -> DiffuseMap:
    """Refit ρ_d per texel with each region's glossy part fixed (sec. 5.3).

    Parameters
    ----------
    model : BRDFModel or str
    params_by_region : dict
        Region label -> fitted parameters (as in ``RegionFit.params``).
    samples : ReflectanceSamples
        The samples, with their region labels (``label``); σ the confidence of eq. 10 (or 9).
    region_map : ndarray (R, R)
        Region label of every texel, for filling texels without samples.
    shrinkage : bool
        Pull sparsely sampled texels towards the region's albedo by the
        empirical-Bayes weight λ (module docstring); False gives the paper's
        plain per-texel least squares.

    Returns
    -------
    DiffuseMap
    """
    region_map = np.asarray(region_map)
    if region_map.ndim != 2 or region_map.shape[0] != region_map.shape[1]:
        raise ValueError(f"region_map must be a square (R, R) label image, got shape {region_map.shape}")
    size = region_map.size
    texel, region = np.asarray(samples.texel), samples.labels()
    if texel.size and (texel.min() < 0 or texel.max() >= size):
        raise ValueError(f"texel indices must lie in [0, {size}) for a {region_map.shape} region map")
    specular = (specular_reflectance_factor(model, params_by_region, samples.light, samples.view, region,
                                            samples.footprint)
                if len(texel) else np.zeros((0, 3)))
    w = 1.0 / np.square(np.asarray(samples.sigma, np.float64))
    total = np.bincount(texel, weights=w, minlength=size)
    albedo = np.empty((size, 3))
    residual = np.asarray(samples.reflectance, np.float64) - specular
    for c in range(3):
        albedo[:, c] = np.bincount(texel, weights=w * residual[:, c], minlength=size) / np.maximum(total, 1e-300)
    counts = np.bincount(texel, minlength=size)
    labels = region_map.ravel()
    # NaN (not known) on the texels of the regions with a BRDF until estimated, 0 outside the face
    variance = np.where(np.isin(labels, list(params_by_region))[:, None], np.nan, 0.0) * np.ones(3)
    weights = {}  # region label -> λ per channel
    if len(texel):
        texel_region = np.zeros(size, dtype=region.dtype)
        texel_region[texel] = region  # a texel's samples share its region
        stats = noise_and_spread(residual, w, texel, region, albedo, total, counts, np.unique(region))
        seen = np.flatnonzero(total > 0)
        for label, (weight, s0, tau) in stats.items():
            weight = weight if shrinkage else np.zeros(3)
            weights[label] = np.asarray(weight, np.float64)
            t = seen[texel_region[seen] == label]
            prior = np.broadcast_to(np.asarray(params_by_region[label]["diffuse_reflectance"], np.float64), (3,))
            albedo[t] = (total[t, None] * albedo[t] + weight * prior) / (total[t, None] + weight)
            variance[t] = s0 / (total[t, None] + weight)
            variance[(total <= 0) & (labels == label)] = tau if shrinkage else np.nan
    empty = total <= 0
    r = region_map.shape[0]
    for label in np.unique(labels[empty]):
        fill = empty & (labels == label)
        if label in params_by_region:
            albedo[fill] = np.broadcast_to(params_by_region[label]["diffuse_reflectance"], (3,))
            local, weight = _local_mean(albedo, ~empty & (labels == label), r)
            close = fill & (weight > 0.05)
            albedo[close] = local[close]
        else:
            albedo[fill] = 0.0  # outside the face: no region, no BRDF
    return DiffuseMap(albedo=np.clip(albedo, 0.0, None).reshape(r, r, 3).astype(np.float32),
                      weight=total.reshape(r, r).astype(np.float32), samples=counts.reshape(r, r),
                      std=np.sqrt(variance).reshape(r, r, 3).astype(np.float32), shrinkage=weights)
