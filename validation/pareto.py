"""Error against run time for the whole pipeline (SIMULATED captures).

For every combination of the number of measurements (photographs), the
photographs' resolution and their samples per pixel (the simulated
photographs' Monte Carlo noise, standing in for a camera's noise), this
simulates a capture of the built-in face (Cook–Torrance truth,
:func:`mifaces.studio.simulate`) and runs the main job on it
(:func:`mifaces.pipeline.measure.measure`: fit the face model to each photograph,
sample reflectance, fit the BRDF models), then reads from its report
(:mod:`mifaces.validation.validator`):

- the BRDF error over the hemisphere (skin, ``brdf_rmse``),
- the albedo error (``albedo_rmse``),
- the environment-lit novel-view image error (``environment_rmse``),

against the wall time of ``mifaces measure`` as a user runs it without a
capture: simulating the photographs plus the measurement, without the
validation's own renders (reported apart). The Pareto front of each error
against time is drawn, and the README's defaults (:data:`DEFAULT`) are
marked, with whether they lie on the front.

Every grid point is run on each of ``--seeds`` (each seed simulates another
face, poses, lamps and noise): the errors are given as the mean over the
seeds with their range, and the fronts are drawn through the means, so a
difference between two settings counts only beside the spread one setting
has from seed to seed.

    python validation/pareto.py                       # the full grid (hours on 2 cores)
    python validation/pareto.py --measurements 2 6 --resolutions 256 512 --spp 16 64 --geometry ground-truth

Writes ``validation/results/pareto.json`` and ``pareto.png``; a run adds its
points to an existing ``pareto.json`` of the same options (resumable), and
``--work`` keeps the simulated captures.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
import warnings
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

import mitsuba as mi
import numpy as np

from mifaces.io.atomic import save_figure, write_json
from mifaces.pipeline.measure import measure
from mifaces.studio import SimulationOptions, simulate
from mifaces.reflectance import FitOptions

RESULTS = Path(__file__).resolve().parent / "results"
#: The full grid: measurements, photograph resolutions (square), samples per pixel of the photographs.
MEASUREMENTS = (2, 4, 8, 16, 22)
RESOLUTIONS = (256, 512, 1024)
SPP = (16, 64, 256)
#: The README's defaults: ``mifaces measure`` simulates this capture (mifaces.studio.simulate's defaults).
DEFAULT = {"measurements": 6, "resolution": 512, "spp": 64}
#: The seeds each grid point is run on.
SEEDS = (3, 4, 5)
#: The errors read from each model's validation, and their labels.
ERRORS = {"brdf_skin": "BRDF RMSE (skin, relative)", "albedo_rmse": "albedo RMSE",
          "environment_rmse": "environment-lit image RMSE (relative)"}


def point(work: Path, measurements: int, resolution: int, spp: int, seed: int, args) -> dict:
    """Simulate one capture, measure it, and return its errors and times."""
    name = f"{measurements}_{resolution}_{spp}_seed{seed}"
    capture = work / f"capture_{name}"
    t = time.perf_counter()
    simulate(capture, SimulationOptions(measurements=measurements, resolution=(resolution, resolution), spp=spp,
                                        seed=seed), progress=False, force=True)
    simulate_s = time.perf_counter() - t
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = measure(work / f"measure_{name}", capture, models=args.models,
                         geometry=args.geometry, progress=False, options=FitOptions(resolution=args.texture))
    seconds = report["seconds"]
    validation_s = sum(v for k, v in seconds.items() if k.startswith("validation"))
    models = {}
    for model, entry in report["models"].items():
        v = entry["validation"]
        models[model] = {"brdf_skin": v["brdf_rmse"].get("skin"), "brdf_rmse": v["brdf_rmse"],
                         "albedo_rmse": v["albedo_rmse"], "heldout_rmse": v["heldout_rmse"],
                         "environment_rmse": v["environment_rmse"], "training_rmse": entry["training_rmse"]}
    return {"measurements": measurements, "resolution": resolution, "spp": spp, "seed": seed,
            "wall_s": simulate_s + seconds["total"] - validation_s, "simulate_s": simulate_s,
            "measure_s": seconds["total"] - validation_s, "validation_s": validation_s,
            "shape_floor": report["validation"]["shape_floor"],
            "noise_floor": report["validation"].get("noise_floor"), "models": models}


def pareto_front(times: np.ndarray, errors: np.ndarray) -> np.ndarray:
    """Indices of the points no other point beats in both time and error, by increasing time."""
    order = np.lexsort((errors, times))
    front, best = [], np.inf
    for i in order:
        if errors[i] < best:
            front.append(int(i))
            best = errors[i]
    return np.array(front, int)


def grid_key(p: dict) -> tuple[int, int, int]:
    """A point's setting: measurements, resolution, spp."""
    return p["measurements"], p["resolution"], p["spp"]


def summary(points: list[dict], model: str) -> list[dict]:
    """Per setting (in the order first run): the seeds run, the mean wall time, and per error
    (:data:`ERRORS` and the held-out lights') the mean, least and largest over the seeds."""
    settings: dict = {}
    for p in points:
        settings.setdefault(grid_key(p), []).append(p)
    out = []
    for (measurements, resolution, spp), runs in settings.items():
        entry = {"measurements": measurements, "resolution": resolution, "spp": spp,
                 "seeds": [r.get("seed") for r in runs], "wall_s": float(np.mean([r["wall_s"] for r in runs]))}
        for key in (*ERRORS, "heldout_rmse"):
            values = np.array([r["models"][model][key] for r in runs], float)
            entry[key] = {"mean": float(values.mean()), "min": float(values.min()), "max": float(values.max())}
        out.append(entry)
    return out


