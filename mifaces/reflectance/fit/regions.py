"""Fitting an analytic BRDF model to reflectance samples (paper sec. 5.1-5.2).

For one region, minimise the weighted error of eq. 8,

    E(a) = ½ Σ_s |r_s - π f_a(l̂_s, v̂_s)|² / σ_s²,

where r is the reflectance scaled so that a white Lambertian target has
r = 1 (so the model predicts π f; f without cosine, see
:mod:`mifaces.brdf.model`) and σ the confidence of eq. 9/10. The model is
evaluated by the same Dr.Jit functions the plugins use; its Jacobian comes
from Dr.Jit's forward mode (a tangent per free parameter), and the normal
equations are summed in the same kernel, one pass over the samples per step
(:class:`_Problem`); the steps are Levenberg-Marquardt
(:mod:`mifaces.reflectance.fit.levenberg_marquardt`) on random subsets of growing size, each stage starting from the previous result (the paper's
hierarchy). Parameters are kept in their valid ranges by reparameterisation:
p = lo + (hi - lo)·sigmoid(x), or its logarithmic form for parameters that
span decades (roughness, α, exponents).
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import asdict, dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ... import brdf as brdf_models
from ...brdf.model import BRDFModel
from ...progress import progress as progress_bar
from ...arrays import device_array
from ...status import AT_BOUND, AT_START, CONVERGED, DEFAULTS, PRIOR
from ..maps.diffuse import AlbedoOffsets
from .levenberg_marquardt import levenberg_marquardt
from .parameters import ParameterSpace, conservative_start, linear_start
from .uncertainty import (BOOTSTRAP_DRAWS, METHODS, NOT_IDENTIFIED, PRUNED, Covariance, cluster_index, covariance,
                          held_entries, independent_clusters, offset_sums, parameter_intervals, prior_intervals)


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
    #: (:func:`mifaces.reflectance.fit.uncertainty.parameter_intervals`); empty if not estimated
    uncertainty: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        d = asdict(self)
        d["history"] = [[round(t, 6), float(e), int(n)] for t, e, n in self.history]
        return d


class _Problem:
    """Residuals (r - π f)/σ of one set of samples, evaluated with Dr.Jit.

    :meth:`system` and :meth:`loss` are one kernel each over the samples: the
    model, its derivatives by forward mode (one tangent per free parameter, all
    in the same kernel) and the sums of the normal equations, accumulated in
    float64 (:func:`_sums`), frozen per model, parameter space and sample count
    (``dr.freeze``), so a step replays the kernel instead of tracing the model again.
    """

    def __init__(self, model, space, light, view, reflectance, sigma):
        self.model, self.space = model, space
        # in Dr.Jit's own memory (device_array): a mapped NumPy array's alignment would enter the kernels
        self.wi = mi.Vector3f(*(device_array(np.float32, light[:, k]) for k in range(3)))
        self.wo = mi.Vector3f(*(device_array(np.float32, view[:, k]) for k in range(3)))
        self.r = mi.Color3f(*(device_array(np.float32, reflectance[:, k]) for k in range(3)))
        self.w = device_array(np.float32, 1.0 / np.asarray(sigma, np.float32))
        self.n = len(sigma)
        key = _signature(space)
        if key not in _FROZEN:
            def sums(arrays, u, jacobian):
                return _sums(space, arrays, u, jacobian)

            _FROZEN[key] = dr.freeze(sums, warn_after=1000,  # one recording per sample count
                                     state_fn=lambda arrays, u, jacobian: (dr.width(arrays["w"]), jacobian))
        self._sums = _FROZEN[key]

    def _residuals(self, u):
        params = self.space.drjit_params(u)
        return (self.r - dr.pi * self.model.eval(self.wi, self.wo, params)) * self.w

    def _run(self, x, jacobian: bool) -> np.ndarray:
        arrays = {"wi": self.wi, "wo": self.wo, "r": self.r, "w": self.w}
        # opaque scalars: the kernel does not depend on the parameters' values
        return np.asarray(self._sums(arrays, [dr.opaque(mi.Float, float(v)) for v in x], jacobian), np.float64)

    def loss(self, x) -> float:
        """½ Σ r², accumulated in float64."""
        return float(self._run(x, False)[0])

    def system(self, x):
        """``(JᵀJ, Jᵀr, ½ Σ r²)`` (float64) at ``x``, in one pass over the samples."""
        values, p = self._run(x, True), len(x)
        jtj = np.zeros((p, p))
        rows, cols = np.triu_indices(p)
        jtj[rows, cols] = values[1:1 + len(rows)]
        jtj[cols, rows] = values[1:1 + len(rows)]
        return jtj, values[1 + len(rows):], float(values[0])

    def cluster_sums(self, x, cluster: np.ndarray, groups: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Per cluster g, the score u_g = Σ_{i ∈ g} J_iᵀ ρ_i (G, P) and H_g = Σ_{i ∈ g} J_iᵀ J_i
        (G, P, P), summed over the colour channels, and the loss ½ Σ |ρ|², at ``x``; ``cluster``
        (N,) numbers the clusters 0 … ``groups`` - 1 (JᵀJ = Σ_g H_g). One kernel (frozen per
        parameter space as :meth:`system`'s is), whose sums stay on the Dr.Jit side: for the
        covariance (:mod:`mifaces.reflectance.fit.uncertainty`), once per fit."""
        p = len(x)
        sums = self._group_sums("clusters", _cluster_sums, x, cluster, groups, 1 + p + p * (p + 1) // 2)
        hg = np.zeros((groups, p, p))
        rows, cols = np.triu_indices(p)
        hg[:, rows, cols] = sums[:, 1 + p:]
        hg[:, cols, rows] = sums[:, 1 + p:]
        return sums[:, 1:1 + p], hg, 0.5 * float(sums[:, 0].sum())

    def texel_sums(self, x, texel: np.ndarray, groups: int) -> tuple[np.ndarray, np.ndarray]:
        """Per texel t, W_t = Σ_{i ∈ t} 1/σ_i² (T,) and S_t = Σ_{i ∈ t} J_i/σ_i per colour channel
        (T, 3, P), at ``x``; ``texel`` (N,) numbers the texels 0 … ``groups`` - 1. What the
        offsets' part of the uncertainty needs (:func:`mifaces.reflectance.fit.uncertainty.offset_sums`):
        one kernel as :meth:`cluster_sums`'s, once per fit with ``albedo_rounds``."""
        p = len(x)
        sums = self._group_sums("texels", _texel_sums, x, texel, groups, 1 + 3 * p)
        return sums[:, 0], sums[:, 1:].reshape(groups, 3, p)

    def _group_sums(self, name: str, kernel, x, group: np.ndarray, groups: int, width: int) -> np.ndarray:
        """``kernel(space, arrays, u, groups)``'s per-group sums at ``x`` for the samples' ``group``
        (N,) numbers 0 … ``groups`` - 1, as a (groups, width) float64 array: one kernel, frozen per
        parameter space and ``name``."""
        key = (name,) + _signature(self.space)
        if key not in _FROZEN:
            space = self.space
            _FROZEN[key] = dr.freeze(lambda arrays, u, g: kernel(space, arrays, u, g), warn_after=1000,
                                     state_fn=lambda arrays, u, g: (dr.width(arrays["w"]), g))
        arrays = {"wi": self.wi, "wo": self.wo, "r": self.r, "w": self.w,
                  "c": device_array(np.uint32, np.asarray(group, np.uint32))}
        sums = _FROZEN[key](arrays, [dr.opaque(mi.Float, float(v)) for v in x], int(groups))
        return np.asarray(sums, np.float64).reshape(groups, width)

    def residuals_and_jacobian(self, x):
        """The residuals (M,) and their Jacobian (M, P), float32, on the host (for solvers that
        want them; :meth:`system` is what the fits use)."""
        u = [dr.opaque(mi.Float, float(v)) for v in x]
        dr.enable_grad(u)
        res = self._residuals(u)
        dr.eval(res)
        r = np.array(dr.detach(res)).ravel()
        jac = np.empty((r.size, len(u)), dtype=np.float32)
        for k, uk in enumerate(u):
            dr.forward_from(uk, flags=dr.ADFlag.ClearVertices)
            jac[:, k] = np.array(dr.grad(res)).ravel()
            dr.clear_grad(res)
        return r, jac


#: The frozen :func:`_sums` per parameter space (:func:`_signature`).
_FROZEN: dict = {}


def _signature(space: ParameterSpace) -> tuple:
    """What the kernel of a parameter space depends on: the model and its options, the fixed
    values (literals of the code) and the free parameters with their ranges."""
    return (mi.variant(), space.model.name, repr(sorted(dict(space.model.options).items())),
            repr(sorted(space.fixed.items())),
            tuple((f.name, f.channel, f.lower, f.upper, f.log) for f in space.free))


def _sums(space: ParameterSpace, arrays: dict, u: list, jacobian: bool):
    """``[½ Σ r², (JᵀJ)_ab for a <= b (row-major upper triangle), (Jᵀr)_a]`` as one float64
    array, summed over the samples and colour channels of the residuals
    ``(r - π f)/σ`` of ``arrays`` (``wi``, ``wo``, ``r``, ``w``) at the free variables ``u``;
    without ``jacobian`` only the first entry. One kernel: the derivatives are forward-mode
    tangents of the same expression, the sums scatter-adds into a small array (per-thread
    copies on the LLVM backend, ``dr.ReduceMode.Expand``)."""
    n, p = dr.width(arrays["w"]), len(u)
    r, d = _residual_tangents(space, arrays, u, tangents=jacobian)
    sums = [0.5 * (r[0] * r[0] + r[1] * r[1] + r[2] * r[2])]
    if jacobian:
        sums += [d[a][0] * d[b][0] + d[a][1] * d[b][1] + d[a][2] * d[b][2] for a in range(p) for b in range(a, p)]
        sums += [d[a][0] * r[0] + d[a][1] * r[1] + d[a][2] * r[2] for a in range(p)]
    return _group_scatter(sums, dr.zeros(mi.UInt32, n), 1)  # one group: every sample


#: Largest per-cluster sum array (float64 entries) summed with a per-thread copy (``dr.ReduceMode.Expand``).
EXPAND_LIMIT = 1 << 16


def _residual_tangents(space: ParameterSpace, arrays: dict, u: list, tangents: bool = True) -> tuple[list, list]:
    """The residuals ``(r - π f)/σ`` of ``arrays`` (``wi``, ``wo``, ``r``, ``w``; three float64
    channels) and, with ``tangents``, their forward-mode tangents along each unconstrained
    parameter ``u[a]`` (``d[a][c]``; else none)."""
    if tangents:
        dr.enable_grad(u)
    res = (arrays["r"] - dr.pi * space.model.eval(arrays["wi"], arrays["wo"], space.drjit_params(u))) * arrays["w"]
    r = [mi.Float64(c) for c in dr.detach(res)]
    d = []
    for uk in u if tangents else ():
        dr.forward_from(uk, flags=dr.ADFlag.ClearVertices)
        d.append([mi.Float64(c) for c in dr.grad(res)])
        dr.clear_grad(res)
    return r, d


def _group_scatter(terms: list, group, groups: int):
    """``terms`` (per-sample float64 arrays) summed per group ``group`` into one array of ``groups``
    rows of ``len(terms)``. Neighbouring samples share a group: per-thread copies of a small array,
    else atomics reduced per packet. One kernel."""
    k = len(terms)
    acc = dr.zeros(mi.Float64, groups * k)
    base = group * k
    mode = dr.ReduceMode.Expand if groups * k <= EXPAND_LIMIT else dr.ReduceMode.Local
    for j, value in enumerate(terms):
        dr.scatter_add(acc, value, base + j, mode=mode)
    dr.eval(acc)
    return acc


def _cluster_sums(space: ParameterSpace, arrays: dict, u: list, groups: int):
    """``[Σ |ρ|², u_g (P entries), H_g (upper triangle, row-major)]`` per cluster ``arrays["c"]`` as one
    float64 array of ``groups`` rows: the residuals ``(r - π f)/σ`` and their forward-mode
    tangents (as in :func:`_sums`), scatter-added per cluster. One kernel."""
    r, d = _residual_tangents(space, arrays, u)
    p = len(u)
    terms = [r[0] * r[0] + r[1] * r[1] + r[2] * r[2]]
    terms += [d[a][0] * r[0] + d[a][1] * r[1] + d[a][2] * r[2] for a in range(p)]
    terms += [d[a][0] * d[b][0] + d[a][1] * d[b][1] + d[a][2] * d[b][2] for a in range(p) for b in range(a, p)]
    return _group_scatter(terms, arrays["c"], groups)


def _texel_sums(space: ParameterSpace, arrays: dict, u: list, groups: int):
    """``[Σ 1/σ², Σ J_c/σ for channel c and free entry a (row-major)]`` per texel ``arrays["c"]``
    as one float64 array of ``groups`` rows (J the forward-mode tangents of the residuals
    ``(r - π f)/σ``, as in :func:`_cluster_sums`). One kernel."""
    _, d = _residual_tangents(space, arrays, u)
    w = mi.Float64(arrays["w"])
    terms = [w * w] + [w * d[a][c] for c in range(3) for a in range(len(u))]
    return _group_scatter(terms, arrays["c"], groups)


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


def min_samples(model: BRDFModel, fixed: dict | None = None) -> int:
    """Fewest samples a region needs for its own fit: 10 per free parameter."""
    return 10 * len(ParameterSpace(model, fixed))


def fit_region(model: BRDFModel | str, light, view, reflectance, sigma, *, start: dict | None = None,
               fixed: dict | None = None, bounds: dict | None = None, schedule: SubsetSchedule | None = None,
               seed: int = 0, ftol: float = 1e-7, trace: list | None = None, cluster=None,
               uncertainty: str | None = METHODS[0], offsets: AlbedoOffsets | None = None) -> RegionFit:
    """Fit ``model`` to one region's samples by hierarchical Levenberg-Marquardt.

    Parameters
    ----------
    model : BRDFModel or str
        A model from :mod:`mifaces.brdf`, or its name with default options.
    light, view : ndarray (N, 3)
        l̂ and v̂ in the local shading frame (z = normal).
    reflectance : ndarray (N, 3)
        r, scaled so that a white Lambertian target is 1 (r = π f).
    sigma : ndarray (N,)
        Confidence σ of each sample (eq. 9/10); weights are 1/σ².
    start : dict, optional
        Initial values; the rest come from :func:`linear_start`.
    fixed, bounds : dict, optional
        See :class:`ParameterSpace`; ``fixed`` defaults to the model's
        :meth:`~mifaces.brdf.model.BRDFModel.fixed_defaults`.
    schedule : SubsetSchedule, optional
        The subset hierarchy; :data:`FULL_DATA` fits all samples at once.
    seed : int
        Seed of the random subsets.
    trace : list, optional
        If given, receives (seconds, parameter values) after every accepted
        step, for reports that evaluate the full-data loss along the way.
    cluster : ndarray (N,), optional
        Cluster of each sample for the sandwich and bootstrap covariance (e.g.
        :func:`~mifaces.reflectance.fit.uncertainty.tile_clusters`); default: the
        samples independent (:func:`~mifaces.reflectance.fit.uncertainty.independent_clusters`).
    uncertainty : str or None
        How :attr:`RegionFit.uncertainty` is estimated at the optimum, one of
        :data:`~mifaces.reflectance.fit.uncertainty.METHODS`; None leaves it out.
    offsets : AlbedoOffsets, optional
        The per-texel albedo offsets ``reflectance`` was corrected by (``fit_brdf(...,
        albedo_rounds=k)``): the jackknife and the sandwich then re-estimate them with
        each cluster left out (:func:`~mifaces.reflectance.fit.uncertainty.offset_sums`;
        every texel's samples must lie in one cluster); Laplace and the bootstrap
        take them as known.

    Returns
    -------
    RegionFit
        Parameters, the loss E of eq. 8 on all samples, status, history and
        the parameters' uncertainty.
    """
    t0 = time.perf_counter()
    model = brdf_models.model(model) if isinstance(model, str) else model
    light, view = np.asarray(light, np.float32), np.asarray(view, np.float32)
    reflectance, sigma = np.asarray(reflectance, np.float32), np.asarray(sigma, np.float32)
    validate_samples(light, view, reflectance, sigma)
    if uncertainty is not None and uncertainty not in METHODS:
        raise ValueError(f"uncertainty must be one of {METHODS} or None, got {uncertainty!r}")
    if cluster is not None and np.shape(cluster) != np.shape(sigma):
        raise ValueError(f"cluster must have shape {np.shape(sigma)}, got {np.shape(cluster)}")
    fixed = model.fixed_defaults() if fixed is None else fixed
    space = ParameterSpace(model, fixed, bounds)
    if len(sigma) < len(space):
        raise ValueError(f"{model.name} has {len(space)} free parameters but only {len(sigma)} samples were given")
    start = {**linear_start(model, light, view, reflectance, sigma, fixed, seed=seed), **(start or {})}
    x = x_start = space.vector(start)
    schedule = schedule or SubsetSchedule()
    order = np.random.default_rng(seed).permutation(len(sigma))
    history, iterations, result = [], 0, None
    sizes = schedule.sizes(len(sigma))
    for stage, size in enumerate(sizes):
        idx = np.sort(order[:size])
        problem = _Problem(model, space, light[idx], view[idx], reflectance[idx], sigma[idx])
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
    bounded = space.at_bounds(x)
    if bounded and status == CONVERGED:
        # the best fit lies outside the valid range: the samples do not support this model there
        status, reason = AT_BOUND, f"{reason}; at the bound of its range: {', '.join(bounded)}"
    elif space.glossy_unchanged(x_start, x):
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
        data = (light, view, reflectance, sigma)
        intervals = region_uncertainty(space, problem, params, pruned, cluster, uncertainty, data, seed,
                                       offsets=offsets)
    return RegionFit(model=model.name, options=dict(model.options), params=params, loss=loss,
                     samples=len(sigma), seconds=time.perf_counter() - t0, status=status,
                     reason=reason, iterations=iterations, history=history, uncertainty=intervals)


def region_uncertainty(space: ParameterSpace, problem: _Problem, params: dict, pruned: list, cluster,
                       method: str, data: tuple, seed: int = 0, offsets: AlbedoOffsets | None = None) -> dict:
    """The parameters' uncertainty at the optimum ``params`` of ``problem`` (all
    the region's samples), by ``method``
    (:mod:`mifaces.reflectance.fit.uncertainty`): the clusters' sums (and JᵀJ, E) from
    one kernel pass at the optimum; the bootstrap refits instead.
    ``pruned`` lobes' scales and exponents get the status ``pruned``; ``data``
    is the region's (light, view, reflectance, sigma), for the bootstrap; ``offsets``
    the albedo offsets the reflectance was corrected by (:func:`fit_region`)."""
    x = space.vector(params)
    held = held_entries(space, x)
    model, statuses = space.model, {}
    names = {s for j in pruned for s in model.lobe_scales()[j]}
    names |= {space.coupled[s] for s in names if s in space.coupled}
    for k, f in enumerate(space.free):
        if f.name in names:
            held[k], statuses[k] = True, PRUNED
    # a lobe whose every scale sits at 0 has no width to measure
    t = 0.5 * (1.0 + np.tanh(0.5 * x))
    for j, scales in model.lobe_scales().items():
        entries = [k for k, f in enumerate(space.free) if f.name in scales]
        width = _lobe_width(space, j, scales)
        if entries and all(held[k] and t[k] < 0.5 for k in entries) and width is not None:
            for k, f in enumerate(space.free):
                if f.name == width and not held[k]:
                    held[k], statuses[k] = True, NOT_IDENTIFIED
    if method == "bootstrap":
        cov = bootstrap_covariance(space, x, held, cluster, data, seed=seed)
    else:
        index, groups = cluster_index(independent_clusters(problem.n) if cluster is None else cluster)
        u, hg, loss = problem.cluster_sums(x, index, groups)  # one pass: JᵀJ = Σ_g H_g
        terms = None
        if offsets is not None and method != "laplace":
            texel, texels = cluster_index(offsets.texel)
            weight, jsum = problem.texel_sums(x, texel, texels)
            terms = offset_sums(texel, index, groups, weight, jsum, offsets.shrinkage, offsets.offsets)
        cov = covariance(x, hg.sum(axis=0), loss, problem.n, u, hg, held, method, offsets=terms)
    return parameter_intervals(space, cov, statuses)


def _lobe_width(space: ParameterSpace, lobe: int, scales: tuple) -> str | None:
    """The parameter that sets lobe ``lobe``'s width: its scales' exponent (Lafortune), or the
    model's :attr:`~mifaces.brdf.model.BRDFModel.WIDTH_GRID` parameter for the first lobe."""
    for name in scales:
        if name in space.coupled:
            return space.coupled[name]
    grid = space.model.WIDTH_GRID
    return grid[0] if lobe == 1 and grid is not None else None


def bootstrap_covariance(space: ParameterSpace, x, held, cluster, data: tuple, draws: int = BOOTSTRAP_DRAWS,
                         iterations: int = 10, seed: int = 0) -> Covariance:
    """Cov(x̂) from ``draws`` refits on clusters drawn with replacement (a
    cluster drawn m times weighs m times: σ/√m), each started at ``x`` with at
    most ``iterations`` LM steps; ``held`` entries are left out."""
    light, view, reflectance, sigma = data
    cluster = independent_clusters(len(sigma)) if cluster is None else np.asarray(cluster)
    index, g = cluster_index(cluster)
    rng = np.random.default_rng(seed)
    xs = []
    for _ in range(draws):
        m = np.bincount(rng.integers(0, g, g), minlength=g)[index]
        keep = m > 0
        problem = _Problem(space.model, space, light[keep], view[keep], reflectance[keep],
                           sigma[keep] / np.sqrt(m[keep]))
        xs.append(levenberg_marquardt(None, None, x, system=problem.system, max_iterations=iterations,
                                      ftol=1e-6).x)
    free = ~np.asarray(held, bool)
    cov = np.zeros((len(x), len(x)))
    if free.any():
        cov[np.ix_(free, free)] = np.atleast_2d(np.cov(np.array(xs)[:, free], rowvar=False))
    return Covariance(x=np.asarray(x, np.float64), covariance=cov, held=np.asarray(held, bool), dof=float(g - 1),
                      method="bootstrap")


def prune_lobes(model: BRDFModel, space: ParameterSpace, problem: _Problem, params: dict, loss: float,
                rtol: float = 1e-4) -> tuple[dict, float, list[int]]:
    """Zero the lobes the samples do not need, of a model with several.

    A lobe whose removal raises the loss by less than ``rtol`` (relative)
    explains no sample: typically it has drifted to a sharp spike where no
    sample lies, where it would only add a highlight no photograph showed.
    Such lobes get their scales (:meth:`~mifaces.brdf.model.BRDFModel.lobe_scales`,
    a Lafortune lobe's C_xy and C_z) set to 0; the plugin then leaves them
    out. Returns the parameters, their loss and the numbers of the lobes
    removed.
    """
    pruned = []
    for j, scales in model.lobe_scales().items():
        if any(name in space.fixed for name in scales):
            continue
        trial = {**params, **{name: [0.0] * 3 if model.parameter(name).kind == "rgb" else 0.0 for name in scales}}
        trial_loss = problem.loss(space.vector(trial))
        if np.isfinite(trial_loss) and trial_loss <= loss * (1 + rtol):
            params, loss = space.values(space.vector(trial)), min(loss, trial_loss)
            pruned.append(j)
    return params, loss, pruned


def prior_fit(model: BRDFModel, params: dict, samples: int, reason: str, status: str = PRIOR) -> RegionFit:
    """A region's BRDF taken from elsewhere: a fitted neighbour (status
    ``'prior'``) or the model's defaults (``status='defaults'``)."""
    return RegionFit(model=model.name, options=dict(model.options), params=params, loss=float("nan"),
                     samples=samples, seconds=0.0, status=status, reason=reason, iterations=0,
                     uncertainty=prior_intervals(params))


#: Why a fit whose lobe width ended at its sharp end is not trusted.
SPIKE = "the lobe became a spike at the sharp end of its width range"
#: A fitted glossy lobe whose peak reflectance (π f at the mirror direction, the brightest incidence
#: of a grid) exceeds this many times the region's brightest sample is a spike no photograph showed
#: (a narrow, strong lobe fitted to a few samples' noise; under a light the photographs did not cover
#: it would blow up): it is handled as one (:data:`SPIKE`).
PEAK_FACTOR = 5.0
#: Incidence angles (degrees) at which :func:`glossy_peak` evaluates the lobe at its mirror direction:
#: up to 40°, where photographs see highlights; towards grazing a true microfacet lobe rises far above
#: any sample (1 / (4 cos cos) and Fresnel), which says nothing about noise.
PEAK_ANGLES = (0.0, 20.0, 40.0)


def no_lobe(model: BRDFModel) -> dict:
    """The model's default parameters with every glossy lobe's scales at zero: what a region renders
    when nothing measured its glossy part and no region can lend one (status ``'defaults'``): no
    highlight rather than an invented one."""
    params = {**model.defaults(), **model.fixed_defaults()}
    for scales in model.lobe_scales().values():
        for name in scales:
            if name in params:
                params[name] = (np.zeros_like(np.asarray(params[name], np.float64)).tolist()
                                if np.ndim(params[name]) else 0.0)
    return params


def glossy_peak(model: BRDFModel, params: dict) -> float:
    """The largest π f_s(wi, mirror(wi)) of the glossy part over :data:`PEAK_ANGLES`, all
    channels: the brightest highlight the fitted lobe predicts, in the units of reflectance samples."""
    theta = np.radians(np.asarray(PEAK_ANGLES))
    wi = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)])
    wo = wi * np.array([[-1.0], [-1.0], [1.0]])
    values = {k: (mi.Color3f(*(float(c) for c in np.broadcast_to(np.asarray(v, np.float64), 3))) if np.ndim(v)
                  else mi.Float(float(v)))
              for k, v in params.items()}
    f = np.array(model.eval(mi.Vector3f(wi.astype(np.float32)), mi.Vector3f(wo.astype(np.float32)), values,
                            diffuse=False))
    return float(np.pi * np.nanmax(f)) if f.size else 0.0

