"""The free parameters of a BRDF fit and where it starts (paper sec. 5.1).

:class:`ParameterSpace` maps a model's parameters to an unconstrained vector
(p = lo + (hi - lo)·sigmoid(x), or its logarithmic form for parameters that
span decades), holding some fixed and keeping Lafortune lobes energy-bounded;
:func:`linear_start` finds start values by a grid search over the lobe width.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ...brdf.model import DIFFUSE, BRDFModel, Parameter
from ...runtime.arrays import device_array


@dataclass(frozen=True)
class _Free:
    name: str
    channel: int | None  # colour channel of an RGB parameter, or None
    lower: float
    upper: float
    log: bool


def _is_log(p: Parameter) -> bool:
    return p.lower > 0 and p.upper / p.lower >= 100


class ParameterSpace:
    """The free parameters of a model and their map to an unconstrained vector.

    Parameters
    ----------
    model : BRDFModel
    fixed : dict, optional
        Parameter name -> value held constant (floats or RGB triples).
    bounds : dict, optional
        Parameter name -> (lower, upper) narrowing the model's valid range.

    Coefficients the model declares energy-coupled
    (:meth:`~mifaces.brdf.model.BRDFModel.energy_coupled`) are kept in
    [-c_max, c_max] with c_max the model's
    :meth:`~mifaces.brdf.model.BRDFModel.coefficient_bound` of their
    exponent: for a Lafortune lobe j, c_max = ((n_j + 2) / 2π)^{1/n_j}, so
    the lobe's peak, at most max(|C_xy|, |C_z|)^n, stays below (n + 2)/2π and
    its albedo estimate |s|^n 2π/(n + 2) below 1. Without it a lobe fitted to
    the directions a capture observes may grow without limit towards those it
    does not (the over-fitting Fuchs et al. 2005, sec. 6.1, report).
    """

    def __init__(self, model: BRDFModel, fixed: dict | None = None, bounds: dict | None = None):
        self.model = model
        self.fixed = dict(fixed or {})
        bounds = bounds or {}
        unknown = (set(self.fixed) | set(bounds)) - {p.name for p in model.parameters()}
        if unknown:
            raise ValueError(f"{model.name}: no parameter(s) {sorted(unknown)}")
        self.coupled = model.energy_coupled()
        self.free: list[_Free] = []
        for p in model.parameters():
            if p.name in self.fixed:
                continue
            lo, hi = bounds.get(p.name, (p.lower, p.upper))
            if p.name in self.coupled:
                lo, hi = -1.0, 1.0  # a fraction of the energy bound c_max(n)
            channels = (0, 1, 2) if p.kind == "rgb" else (None,)
            self.free += [_Free(p.name, c, lo, hi, _is_log(p)) for c in channels]

    def __len__(self) -> int:
        return len(self.free)

    def _forward(self, x, f: _Free, sigmoid, log, exp):
        s = sigmoid(x)
        if f.log:
            return exp(log(f.lower) + (log(f.upper) - log(f.lower)) * s)
        return f.lower + (f.upper - f.lower) * s

    def entry_value(self, f: _Free, x: float) -> float:
        """The value of free entry ``f`` (its channel) at its unconstrained ``x``, before any
        energy coupling (:meth:`values` applies that)."""
        return float(self._forward(x, f, lambda t: 0.5 * (1.0 + np.tanh(0.5 * t)), np.log, np.exp))

    def values(self, x: np.ndarray) -> dict:
        """Parameter values (floats, or lists of three) for the vector ``x``."""
        out = {k: (list(map(float, v)) if np.ndim(v) else float(v)) for k, v in self.fixed.items()}
        sig = lambda t: 0.5 * (1.0 + np.tanh(0.5 * t))  # the logistic function, without overflow  # noqa: E731
        for xi, f in zip(x, self.free):
            v = float(self._forward(xi, f, sig, np.log, np.exp))
            if f.channel is None:
                out[f.name] = v
            else:
                out.setdefault(f.name, [0.0, 0.0, 0.0])[f.channel] = v
        for name, exponent in self.coupled.items():
            if name not in self.fixed:
                bound = float(self.model.coefficient_bound(out[exponent], np.log, np.exp))
                out[name] = [v * bound for v in out[name]] if np.ndim(out[name]) else out[name] * bound
        return out

    def at_bounds(self, x: np.ndarray, margin: float = 1e-3) -> list[str]:
        """Names of the free parameters that ``x`` puts within ``margin`` (a
        fraction of their range, in the reparameterised scale) of their upper
        bound, or energy-coupled coefficients whose lobe is within 1 % of its
        energy bound. Lower bounds are legitimate answers (no glossy lobe, a
        black albedo) and not listed."""
        t = 0.5 * (1.0 + np.tanh(0.5 * np.asarray(x, np.float64)))
        values = self.values(x)
        out = []
        for f, ti in zip(self.free, t):
            if f.name in self.coupled:
                # a lobe at its energy bound: albedo estimate |C|^n 2π/(n+2) within 1 % of 1
                n = float(values[self.coupled[f.name]])
                ratio = abs(2.0 * ti - 1.0)
                hit = n * np.log(max(ratio, 1e-300)) > np.log(0.99)
            else:
                hit = ti > 1 - margin
            if hit:
                out.append(f.name if f.channel is None else f"{f.name}[{f.channel}]")
        return out

    def glossy_unchanged(self, start: np.ndarray, x: np.ndarray, rtol: float = 1e-6) -> bool:
        """Whether ``x`` leaves every free glossy parameter (all but the
        diffuse albedo) where ``start`` put it, to ``rtol`` in the
        reparameterised scale: a fit that never moved them has not measured them."""
        glossy = [i for i, f in enumerate(self.free) if f.name != DIFFUSE.name]
        if not glossy:
            return False
        a, b = np.asarray(start, np.float64)[glossy], np.asarray(x, np.float64)[glossy]
        return bool(np.all(np.abs(b - a) <= rtol * np.maximum(np.abs(a), 1.0)))

    def at_spike(self, x: np.ndarray, margin: float = 1e-3) -> bool:
        """Whether ``x`` puts the lobe-width parameter within ``margin`` (a
        fraction of its range, reparameterised) of the end where the lobe is a
        spike (the model's ``SHARP_END``)."""
        if self.model.WIDTH_GRID is None:
            return False
        name = self.model.WIDTH_GRID[0]
        t = 0.5 * (1.0 + np.tanh(0.5 * np.asarray(x, np.float64)))
        for f, ti in zip(self.free, t):
            if f.name == name and (ti < margin if self.model.SHARP_END == "lower" else ti > 1 - margin):
                return True
        return False

    def vector(self, values: dict) -> np.ndarray:
        """The unconstrained vector whose :meth:`values` are ``values``
        (clipped just inside the bounds)."""
        x = []
        for f in self.free:
            v = values[f.name]
            v = float(v[f.channel] if f.channel is not None and np.ndim(v) else v)
            if f.name in self.coupled:
                v /= float(self.model.coefficient_bound(float(values[self.coupled[f.name]]), np.log, np.exp))
            if f.log:
                t = (np.log(v) - np.log(f.lower)) / (np.log(f.upper) - np.log(f.lower))
            else:
                t = (v - f.lower) / (f.upper - f.lower)
            t = float(np.clip(t, 1e-6, 1 - 1e-6))
            x.append(np.log(t / (1 - t)))
        return np.array(x)

    def drjit_params(self, u: list) -> dict:
        """Model parameters as Dr.Jit values from the free variables ``u``
        (differentiable)."""
        out = {}
        for k, v in self.fixed.items():
            out[k] = mi.Color3f(*v) if np.ndim(v) else mi.Float(v)
        rgb = {}
        for ui, f in zip(u, self.free):
            v = self._forward(ui, f, lambda t: 1.0 / (1.0 + dr.exp(-t)), dr.log, dr.exp)
            if f.channel is None:
                out[f.name] = v
            else:
                rgb.setdefault(f.name, [None, None, None])[f.channel] = v
        for name, (r, g, b) in rgb.items():
            out[name] = mi.Color3f(r, g, b)
        for name, exponent in self.coupled.items():
            if name not in self.fixed:
                out[name] = out[name] * self.model.coefficient_bound(out[exponent], dr.log, dr.exp)
        return out


def conservative_start(model: BRDFModel, reflectance: np.ndarray) -> dict:
    """A start far from any sharp minimum: the diffuse albedo at the 40th
    percentile of the observed reflectance (highlights lie above it), the
    glossy part at the model's :meth:`~mifaces.brdf.model.BRDFModel.start_values`
    (a weak lobe of medium width)."""
    diffuse = np.clip(np.percentile(reflectance, 40, axis=0), 0.01, 0.95)
    return {"diffuse_reflectance": list(map(float, diffuse)), **model.start_values()}


def linear_start(model: BRDFModel, light, view, reflectance, sigma, fixed: dict | None = None,
                 max_samples: int = 50_000, seed: int = 0) -> dict:
    """Start values from a grid search over the lobe width.

    For a fixed width the models are linear in the diffuse albedo and the
    lobe's scale: r ≈ ρ_d + b g(l̂, v̂) with g = π f_s of the model's
    :meth:`~mifaces.brdf.model.BRDFModel.unit_lobe` (for Lafortune, the lobe
    (c(-x·x - y·y + z·z))^n has scale b = c^n). So for each width on the
    model's :attr:`~mifaces.brdf.model.BRDFModel.WIDTH_GRID` the best ρ_d
    and b follow from a 2×2 weighted least-squares problem per channel (with
    b >= 0), and the width with the lowest error wins; the model's
    :meth:`~mifaces.brdf.model.BRDFModel.scaled_lobe` turns b into its
    parameters. This finds sharp lobes that a local method started from a
    medium width misses. Uses at most ``max_samples`` random samples.
    Parameters the unit lobe does not set (extra Lafortune lobes) keep their
    conservative start.
    """
    start = conservative_start(model, reflectance)
    if model.WIDTH_GRID is None:
        return start
    width_name, grid = model.WIDTH_GRID
    n = len(sigma)
    idx = np.sort(np.random.default_rng(seed).permutation(n)[:max_samples]) if n > max_samples else np.arange(n)
    # in Dr.Jit's own memory (device_array): a mapped NumPy array's alignment would enter the kernels
    wi = mi.Vector3f(*(device_array(np.float32, np.asarray(light, np.float32)[idx, k]) for k in range(3)))
    wo = mi.Vector3f(*(device_array(np.float32, np.asarray(view, np.float32)[idx, k]) for k in range(3)))
    r = np.asarray(reflectance, np.float64)[idx]
    w = 1.0 / np.square(np.asarray(sigma, np.float64)[idx])
    unit = {**model.defaults(), **(fixed or {}), **model.unit_lobe()}
    best = None
    sw = w.sum()
    for width in grid:
        params = {**unit, width_name: dr.opaque(mi.Float, float(width))}  # one kernel for every width
        g = np.pi * np.array(model.eval(wi, wo, params, diffuse=False))[0].astype(np.float64)
        # weighted normal equations of [1, g] per channel
        sg, sgg = (w * g).sum(), (w * g * g).sum()
        det = sw * sgg - sg * sg
        error, fit = 0.0, []
        for c in range(3):
            sr, sgr = (w * r[:, c]).sum(), (w * g * r[:, c]).sum()
            b = (sw * sgr - sg * sr) / det if det > 1e-300 else 0.0
            if b < 0:
                b = 0.0
            a = (sr - b * sg) / sw
            error += float((w * np.square(r[:, c] - a - b * g)).sum())
            fit.append((a, b))
        if np.isfinite(error) and (best is None or error < best[0]):
            best = (error, width, fit)
    if best is None:
        return start
    _, width, fit = best
    start["diffuse_reflectance"] = [float(np.clip(a, 0.005, 0.995)) for a, _ in fit]
    start[width_name] = float(width)
    start.update(model.scaled_lobe([b for _, b in fit], width))
    return start
