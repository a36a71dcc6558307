"""The refinement's schedule chosen on training captures and reported on others (SIMULATED).

Each seed simulates the default capture (:func:`mifaces.studio.simulate`: the built-in face,
6 measurements under 2 lights, Cook–Torrance truth) at ``--image``², fits Cook–Torrance in texture
space on the ground-truth geometry, and refines it (:func:`mifaces.refine.reflectance.refine_estimate`)
under each variant of the schedule:

* ``gains``: each light's intensity a variable (the light gains), no region held;
* ``gains_skin_held``: the light gains, skin and beard held at their texture-space fit;
* ``calibrated``: the lights as calibrated (``light_gain_learning_rate=None``), no region held;
* ``calibrated_skin_held``: both held (the schedule before the light gains);
* ``gains_eyebrows_held``: the light gains, the eyebrows held.

The rest of the schedule is :class:`~mifaces.refine.schedule.RefineSchedule`'s default;
the result names the variant that is the default.

Per variant: each region's errors against the truth (:func:`mifaces.validation.truth_errors.ground_truth_errors`),
whether the refinement was kept (held-out pixels), the relative RMSE under a light no photograph
used, and the fitted light gains against the true ones (the calibrated lights' irradiance error at
the face: (d_calibrated / d_true)², normalised like the gains).

Training seeds choose the defaults; the reported seeds play no part in that (the default is
``gains_eyebrows_held``)::

    python validation/refine_seeds.py --seeds 11 12 100 --out validation/results/refine_seeds_train.json
    python validation/refine_seeds.py --seeds 1 2 3 --out validation/results/refine_seeds_test.json
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
import tempfile
import time
import warnings
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

import mitsuba as mi
import numpy as np

from mifaces.capture import load_capture, read_ground_truth
from mifaces.io.atomic import write_json
from mifaces.shape.io import load_geometry
from mifaces.reflectance import FitOptions, fit_brdf
from mifaces.refine import RefineSchedule, refine_estimate
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate

from refine import novel_light_errors, region_errors  # noqa: E402  (validation/refine.py)
from roles import SIMULATED, refuse_report_data  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
#: The variants compared: name -> changes to the default schedule.
_GAIN = RefineSchedule.light_gain_learning_rate or 0.005
VARIANTS = {"gains": {"light_gain_learning_rate": _GAIN, "held_regions": ()},
            "gains_skin_held": {"light_gain_learning_rate": _GAIN, "held_regions": ("skin", "beard")},
            "calibrated": {"light_gain_learning_rate": None, "held_regions": ()},
            "calibrated_skin_held": {"light_gain_learning_rate": None, "held_regions": ("skin", "beard")},
            "gains_eyebrows_held": {"light_gain_learning_rate": _GAIN, "held_regions": ("eyebrows",)}}


def true_gains(capture, shapes) -> dict:
    """Light name -> the calibrated light's irradiance error at the face, (d_calibrated / d_true)²,
    divided by its geometric mean over the lights (the gains' normalisation)."""
    truth = {light.name: light for light in read_ground_truth(capture).lights}
    ratios = {}
    for light in capture.lights:
        centre = np.mean([np.asarray(shapes[m.name]).mean(axis=0) for m in capture.measurements
                          if m.light == light.name], axis=0)
        ratios[light.name] = (np.linalg.norm(np.asarray(light.position) - centre)
                              / np.linalg.norm(np.asarray(truth[light.name].position) - centre)) ** 2
    mean = np.exp(np.mean(np.log(list(ratios.values()))))
    return {name: float(r / mean) for name, r in ratios.items()}


def run_seed(seed: int, image: int, resolution: int, variants: list[str], work: Path) -> dict:
    folder = work / f"capture_{seed}"
    t = time.perf_counter()
    simulate(folder, SimulationOptions(resolution=(image, image), seed=seed), progress=False)
    capture = load_capture(folder)
    face, shapes = load_geometry(capture, "ground-truth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimate = fit_brdf(capture, "cooktorrance", shapes, face_model=face, progress=False,
                            options=FitOptions(resolution=resolution))
    out = {"seed": seed, "simulate_and_fit_seconds": round(time.perf_counter() - t, 1),
           "true_light_gains": true_gains(capture, shapes),
           "texture_space": region_errors(estimate, capture), "variants": {}}
    estimates = {"texture_space": estimate}
    for name in variants:
        schedule = dataclasses.replace(RefineSchedule(), **VARIANTS[name])
        t = time.perf_counter()
        refined = refine_estimate(estimate, capture, shapes, face, schedule, seed=seed, progress=False)
        record = refined.refinement
        estimates[name] = refined
        out["variants"][name] = {
            "errors": region_errors(refined, capture), "accepted": record["accepted"],
            "light_gains": record["light_gains"], "regions_refined": record["regions"],
            "loss": {k: record[k] for k in ("loss_before", "loss_after", "heldout_loss_before",
                                            "heldout_loss_after")},
            "seconds": round(time.perf_counter() - t, 1)}
        print(f"seed {seed} {name}: kept {record['accepted']}, gains {record['light_gains']} "
              f"(true {out['true_light_gains']}), {time.perf_counter() - t:.0f} s", flush=True)
    held_out, _ = novel_light_errors(estimates, capture, face, shapes, 64)
    out["novel_light_relative_rmse"] = held_out
    print(f"seed {seed}: novel light {held_out}", flush=True)
    return out


def summary(seeds: list[dict], variants: list[str]) -> dict:
    """Per variant: the mean over seeds of each region's ρs and roughness errors and the novel-light error."""
    out = {}
    for name in ["texture_space", *variants]:
        def errors(s):
            return s["texture_space"] if name == "texture_space" else s["variants"][name]["errors"]
        regions = errors(seeds[0])["regions"]
        out[name] = {"regions": {r: {p: round(float(np.mean([errors(s)["regions"][r][p] for s in seeds])), 4)
                                     for p in ("specular_reflectance", "roughness") if p in regions[r]}
                                 for r in regions},
                     "novel_light_relative_rmse": round(float(np.mean(
                         [s["novel_light_relative_rmse"][name] for s in seeds])), 4)}
        if name != "texture_space":
            out[name]["kept"] = int(sum(s["variants"][name]["accepted"] for s in seeds))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", required=True)
    parser.add_argument("--image", type=int, default=256)
    parser.add_argument("--resolution", type=int, default=256, help="texture resolution of the fit")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--role", choices=["training", "test"], required=True,
                        help="training seeds choose the defaults; test seeds only report")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    if args.role == "training":
        refuse_report_data(parser, SIMULATED, args.seeds, "the refinement's defaults (--role training)")
    work = Path(tempfile.mkdtemp(prefix="refine_seeds_"))
    seeds = [run_seed(seed, args.image, args.resolution, args.variants, work) for seed in args.seeds]
    result = {
        "simulated": True, "role": args.role, "command": "python validation/refine_seeds.py " + " ".join(sys.argv[1:]),
        "what": "Cook-Torrance fitted in texture space on the ground-truth geometry, refined by differentiable "
                "rendering under each schedule variant; errors against the simulator's truth (SIMULATED captures)",
        "machine": {"cpus": os.cpu_count(), "load_average_at_end": list(os.getloadavg()),
                    "platform": platform.platform(), "variant": mi.variant(), "mitsuba": mi.__version__},
        "image": args.image, "texture_resolution": args.resolution, "variants": VARIANTS,
        "schedule": dataclasses.asdict(RefineSchedule()),
        "default_variant": next((name for name, v in VARIANTS.items()
                                 if dataclasses.replace(RefineSchedule(), **v) == RefineSchedule()), None),
        "seeds": seeds,
        "summary": summary(seeds, args.variants)}
    write_json(Path(args.out), result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
