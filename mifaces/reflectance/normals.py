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

**The prior.** λ = ``prior_weight`` · s², with s² the mean of |I_kp|² over
the usable observations: an observation's value changes by about |I| per
radian of tilt, so the prior counts as much as ``prior_weight`` observations
(default 0.1). It decides the normal of a pixel with fewer than two usable
observations, keeps one with no usable observation at n̄_p exactly, and
moves a well-observed pixel by about ``prior_weight`` / (its usable
observations) of its distance from n̄_p.

**The normal step** (:func:`refine_normals`, θ fixed) is Levenberg-Marquardt
on five unknowns per pixel, all pixels in one batch: the normal as two
coordinates (a, b) in the tangent plane at its current value,
n = normalise(n₀ + a t₁ + b t₂), re-centred after every step, and ρ_p per
colour channel. Î's derivatives in a and b come from Dr.Jit's forward mode
through the same model code the plugins and the BRDF fitter call; ρ enters
linearly. Each pixel has its own damping and accepts a step only if its own
loss decreases.

**The alternation** (:func:`fit_normals_and_brdf`): from Lambertian
photometric stereo, fit θ with :func:`~mifaces.reflectance.fitting.fit_region`
on all pixels' samples in their current local frames (r = I / cos θ_i,
σ = 1 / (cos θ_i √w), so eq. 8's residuals are the image residuals above;
each sample's pixel albedo offset ρ_p - ρ̄ subtracted, so one region albedo
ρ̄ stands for all), then ρ_p in closed form given the glossy part (as
:mod:`mifaces.reflectance.diffuse` does per texel), then the normal step;
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
from .. import photometric_stereo
from ..brdf.model import BRDFModel
from .fitting import RegionFit, fit_region
from .observations import Observations, tangents

#: Default weight of the prior normal, in observations (see the module docstring).
PRIOR_WEIGHT = 0.1
#: Samples of the BRDF fit with cos θ_i below this are left out (r = I / cos θ_i is noise there).
MIN_COSINE = 0.05
#: Largest tilt of one normal step, in radians.
MAX_STEP = 0.3
#: The start search of :func:`refine_normals`: a grid of tilts up to RADIUS degrees in steps of STEP, then
#: LEVELS - 1 finer 3 x 3 grids (each a third of the step) around the best.
SEARCH = (12.0, 3.0, 3)


@dataclass
class NormalFit:
    """Outcome of :func:`refine_normals` for P pixels.

    Attributes
    ----------
    normals : ndarray (P, 3)
        Unit normals, in the frame of the light directions.
    albedo : ndarray (P, 3)
        Diffuse albedo ρ_p per colour channel.
    loss : float
        E of the module docstring, data term plus prior.
    iterations : int
        Steps taken.
    history : list of float
        E after each step.
    """

    normals: np.ndarray
    albedo: np.ndarray
    loss: float
    iterations: int
    history: list = field(default_factory=list)


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


def observation_weights(values, saturated=None, shadow: float = photometric_stereo.SHADOW_FRACTION) -> np.ndarray:
    """Weight 1 for each usable observation, 0 for a shadowed or saturated one, (K, P).

    ``values`` (K, P, 3) or (K, P); ``saturated`` (K, P) bool. An observation
    below ``shadow`` times its pixel's brightest is shadowed, as in
    :func:`mifaces.photometric_stereo.observation_weights`.
    """
    values = np.asarray(values, np.float64)
    grey = values.mean(axis=2) if values.ndim == 3 else values
    return photometric_stereo.observation_weights(grey, saturated, shadow)


def prior_strength(values, weights, prior_weight: float = PRIOR_WEIGHT) -> float:
    """λ = ``prior_weight`` times the mean |I|² of the usable observations."""
    energy = np.sum(np.square(np.asarray(values, np.float64)), axis=-1)
    used = np.asarray(weights) > 0
    return float(prior_weight * (energy[used].mean() if used.any() else 1.0))


def _prior_term(normals, prior, lam) -> np.ndarray:
    return lam * np.sum(np.square(normals - prior), axis=1)


