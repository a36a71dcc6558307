"""Intervals of a region fit's parameters from the covariance of its free variables (the method:
:mod:`mifaces.reflectance.fit.uncertainty`): symmetric in the fit's own coordinates and mapped
back, so they never leave a parameter's range; a status instead where the fit does not estimate
a parameter."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.stats

from .parameters import ParameterSpace

#: The intervals' coverage.
LEVEL = 0.95
#: Statuses of parameters without an interval.
FIXED, AT_BOUND, PRUNED, PRIOR, ESTIMATED = "fixed", "at_bound", "pruned", "prior", "estimated"
#: Status of a parameter the samples do not constrain (JᵀJ singular in its direction).
NOT_IDENTIFIED = "not_identified"
#: What the default fit leaves in a glossy parameter that no replicate of the photographs shows (the
#: light's calibration, bounced light not quite taken out, the albedo's detail: ``docs/reflectance.md``,
#: "Where skin's bias comes from"), as a relative standard deviation per model and parameter: it
#: enters every interval beside the statistical part, the half-widths in quadrature,
#: √((t·std)² + (z·s·value)²) (t the statistical part's Student quantile, z the normal one: the
#: systematic part is known from many captures, not estimated from this one). Chosen on development
#: captures by ``python validation/reflectance_coverage.py --tune``
#: (``validation/results/reflectance_coverage_tuning.json``; ``tests/test_uncertainty.py`` holds the two
#: equal); a parameter not named here has none.
SYSTEMATIC: dict[str, dict[str, float]] = {
    "cooktorrance": {"specular_reflectance": 0.015, "roughness": 0.01},
    "ward": {"specular_reflectance": 0.04, "alpha": 0.01},
    "phong": {"specular_reflectance": 0.02, "exponent": 0.01},
    "lafortune": {"cxy": 0.01, "cz": 0.08, "exponent": 0.025},
}


@dataclass
class Covariance:
    """The covariance of the free variables x at the optimum.

    Attributes
    ----------
    x : ndarray (P,)
        The optimum.
    covariance : ndarray (P, P)
        Cov(x̂); rows and columns of held entries are 0.
    held : ndarray (P,) of bool
        Entries at a bound or pruned, held where they are.
    dof : float
        Degrees of freedom of the t quantile.
    method : str
    """

    x: np.ndarray
    covariance: np.ndarray
    held: np.ndarray
    dof: float
    method: str

    def quantile(self, level: float = LEVEL) -> float:
        """Two-sided ``level`` quantile of Student's t with :attr:`dof`."""
        return float(scipy.stats.t.ppf(0.5 + level / 2, max(self.dof, 1.0)))


def parameter_intervals(space: ParameterSpace, cov: Covariance, statuses: dict | None = None,
                        level: float = LEVEL) -> dict:
    """Per parameter of the model, ``{"std", "interval95"}`` (and ``"systematic_std"`` where
    :data:`SYSTEMATIC` names one for the model's parameter) or ``{"status"}``.

    ``std`` and the interval's ends are floats, or lists per channel for RGB
    parameters (``interval95`` is then ``[[lo_r, lo_g, lo_b], [hi_r, hi_g, hi_b]]``,
    with ``None`` and a per-channel ``status`` list where only some channels
    are held). ``statuses`` names a status for held entries (free-vector
    index -> status; default ``at_bound``). The diffuse reflectance is
    included; fixed parameters are ``{"status": "fixed"}``.
    """
    statuses = statuses or {}
    x, var = cov.x, np.diag(cov.covariance)
    q = cov.quantile(level)
    z = float(scipy.stats.norm.ppf(0.5 + level / 2))  # the systematic part is known, not estimated: normal
    values = space.values(x)
    jac = _value_jacobian(space, x)
    systematic = SYSTEMATIC.get(space.model.name, {})
    out: dict = {name: {"status": FIXED} for name in space.fixed}
    entries: dict = {}
    for k, f in enumerate(space.free):
        if cov.held[k]:
            entry = (statuses.get(k, AT_BOUND), None, None, None, None)
        else:
            std = _std(jac[k], cov.covariance)
            if np.isfinite(std):
                value = values[f.name] if f.channel is None else values[f.name][f.channel]
                shared = systematic.get(f.name, 0.0) * abs(float(value))
                # the two half-widths in quadrature, the systematic one in the fit's own coordinates
                # through the entry's own map
                half_x = float(np.hypot(q * np.sqrt(var[k]), z * shared / abs(jac[k, k]) if jac[k, k] else 0.0))
                lo, hi = _interval(space, x, k, f, half_x, float(np.hypot(q * std, z * shared)), values)
                entry = (ESTIMATED, std, lo, hi, shared)
            else:
                entry = (NOT_IDENTIFIED, None, None, None, None)
        entries.setdefault(f.name, {})[f.channel] = entry
    for name, channels in entries.items():
        if None in channels:
            status, std, lo, hi, shared = channels[None]
            out[name] = {"status": status} if status != ESTIMATED else _estimated(std, lo, hi, shared)
            continue
        parts = [channels[c] for c in range(3)]
        kinds = {p[0] for p in parts}
        if kinds != {ESTIMATED} and len(kinds) == 1:
            out[name] = {"status": parts[0][0]}
            continue
        out[name] = _estimated([p[1] for p in parts], [p[2] for p in parts], [p[3] for p in parts],
                               [p[4] for p in parts])
        if kinds != {ESTIMATED}:
            out[name]["status"] = [p[0] for p in parts]
    return out


