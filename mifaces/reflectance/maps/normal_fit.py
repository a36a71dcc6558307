"""One normal per pixel or texel under a known analytic BRDF: the normal step
shared by the face's normal map (:mod:`mifaces.reflectance.maps.normals`) and
non-Lambertian photometric stereo (:mod:`mifaces.photometric_stereo.nonlambertian`).

Each pixel (or texel) p seen under K directional lights gets the normal n_p
and the diffuse albedo ρ_p that minimise

    E = Σ_p Σ_k w_kp |I_kp - Î_kp|² + λ Σ_p |n_p - n̄_p|²,

    Î_kp = (ρ_p + π f_s(l̂_k, v̂_p; θ)) max(0, n_p·l_k),

with θ, the glossy parameters, held (:mod:`mifaces.photometric_stereo.nonlambertian`
explains the terms).

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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ... import brdf as brdf_models
from ...brdf.model import BRDFModel
from ...options.fields import check, option
from .observations import Observations, tangents

#: Default weight of the prior normal, in observations (see the module docstring).
PRIOR_WEIGHT = 0.1
#: Largest tilt of one normal step, in radians.
MAX_STEP = 0.3
#: The start search of :func:`refine_normals`: a grid of tilts up to RADIUS degrees in steps of STEP, then
#: LEVELS - 1 finer 3 x 3 grids (each a third of the step) around the best.
SEARCH = (12.0, 3.0, 3)


@dataclass(frozen=True, eq=False)
class LitPixels:
    """P pixels (or texels) seen under K lights: what the normal step fits. Validated on construction
    (shapes agree, values and weights finite, weights non-negative; a ``ValueError`` names the array).

    Attributes
    ----------
    values : ndarray (K, P, 3) float64
        Pixel values per unit light intensity under each of K lights.
    directions : ndarray (K, 3) or (K, P, 3)
        Unit directions towards the lights.
    weights : ndarray (K, P)
        Confidence of each observation; 0 leaves it out
        (:func:`~mifaces.photometric_stereo.nonlambertian.observation_weights`).
    view : ndarray (3,), (P, 3) or (K, P, 3)
        Unit direction towards the viewer (orthographic camera: one for all; texels of a face seen in
        several poses: one per observation).
    footprint : ndarray (K, P, 3), optional
        Each observation's pixel footprint (:class:`~mifaces.reflectance.maps.observations.Observations`):
        the glossy part is averaged over it.
    """

    values: np.ndarray
    directions: np.ndarray
    weights: np.ndarray
    view: np.ndarray = (0.0, 0.0, 1.0)
    footprint: np.ndarray | None = None

    def __post_init__(self):
        values = np.asarray(self.values, np.float64)
        if values.ndim != 3 or values.shape[2] != 3:
            raise ValueError(f"values must have shape (K, P, 3), got {values.shape}")
        k, p, _ = values.shape
        if np.shape(self.directions) not in ((k, 3), (k, p, 3)):
            raise ValueError(f"directions must have shape ({k}, 3) or ({k}, {p}, 3), got {np.shape(self.directions)}")
        if np.shape(self.weights) != (k, p):
            raise ValueError(f"weights must have shape ({k}, {p}), got {np.shape(self.weights)}")
        if not (np.all(np.isfinite(values)) and np.all(np.isfinite(self.weights))
                and np.all(np.asarray(self.weights) >= 0)):
            raise ValueError("values and weights must be finite, and weights non-negative")
        object.__setattr__(self, "values", values)

    def __len__(self) -> int:
        """P, the pixels."""
        return self.values.shape[1]

    def observations(self, model: BRDFModel, params: dict) -> Observations:
        """These pixels on the Dr.Jit side, shaded by ``model`` with glossy parameters ``params``."""
        return Observations(model, params, self.directions, self.view, len(self), self.values, self.weights,
                            self.footprint)


@dataclass(frozen=True)
class NormalStepOptions:
    """How :func:`refine_normals` runs, validated on construction (a number out of its range raises a
    ``ValueError`` naming the field).

    Attributes
    ----------
    prior_weight : float
        The prior's weight in observations (module docstring).
    iterations : int
        Most Levenberg-Marquardt steps.
    tol : float
        Stop when a step lowers E by less than ``tol`` · E.
    search : (radius, step, levels) or None
        The start search of :func:`search_start` (None: start at the normals as given).
    """

    prior_weight: float = option(PRIOR_WEIGHT, bounds=(0.0, None))
    iterations: int = option(30, bounds=(0, None))
    tol: float = option(1e-7, bounds=(0.0, None))
    search: tuple | None = SEARCH

    def __post_init__(self):
        check(self)


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


def _check_start(pixels: LitPixels, normals, albedo) -> None:
    """``normals`` and ``albedo`` (if given) are (P, 3) for ``pixels``; a ``ValueError`` names the one that is not."""
    for name, a in (("normals", normals), ("albedo", albedo)):
        if a is not None and np.shape(a) != (len(pixels), 3):
            raise ValueError(f"{name} must have shape ({len(pixels)}, 3), got {np.shape(a)}")


def _unit(normals, view) -> np.ndarray:
    """Unit normals; zero rows (unsolved pixels) become the view direction."""
    normals = np.array(normals, np.float64)
    length = np.linalg.norm(normals, axis=1)
    view = np.asarray(view, np.float64)
    view = view.mean(axis=0) if view.ndim == 3 else view  # one per observation: their mean per pixel
    fallback = np.broadcast_to(view.reshape(-1, 3), normals.shape)
    normals[length <= 0] = fallback[length <= 0]
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def refine_normals(model: BRDFModel | str, params: dict, pixels: LitPixels, normals, *, albedo=None, prior=None,
                   options: NormalStepOptions | None = None) -> NormalFit:
    """The normal step: n_p and ρ_p per pixel minimising E with the glossy part θ fixed.

    Parameters
    ----------
    model : BRDFModel or str
        A model of :mod:`mifaces.brdf`.
    params : dict
        Its glossy parameters θ (as in ``RegionFit.params``; the diffuse one is not used).
    pixels : LitPixels
        The observations: values, light directions, weights, view directions (and footprints).
    normals : ndarray (P, 3)
        Start normals (Lambertian photometric stereo); zero rows start at ``pixels.view``.
    albedo : ndarray (P, 3), optional
        Start albedo; default the closed form at the start normals.
    prior : ndarray (P, 3), optional
        Prior normals n̄ (default: the start normals).
    options : NormalStepOptions, optional
        The prior's weight, the most steps, the tolerance, the start search (default
        ``NormalStepOptions()``).

    Returns
    -------
    NormalFit
    """
    model = brdf_models.model(model) if isinstance(model, str) else model
    options = options or NormalStepOptions()
    _check_start(pixels, normals, albedo)
    values, weights, view = pixels.values, pixels.weights, pixels.view
    normals = _unit(normals, view)
    prior = normals.copy() if prior is None else _unit(prior, view)
    lam = prior_strength(values, weights, options.prior_weight)
    obs = pixels.observations(model, params)
    pixel_loss, albedo = obs.losses(normals, None if albedo is None else np.asarray(albedo, np.float64))
    pixel_loss += _prior_term(normals, prior, lam)
    if options.search is not None:
        found, found_albedo, found_loss = search_start(obs, normals, prior, lam, options.search)
        better = found_loss < pixel_loss
        normals[better], albedo[better], pixel_loss[better] = found[better], found_albedo[better], \
            found_loss[better]
    damping = np.full(len(normals), 1e-3)
    history = [float(pixel_loss.sum())]
    for _ in range(options.iterations):
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
        if history[-2] - history[-1] <= options.tol * history[-1]:
            break
    return NormalFit(normals=normals, albedo=albedo, loss=history[-1], iterations=len(history) - 1,
                     history=history)


def loss(model: BRDFModel | str, params: dict, pixels: LitPixels, normals, albedo=None, prior=None,
         prior_weight: float = PRIOR_WEIGHT) -> float:
    """E of the module docstring for ``pixels`` (their glossy part averaged over their footprints, where
    they have them) at unit ``normals`` (P, 3) and ``albedo`` (default: the closed form); the prior term is
    0 where ``prior`` is None."""
    model = brdf_models.model(model) if isinstance(model, str) else model
    _check_start(pixels, normals, albedo)
    normals = np.asarray(normals, np.float64)
    obs = pixels.observations(model, params)
    data, _ = obs.losses(normals, None if albedo is None else np.asarray(albedo, np.float64))
    if prior is None:
        return float(data.sum())
    return float(data.sum() + _prior_term(normals, prior, prior_strength(pixels.values, pixels.weights,
                                                                         prior_weight)).sum())


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


__all__ = ["MAX_STEP", "PRIOR_WEIGHT", "SEARCH", "LitPixels", "NormalStepOptions", "NormalFit", "loss", "predict",
           "prior_strength", "refine_normals", "search_start"]
