"""Per-pixel normals with a fitted analytic BRDF: non-Lambertian photometric stereo.

Lambertian photometric stereo (:mod:`mifaces.photometric_stereo`) reads a
glossy surface's highlights as tilted normals. Here each pixel (or texel) p
seen under K directional lights gets the normal n_p and the diffuse albedo
ρ_p that minimise

    E = Σ_p Σ_k w_kp |I_kp - Î_kp|² + λ Σ_p |n_p - n̄_p|²,

    Î_kp = (ρ_p + π f_s(l̂_k, v̂_p; θ)) max(0, n_p·l_k),

where I is the pixel value per unit light intensity (radiance up to one
global factor, so the reflectance r = I / cos θ_i is scaled like the
pipeline's, where a white Lambertian target reads 1 and the model predicts
r = π f), f_s the glossy part of a model of :mod:`mifaces.brdf` with
parameters θ shared by all pixels, l̂ and v̂ the light and view directions in
the pixel's local shading frame (z = n_p), w_kp a confidence weight (0 for a
shadowed or saturated observation) and n̄_p a prior normal.

The prior and the normal step are :mod:`mifaces.reflectance.maps.normal_fit`'s.

**The alternation** (:func:`fit_normals_and_brdf`): from Lambertian
photometric stereo, fit θ with :func:`~mifaces.reflectance.fit.region_fit.fit_region`
on all pixels' samples in their current local frames (r = I / cos θ_i,
σ = 1 / (cos θ_i √w), so eq. 8's residuals are the image residuals above;
each sample's pixel albedo offset ρ_p - ρ̄ subtracted, so one region albedo
ρ̄ stands for all), then ρ_p in closed form given the glossy part (as
:mod:`mifaces.reflectance.maps.diffuse` does per texel), then the normal step;
repeat until E improves by less than ``tol`` (relative).

Frames: the directions towards the lights and the viewer and the normals
share the caller's frame (DiLiGenT: x right, y up, z towards the camera).
Models are isotropic, so the tangent frame's rotation about n is irrelevant.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .. import brdf as brdf_models
from ..brdf.model import BRDFModel
from ..reflectance.fit.region_fit import RegionFit, fit_region
from ..reflectance.maps.normal_fit import (PRIOR_WEIGHT, NormalFit, _check, _unit, loss, predict,
                                           refine_normals)
from ..reflectance.maps.observations import Observations, tangents
from . import lambertian

#: Samples of the BRDF fit with cos θ_i below this are left out (r = I / cos θ_i is noise there).
MIN_COSINE = 0.05


@dataclass
class NormalsEstimate:
    """Outcome of :func:`fit_normals_and_brdf`: normals, albedo and the shared glossy BRDF.

    Attributes
    ----------
    normals, albedo : ndarray (P, 3)
    brdf : RegionFit
        The BRDF fitted in the last round (``params`` hold θ and the region albedo ρ̄).
    loss : float
        E of the module docstring at the result.
    history : list of dict
        Per round: ``{"round", "loss", "seconds", "brdf_loss", "normal_iterations"}``;
        round 0 is the Lambertian start (its loss with the first BRDF fit).
    """

    normals: np.ndarray
    albedo: np.ndarray
    brdf: RegionFit
    loss: float
    history: list = field(default_factory=list)


def observation_weights(values, saturated=None, shadow: float = lambertian.SHADOW_FRACTION) -> np.ndarray:
    """Weight 1 for each usable observation, 0 for a shadowed or saturated one, (K, P).

    ``values`` (K, P, 3) or (K, P); ``saturated`` (K, P) bool. An observation
    below ``shadow`` times its pixel's brightest is shadowed, as in
    :func:`mifaces.photometric_stereo.lambertian.observation_weights`.
    """
    values = np.asarray(values, np.float64)
    grey = values.mean(axis=2) if values.ndim == 3 else values
    return lambertian.observation_weights(grey, saturated, shadow)


def brdf_samples(values, directions, weights, normals, albedo, view=(0.0, 0.0, 1.0),
                 max_samples: int | None = 200_000, seed: int = 0):
    """The observations as reflectance samples for :func:`~mifaces.reflectance.fit.region_fit.fit_region`.

    Each usable observation with cos θ_i >= :data:`MIN_COSINE` gives l̂ and v̂
    in its pixel's local frame (z = n_p), r = I / cos θ_i - (ρ_p - ρ̄) and
    σ = 1 / (cos θ_i √w), with ρ̄ the mean albedo (weighted by the usable
    observations): eq. 8's residual (r - π f)/σ is then the image residual
    of :func:`refine_normals` with ρ̄ in place of each pixel's albedo. At most
    ``max_samples`` (a seeded random subset; None: all).

    Returns
    -------
    light, view, reflectance : ndarray (N, 3)
    sigma : ndarray (N,)
    """
    values, weights = np.asarray(values, np.float64), np.asarray(weights, np.float64)
    k, p, _ = values.shape
    normals = _unit(normals, view)
    t1, t2 = tangents(normals)
    frame = np.stack([t1, t2, normals], axis=1)  # (P, 3 local axes, 3)
    lights = np.broadcast_to(np.asarray(directions, np.float64).reshape(k, -1, 3), (k, p, 3))
    local_light = np.einsum("pij,kpj->kpi", frame, lights)
    views = np.broadcast_to(np.asarray(view, np.float64).reshape(-1, 3), (p, 3))
    local_view = np.broadcast_to(np.einsum("pij,pj->pi", frame, views), (k, p, 3))
    cos = local_light[..., 2]
    used = (weights > 0) & (cos >= MIN_COSINE) & (local_view[..., 2] > 0)
    index = np.flatnonzero(used.ravel())
    if max_samples is not None and len(index) > max_samples:
        index = np.sort(np.random.default_rng(seed).choice(index, max_samples, replace=False))
    albedo = np.asarray(albedo, np.float64)
    counts = used.sum(axis=0)
    mean_albedo = (counts[:, None] * albedo).sum(axis=0) / max(counts.sum(), 1)
    reflectance = values / np.where(used, cos, 1.0)[..., None] - (albedo - mean_albedo)[None]
    sigma = 1.0 / (np.where(used, cos, 1.0) * np.sqrt(np.where(used, weights, 1.0)))
    pick = lambda a: a.reshape(k * p, *a.shape[2:])[index]  # noqa: E731
    return pick(local_light), pick(np.ascontiguousarray(local_view)), pick(reflectance), pick(sigma)


def fit_normals_and_brdf(model: BRDFModel | str, values, directions, weights, normals, albedo,
                         view=(0.0, 0.0, 1.0), prior=None, prior_weight: float = PRIOR_WEIGHT, rounds: int = 5,
                         tol: float = 1e-3, iterations: int = 30, max_samples: int | None = 200_000,
                         seed: int = 0, progress=None) -> NormalsEstimate:
    """Alternate the BRDF fit and the normal step from a Lambertian start (module docstring).

    Parameters
    ----------
    model : BRDFModel or str
    values, directions, weights, view, prior, prior_weight, iterations
        As for :func:`refine_normals` (``iterations``: per normal step).
    normals, albedo : ndarray (P, 3)
        The start, normally :func:`mifaces.photometric_stereo.fit`'s.
    rounds : int
        Most rounds of BRDF fit + normal step.
    tol : float
        Stop when a round lowers E by less than ``tol`` · E.
    max_samples : int or None
        Samples of each BRDF fit (:func:`brdf_samples`).
    seed : int
        Seed of the BRDF fits' random subsets.
    progress : callable, optional
        Called with each round's history entry.

    Returns
    -------
    NormalsEstimate
        The best round's state (E never increases).
    """
    model = brdf_models.model(model) if isinstance(model, str) else model
    values = _check(values, directions, weights, normals, albedo)
    normals = _unit(normals, view)
    prior = normals.copy() if prior is None else _unit(prior, view)
    albedo = np.asarray(albedo, np.float64)
    args = dict(view=view, prior=prior, prior_weight=prior_weight)
    best, history, start = None, [], None
    for round_ in range(rounds + 1):
        t0 = time.perf_counter()
        fit = fit_region(model, *brdf_samples(values, directions, weights, normals, albedo, view, max_samples,
                                              seed + round_), start=start, uncertainty=None)
        if round_ == 0:  # the Lambertian normals under the first BRDF fit, their albedo in closed form
            data, albedo = Observations(model, fit.params, directions, view, len(normals), values,
                                        weights).losses(normals)
            state = NormalFit(normals, albedo, float(data.sum()), 0)
        else:  # from the closed-form albedo given the glossy part
            state = refine_normals(model, fit.params, values, directions, weights, normals, iterations=iterations,
                                   **args)
        entry = {"round": round_, "loss": state.loss, "brdf_loss": fit.loss, "normal_iterations": state.iterations,
                 "seconds": time.perf_counter() - t0}
        history.append(entry)
        if progress is not None:
            progress(entry)
        if best is not None and state.loss >= best[0].loss * (1 - tol):
            if state.loss < best[0].loss:
                best = (state, fit)
            break
        best = (state, fit)
        normals, albedo, start = state.normals, state.albedo, fit.params
    state, fit = best
    return NormalsEstimate(normals=state.normals, albedo=state.albedo, brdf=fit, loss=state.loss, history=history)


__all__ = ["MIN_COSINE", "NormalsEstimate", "brdf_samples", "fit_normals_and_brdf", "loss", "observation_weights",
           "predict", "refine_normals"]