def _estimated(std, lo, hi, shared) -> dict:
    """An estimated parameter's entry: its statistical ``std``, the interval (both parts in it) and,
    where :data:`SYSTEMATIC` names one, ``systematic_std``."""
    entry = {"std": std, "interval95": [lo, hi]}
    if any(s for s in np.atleast_1d(np.asarray(shared, dtype=object)) if s is not None):
        entry["systematic_std"] = shared
    return entry


def _std(row: np.ndarray, cov: np.ndarray) -> float:
    """√(row Cov rowᵀ), the delta-method standard deviation; inf where an entry it needs is."""
    idx = np.flatnonzero(row != 0)
    block = cov[np.ix_(idx, idx)]
    if not np.all(np.isfinite(block)):
        return float("inf")  # it depends on an entry the samples do not constrain
    return float(np.sqrt(max(float(row[idx] @ block @ row[idx]), 0.0)))


def _interval(space: ParameterSpace, x, k: int, f, half_x: float, half: float, values: dict):
    """Ends of the interval of free entry ``k``: x ± ``half_x`` mapped back, or for an
    energy-coupled coefficient the value ± ``half`` (in the parameter's units) clipped to its bound."""
    if f.name in space.coupled:
        value = values[f.name][f.channel] if f.channel is not None else values[f.name]
        bound = float(space.model.coefficient_bound(float(values[space.coupled[f.name]]), np.log, np.exp))
        return max(value - half, -bound), min(value + half, bound)
    return space.entry_value(f, x[k] - half_x), space.entry_value(f, x[k] + half_x)


def _value_jacobian(space: ParameterSpace, x, h: float = 1e-6) -> np.ndarray:
    """d value / d x: row k is the derivative of free entry k's parameter value (its channel)
    with respect to every entry of x, by central differences: of the entry's own map for the
    parameters that depend on their entry alone, of all values for energy-coupled ones."""
    x = np.asarray(x, np.float64)
    p = len(x)
    jac = np.zeros((p, p))
    for k, f in enumerate(space.free):
        if f.name not in space.coupled:
            jac[k, k] = (space.entry_value(f, x[k] + h) - space.entry_value(f, x[k] - h)) / (2 * h)
    coupled = [k for k, f in enumerate(space.free) if f.name in space.coupled]
    if coupled:
        def flat(v):
            return np.array([float(v[space.free[k].name][space.free[k].channel] if space.free[k].channel is not None
                                   else v[space.free[k].name]) for k in coupled])

        for j in range(p):
            step = np.zeros(p)
            step[j] = h
            jac[coupled, j] = (flat(space.values(x + step)) - flat(space.values(x - step))) / (2 * h)
    return jac


def held_entries(space: ParameterSpace, x, margin: float = 1e-3) -> np.ndarray:
    """Free entries at either end of their range (within ``margin`` of it in
    the reparameterised scale), or energy-coupled coefficients whose lobe is at
    its energy bound (:meth:`ParameterSpace.at_bounds`)."""
    t = 0.5 * (1.0 + np.tanh(0.5 * np.asarray(x, np.float64)))
    upper = set(space.at_bounds(x, margin))
    held = np.zeros(len(space.free), bool)
    for k, (f, tk) in enumerate(zip(space.free, t)):
        label = f.name if f.channel is None else f"{f.name}[{f.channel}]"
        held[k] = label in upper or (f.name not in space.coupled and tk < margin)
    return held


def prior_intervals(params: dict) -> dict:
    """``{"status": "prior"}`` for every parameter of a borrowed fit."""
    return {name: {"status": PRIOR} for name in params}


__all__ = ["LEVEL", "SYSTEMATIC", "FIXED", "AT_BOUND", "PRUNED", "PRIOR", "ESTIMATED", "NOT_IDENTIFIED", "Covariance",
           "parameter_intervals", "held_entries", "prior_intervals"]
