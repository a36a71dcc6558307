"""Error against run time of the BRDF fit: hierarchical LM, full-data LM,
and scipy's Levenberg-Marquardt, on the same reflectance samples.

The samples are synthetic skin-like regions (the ground-truth BRDF of each
model, random directions with cos θ > 0.17, 3 % multiplicative noise, σ
from eq. 9). scipy runs
``least_squares(method='lm')`` on the same residuals (r - π f)/σ, evaluated
by the same Dr.Jit functions, twice: with its default finite-difference
Jacobian ('2-point', with ``diff_step=1e-3``: the residuals are float32, and
scipy's default step is below their precision) and with the Dr.Jit Jacobian
mifaces uses. Every run starts from the same start (mifaces' lobe-width grid
search, which each run's time includes).

How far each of mifaces' fits is from the physical limit, one pass over the
samples per Jacobian: every pass the fit makes (:meth:`Problem.system`, which
computes the residuals, their Jacobian and the normal equations in one kernel)
is counted with its number of samples, giving the equivalent number of
full-data passes; the limit is that number times the wall time of one
full-data pass (warm, median of 5), and ``kernel_limit_s`` the same with the
pass's kernel execution time alone (Dr.Jit's kernel history). The machine
may be shared: the times are taken side by side in one process, and the load
average is recorded.

Run:  python validation/bench_brdf_fit.py [--samples N] [--quick]
Writes validation/results/bench_brdf_fit.{json,png} and prints a table.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import drjit as dr
import mitsuba as mi
import numpy as np
import scipy.optimize

from mifaces import brdf
from mifaces.reflectance.fit.parameters import ParameterSpace, linear_start
from mifaces.reflectance.fit.problem import Problem
from mifaces.reflectance.fit.region_fit import FULL_DATA, RegionFitOptions, RegionSamples, SubsetSchedule, fit_region
from mifaces.io.atomic import save_figure, write_json

OUT = Path(__file__).resolve().parent / "results"

TRUTH = {
    "phong": {"diffuse_reflectance": [0.52, 0.36, 0.29], "specular_reflectance": [0.09] * 3, "exponent": 35.0},
    "cooktorrance": {"diffuse_reflectance": [0.52, 0.36, 0.29], "specular_reflectance": [2.2] * 3,
                     "roughness": 0.3, "eta": 1.38},
    "ward": {"diffuse_reflectance": [0.52, 0.36, 0.29], "specular_reflectance": [0.07] * 3, "alpha": 0.25},
    "lafortune": {"diffuse_reflectance": [0.52, 0.36, 0.29], "cxy": [-0.92] * 3, "cz": [0.92] * 3,
                  "exponent": 18.0},
}


def samples(model, truth, n, seed=0, noise=0.03):
    rng = np.random.default_rng(seed)

    def directions():
        v = rng.normal(size=(4 * n, 3))
        v[:, 2] = np.abs(v[:, 2])
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        return v[v[:, 2] > 0.17][:n]

    light, view = directions(), directions()
    p = {k: (mi.Color3f(*v) if isinstance(v, list) else mi.Float(v)) for k, v in truth.items()}
    f = np.array(model.eval(mi.Vector3f(light.T.astype(np.float32)), mi.Vector3f(view.T.astype(np.float32)), p)).T
    r = np.pi * f * (1 + noise * rng.normal(size=f.shape))
    return light, view, r, 1.0 / (light[:, 2] ** 2 * view[:, 2])


class PassCounter:
    """Counts the passes of :meth:`Problem.system` (samples per call) while it is installed."""

    def __init__(self):
        self.sizes = []
        self.original = Problem.system

    def __enter__(self):
        counter = self

        def system(problem, x):
            counter.sizes.append(problem.n)
            return counter.original(problem, x)

        Problem.system = system
        return self

    def __exit__(self, *exc):
        Problem.system = self.original

    def full_passes(self, n: int) -> float:
        return sum(self.sizes) / n


def one_pass(problem, x, repeats: int = 5) -> tuple[float, float]:
    """Wall time (median) and kernel execution time of one full-data pass (residuals, Jacobian,
    normal equations) at ``x``, warm."""
    problem.system(x)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        problem.system(x)
        times.append(time.perf_counter() - t)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    problem.system(x)
    execution = sum(e.get("execution_time", 0.0) for e in dr.kernel_history()) / 1e3
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    return float(np.median(times)), execution


def scipy_fit(model, light, view, r, sigma, jacobian: str):
    space = ParameterSpace(model, model.fixed_defaults())
    problem = Problem(model, space, light, view, r, sigma)
    trace, t0 = [], time.perf_counter()

    def residuals(x):
        u = [mi.Float(float(v)) for v in x]
        out = np.array(problem._residuals(u)).ravel().astype(np.float64)
        trace.append((time.perf_counter() - t0, 0.5 * float(out @ out)))
        return out

    def jac(x):
        return problem.residuals_and_jacobian(x)[1].astype(np.float64)

    # the same start as mifaces' fit (its lobe-width grid search), timed with scipy
    x0 = space.vector(linear_start(model, light, view, r, sigma, model.fixed_defaults()))
    # residuals are float32: finite differences need a step well above its precision
    result = scipy.optimize.least_squares(residuals, x0, method="lm", diff_step=1e-3,
                                          jac=jac if jacobian == "drjit" else "2-point")
    seconds = time.perf_counter() - t0
    best, history = np.inf, []
    for t, e in trace:
        best = min(best, e)
        history.append((t, best))
    return {"loss": float(result.cost), "seconds": seconds, "history": history,
            "evaluations": int(result.nfev), "status": result.message}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=300_000)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    n = 20_000 if args.quick else args.samples
    load = os.getloadavg()[0]  # the machine may be shared: its load before and after
    rows, curves = [], {}
    for name, truth in TRUTH.items():
        model = brdf.model(name)
        light, view, r, sigma = samples(model, truth, n)
        # one throw-away fit compiles the kernels, for everyone's benefit
        fit_region(model, RegionSamples(light[:1000], view[:1000], r[:1000], sigma[:1000]),
                   options=RegionFitOptions(schedule=FULL_DATA))
        runs = {}
        space = ParameterSpace(model, model.fixed_defaults())
        full = Problem(model, space, light, view, r, sigma)
        for label, schedule in [("hierarchical LM", SubsetSchedule()), ("full-data LM", FULL_DATA)]:
            trace = []
            with PassCounter() as passes:
                fit = fit_region(model, RegionSamples(light, view, r, sigma),
                                 options=RegionFitOptions(schedule=schedule), trace=trace)
            # the full-data loss along the way, evaluated after the timed run
            history = [(t, full.loss(space.vector(values))) for t, values in trace]
            pass_s, kernel_s = one_pass(full, space.vector(fit.params))
            equivalent = passes.full_passes(len(sigma))
            runs[label] = {"loss": fit.loss, "seconds": fit.seconds, "history": history,
                           "evaluations": fit.iterations, "status": fit.status,
                           "passes": len(passes.sizes), "full_data_passes": equivalent, "pass_s": pass_s,
                           "limit_s": equivalent * pass_s, "kernel_limit_s": equivalent * kernel_s}
        for label, jac in [("scipy LM, 2-point Jacobian", "2-point"), ("scipy LM, Dr.Jit Jacobian", "drjit")]:
            runs[label] = scipy_fit(model, light, view, r, sigma, jac)
        best = min(run["loss"] for run in runs.values())
        scipy_time = runs["scipy LM, 2-point Jacobian"]["seconds"]
        for label, run in runs.items():
            row = {"model": name, "method": label, "samples": len(sigma), "loss": run["loss"],
                   "loss_over_best": run["loss"] / best, "seconds": run["seconds"],
                   "speedup_vs_scipy": scipy_time / run["seconds"], "status": str(run["status"])}
            limit = ""
            if "limit_s" in run:
                row.update({k: run[k] for k in ("passes", "full_data_passes", "pass_s", "limit_s", "kernel_limit_s")})
                row["seconds_over_limit"] = run["seconds"] / run["limit_s"]
                limit = (f"; {run['passes']} passes = {run['full_data_passes']:.1f} full-data passes x "
                         f"{1e3 * run['pass_s']:.0f} ms = {run['limit_s']:.2f} s limit "
                         f"({row['seconds_over_limit']:.1f}x it; kernels alone {run['kernel_limit_s']:.2f} s)")
            rows.append(row)
            print(f"{name:<13} {label:<28} loss {run['loss']:12.6g} ({run['loss'] / best - 1:+.2e})"
                  f"  {run['seconds']:7.2f} s  ({scipy_time / run['seconds']:5.1f}x faster than scipy){limit}",
                  flush=True)
        curves[name] = {label: run["history"] for label, run in runs.items()}
    if args.quick:
        return
    write_json(OUT / "bench_brdf_fit.json", {"samples": n, "threads": os.cpu_count(), "rows": rows,
                                             "load_average_1min": [load, os.getloadavg()[0]], "curves": curves})
    plot(curves, OUT / "bench_brdf_fit.png")
    print(f"wrote {OUT / 'bench_brdf_fit.json'} and {OUT / 'bench_brdf_fit.png'}")


def plot(curves, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(curves), figsize=(4 * len(curves), 3.4))
    for ax, (name, runs) in zip(axes, curves.items()):
        best = min(hist[-1][1] for hist in runs.values())
        for label, hist in runs.items():
            t, e = np.array(hist).T
            ax.loglog(np.maximum(t, 1e-3), np.maximum(e / best - 1, 1e-7), label=label)
        ax.set_title(name)
        ax.set_xlabel("wall time (s)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("full-data loss / best final - 1")
    axes[-1].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


if __name__ == "__main__":
    main()