def fronts(settings: list[dict]) -> dict:
    """Per error: the front's settings (as grid keys) through the means over the seeds, and whether
    the default lies on it."""
    times = np.array([p["wall_s"] for p in settings])
    out = {}
    for key in ERRORS:
        errors = np.array([p[key]["mean"] for p in settings], float)
        front = pareto_front(times, errors)
        keys = [grid_key(p) for p in settings]
        default = (DEFAULT["measurements"], DEFAULT["resolution"], DEFAULT["spp"])
        out[key] = {"front": [list(keys[i]) for i in front],
                    "default_on_front": bool(keys.index(default) in front) if default in keys else None}
    return out


def figure(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    settings, model = result["summary"], result["model"]
    times = np.array([p["wall_s"] for p in settings])
    fig, axes = plt.subplots(1, len(ERRORS), figsize=(5 * len(ERRORS), 4.5))
    markers = {r: m for r, m in zip(sorted({p["resolution"] for p in settings}), "os^D")}
    counts = sorted({p["measurements"] for p in settings})
    colours = dict(zip(counts, plt.cm.viridis(np.linspace(0, 0.85, len(counts)))))
    for ax, (key, label) in zip(axes, ERRORS.items()):
        errors = np.array([p[key]["mean"] for p in settings], float)
        for p, t, e in zip(settings, times, errors):
            colour = colours[p["measurements"]]
            ax.errorbar(t, e, yerr=[[e - p[key]["min"]], [p[key]["max"] - e]], color=colour, lw=0.8, capsize=2,
                        zorder=2)
            ax.scatter(t, e, marker=markers[p["resolution"]], s=20 + 30 * np.log2(p["spp"] / 8), color=colour,
                       edgecolor="k", linewidth=0.5, zorder=3)
            ax.annotate(f"{p['measurements']}/{p['resolution']}/{p['spp']}", (t, e), fontsize=6,
                        xytext=(3, 3), textcoords="offset points")
            if all(p[k] == DEFAULT[k] for k in DEFAULT):
                ax.scatter(t, e, marker="*", s=250, facecolor="none", edgecolor="r", zorder=4, label="README default")
        front = pareto_front(times, errors)
        ax.step(times[front], errors[front], where="post", color="r", lw=1, zorder=2, label="Pareto front")
        ax.set_xscale("log")
        ax.set_xlabel("wall time (s): simulate + measure, shared 2 cores")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    seeds = ", ".join(str(s) for s in result["seeds"])
    fig.suptitle(f"SIMULATED captures (truth Cook–Torrance, built-in face), model {model}, geometry "
                 f"{result['options']['geometry']}; labels: measurements/resolution/spp; marker: resolution, size: spp\n"
                 f"each point the mean over seeds {seeds}, its bar the least and largest", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--measurements", type=int, nargs="+", default=list(MEASUREMENTS))
    parser.add_argument("--resolutions", type=int, nargs="+", default=list(RESOLUTIONS))
    parser.add_argument("--spp", type=int, nargs="+", default=list(SPP))
    parser.add_argument("--models", nargs="+", default=["cooktorrance"], help="BRDF models to fit")
    parser.add_argument("--geometry", default="fitted", choices=("fitted", "ground-truth"))
    parser.add_argument("--texture", type=int, default=512, help="texture resolution R of the measurement")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS))
    parser.add_argument("--work", type=Path, default=None, help="keep the captures and reports here")
    parser.add_argument("--out", type=Path, default=RESULTS / "pareto.json")
    parser.add_argument("--replot", action="store_true", help="only draw the figure of an existing --out")
    args = parser.parse_args()
    if args.replot:
        figure(json.loads(args.out.read_text()), args.out.with_suffix(".png"))
        return
    options = {"models": args.models, "geometry": args.geometry, "texture": args.texture}
    result = {"label": "SIMULATED", "model": args.models[0], "options": options, "seeds": args.seeds,
              "default": DEFAULT,
              "grid": {"measurements": args.measurements, "resolutions": args.resolutions, "spp": args.spp},
              "full_grid": {"measurements": MEASUREMENTS, "resolutions": RESOLUTIONS, "spp": SPP},
              "machine": {"platform": platform.platform(), "variant": mi.variant(), "cores": os.cpu_count()}, "points": []}
    if args.out.is_file():
        previous = json.loads(args.out.read_text())
        if previous.get("options") == options:
            result["points"] = previous["points"]
            result["seeds"] = sorted(set(args.seeds) | {p["seed"] for p in result["points"]})
    done = {(*grid_key(p), p["seed"]) for p in result["points"]}
    grid = [(k, r, s, seed) for k in args.measurements for r in args.resolutions for s in args.spp
            for seed in args.seeds if (k, r, s, seed) not in done]
    grid.sort(key=lambda c: (c[0] * c[1] ** 2, c[2], c[3]))  # cheapest first: an interrupted run keeps a usable front
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        for n, (measurements, resolution, spp, seed) in enumerate(grid, 1):
            p = point(work, measurements, resolution, spp, seed, args)
            result["points"].append(p)
            errors = ", ".join(f"{k} {p['models'][result['model']][k]:.4f}" for k in ERRORS)
            print(f"[{n}/{len(grid)}] {measurements:3d} photos {resolution:5d} px {spp:4d} spp seed {seed}: "
                  f"{p['wall_s']:7.1f} s; {errors}", flush=True)
            result["summary"] = summary(result["points"], result["model"])
            result["fronts"] = fronts(result["summary"])
            write_json(args.out, result)
            figure(result, args.out.with_suffix(".png"))


if __name__ == "__main__":
    main()
