"""The shape refinement by differentiable rendering from fitted shapes, on the default simulated
capture (SIMULATED): the world-frame error of every photograph's face against the truth before and
after, as ``mifaces fit-shape --refine-shape`` runs it.

Simulates the default capture (seed 0, 6 photographs) at ``--resolution`` (256² by default: the
refinement's cost grows with the pixels), fits the shapes with the defaults
(:func:`mifaces.shape.fit_shape`), refines them (:func:`mifaces.refine.shape_lit.refine_fits`,
lit by a quick per-region fit) and scores both by :func:`mifaces.validation.shape_errors.capture_shape_errors`:
the faces it returns (``refined``: the model fit where the refinement was not kept) and the faces
displaced by its displacement whether kept or not (``displaced``).

    python validation/refine_shape_default.py [--resolution 256] [--seed 0] [--work DIR] [--judged 1]
                                              [--early-stop] [--brdf phong] [--downsample K] [--out FILE]

The render resolution's default (:data:`mifaces.refine.shape_schedule.RENDER_SIDE`) was chosen on the
tuning seed 11 at 512², rendered at full resolution and at the default::

    python validation/refine_shape_default.py --resolution 512 --seed 11 --downsample 1 \
        --out validation/results/refine_shape_default_512_tuning_full.json
    python validation/refine_shape_default.py --resolution 512 --seed 11 \
        --out validation/results/refine_shape_default_512_tuning.json

Writes ``validation/results/refine_shape_default{,_judged}{,_early_stop}.json`` (or ``--out``): per set of faces
the errors of :func:`~mifaces.validation.shape_errors.capture_shape_errors`, the normals' among them.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

from mifaces.capture import load_capture
from mifaces.io.atomic import write_json
from mifaces.shape.io import load_geometry
from mifaces.refine.shape import ShapeRefineSchedule, displaced
from mifaces.brdf import NAMES as BRDF_MODELS
from mifaces.refine.shape_lit import FIT_SHAPE_BRDF, refine_fits
from mifaces.shape import fit_shape, shapes_in_world
from mifaces.validation.shape_errors import capture_shape_errors
from mifaces.studio import SimulationOptions, simulate
from roles import SIMULATED, refuse_report_data

RESULTS = Path(__file__).resolve().parent / "results"


def errors(fits, capture, face, truth) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a failed fit is left out, and its status says so
        shapes = shapes_in_world(fits, capture)
    return capture_shape_errors(face, shapes, truth, capture.camera)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--work", type=Path, default=Path("out/refine_shape_default"))
    parser.add_argument("--judged", type=int, default=ShapeRefineSchedule.judged,
                        help="photographs held out of the refinement to judge it by; above 0 the result's name "
                             "ends in _judged")
    parser.add_argument("--early-stop", action="store_true",
                        help="ShapeRefineSchedule(early_stop=True); the result's name ends in _early_stop")
    parser.add_argument("--brdf", default=FIT_SHAPE_BRDF, choices=sorted(BRDF_MODELS),
                        help="the model of the quick fit that lights the refinement")
    parser.add_argument("--downsample", type=int, default=ShapeRefineSchedule.downsample,
                        help="render at 1/K of the photographs' resolution (default: the schedule's, "
                             "the longer side at most RENDER_SIDE pixels)")
    parser.add_argument("--out", type=Path, default=None,
                        help="the result file (default validation/results/refine_shape_default{,_judged}.json)")
    args = parser.parse_args(argv)
    if args.out is not None and "tuning" in args.out.name:  # a run that chooses the schedule's defaults
        refuse_report_data(parser, SIMULATED, [args.seed], "the shape refinement's schedule (--out …tuning…)")
    mifaces.set_variant("llvm_ad_rgb")
    folder = args.work / f"capture_{args.resolution}_{args.seed}"
    simulate(folder, SimulationOptions(resolution=(args.resolution, args.resolution), seed=args.seed), progress=False,
             force=True)
    capture = load_capture(folder)
    face = mifaces.load_model()
    _, truth = load_geometry(capture, "ground-truth")
    t = time.perf_counter()
    fits = fit_shape(capture, face, progress=False)
    fitted = time.perf_counter() - t
    before = errors(fits, capture, face, truth)
    t = time.perf_counter()
    refined, result = refine_fits(capture, fits, face, brdf=args.brdf,
                                  schedule=ShapeRefineSchedule(judged=args.judged, early_stop=args.early_stop,
                                                               downsample=args.downsample),
                                  progress=True)
    refining = time.perf_counter() - t
    after = errors(refined, capture, face, truth)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        start = shapes_in_world(fits, capture)
    moved = capture_shape_errors(face, {name: displaced(v, result.displacement, face.triangles)
                                        for name, v in start.items()}, truth, capture.camera)
    name = f"refine_shape_default{'_judged' if args.judged else ''}{'_early_stop' if args.early_stop else ''}.json"
    write_json(args.out or RESULTS / name, {
        "label": "SIMULATED", "command": "python validation/refine_shape_default.py " + " ".join(argv or sys.argv[1:]),
        "resolution": args.resolution, "seed": args.seed, "lit_by": args.brdf, "accepted": result.accepted,
        "downsample": result.record["downsample"],
        "reason": result.reason,
        "heldout_loss": {"before": result.record["loss_before"]["heldout"],
                         "after": result.record["loss_after"]["heldout"]},
        "judged_photographs": result.record["judged_photographs"],
        "chosen_iteration": result.record["chosen_iteration"],
        "judged_loss": {"before": result.record["loss_before"].get("judged"),
                        "after": result.record["loss_after"].get("judged")},
        "seconds": {"fit_shape": fitted, "refine": refining},
        "shape_errors": {"model_fit": before, "refined": after, "displaced": moved}})
    print(f"{result.reason}; world-frame mean {before['summary']['mean_world_mm']:.2f} -> "
          f"{after['summary']['mean_world_mm']:.2f} mm, aligned {before['summary']['mean_aligned_mm']:.2f} -> "
          f"{after['summary']['mean_aligned_mm']:.2f} mm, normals {before['summary']['mean_normal_deg']:.2f} -> "
          f"{after['summary']['mean_normal_deg']:.2f} deg ({refining:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
