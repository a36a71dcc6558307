"""Fitting an analytic BRDF model to one set of reflectance samples, given as arrays (paper
sec. 5.1-5.2): one face region's, or any other surface's.

For one region, minimise the weighted error of eq. 8,

    E(a) = ½ Σ_s |r_s - π f_a(l̂_s, v̂_s)|² / σ_s²,

where r is the reflectance scaled so that a white Lambertian target has
r = 1 (so the model predicts π f; f without cosine, see
:mod:`mifaces.brdf.model`) and σ the confidence of eq. 9/10. The model is
evaluated by the same Dr.Jit functions the plugins use; its Jacobian comes
from Dr.Jit's forward mode (a tangent per free parameter), and the normal
equations are summed in the same kernel, one pass over the samples per step
(:class:`~mifaces.reflectance.fit.problem.Problem`); the steps are
Levenberg-Marquardt (:mod:`mifaces.reflectance.fit.levenberg_marquardt`) on
random subsets of growing size, each stage starting from the previous result
(the paper's hierarchy). Parameters are kept in their valid ranges by reparameterisation:
p = lo + (hi - lo)·sigmoid(x), or its logarithmic form for parameters that
span decades (roughness, α, exponents).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ... import brdf as brdf_models
from ...brdf.model import DIFFUSE as DIFFUSE_PARAMETER, BRDFModel
from ...options.fields import check, option
from ...runtime.status import AT_BOUND, AT_START, CONVERGED
from ..maps.diffuse import AlbedoOffsets
from ..samples import ReflectanceSamples
from .levenberg_marquardt import levenberg_marquardt
from .lobes import SPIKE, prune_lobes
from .parameters import ParameterSpace, linear_start
from .problem import Problem
from .uncertainty import METHODS, region_uncertainty


@dataclass
class SubsetSchedule:
    """The hierarchy of random subsets: ``first`` samples, then ``growth``
    times more per stage until all are used; at most ``iterations`` LM
    iterations per stage and ``final_iterations`` on the full set."""

    first: int = 2000
    growth: int = 4
    iterations: int = 20
    final_iterations: int = 100
    #: relative loss decrease that ends a stage before the last
    stage_ftol: float = 1e-4

    def sizes(self, n: int) -> list[int]:
        sizes, k = [], max(1, self.first)
        while k < n:
            sizes.append(k)
            k *= self.growth
        return sizes + [n]


#: One LM stage over all samples.
FULL_DATA = SubsetSchedule(first=1 << 62)


@dataclass
class RegionFit:
    """The fitted BRDF of one region, and how the fit went."""

    model: str
    options: dict
    params: dict
    loss: float
    samples: int
    seconds: float
    status: str
    reason: str
    iterations: int
    #: (seconds, loss, samples): after each accepted step, the loss on the
    #: stage's subset scaled to the full set, and the subset's size
    history: list = field(default_factory=list)
    #: parameter -> ``{"std", "interval95"}`` or ``{"status"}``
    #: (:func:`mifaces.reflectance.fit.intervals.parameter_intervals`); empty if not estimated
    uncertainty: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        d = asdict(self)
        d["history"] = [[round(t, 6), float(e), int(n)] for t, e, n in self.history]
        return d

def validate_samples(light, view, reflectance, sigma) -> None:
    """Shapes agree and nothing is NaN; raises ValueError naming the array."""
    n = len(sigma)
    for name, a, shape in [("light", light, (n, 3)), ("view", view, (n, 3)),
                           ("reflectance", reflectance, (n, 3)), ("sigma", sigma, (n,))]:
        if np.shape(a) != shape:
            raise ValueError(f"{name} must have shape {shape}, got {np.shape(a)}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} contains {np.count_nonzero(~np.isfinite(a))} NaN or infinite values")
    if np.any(sigma <= 0):
        raise ValueError("sigma must be positive (it is a confidence scale, 1/weight)")


def check_footprint(footprint, n: int) -> np.ndarray:
    """``footprint`` as (n, 3) float64 covariances (tt, tb, bb); a ValueError unless it has that
    shape, is finite and each is positive semi-definite."""
    footprint = np.asarray(footprint, np.float64)
    if footprint.shape != (n, 3):
        raise ValueError(f"footprint must have shape {(n, 3)}, got {footprint.shape}")
    if not np.all(np.isfinite(footprint)):
        raise ValueError(f"footprint contains {np.count_nonzero(~np.isfinite(footprint))} NaN or infinite values")
    tt, tb, bb = footprint.T
    if np.any(tt < 0) or np.any(bb < 0) or np.any(tt * bb - tb * tb < -1e-5 * tt * bb - 1e-30):  # float32 rounding
        raise ValueError("footprint must hold covariances (tt, tb, bb): tt, bb >= 0 and tt·bb >= tb²")
    return footprint


@dataclass(frozen=True, eq=False)
class RegionSamples:
    """The reflectance samples one fit takes (paper eq. 5): N samples' arrays, as float32, validated
    on construction (shapes agree, nothing NaN, σ positive; a ``ValueError`` names the array).

    Attributes
    ----------
    light, view : ndarray (N, 3)
        l̂ and v̂ in the local shading frame (z = normal).
    reflectance : ndarray (N, 3)
        r, scaled so that a white Lambertian target is 1 (r = π f).
    sigma : ndarray (N,)
        Confidence σ of each sample (eq. 9/10); weights are 1/σ².
    footprint : ndarray (N, 3) float64, optional
        The covariance of each sample's normal tilt over its pixel
        (:attr:`~mifaces.reflectance.samples.ReflectanceSamples.footprint`): the model is averaged
        over it (:func:`~mifaces.reflectance.footprint.tilted`). None: point samples.
    texel : ndarray (N,), optional
        Each sample's texel, for a fit with an albedo per texel (:attr:`RegionFitOptions.texel_albedo`).
    """

    light: np.ndarray
    view: np.ndarray
    reflectance: np.ndarray
    sigma: np.ndarray
    footprint: np.ndarray | None = None
    texel: np.ndarray | None = None

    def __post_init__(self):
        for name in ("light", "view", "reflectance", "sigma"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), np.float32))
        validate_samples(self.light, self.view, self.reflectance, self.sigma)
        if self.footprint is not None:
            object.__setattr__(self, "footprint", check_footprint(self.footprint, len(self.sigma)))
        if self.texel is not None and np.shape(self.texel) != np.shape(self.sigma):
            raise ValueError(f"texel must have shape {np.shape(self.sigma)}, got {np.shape(self.texel)}")

    def __len__(self) -> int:
        return len(self.sigma)

    @classmethod
    def of(cls, samples: ReflectanceSamples) -> RegionSamples:
        """The arrays of ``samples`` (:class:`~mifaces.reflectance.samples.ReflectanceSamples`) a fit takes."""
        return cls(samples.light, samples.view, samples.reflectance, samples.sigma, footprint=samples.footprint,
                   texel=samples.texel)


@dataclass(frozen=True)
class RegionFitOptions:
    """How :func:`fit_region` fits (and :func:`~mifaces.reflectance.fit.regions.fit_regions` every
    region), validated on construction.

    Attributes
    ----------
    fixed, bounds : dict, optional
        See :class:`ParameterSpace`; ``fixed`` defaults to the model's
        :meth:`~mifaces.brdf.model.BRDFModel.fixed_defaults`.
    schedule : SubsetSchedule, optional
        The subset hierarchy (default ``SubsetSchedule()``); :data:`FULL_DATA` fits all samples at once.
    seed : int
        Seed of the random subsets (and of the start search and the bootstrap).
    ftol : float
        Relative loss decrease that ends the last stage.
    texel_albedo : bool
        Give every texel (:attr:`RegionSamples.texel`) its own albedo, eliminated from the
        problem (:meth:`~mifaces.reflectance.fit.problem.Problem.system`), so that the glossy
        part is measured from each texel's variation between photographs, whatever the albedo
        texture; the region's ``diffuse_reflectance`` is the weighted mean of the texels' albedos.
        Its intervals come from the projected sums, over :attr:`Uncertainty.cluster` (which must
        hold each texel's samples whole; :mod:`mifaces.reflectance.fit.texel_uncertainty`); not
        with the bootstrap or :attr:`Uncertainty.offsets`.
    """

    fixed: dict | None = None
    bounds: dict | None = None
    schedule: SubsetSchedule | None = None
    seed: int = option(0, bounds=(0, None))
    ftol: float = option(1e-7, bounds=(0.0, None))
    texel_albedo: bool = False

    def __post_init__(self):
        check(self)


@dataclass(frozen=True, eq=False)
class Uncertainty:
    """How a fit's parameter uncertainty (:attr:`RegionFit.uncertainty`) is estimated at the optimum
    (:func:`~mifaces.reflectance.fit.uncertainty.region_uncertainty`); the method is validated on
    construction.

    Attributes
    ----------
    method : str
        One of :data:`~mifaces.reflectance.fit.uncertainty.METHODS`.
    cluster : ndarray (N,), optional
        Cluster of each sample for the sandwich, jackknife and bootstrap (e.g.
        :func:`~mifaces.reflectance.fit.uncertainty.tile_clusters`); default: the samples independent
        (:func:`~mifaces.reflectance.fit.uncertainty.independent_clusters`).
    offsets : AlbedoOffsets, optional
        The per-texel albedo offsets the reflectance was corrected by (``FitOptions(albedo_rounds=k)``):
        the jackknife and the sandwich then re-estimate them with each cluster left out
        (:func:`~mifaces.reflectance.fit.offset_uncertainty.offset_sums`; every texel's samples must
        lie in one cluster); Laplace and the bootstrap take them as known.
    """

    method: str = option(METHODS[0], choices=METHODS)
    cluster: np.ndarray | None = None
    offsets: AlbedoOffsets | None = None

    def __post_init__(self):
        check(self)

    def select(self, mask) -> Uncertainty:
        """The same estimate for the samples ``mask`` selects (their clusters and offsets)."""
        return dataclasses.replace(self, cluster=None if self.cluster is None else np.asarray(self.cluster)[mask],
                                   offsets=None if self.offsets is None else self.offsets[mask])


def min_samples(model: BRDFModel, fixed: dict | None = None) -> int:
    """Fewest samples a region needs for its own fit: 10 per free parameter."""
    return 10 * len(ParameterSpace(model, fixed))


def fit_region(model: BRDFModel | str, samples: RegionSamples, *, start: dict | None = None,
               options: RegionFitOptions | None = None, uncertainty: Uncertainty | None = Uncertainty(),
               trace: list | None = None) -> RegionFit:
    """Fit ``model`` to one region's samples by hierarchical Levenberg-Marquardt.

    Parameters
    ----------
    model : BRDFModel or str
        A model from :mod:`mifaces.brdf`, or its name with default options.
    samples : RegionSamples
        The region's samples: l̂, v̂, r, σ (and each one's footprint and texel, where given).
    start : dict, optional
        Initial values; the rest come from :func:`linear_start`. A start that gives every
        free glossy parameter is taken for a measurement (a previous fit's optimum): a fit
        that does not move from it is not flagged ``'at_start'``.
    options : RegionFitOptions, optional
        The fixed parameters and bounds, the subset hierarchy, its seed and tolerance, an albedo per
        texel (default ``RegionFitOptions()``).
    uncertainty : Uncertainty or None
        How :attr:`RegionFit.uncertainty` is estimated at the optimum (by default the jackknife over
        the samples taken as independent); None leaves it out.
    trace : list, optional
        If given, receives (seconds, parameter values) after every accepted
        step, for reports that evaluate the full-data loss along the way.

    Returns
    -------
    RegionFit
        Parameters, the loss E of eq. 8 on all samples, status, history and
        the parameters' uncertainty.
    """
    t0 = time.perf_counter()
    model = brdf_models.model(model) if isinstance(model, str) else model
    options = options or RegionFitOptions()
    light, view, reflectance, sigma, footprint = (samples.light, samples.view, samples.reflectance, samples.sigma,
                                                  samples.footprint)
    cluster = None if uncertainty is None else uncertainty.cluster
    if cluster is not None and np.shape(cluster) != np.shape(sigma):
        raise ValueError(f"cluster must have shape {np.shape(sigma)}, got {np.shape(cluster)}")
    fixed, seed = model.fixed_defaults() if options.fixed is None else options.fixed, options.seed
    given = {k for k, v in (start or {}).items() if v is not None}
    measured_start = {q.name for q in model.parameters() if q.name not in fixed
                      and q.name != DIFFUSE_PARAMETER.name} <= given
    if not {q.name for q in model.parameters() if q.name not in fixed} <= given:  # a search for what is missing
        start = {**linear_start(model, light, view, reflectance, sigma, fixed, seed=seed), **(start or {})}
    order = np.random.default_rng(seed).permutation(len(sigma))
    texel = None
    if options.texel_albedo:
        if uncertainty is not None and (uncertainty.offsets is not None or uncertainty.method == "bootstrap"):
            raise ValueError("a fit with a free albedo per texel (texel_albedo) takes no albedo offsets and no "
                             "bootstrap: its albedos are its own")
        if samples.texel is None:
            raise ValueError("a fit with a free albedo per texel (texel_albedo) needs each sample's texel "
                             "(RegionSamples.texel)")
        texel = np.asarray(samples.texel)
        fixed = {**fixed, DIFFUSE_PARAMETER.name: [0.0, 0.0, 0.0]}  # per texel instead, eliminated from the problem
        # the subsets take whole texels: a texel's single sample says nothing of the glossy part
        _, rank = np.unique(texel, return_inverse=True)
        order = np.argsort(np.random.default_rng(seed).permutation(rank.max() + 1)[rank], kind="stable")
    space = ParameterSpace(model, fixed, options.bounds)
    if len(sigma) < len(space):
        raise ValueError(f"{model.name} has {len(space)} free parameters but only {len(sigma)} samples were given")
    x = x_start = space.vector({k: v for k, v in start.items() if k not in fixed})
    schedule, ftol = options.schedule or SubsetSchedule(), options.ftol
    history, iterations, result = [], 0, None
    sizes = schedule.sizes(len(sigma))
    for stage, size in enumerate(sizes):
        idx = np.sort(order[:size])
        problem = Problem(model, space, light[idx], view[idx], reflectance[idx], sigma[idx],
                          footprint=None if footprint is None else footprint[idx],
                          texel=None if texel is None else texel[idx])
        last = stage == len(sizes) - 1
        result = levenberg_marquardt(None, None, x, system=problem.system,
                                     max_iterations=schedule.final_iterations if last else schedule.iterations,
                                     ftol=ftol if last else max(ftol, schedule.stage_ftol), clock_start=t0)
        x = result.x
        iterations += result.iterations
        history += [(t, e * len(sigma) / size, size) for t, e, _ in result.history]
        if trace is not None:
            trace += [(t, space.values(xs)) for t, _, xs in result.history]
    params, loss, reason, status = space.values(x), result.loss, result.reason, result.status
    if texel is not None:
        params[DIFFUSE_PARAMETER.name] = [float(v) for v in problem.texel_albedo(x)]
    bounded = space.at_bounds(x)
    if bounded and status == CONVERGED:
        # the best fit lies outside the valid range: the samples do not support this model there
        status, reason = AT_BOUND, f"{reason}; at the bound of its range: {', '.join(bounded)}"
    elif not measured_start and space.glossy_unchanged(x_start, x):
        # the solver never moved the glossy part: its values are the start's, not a measurement
        status, reason = AT_START, f"{reason}; the glossy parameters stayed at their start values"
    pruned = []
    if len(model.lobe_scales()) > 1:
        params, loss, pruned = prune_lobes(model, space, problem, params, loss)
        if pruned:
            reason += f"; lobe(s) {pruned} explained no sample and were set to zero"
    # the lobe whose width the model names (its first), if it still reflects anything, as a spike
    first = model.lobe_scales().get(1, ())
    if any(np.any(np.asarray(params.get(s, 0.0)) != 0) for s in first) and space.at_spike(x):
        status, reason = AT_BOUND, f"{reason}; {SPIKE}"
    intervals = {}
    if uncertainty is not None:
        data = (light, view, reflectance, sigma, footprint)
        intervals = region_uncertainty(space, problem, params, pruned, cluster, uncertainty.method, data, seed,
                                       offsets=uncertainty.offsets)
    return RegionFit(model=model.name, options=dict(model.options), params=params, loss=loss,
                     samples=len(sigma), seconds=time.perf_counter() - t0, status=status,
                     reason=reason, iterations=iterations, history=history, uncertainty=intervals)


__all__ = ["SubsetSchedule", "FULL_DATA", "RegionFit", "validate_samples", "check_footprint", "RegionSamples",
           "RegionFitOptions", "Uncertainty", "min_samples", "fit_region"]