def search_start(obs: Observations, normals, prior, lam,
                 search=SEARCH) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The best of a grid of normals around each of ``normals``, with the closed-form albedo of each.

    ``search`` = (radius, step, levels) in degrees: tangent-plane offsets
    (tan of the tilt) on a square grid of spacing ``step`` within ``radius``,
    then ``levels`` - 1 finer 3 x 3 grids, each a third of the previous
    spacing, around the best so far. A highlight that the start normal places
    away from where it was observed gives no gradient towards it (a sharp lobe
    is flat there), so a local method keeps a Lambertian-like normal; this
    coarse search moves the start into the highlight's basin.

    Returns
    -------
    normals, albedo : ndarray (P, 3)
    loss : ndarray (P,)
        Each pixel's term of E.
    """
    radius, step, levels = search
    t1, t2 = tangents(normals)
    best, best_albedo = obs.losses(normals)
    best += _prior_term(normals, prior, lam)
    best_offset = np.zeros((len(normals), 2))
    m = int(round(radius / step))
    grid = np.arange(-m, m + 1)
    for _ in range(int(levels)):
        centre = best_offset.copy()
        for i, j in [(i, j) for i in grid for j in grid if (i, j) != (0, 0) and np.hypot(i, j) <= m + 1e-9]:
            offset = centre + np.tan(np.radians(step)) * np.array([i, j])
            candidate = normals + offset[:, :1] * t1 + offset[:, 1:] * t2
            candidate /= np.linalg.norm(candidate, axis=1, keepdims=True)
            candidate_loss, albedo = obs.losses(candidate)
            candidate_loss += _prior_term(candidate, prior, lam)
            better = candidate_loss < best
            best_offset[better], best_albedo[better], best[better] = offset[better], albedo[better], \
                candidate_loss[better]
        step, m, grid = step / 3.0, 1, np.arange(-1, 2)
    found = normals + best_offset[:, :1] * t1 + best_offset[:, 1:] * t2
    return found / np.linalg.norm(found, axis=1, keepdims=True), best_albedo, best


def _damped_steps(h, grad, damping) -> np.ndarray:
    """Solve (H + μ diag H + ε I) δ = -grad per pixel; tilts capped at :data:`MAX_STEP`."""
    diag = np.diagonal(h, axis1=1, axis2=2)
    scale = np.maximum(diag.max(axis=1), 1e-30)
    system = h + (damping[:, None] * diag + 1e-12 * scale[:, None])[:, :, None] * np.eye(5)
    delta = np.linalg.solve(system, -grad[:, :, None])[:, :, 0]
    tilt = np.linalg.norm(delta[:, :2], axis=1)
    delta[:, :2] *= np.minimum(1.0, MAX_STEP / np.maximum(tilt, 1e-30))[:, None]
    return delta


def _check(values, directions, weights, normals, albedo):
    values = np.asarray(values, np.float64)
    if values.ndim != 3 or values.shape[2] != 3:
        raise ValueError(f"values must have shape (K, P, 3), got {values.shape}")
    k, p, _ = values.shape
    if np.shape(directions) not in ((k, 3), (k, p, 3)):
        raise ValueError(f"directions must have shape ({k}, 3) or ({k}, {p}, 3), got {np.shape(directions)}")
    if np.shape(weights) != (k, p):
        raise ValueError(f"weights must have shape ({k}, {p}), got {np.shape(weights)}")
    for name, a in (("normals", normals), ("albedo", albedo)):
        if a is not None and np.shape(a) != (p, 3):
            raise ValueError(f"{name} must have shape ({p}, 3), got {np.shape(a)}")
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(weights)) and np.all(np.asarray(weights) >= 0)):
        raise ValueError("values and weights must be finite, and weights non-negative")
    return values


def _unit(normals, view) -> np.ndarray:
    """Unit normals; zero rows (unsolved pixels) become the view direction."""
    normals = np.array(normals, np.float64)
    length = np.linalg.norm(normals, axis=1)
    view = np.asarray(view, np.float64)
    view = view.mean(axis=0) if view.ndim == 3 else view  # one per observation: their mean per pixel
    fallback = np.broadcast_to(view.reshape(-1, 3), normals.shape)
    normals[length <= 0] = fallback[length <= 0]
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def refine_normals(model: BRDFModel | str, params: dict, values, directions, weights, normals, albedo=None,
                   view=(0.0, 0.0, 1.0), prior=None, prior_weight: float = PRIOR_WEIGHT, iterations: int = 30,
                   tol: float = 1e-7, search=SEARCH) -> NormalFit:
    """The normal step: n_p and ρ_p per pixel minimising E with the glossy part θ fixed.

    Parameters
    ----------
    model : BRDFModel or str
        A model of :mod:`mifaces.brdf`.
    params : dict
        Its glossy parameters θ (as in ``RegionFit.params``; the diffuse one is not used).
    values : ndarray (K, P, 3)
        Pixel values per unit light intensity under each of K lights.
    directions : ndarray (K, 3) or (K, P, 3)
        Unit directions towards the lights.
    weights : ndarray (K, P)
        Confidence of each observation; 0 leaves it out (see :func:`observation_weights`).
    normals : ndarray (P, 3)
        Start normals (Lambertian photometric stereo); zero rows start at ``view``.
    albedo : ndarray (P, 3), optional
        Start albedo; default the closed form at the start normals.
    view : ndarray (3,), (P, 3) or (K, P, 3)
        Unit direction towards the viewer (orthographic camera: one for all; texels of a face seen in
        several poses: one per observation).
    prior : ndarray (P, 3), optional
        Prior normals n̄ (default: the start normals).
    prior_weight : float
        The prior's weight in observations (module docstring).
    iterations : int
        Most Levenberg-Marquardt steps.
    tol : float
        Stop when a step lowers E by less than ``tol`` · E.
    search : (radius, step, levels) or None
        The start search of :func:`search_start` (None: start at ``normals`` as given).

    Returns
    -------
    NormalFit
    """
    model = brdf_models.model(model) if isinstance(model, str) else model
    values = _check(values, directions, weights, normals, albedo)
    normals = _unit(normals, view)
    prior = normals.copy() if prior is None else _unit(prior, view)
    lam = prior_strength(values, weights, prior_weight)
    obs = Observations(model, params, directions, view, len(normals), values, weights)
    pixel_loss, albedo = obs.losses(normals, None if albedo is None else np.asarray(albedo, np.float64))
    pixel_loss += _prior_term(normals, prior, lam)
    if search is not None:
        found, found_albedo, found_loss = search_start(obs, normals, prior, lam, search)
        better = found_loss < pixel_loss
        normals[better], albedo[better], pixel_loss[better] = found[better], found_albedo[better], \
            found_loss[better]
    damping = np.full(len(normals), 1e-3)
    history = [float(pixel_loss.sum())]
    for _ in range(iterations):
        t1, t2 = tangents(normals)
        h, grad, _ = obs.system(normals, albedo, t1, t2)
        h[:, :2, :2] += lam * np.eye(2)  # the prior λ|n - n̄|², n ≈ n₀ + a t₁ + b t₂
        grad[:, :2] += lam * np.stack([np.sum(t * (normals - prior), axis=1) for t in (t1, t2)], axis=1)
        delta = _damped_steps(h, grad, damping)
        trial_normals = normals + delta[:, :1] * t1 + delta[:, 1:2] * t2
        trial_normals /= np.linalg.norm(trial_normals, axis=1, keepdims=True)
        trial_albedo = albedo + delta[:, 2:]
        trial_loss = obs.losses(trial_normals, trial_albedo)[0] + _prior_term(trial_normals, prior, lam)
        better = trial_loss < pixel_loss
        normals[better], albedo[better], pixel_loss[better] = trial_normals[better], trial_albedo[better], \
            trial_loss[better]
        damping = np.where(better, np.maximum(damping / 3.0, 1e-9), np.minimum(damping * 4.0, 1e12))
        history.append(float(pixel_loss.sum()))
        if history[-2] - history[-1] <= tol * history[-1]:
            break
    return NormalFit(normals=normals, albedo=albedo, loss=history[-1], iterations=len(history) - 1,
                     history=history)


def loss(model: BRDFModel | str, params: dict, values, directions, weights, normals, albedo=None,
         view=(0.0, 0.0, 1.0), prior=None, prior_weight: float = PRIOR_WEIGHT) -> float:
    """E of the module docstring at unit ``normals`` (P, 3) and ``albedo`` (default: the closed form);
    the prior term is 0 where ``prior`` is None."""
    model = brdf_models.model(model) if isinstance(model, str) else model
    normals = np.asarray(normals, np.float64)
    obs = Observations(model, params, directions, view, len(normals), values, weights)
    data, _ = obs.losses(normals, None if albedo is None else np.asarray(albedo, np.float64))
    if prior is None:
        return float(data.sum())
    return float(data.sum() + _prior_term(normals, prior, prior_strength(values, weights, prior_weight)).sum())


def predict(model: BRDFModel | str, params: dict, albedo, normals, directions, view=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Î = (ρ + π f_s) max(0, n·l) per pixel under each light, (K, P, 3).

    ``directions`` (K, 3) or (K, P, 3) towards the lights of unit intensity;
    ``albedo`` and ``normals`` (P, 3); zero normals predict 0.
    """
    model = brdf_models.model(model) if isinstance(model, str) else model
    normals = np.asarray(normals, np.float64)
    solved = np.linalg.norm(normals, axis=1) > 0
    obs = Observations(model, params, np.atleast_2d(directions), view, len(normals))
    s, g = obs.shading(_unit(normals, view))
    return (np.asarray(albedo, np.float64)[None] * s[..., None] + g) * solved[None, :, None]


def brdf_samples(values, directions, weights, normals, albedo, view=(0.0, 0.0, 1.0),
                 max_samples: int | None = 200_000, seed: int = 0):
    """The observations as reflectance samples for :func:`~mifaces.reflectance.fitting.fit_region`.

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


__all__ = ["PRIOR_WEIGHT", "SEARCH", "NormalFit", "NormalsEstimate", "Observations", "observation_weights",
           "prior_strength", "search_start", "refine_normals", "loss", "predict", "brdf_samples", "fit_normals_and_brdf"]
