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
repeat until E improves by less than ``tol`` (relative); :class:`AlternationOptions` holds its
settings.

Frames: the directions towards the lights and the viewer and the normals
share the caller's frame (DiLiGenT: x right, y up, z towards the camera).
Models are isotropic, so the tangent frame's rotation about n is irrelevant.
"""

from __future__ import annotations

import numbers
import time
from dataclasses import dataclass, field

import numpy as np

from .. import brdf as brdf_models
from ..brdf.model import BRDFModel
from ..options.fields import check, option
from ..reflectance.fit.region_fit import RegionFit, RegionSamples, fit_region
from ..reflectance.maps.normal_fit import (LitPixels, NormalFit, NormalStepOptions, _check_start, _unit, loss, predict,
                                           refine_normals)
from ..reflectance.maps.observations import tangents
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


@dataclass(frozen=True)
class AlternationOptions:
    """How :func:`fit_normals_and_brdf` alternates (module docstring). Validated on construction: a
    number out of its range raises a ``ValueError`` naming the field.

    Attributes
    ----------
    rounds : int
        Most rounds of BRDF fit + normal step.
    tol : float
        Stop when a round lowers E by less than ``tol`` · E.
    max_samples : int or None
        Samples of each BRDF fit (:func:`brdf_samples`; None: all).
    seed : int
        Seed of the BRDF fits' random subsets (round ``r`` draws with ``seed + r``).
    step : NormalStepOptions
        How each normal step runs (:func:`refine_normals`): the prior's weight, its most
        Levenberg-Marquardt steps, its tolerance and start search.
    """

    rounds: int = option(5, bounds=(0, None))
    tol: float = option(1e-3, bounds=(0.0, None))
    max_samples: int | None = 200_000
    seed: int = option(0, bounds=(0, None))
    step: NormalStepOptions = option(factory=NormalStepOptions, nested=NormalStepOptions)

    def __post_init__(self):
        check(self)
        if not isinstance(self.step, NormalStepOptions):
            raise ValueError(f"AlternationOptions.step must be a NormalStepOptions, got {self.step!r}")
        if self.max_samples is not None and (isinstance(self.max_samples, bool) or not isinstance(
                self.max_samples, numbers.Integral) or self.max_samples < 1):
            raise ValueError(f"AlternationOptions.max_samples must be an integer >= 1 or None, got "
                             f"{self.max_samples!r}")


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


def fit_normals_and_brdf(model: BRDFModel | str, pixels: LitPixels, normals, albedo, prior=None,
                         options: AlternationOptions | None = None, progress=None) -> NormalsEstimate:
    """Alternate the BRDF fit and the normal step from a Lambertian start (module docstring).

    Parameters
    ----------
    model : BRDFModel or str
    pixels : LitPixels
        The observations: values, light directions, weights and view directions, as
        :func:`refine_normals` takes them; without footprints (the BRDF fit's samples have none).
    normals, albedo : ndarray (P, 3)
        The start, normally :func:`mifaces.photometric_stereo.fit`'s.
    prior : ndarray (P, 3), optional
        Prior normals n̄ (default: the start normals).
    options : AlternationOptions, optional
        The most rounds, the tolerance, the BRDF fits' samples and seed, and how each normal step
        runs (default ``AlternationOptions()``).
    progress : callable, optional
        Called with each round's history entry.

    Returns
    -------
    NormalsEstimate
        The best round's state (E never increases).
    """
    options = options or AlternationOptions()
    if pixels.footprint is not None:
        raise ValueError("fit_normals_and_brdf takes pixels without footprints: its BRDF fit's samples have none")
    model = brdf_models.model(model) if isinstance(model, str) else model
    _check_start(pixels, normals, albedo)
    values, directions, weights, view = pixels.values, pixels.directions, pixels.weights, pixels.view
    normals = _unit(normals, view)
    prior = normals.copy() if prior is None else _unit(prior, view)
    albedo = np.asarray(albedo, np.float64)
    best, history, start = None, [], None
    for round_ in range(options.rounds + 1):
        t0 = time.perf_counter()
        samples = brdf_samples(values, directions, weights, normals, albedo, view, options.max_samples,
                               options.seed + round_)
        fit = fit_region(model, RegionSamples(*samples), start=start, uncertainty=None)
        if round_ == 0:  # the Lambertian normals under the first BRDF fit, their albedo in closed form
            data, albedo = pixels.observations(model, fit.params).losses(normals)
            state = NormalFit(normals, albedo, float(data.sum()), 0)
        else:  # from the closed-form albedo given the glossy part
            state = refine_normals(model, fit.params, pixels, normals, prior=prior, options=options.step)
        entry = {"round": round_, "loss": state.loss, "brdf_loss": fit.loss, "normal_iterations": state.iterations,
                 "seconds": time.perf_counter() - t0}
        history.append(entry)
        if progress is not None:
            progress(entry)
        if best is not None and state.loss >= best[0].loss * (1 - options.tol):
            if state.loss < best[0].loss:
                best = (state, fit)
            break
        best = (state, fit)
        normals, albedo, start = state.normals, state.albedo, fit.params
    state, fit = best
    return NormalsEstimate(normals=state.normals, albedo=state.albedo, brdf=fit, loss=state.loss, history=history)


__all__ = ["MIN_COSINE", "AlternationOptions", "LitPixels", "NormalStepOptions", "NormalsEstimate", "brdf_samples",
           "fit_normals_and_brdf", "loss", "observation_weights", "predict", "refine_normals"]