#: Where a region without enough samples borrows its BRDF from, in order
#: (``skin`` is always the last resort).
NEIGHBOURS = {"lips": ["skin"], "nostrils": ["skin"], "beard": ["skin"], "eyes": ["skin"],
              "eyebrows": ["hair", "beard"], "hair": ["eyebrows", "beard"]}


def fit_regions(model: BRDFModel | str, light, view, reflectance, sigma, region, region_names: dict,
                neighbours: dict | None = None, progress: bool = False, fixed_by_region: dict | None = None,
                cluster=None, offsets: AlbedoOffsets | None = None, **options) -> dict[str, RegionFit]:
    """Fit ``model`` separately in every region (paper sec. 4.4, 5.2).

    ``region`` gives each sample's label, ``region_names`` label -> name.
    A region with fewer than :func:`min_samples` samples gets a warning and
    the parameters of its first fitted neighbour in ``neighbours`` (name ->
    names; default :data:`NEIGHBOURS`), else of ``skin``, else the model's
    defaults; its status is ``'prior'``. So does the glossy part of a region
    with fewer than 10x that many samples whose own fit ended at a bound of
    the parameters' range (status ``'at_bound'``); a larger region keeps such
    a fit, with a warning. Regions without samples are not
    fitted either. ``progress`` shows a bar over the regions fitted.
    ``fixed_by_region`` (name -> parameters) holds parameters fixed in one
    region on top of ``fixed``. A region that takes the model's defaults
    because no region has a fit to lend (skin's own fit a spike, say) has
    status ``'defaults'``, and a warning says so; a fit whose glossy
    parameters stayed at their start values measured nothing of them: it takes
    its neighbour's glossy part (status ``'prior'``, the reason says so) and
    lends nothing. ``cluster`` (N,) is each sample's cluster for the
    uncertainty, ``offsets`` the albedo offsets the reflectance was corrected by
    (:func:`fit_region`).
    """
    model = brdf_models.model(model) if isinstance(model, str) else model
    neighbours = NEIGHBOURS if neighbours is None else neighbours
    region = np.asarray(region)
    fixed = options.get("fixed")
    needed = min_samples(model, model.fixed_defaults() if fixed is None else fixed)
    counts = {name: int(np.count_nonzero(region == label)) for label, name in region_names.items()}
    fits: dict[str, RegionFit] = {}
    fitted = [(label, name) for label, name in region_names.items() if counts[name] >= needed]
    bar = progress_bar(fitted, desc=f"fitting {model.name}", unit="region", enabled=progress)
    held = {}  # region name -> its fixed parameters
    for label, name in bar:
        bar.set_postfix_str(f"{name}: {counts[name]} samples")
        mask = region == label
        region_options = dict(options)
        held[name] = model.fixed_defaults() if fixed is None else fixed
        if fixed_by_region and name in fixed_by_region:
            held[name] = region_options["fixed"] = {**held[name], **fixed_by_region[name]}
        fits[name] = fit_region(model, light[mask], view[mask], reflectance[mask], sigma[mask],
                                cluster=None if cluster is None else np.asarray(cluster)[mask],
                                offsets=None if offsets is None else offsets[mask], **region_options)
        peak = glossy_peak(model, fits[name].params)
        seen = float(np.max(reflectance[mask])) if mask.any() else 0.0
        if fits[name].status in (CONVERGED, AT_BOUND) and SPIKE not in fits[name].reason \
                and peak > PEAK_FACTOR * max(seen, 1e-6):
            # a lobe brighter than anything the photographs showed: fitted to a few samples' noise
            fits[name] = dataclasses.replace(fits[name], status=AT_BOUND, reason=(
                f"{fits[name].reason}; {SPIKE}: its peak (pi f = {peak:.3g}) is more than {PEAK_FACTOR:g} times "
                f"the brightest sample ({seen:.3g})"))
    def donor_of(name):
        # a neighbour's fit that is rendered as it stands can be lent: a converged one, or a large
        # region's fit at a bound that it keeps (never a spike, start values or defaults)
        donors = list(neighbours.get(name, [])) + ["skin"]
        return next((d for d in donors if d != name and d in fits and fits[d].status not in (AT_START, DEFAULTS)
                     and not (fits[d].status == AT_BOUND and (SPIKE in fits[d].reason or counts[d] < 10 * needed))),
                    None)

    # A fit whose glossy part never left its start values measured nothing of it: rendering those
    # (a Phong exponent of 1800, say) would invent a highlight. It takes a neighbour's glossy part,
    # keeping its own albedo, flagged 'prior' (the model's defaults, 'defaults', without a neighbour).
    def borrow(name, why):
        """Region ``name`` keeps its albedo and takes its donor's glossy part (or none), for ``why``."""
        donor = donor_of(name)
        glossy = fits[donor].params if donor else no_lobe(model)
        borrowed = {**glossy, **held[name], "diffuse_reflectance": fits[name].params["diffuse_reflectance"]}
        source = repr(donor) if donor else "no region: no glossy part"
        reason = f"{counts[name]} samples, and {why}: the glossy part of {source}"
        warnings.warn(f"region {name!r}: {reason}", stacklevel=3)
        fits[name] = prior_fit(model, borrowed, counts[name], reason, PRIOR if donor else DEFAULTS)

    for name in [n for n, fit in fits.items() if fit.status == AT_START]:
        borrow(name, f"{fits[name].reason.split('; ')[-1]} (not measured)")

    # A small region (fewer than 10x the samples a fit needs) whose best fit lies at a
    # bound of the valid range is more likely fitting noise than showing a material
    # the model cannot represent: it takes its neighbour's glossy part, keeping its own
    # albedo. A large one keeps its own fit, flagged at_bound, unless its lobe became a
    # spike (sharper than the grid resolves), which no photograph shows: any region does.
    for name in [n for n, fit in fits.items() if fit.status == AT_BOUND]:
        donor = donor_of(name)
        spike = SPIKE in fits[name].reason
        if not spike and (donor is None or counts[name] >= 10 * needed):
            warnings.warn(f"region {name!r}: the fit ended {fits[name].reason.split('; ')[-1]}", stacklevel=2)
            continue
        borrow(name, f"its own fit ended {fits[name].reason.split('; ')[-1]}")
    for label, name in region_names.items():
        if name in fits:
            continue
        donor = donor_of(name)
        params = fits[donor].params if donor else no_lobe(model)
        source = f"the fit of {donor!r}" if donor else "no region to borrow from: no glossy part"
        reason = f"{counts[name]} samples, fewer than the {needed} a {model.name} fit needs: {source}"
        if counts[name] > 0:
            warnings.warn(f"region {name!r}: {reason}", stacklevel=2)
        fits[name] = prior_fit(model, params, counts[name], reason, PRIOR if donor else DEFAULTS)
    return fits


__all__ = ["ParameterSpace", "SubsetSchedule", "FULL_DATA", "RegionFit", "fit_region", "fit_regions",
           "conservative_start", "linear_start", "prune_lobes", "min_samples", "NEIGHBOURS", "CONVERGED",
           "AT_BOUND", "AT_START", "DEFAULTS"]
