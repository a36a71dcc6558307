"""The frozen Levenberg-Marquardt problem of a region fit: the weighted residuals (r - π f)/σ of
one set of samples and the sums the solver and the uncertainty need, each one Dr.Jit kernel over the
samples (:class:`Problem`).

The model is evaluated by the same Dr.Jit functions the plugins use, averaged over each sample's
pixel footprint where the samples have one (:mod:`mifaces.reflectance.footprint`); its Jacobian comes from
Dr.Jit's forward mode (a tangent per free parameter), and the normal equations are summed in the
same kernel, one pass over the samples per step, accumulated in float64 (:func:`_sums`), frozen per
model, parameter space and sample count (``dr.freeze``).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ...runtime.arrays import device_array
from ..footprint import seen_by_pixel
from .parameters import ParameterSpace


class Problem:
    """Residuals (r - π f)/σ of one set of samples, evaluated with Dr.Jit.

    :meth:`system` and :meth:`loss` are one kernel each over the samples: the
    model, its derivatives by forward mode (one tangent per free parameter, all
    in the same kernel) and the sums of the normal equations, accumulated in
    float64 (:func:`_sums`), frozen per model, parameter space and sample count
    (``dr.freeze``), so a step replays the kernel instead of tracing the model again.
    """

    def __init__(self, model, space, light, view, reflectance, sigma, texel=None, footprint=None):
        self.model, self.space = model, space
        # in Dr.Jit's own memory (device_array): a mapped NumPy array's alignment would enter the kernels
        self.wi = mi.Vector3f(*(device_array(np.float32, light[:, k]) for k in range(3)))
        self.wo = mi.Vector3f(*(device_array(np.float32, view[:, k]) for k in range(3)))
        #: each sample's footprint (tt, tb, bb; :mod:`mifaces.reflectance.footprint`), or none: points
        self.spread = () if footprint is None else tuple(device_array(np.float32, np.asarray(footprint)[:, k])
                                                         for k in range(3))
        self.r = mi.Color3f(*(device_array(np.float32, reflectance[:, k]) for k in range(3)))
        self.w = device_array(np.float32, 1.0 / np.asarray(sigma, np.float32))
        self.n = len(sigma)
        key = _signature(space) + (bool(self.spread),)
        if key not in _FROZEN:
            def sums(arrays, u, jacobian):
                return _sums(space, arrays, u, jacobian)

            _FROZEN[key] = dr.freeze(sums, warn_after=1000,  # one recording per sample count
                                     state_fn=lambda arrays, u, jacobian: (dr.width(arrays["w"]), jacobian))
        self._sums = _FROZEN[key]
        #: with ``texel`` (N,): each texel's albedo is its own free parameter, eliminated (see :meth:`system`)
        self.texel_index, self.texels = None, 0
        self._texel_cache: dict = {}  # the texel sums of the last two points (:meth:`texel_sums`)
        if texel is not None:
            if np.shape(texel) != np.shape(sigma):
                raise ValueError(f"texel must have shape {np.shape(sigma)}, got {np.shape(texel)}")
            self.texel_index = np.unique(np.asarray(texel), return_inverse=True)[1]
            self.texels = int(self.texel_index.max()) + 1 if len(self.texel_index) else 0

    def _residuals(self, u):
        return (self.r - dr.pi * _model(self.space, self.wi, self.wo, self.spread, u)) * self.w

    def _run(self, x, jacobian: bool) -> np.ndarray:
        arrays = {"wi": self.wi, "wo": self.wo, "spread": self.spread, "r": self.r, "w": self.w}
        # opaque scalars: the kernel does not depend on the parameters' values
        return np.asarray(self._sums(arrays, [dr.opaque(mi.Float, float(v)) for v in x], jacobian), np.float64)

    def loss(self, x) -> float:
        """½ Σ r², accumulated in float64."""
        if self.texel_index is not None:
            return self.system(x)[2]
        return float(self._run(x, False)[0])

    def system(self, x):
        """``(JᵀJ, Jᵀr, ½ Σ r²)`` (float64) at ``x``, in one pass over the samples.

        With ``texel``, of the residuals with each texel's albedo at its best value for ``x``
        (a per-texel constant a_t added to π f, eliminated: variable projection). For texel t
        with W_t = Σ w², A_t = Σ w ρ and S_t = Σ w J per channel (ρ, J the residuals and
        their Jacobian with no albedo), a_t = A_t / W_t, and the projected sums are
        JᵀJ - Σ_t S_t S_tᵀ / W_t, Jᵀr - Σ_t S_t A_t / W_t and ½ (Σ ρ² - Σ_t A_t² / W_t):
        the samples' within-texel variation only, whatever the albedo texture."""
        values, p = self._run(x, True), len(x)
        jtj = np.zeros((p, p))
        rows, cols = np.triu_indices(p)
        jtj[rows, cols] = values[1:1 + len(rows)]
        jtj[cols, rows] = values[1:1 + len(rows)]
        jtr, loss = values[1 + len(rows):], float(values[0])
        if self.texel_index is not None:
            weight, a, s = self.texel_sums(x, self.texel_index, self.texels)
            scaled = (s / weight[:, None, None]).reshape(-1, p)  # (T·3, P): S_t / W_t per channel
            jtj = jtj - scaled.T @ s.reshape(-1, p)
            jtr = jtr - scaled.T @ a.reshape(-1)
            loss = loss - 0.5 * float(np.sum(a * a / weight[:, None]))
        return jtj, jtr, loss

    def texel_albedo(self, x) -> np.ndarray:
        """The region's albedo (3,) at ``x`` with ``texel``: the weighted mean of the texels' best
        albedos, Σ_t A_t / Σ_t W_t per channel (the albedo of :attr:`space` fixed at 0: the
        residuals are r - π f_s)."""
        weight, a, _ = self.texel_sums(x, self.texel_index, self.texels)
        return a.sum(axis=0) / weight.sum()

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

    def texel_sums(self, x, texel: np.ndarray, groups: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per texel t, W_t = Σ_{i ∈ t} 1/σ_i² (T,), A_t = Σ_{i ∈ t} ρ_i/σ_i (T, 3) and
        S_t = Σ_{i ∈ t} J_i/σ_i per colour channel (T, 3, P), at ``x``; ``texel`` (N,) numbers the
        texels 0 … ``groups`` - 1. What the offsets' part of the uncertainty needs
        (:func:`mifaces.reflectance.fit.offset_uncertainty.offset_sums`) and the fit with an albedo
        per texel (:meth:`system`): one kernel as :meth:`cluster_sums`'s."""
        own = texel is self.texel_index
        key = np.round(np.asarray(x, np.float64), 10).tobytes()  # x read back from its values: equal to ~1e-16
        if own and key in self._texel_cache:  # the last steps' points: the fit's optimum is one of them
            return self._texel_cache[key]
        p = len(x)
        sums = self._group_sums("texels", _texel_sums, x, texel, groups, 4 + 3 * p)
        out = sums[:, 0], sums[:, 1:4], sums[:, 4:].reshape(groups, 3, p)
        if own:
            self._texel_cache = {k: v for k, v in list(self._texel_cache.items())[-1:]} | {key: out}
        return out

    def _group_sums(self, name: str, kernel, x, group: np.ndarray, groups: int, width: int) -> np.ndarray:
        """``kernel(space, arrays, u, groups)``'s per-group sums at ``x`` for the samples' ``group``
        (N,) numbers 0 … ``groups`` - 1, as a (groups, width) float64 array: one kernel, frozen per
        parameter space and ``name``."""
        key = (name,) + _signature(self.space) + (bool(self.spread),)
        if key not in _FROZEN:
            space = self.space
            _FROZEN[key] = dr.freeze(lambda arrays, u, g: kernel(space, arrays, u, g), warn_after=1000,
                                     state_fn=lambda arrays, u, g: (dr.width(arrays["w"]), g))
        arrays = {"wi": self.wi, "wo": self.wo, "spread": self.spread, "r": self.r, "w": self.w,
                  "c": device_array(np.uint32, np.asarray(group, np.uint32))}
        sums = _FROZEN[key](arrays, [dr.opaque(mi.Float, float(v)) for v in x], int(groups))
        return np.asarray(sums, np.float64)[:groups * width].reshape(groups, width)  # the padding's rows off

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


#: The frozen :func:`_sums` per parameter space (:func:`_signature`) and footprint (with or without).
_FROZEN: dict = {}


def _model(space: ParameterSpace, wi, wo, spread: tuple, u: list):
    """f at the free variables ``u`` for directions ``wi``, ``wo``; with a ``spread`` per sample
    (:mod:`mifaces.reflectance.footprint`), what the pixel saw: f over the tilted normals, weighted."""
    params = space.drjit_params(u)
    return seen_by_pixel(lambda a, b: space.model.eval(a, b, params), wi, wo, spread)


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
    res = (arrays["r"] - dr.pi * _model(space, arrays["wi"], arrays["wo"], arrays["spread"], u)) * arrays["w"]
    r = [mi.Float64(c) for c in dr.detach(res)]
    d = []
    for uk in u if tangents else ():
        dr.forward_from(uk, flags=dr.ADFlag.ClearVertices)
        d.append([mi.Float64(c) for c in dr.grad(res)])
        dr.clear_grad(res)
    return r, d


def _group_scatter(terms: list, group, groups: int):
    """``terms`` (per-sample float64 arrays) summed per group ``group`` into one array of ``groups``
    rows of ``len(terms)`` (and zero rows after them: see below). Neighbouring samples share a group:
    per-thread copies of a small array (``dr.ReduceMode.Expand``), else atomics reduced per packet.
    The copies' size is a literal of the kernel, so the rows are padded to a power of two: the
    regions of a fit, with their different numbers of texels or clusters, share a few kernels
    rather than compiling one each. One kernel."""
    k = len(terms)
    rows = 1 << max(0, int(groups) - 1).bit_length()
    acc = dr.zeros(mi.Float64, rows * k)
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
    """``[Σ 1/σ², Σ ρ_c/σ per channel c, Σ J_c/σ per channel c and free entry a (row-major)]`` per
    texel ``arrays["c"]`` as one float64 array of ``groups`` rows (ρ the residuals ``(r - π f)/σ``,
    J their forward-mode tangents, as in :func:`_cluster_sums`). One kernel."""
    r, d = _residual_tangents(space, arrays, u)
    w = mi.Float64(arrays["w"])
    terms = [w * w] + [w * r[c] for c in range(3)] + [w * d[a][c] for c in range(3) for a in range(len(u))]
    return _group_scatter(terms, arrays["c"], groups)


__all__ = ["Problem", "EXPAND_LIMIT"]
