"""The per-texel normal step's tolerance (``mifaces.reflectance.maps.normals.STEP_TOL``), chosen on
development captures (SIMULATED).

Each capture is the main job's default one (``mifaces simulate``'s defaults: 6 measurements of 512²,
Cook–Torrance truth) at a development seed (:data:`SEEDS`). Its faces are fitted as ``measure`` fits
them, its samples taken, the bounced light taken out and the lights balanced once with Phong (as
``measure`` does with its first model). Then each of the four models is fitted with the defaults
(per-texel normals on) at each tolerance of :data:`TOLERANCES`, and validated as ``measure``'s
report does: held-out lights and environments in a novel pose (relative image RMSE) on the fitted
shape, skin's BRDF error against the truth. The fits' wall times are taken in turns (the order of
the tolerances rotates from model to model), each model's after one untimed warm-up fit of it (its
kernels compiled).

    python validation/normal_step_tol.py [--work DIR]

Machine: 2 CPU cores; about 20 minutes.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

from provenance import write_result  # noqa: E402
from roles import SIMULATED, refuse_report_data  # noqa: E402

from mifaces import brdf as brdf_models  # noqa: E402
from mifaces.capture import load_capture  # noqa: E402
from mifaces.model import load_model  # noqa: E402
from mifaces.reflectance import FitOptions  # noqa: E402
from mifaces.reflectance.fitting import fit_samples  # noqa: E402
from mifaces.reflectance.maps.normals import STEP_TOL  # noqa: E402
from mifaces.reflectance.sample_stage import take_samples, with_balanced_lights, without_bounced_light  # noqa: E402
from mifaces.shape import fit_shape, shapes_in_world  # noqa: E402
from mifaces.studio import SimulationOptions, simulate  # noqa: E402
from mifaces.validation.validator import Validator  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
#: Development seeds (validation/roles.py).
SEEDS = (101, 102)
#: The tolerances compared: photometric stereo's (1e-7, the texel normals' before) and looser ones.
TOLERANCES = (1e-7, 1e-6, 1e-5, 1e-4)
MODELS = ("phong", "cooktorrance", "ward", "lafortune")


def prepared(folder: Path, seed: int):
    """The seed's default capture simulated into ``folder``, its fitted faces' samples as ``measure``
    takes them, and the validator of its first photograph's face."""
    simulate(folder, SimulationOptions(seed=seed), progress=False, force=True)
    capture, face = load_capture(folder), load_model("builtin")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        shapes = shapes_in_world(fit_shape(capture, face, progress=False), capture)
    options = FitOptions()
    first = brdf_models.model(MODELS[0], **options.brdf_options())
    taken = take_samples(capture, shapes, face, options, progress=False)
    taken = with_balanced_lights(without_bounced_light(taken, first, options, progress=False), first, options)
    name = next(m.name for m in capture.measurements if m.name in shapes)
    return taken, Validator(capture, face, shapes[name], name)


def fit(taken, validator, model: str, tol: float) -> dict:
    """``model``'s default fit with the normal step's tolerance ``tol``: its time and figures."""
    options = FitOptions(normal_options={"step_tol": tol})
    brdf = brdf_models.model(model, **options.brdf_options())
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimate = fit_samples(taken, brdf, options, progress=False)
    seconds = time.perf_counter() - t0
    validation, _ = validator.validate(estimate)
    return {"seconds": round(seconds, 2), "heldout_rmse": round(validation["heldout_rmse"], 5),
            "environment_rmse": round(validation["environment_rmse"], 5),
            "skin_brdf_rmse": round(validation["brdf_rmse"]["skin"], 5),
            "normal_loss": round(estimate.normal_refinement["loss"], 5)}


def summarise(runs: list) -> dict:
    """Per tolerance, over seeds and models: the fits' total time against 1e-7's, and the largest change
    of a model's held-out and environment error against 1e-7's (in points of relative RMSE). Only the
    models a seed fitted at every tolerance count (a seed that failed part-way keeps what it finished)."""
    out = {}
    done = [(r, m) for r in runs for m in MODELS if len((r.get("fits") or {}).get(m) or {}) == len(TOLERANCES)]
    if not done:
        return out
    for tol in TOLERANCES:
        key, base = str(tol), str(TOLERANCES[0])
        pairs = [(r["fits"][m][key], r["fits"][m][base]) for r, m in done]
        out[key] = {"seconds": round(sum(a["seconds"] for a, _ in pairs), 1),
                    "time_ratio": round(sum(a["seconds"] for a, _ in pairs) / sum(b["seconds"] for _, b in pairs), 3),
                    **{f"max_change_{f}_points": round(100 * max(abs(a[f] - b[f]) for a, b in pairs), 3)
                       for f in ("heldout_rmse", "environment_rmse")},
                    "max_change_skin_brdf_rmse": round(max(abs(a["skin_brdf_rmse"] - b["skin_brdf_rmse"])
                                                           for a, b in pairs), 5)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, default=Path("out/validation_normal_step_tol"))
    args = parser.parse_args()
    refuse_report_data(parser, SIMULATED, list(SEEDS), "the normal step's tolerance")
    t0 = time.perf_counter()
    runs = []
    for seed in SEEDS:
        run = {"seed": seed, "fits": {}}
        try:
            taken, validator = prepared(args.work / f"s{seed}", seed)
            for i, model in enumerate(MODELS):
                fit(taken, validator, model, STEP_TOL)  # warm-up: its kernels compiled before any timing
                order = np.roll(np.arange(len(TOLERANCES)), -i)
                run["fits"][model] = {str(TOLERANCES[k]): fit(taken, validator, model, TOLERANCES[k]) for k in order}
                run["fits"][model] = {str(t): run["fits"][model][str(t)] for t in TOLERANCES}
                print(f"seed {seed} {model}: " + ", ".join(f"{t}: {v['seconds']} s {100 * v['heldout_rmse']:.2f} %"
                                                           for t, v in run["fits"][model].items())
                      + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
        except Exception as error:  # one capture's failure is recorded, not fatal to the others
            run["error"] = repr(error)
        runs.append(run)
    result = {"label": "SIMULATED", "seeds": list(SEEDS), "tolerances": list(TOLERANCES), "chosen": STEP_TOL,
              "models": list(MODELS), "summary": summarise(runs), "runs": runs,
              "seconds": round(time.perf_counter() - t0, 1)}
    write_result(RESULTS / "normal_step_tol.json", result, script=__file__, seeds=list(SEEDS))
    print(f"wrote {RESULTS / 'normal_step_tol.json'}")


if __name__ == "__main__":
    main()
