"""Whether ``mifaces measure`` should balance the given lights by default (SIMULATED): the main job with
and without ``--balance-lights`` on the same captures.

Each seed simulates the default capture (:func:`mifaces.studio.simulate`: the built-in face, 6
photographs under 2 lights, Cook–Torrance truth, 512²; the simulator places the lights as its steel
spheres calibrate them, with their errors) and runs :func:`mifaces.pipeline.measure.measure` on it twice, with
``FitOptions(balance_lights=False)`` (the default) and ``True``. Per run and model, from the report: skin's
BRDF error over the hemisphere (``validation.brdf_rmse.skin``), the albedo error, the held-out-light and
environment errors on the fitted faces and with the fitted reflectance on the true shape; and the factors
the balance found (``light_balance``).

The default is chosen on the tuning seeds (``--role tuning``, seeds 100–104, as for the balance's
threshold, ``validation/light_calibration_bias.py``); the report seeds play no part in it::

    python validation/light_balance_measure.py --seeds 100 101 102 103 104 --role tuning
    python validation/light_balance_measure.py --seeds 0 1 2 3 4 --role test

Writes ``validation/results/light_balance_measure_{tuning,test}.json`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

import numpy as np

from mifaces.io.atomic import write_json
from mifaces.pipeline.measure import measure
from mifaces.reflectance import FitOptions
from mifaces.studio import SimulationOptions, simulate
from roles import SIMULATED, refuse_report_data

RESULTS = Path(__file__).resolve().parent / "results"
#: The report's per-model figures kept, and how a run is summarised over the seeds.
KEYS = ("heldout_rmse", "environment_rmse", "heldout_rmse_true_shape", "environment_rmse_true_shape", "albedo_rmse")
SETTINGS = {"given": False, "balanced": True}


def run_entry(report: dict, seconds: float) -> dict:
    models = {}
    for model, entry in report["models"].items():
        v = entry.get("validation") or {}
        models[model] = {"skin_brdf_rmse": (v.get("brdf_rmse") or {}).get("skin"), **{k: v.get(k) for k in KEYS}}
    return {"seconds": round(seconds, 1), "light_balance": report.get("light_balance"),
            "shape_floor": (report.get("validation") or {}).get("shape_floor"), "models": models}


def summary(seeds: list) -> dict:
    """Per setting and model: the mean over seeds of each figure, and on how many seeds the balance
    lowered it."""
    out = {}
    for setting in SETTINGS:
        models = seeds[0]["runs"][setting]["models"]
        out[setting] = {m: {k: float(np.mean([s["runs"][setting]["models"][m][k] for s in seeds]))
                            for k in ("skin_brdf_rmse", *KEYS)} for m in models}
    out["balanced_lower_on_seeds"] = {
        m: {k: int(sum(s["runs"]["balanced"]["models"][m][k] < s["runs"]["given"]["models"][m][k] for s in seeds))
            for k in ("skin_brdf_rmse", *KEYS)} for m in out["given"]}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102, 103, 104])
    parser.add_argument("--role", choices=("tuning", "test"), default="tuning")
    parser.add_argument("--work", type=Path, default=Path("out/light_balance_measure"))
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.role == "tuning":
        refuse_report_data(parser, SIMULATED, args.seeds, "--balance-lights' default (--role tuning)")
    mifaces.set_variant("llvm_ad_rgb")
    seeds = []
    for seed in args.seeds:
        folder = args.work / f"capture_{seed}"
        simulate(folder, SimulationOptions(seed=seed), progress=False, force=True)
        runs = {}
        for setting, balance in SETTINGS.items():
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the reports keep the fits' warnings
                report = measure(args.work / f"measure_{seed}_{setting}", capture=folder, progress=False,
                                 options=FitOptions(balance_lights=balance))
            runs[setting] = run_entry(report, time.perf_counter() - t)
            skin = {m: round(100 * e["skin_brdf_rmse"], 2) for m, e in runs[setting]["models"].items()}
            print(f"seed {seed}, lights {setting}: skin BRDF error (%) {skin}", flush=True)
        seeds.append({"seed": seed, "runs": runs})
    write_json(args.out or RESULTS / f"light_balance_measure_{args.role}.json", {
        "label": "SIMULATED", "role": args.role,
        "command": "python validation/light_balance_measure.py " + " ".join(argv or sys.argv[1:]),
        "what": "mifaces measure on the default capture (512², fitted shapes) with the lights as given and "
                "balanced (FitOptions.balance_lights); figures from each report's validation",
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
        "settings": SETTINGS, "seeds": seeds, "summary": summary(seeds)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
