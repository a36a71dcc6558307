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

Run:  python validation/bench_brdf_fit.py [--samples N] [--quick]
Writes validation/results/bench_brdf_fit.{json,png} and prints a table.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import mitsuba as mi
import numpy as np
import scipy.optimize

from mifaces import brdf
from mifaces.reflectance.fitting import (FULL_DATA, ParameterSpace, SubsetSchedule, _Problem,
                                         fit_region, linear_start)
from mifaces.files import atomic_path, write_json

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


def scipy_fit(model, light, view, r, sigma, jacobian: str):
    space = ParameterSpace(model, model.fixed_defaults())
    problem = _Problem(model, space, light, view, r, sigma)
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
    rows, curves = [], {}
    for name, truth in TRUTH.items():
        model = brdf.model(name)
        light, view, r, sigma = samples(model, truth, n)
        # one throw-away fit compiles the kernels, for everyone's benefit
        fit_region(model, light[:1000], view[:1000], r[:1000], sigma[:1000], schedule=FULL_DATA)
        runs = {}
        space = ParameterSpace(model, model.fixed_defaults())
        full = _Problem(model, space, light, view, r, sigma)
        for label, schedule in [("hierarchical LM", SubsetSchedule()), ("full-data LM", FULL_DATA)]:
            trace = []
            fit = fit_region(model, light, view, r, sigma, schedule=schedule, trace=trace)
            # the full-data loss along the way, evaluated after the timed run
            history = [(t, full.loss(space.vector(values))) for t, values in trace]
            runs[label] = {"loss": fit.loss, "seconds": fit.seconds, "history": history,
                           "evaluations": fit.iterations, "status": fit.status}
        for label, jac in [("scipy LM, 2-point Jacobian", "2-point"), ("scipy LM, Dr.Jit Jacobian", "drjit")]:
            runs[label] = scipy_fit(model, light, view, r, sigma, jac)
        best = min(run["loss"] for run in runs.values())
        scipy_time = runs["scipy LM, 2-point Jacobian"]["seconds"]
        for label, run in runs.items():
            rows.append({"model": name, "method": label, "samples": len(sigma), "loss": run["loss"],
                         "loss_over_best": run["loss"] / best, "seconds": run["seconds"],
                         "speedup_vs_scipy": scipy_time / run["seconds"], "status": str(run["status"])})
            print(f"{name:<13} {label:<28} loss {run['loss']:12.6g} ({run['loss'] / best - 1:+.2e})"
                  f"  {run['seconds']:7.2f} s  ({scipy_time / run['seconds']:5.1f}x faster than scipy)", flush=True)
        curves[name] = {label: run["history"] for label, run in runs.items()}
    if args.quick:
        return
    write_json(OUT / "bench_brdf_fit.json", {"samples": n, "rows": rows, "curves": curves})
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
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")


if __name__ == "__main__":
    main()
