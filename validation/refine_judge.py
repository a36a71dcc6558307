"""How the shape refinement's check judges (SIMULATED, development seeds only): held-out pixels of the
training photographs against a held-out photograph.

``mifaces fit-shape --refine-shape`` keeps the refined shape only if its loss falls on what it did not
fit (:func:`mifaces.refine.shape.refine_shape`). Two judges are on offer
(:attr:`mifaces.refine.shape.ShapeRefineSchedule.judged`): ``0``, pixels of the training photographs
held out in blocks (the default), and ``1``, the last photograph held out of the fit as well. For every
seed this simulates the default capture at ``--resolution``, fits the shapes once with the defaults,
refines them under each judge, and asks whether the judge's verdict was right. A refinement **helped**
by one of two measures, each over every photograph's face (one displacement moves them all):

- ``distance``: the faces' mean error after a rigid alignment fell (what the refinement can change;
  their depth it cannot see);
- ``normals``: their mean normal error fell (what the reflectance samples see).

A judge is right by a measure when it keeps a refinement that helped by it or rejects one that did not.

It chooses the default judge, so it reads development seeds only (:data:`roles.SIMULATED`)::

    python validation/refine_judge.py [--seeds 11 12 100 101 102 103] [--resolution 256] [--work DIR]

Writes ``validation/results/refine_judge.json``: per seed and judge the verdict, its reason, the
losses, the errors before and after; per judge how often it kept, and how often it was right.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

import numpy as np

from mifaces.io.atomic import write_json
from mifaces.capture import load_capture
from mifaces.refine.shape import ShapeRefineSchedule, displaced
from mifaces.refine.shape_lit import FIT_SHAPE_BRDF, refine_fits
from mifaces.shape import fit_shape, shapes_in_world
from mifaces.validation.shape_errors import capture_shape_errors
from mifaces.shape.io import load_geometry
from mifaces.studio import SimulationOptions, simulate
from refine_shape_default import errors
from roles import SIMULATED, refuse_report_data

RESULTS = Path(__file__).resolve().parent / "results"
#: The judges compared: photographs held out of the fit (0: held-out pixels only).
JUDGES = (0, 1)


def aligned_mean(errors_: dict) -> float:
    """The mean rigidly aligned error (mm) over the photographs' faces."""
    return float(np.mean([e["aligned_mm"] for name, e in errors_.items() if name != "summary"]))


def judge_run(capture, fits, face, truth, judged: int) -> dict:
    """One refinement under a judge: its verdict, and the faces' errors before and displaced (kept or not)."""
    t = time.perf_counter()
    _, result = refine_fits(capture, fits, face, brdf=FIT_SHAPE_BRDF,
                            schedule=ShapeRefineSchedule(judged=judged), progress=False)
    seconds = time.perf_counter() - t
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a failed fit is left out, and its status says so
        start = shapes_in_world(fits, capture)
    moved = capture_shape_errors(face, {name: displaced(v, result.displacement, face.triangles)
                                        for name, v in start.items()}, truth, capture.camera)
    before = errors(fits, capture, face, truth)
    record = result.record
    run = {"accepted": bool(result.accepted), "reason": result.reason,
           "judged_photographs": record["judged_photographs"], "chosen_iteration": record["chosen_iteration"],
           "loss_before": record["loss_before"], "loss_after": record["loss_after"], "seconds": seconds,
           "aligned_before_mm": aligned_mean(before), "aligned_refined_mm": aligned_mean(moved),
           "normal_before_deg": before["summary"]["mean_normal_deg"],
           "normal_refined_deg": moved["summary"]["mean_normal_deg"]}
    run["helped"] = {"distance": run["aligned_refined_mm"] < run["aligned_before_mm"],
                     "normals": run["normal_refined_deg"] < run["normal_before_deg"]}
    run["right"] = {measure: run["accepted"] == helped for measure, helped in run["helped"].items()}
    return run


def seed_run(seed: int, resolution: int, work: Path) -> dict:
    folder = work / f"capture_{resolution}_{seed}"
    simulate(folder, SimulationOptions(resolution=(resolution, resolution), seed=seed), progress=False, force=True)
    capture = load_capture(folder)
    face = mifaces.load_model()
    _, truth = load_geometry(capture, "ground-truth")
    fits = fit_shape(capture, face, progress=False)
    out = {"seed": seed, "judges": {}}
    for judged in JUDGES:
        run = out["judges"][str(judged)] = judge_run(capture, fits, face, truth, judged)
        print(f"seed {seed}, judged {judged}: {'kept' if run['accepted'] else 'rejected'}; aligned "
              f"{run['aligned_before_mm']:.3f} -> {run['aligned_refined_mm']:.3f} mm, normals "
              f"{run['normal_before_deg']:.2f} -> {run['normal_refined_deg']:.2f} deg (right by distance: "
              f"{run['right']['distance']}, by normals: {run['right']['normals']}); {run['reason']}", flush=True)
    return out


MEASURES = ("distance", "normals")


def summary(runs: list) -> dict:
    """Per judge: how often it kept, and by each measure how often the refinement helped and the judge
    was right (kept a refinement that helped, rejected one that did not)."""
    out = {}
    for judged in map(str, JUDGES):
        rows = [r["judges"][judged] for r in runs]
        kept = [r for r in rows if r["accepted"]]
        out[judged] = {"runs": len(rows), "kept": len(kept),
                       "mean_aligned_change_when_kept_mm": float(np.mean(
                           [r["aligned_refined_mm"] - r["aligned_before_mm"] for r in kept])) if kept else None,
                       "mean_normal_change_when_kept_deg": float(np.mean(
                           [r["normal_refined_deg"] - r["normal_before_deg"] for r in kept])) if kept else None}
        for measure in MEASURES:
            out[judged][measure] = {
                "helped": sum(r["helped"][measure] for r in rows), "right": sum(r["right"][measure] for r in rows),
                "kept_but_worse": sum(r["accepted"] and not r["helped"][measure] for r in rows),
                "rejected_but_better": sum(not r["accepted"] and r["helped"][measure] for r in rows)}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 100, 101, 102, 103])
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--work", type=Path, default=Path("out/refine_judge"))
    parser.add_argument("--out", type=Path, default=RESULTS / "refine_judge.json")
    args = parser.parse_args(argv)
    refuse_report_data(parser, SIMULATED, args.seeds, "the shape refinement's judge")
    mifaces.set_variant("llvm_ad_rgb")
    runs = [seed_run(seed, args.resolution, args.work) for seed in args.seeds]
    result = summary(runs)
    write_json(args.out, {"label": "SIMULATED", "role": "development",
                          "command": "python validation/refine_judge.py " + " ".join(argv or sys.argv[1:]),
                          "seeds": args.seeds, "resolution": args.resolution, "lit_by": FIT_SHAPE_BRDF,
                          "default_judged": ShapeRefineSchedule.judged, "summary": result, "runs": runs})
    for judged, row in result.items():
        print(f"judged {judged}: kept {row['kept']} of {row['runs']}; " + "; ".join(
            f"by {m}: helped {row[m]['helped']}, right {row[m]['right']} (kept but worse {row[m]['kept_but_worse']}, "
            f"rejected but better {row[m]['rejected_but_better']})" for m in MEASURES))
    return 0


if __name__ == "__main__":
    sys.exit(main())
