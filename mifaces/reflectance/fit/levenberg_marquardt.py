"""Levenberg-Marquardt for small dense least-squares problems.

Minimises E(x) = ½ Σ r_i(x)² over a parameter vector x of a few dozen
entries at most, with the residuals and their Jacobian supplied by the
caller (mifaces computes them with Dr.Jit). The step solves

    (JᵀJ + λ diag(JᵀJ)) δ = -Jᵀr

(Marquardt's scaling, Press et al., *Numerical Recipes*, sec. 15.5, the
method the paper uses), in float64 on the normal equations. λ shrinks by 3
after an accepted step and grows by 4 after a rejected one. The caller gives
either the residuals and their Jacobian, or (``system``) the normal equations
and the loss formed where the residuals are, in one pass per step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ...runtime.status import CONVERGED, MAX_ITERATIONS, STALLED


@dataclass
class LMResult:
    """Outcome of :func:`levenberg_marquardt`.

    Attributes
    ----------
    x : ndarray
        Final parameters.
    loss : float
        E(x) = ½ Σ r².
    status : str
        ``'converged'`` (a tolerance was met, or no step lowers the loss any
        more at the precision of the residuals), ``'max_iterations'``, or
        ``'stalled'`` (the loss is not finite at the trial steps: a broken
        problem).
    reason : str
        Which test ended the run, in words.
    iterations : int
        Accepted steps plus one: the Jacobians the steps were solved with.
    history : list of (seconds, loss, x)
        Loss and parameters after each accepted step, with the wall time
        since the start.
    """

    x: np.ndarray
    loss: float
    status: str
    reason: str
    iterations: int
    evaluations: int
    history: list = field(default_factory=list)


def normal_equations(residuals: np.ndarray, jacobian: np.ndarray):
    """JᵀJ and Jᵀr, as float64 (P, P) and (P,) arrays.

    The products run in the precision of J (float32 BLAS for millions of
    rows: the step needs only a few digits; the loss that accepts or rejects
    it is exact), on columns scaled to a largest entry of 1 so that sharp
    lobes, whose derivatives reach 1e17, cannot overflow the sums."""
    scale = np.max(np.abs(jacobian), axis=0).astype(np.float64)
    scale[~(scale > 0) | ~np.isfinite(scale)] = 1.0
    scaled = jacobian / scale.astype(jacobian.dtype)
    r = residuals.astype(jacobian.dtype)
    r_scale = float(np.max(np.abs(r))) if r.size else 1.0
    r_scale = r_scale if np.isfinite(r_scale) and r_scale > 0 else 1.0
    jtj = (scaled.T @ scaled).astype(np.float64) * np.outer(scale, scale)
    jtr = (scaled.T @ (r / np.float32(r_scale))).astype(np.float64) * scale * r_scale
    return jtj, jtr


def levenberg_marquardt(
    residuals_and_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None,
    loss: Callable[[np.ndarray], float] | None,
    x0: np.ndarray,
    max_iterations: int = 100,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    gtol: float = 1e-12,
    lambda0: float = 1e-3,
    clock_start: float | None = None,
    system: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, float]] | None = None,
) -> LMResult:
    """Minimise ½ Σ r(x)².

    Parameters
    ----------
    residuals_and_jacobian : callable or None
        x -> (r of shape (M,), J of shape (M, P)); the normal equations are
        formed from them (:func:`normal_equations`). None when ``system`` is given.
    loss : callable or None
        x -> ½ Σ r(x)², cheaper than the above (no Jacobian); used to test
        trial steps. May return inf/nan for an invalid x (the step is then
        rejected). None when ``system`` is given.
    x0 : ndarray of shape (P,)
    max_iterations : int
        Jacobian evaluations allowed.
    ftol : float
        Stop when an accepted step lowers the loss by less than ftol·loss.
    xtol : float
        Stop when |δ| < xtol (|x| + xtol).
    gtol : float
        Stop when max |Jᵀr| < gtol · max(loss, tiny) (a stationary point).
    lambda0 : float
        Initial damping λ; dimensionless, as the damping term λ diag(JᵀJ)
        scales with each parameter's own curvature.
    clock_start : float, optional
        ``time.perf_counter()`` value the history's times count from.
    system : callable, optional
        x -> (JᵀJ (P, P), Jᵀr (P,), ½ Σ r²), all float64, in one pass over the
        residuals (the caller forms the sums where the residuals are); then
        every trial step is evaluated with it, and an accepted step's system is
        the trial's, so each step costs one pass.
    """
    start = time.perf_counter() if clock_start is None else clock_start
    x = np.asarray(x0, dtype=np.float64).copy()
    if system is None:
        def system_of(x):
            r, jac = residuals_and_jacobian(x)
            return (*normal_equations(r, jac), 0.5 * float(np.dot(r.astype(np.float64), r.astype(np.float64))))
    else:
        system_of = system
    jtj, jtr, current = system_of(x)
    history = [(time.perf_counter() - start, current, x.copy())]
    lam = lambda0
    iterations, evaluations = 1, 1
    status, reason = MAX_ITERATIONS, f"{max_iterations} iterations"
    if not np.isfinite(current):
        return LMResult(x, current, STALLED, "loss is not finite at the start", 1, 1, history)
    rejections = 0
    while iterations < max_iterations:
        if not (np.all(np.isfinite(jtj)) and np.all(np.isfinite(jtr))):
            status, reason = STALLED, "the Jacobian is not finite at the current parameters"
            break
        if np.max(np.abs(jtr)) <= gtol * max(current, 1e-300):
            status, reason = CONVERGED, "gradient vanished"
            break
        diag = np.maximum(np.diag(jtj), 1e-30 * max(1.0, np.max(np.diag(jtj))))
        try:
            delta = np.linalg.solve(jtj + lam * np.diag(diag), -jtr)
        except np.linalg.LinAlgError:
            delta = None
        if delta is not None and np.all(np.isfinite(delta)):
            predicted = -float(jtr @ delta) - 0.5 * float(delta @ jtj @ delta)
            if predicted <= ftol * current and lam <= lambda0:
                status, reason = CONVERGED, "predicted loss decrease below ftol"
                break
        trial, trial_system = float("inf"), None
        if delta is not None and np.all(np.isfinite(delta)):
            if system is None:
                trial = loss(x + delta)
            else:
                trial_system = system(x + delta)
                trial = trial_system[2]
        evaluations += 1
        if np.isfinite(trial) and trial < current:
            rejections = 0
            x = x + delta
            decrease = current - trial
            current = trial
            lam = max(lam / 3.0, 1e-30)
            jtj, jtr, _ = system_of(x) if trial_system is None else trial_system
            iterations += 1
            history.append((time.perf_counter() - start, current, x.copy()))
            if decrease <= ftol * current:
                status, reason = CONVERGED, "relative loss decrease below ftol"
                break
            if np.linalg.norm(delta) <= xtol * (np.linalg.norm(x) + xtol):
                status, reason = CONVERGED, "step below xtol"
                break
        else:
            lam *= 4.0
            rejections += 1
            if rejections > 60 or lam > 1e16:
                if np.isfinite(trial):
                    status, reason = CONVERGED, "no step lowers the loss at the residuals' precision"
                else:
                    status, reason = STALLED, "the loss is not finite near the current parameters"
                break
    return LMResult(x, current, status, reason, iterations, evaluations, history)
