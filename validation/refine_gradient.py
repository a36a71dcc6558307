"""Why the refinement's loss did not have its minimum at the truth (SIMULATED).

On a simulated capture with the ground-truth geometry, the refinement's image loss
(:class:`mifaces.refine.problem.RefineProblem`) is evaluated at the simulator's true BRDF and
albedo, and its gradient in each region's unconstrained glossy parameters is averaged over the
photographs and ``--repeats`` Monte Carlo seeds, at the true value and a step ``--delta`` either
side. The gradient over the curvature is the offset from the truth to the loss's minimum along
each parameter alone (in the unconstrained coordinate: about the relative change of a parameter in
logarithmic form). Cases:

* ``calibrated``: the capture's lights, as its steel spheres locate them (what the refinement sees);
* ``true_lights``: the simulator's true light positions;
* ``calibrated_quadratic``: the capture's lights, with ε of the Charbonnier penalty large
  (a quadratic loss: whether the robust penalty's median-like minimum moves it);
* ``calibrated_depth4``: the capture's lights and the simulator's path length (4).

Also each photograph's ratio of photograph to render at the truth (256 spp) over the face.

    python validation/refine_gradient.py [--seed 0] [--image 256]

Writes ``validation/results/refine_gradient.json``.
"""

from __future__ import annotations

import argparse
import sys
import dataclasses
import os
import platform
import tempfile
import time
import warnings
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

import drjit as dr
import mitsuba as mi
import numpy as np

from mifaces.capture import load_capture, read_ground_truth, with_true_lights
from mifaces.io.atomic import write_json
from mifaces.shape.io import load_geometry
from mifaces.reflectance import FitOptions, fit_brdf
from mifaces.refine import RefineSchedule
from mifaces.refine.problem import RefineProblem
from mifaces.refine.schedule import ALBEDO
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate

OUT = Path(__file__).resolve().parent / "results"
#: Case -> (use the true light positions, changes to the schedule). No region held; the lights held
#: (no light gains): the question is what the loss's minimum is with the lights as given.
CASES = {"calibrated": (False, {}), "true_lights": (True, {}),
         "calibrated_quadratic": (False, {"epsilon": 100.0}), "calibrated_depth4": (False, {"max_depth": 4})}
REGIONS = ("skin", "beard")


def truth_estimate(capture, face, shapes, resolution: int):
    """A texture-space fit's estimate with every region's parameters and the albedo set to the truth's."""
    truth = read_ground_truth(capture)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimate = fit_brdf(capture, "cooktorrance", shapes, face_model=face, progress=False,
                            options=FitOptions(resolution=resolution))
    fits = {r: dataclasses.replace(f, params={k: truth.brdf["regions"].get(r, {}).get(k, v)
                                              for k, v in f.params.items()})
            for r, f in estimate.fits.items()}
    albedo = dataclasses.replace(estimate.albedo, albedo=np.asarray(truth.albedo, np.float32))
    return dataclasses.replace(estimate, fits=fits, albedo=albedo)


def _variables(problem, names, shift: float) -> dict:
    out = {}
    for n, v in problem.variables.items():
        if n == ALBEDO:
            out[n] = mi.TensorXf(np.ascontiguousarray(v, np.float32))
        else:
            out[n] = mi.Float(np.asarray(v, np.float32) + (shift if n in names else 0.0))
    for n in names:
        dr.enable_grad(out[n])
    return out


def gradients(problem, names, shift: float, repeats: int) -> dict:
    """The loss's gradient in ``names``, all shifted by ``shift``, averaged over photographs and seeds."""
    total = {n: 0.0 for n in names}
    count = repeats * len(problem.photographs)
    for r in range(repeats):
        for i, photo in enumerate(problem.photographs):
            variables = _variables(problem, names, shift)
            loss = problem.loss(photo, variables, problem.schedule.spp, seed=1000 * r + 2 * i)
            dr.backward(loss)
            for n in names:
                total[n] += float(dr.grad(variables[n])[0]) / count
    return total


def ratios(problem) -> dict:
    """Photograph over render at the truth (256 spp), summed over each photograph's fitted pixels, per channel."""
    out = {}
    for i, photo in enumerate(problem.photographs):
        problem.set(photo, _variables(problem, [], 0.0))
        with dr.suspend_grad():
            image = np.array(mi.render(photo.scene, photo.params, spp=256, seed=5 + i)) * photo.scale
        mask = np.array(photo.weight)[..., 0] > 0
        out[photo.name] = (np.array(photo.target)[mask].sum(0) / image[mask].sum(0)).round(4).tolist()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--image", type=int, default=256)
    parser.add_argument("--resolution", type=int, default=256, help="texture resolution of the fit")
    parser.add_argument("--repeats", type=int, default=4, help="Monte Carlo seeds per photograph")
    parser.add_argument("--delta", type=float, default=0.1, help="step of the curvature's central difference")
    parser.add_argument("--out", default=str(OUT / "refine_gradient.json"))
    args = parser.parse_args()
    mifaces.set_variant("llvm_ad_rgb")
    folder = Path(tempfile.mkdtemp(prefix="refine_gradient_")) / "capture"
    simulate(folder, SimulationOptions(resolution=(args.image, args.image), seed=args.seed), progress=False)
    capture = load_capture(folder)
    face, shapes = load_geometry(capture, "ground-truth")
    truth = truth_estimate(capture, face, shapes, args.resolution)
    true_positions = {light.name: light.position for light in read_ground_truth(capture).lights}
    lights = {light.name: {"calibrated_mm": np.asarray(light.position).round(2).tolist(),
                           "true_mm": np.asarray(true_positions[light.name]).round(2).tolist()}
              for light in capture.lights}
    cases = {}
    for case, (true_lights, changes) in CASES.items():
        t = time.perf_counter()
        schedule = dataclasses.replace(RefineSchedule(), held_regions=(), light_gain_learning_rate=None, **changes)
        problem = RefineProblem(truth, with_true_lights(capture) if true_lights else capture, shapes, face, schedule)
        names = [n for n in problem.variables if n.split(".")[0] in REGIONS]
        g0 = gradients(problem, names, 0.0, args.repeats)
        gm = gradients(problem, names, -args.delta, args.repeats)
        gp = gradients(problem, names, args.delta, args.repeats)
        rows = {}
        for n in names:
            region, k = n.split(".")
            space, x = problem.spaces[region], float(problem.variables[n])
            entry = space.free[int(k)]
            curvature = (gp[n] - gm[n]) / (2 * args.delta)
            offset = -g0[n] / curvature if curvature > 0 else None
            rows[n] = {"region": region, "parameter": entry.name, "channel": entry.channel,
                       "gradient": g0[n], "curvature": curvature, "offset_to_minimum": offset,
                       "true_value": space.entry_value(entry, x),
                       "value_at_minimum": space.entry_value(entry, x + offset) if offset is not None else None}
        cases[case] = {"true_lights": true_lights, "schedule_changes": changes, "variables": rows,
                       "photograph_over_render": ratios(problem), "seconds": round(time.perf_counter() - t, 1)}
        print(case, {n: round(r["offset_to_minimum"] or float("nan"), 4) for n, r in rows.items()}, flush=True)
    write_json(Path(args.out), {
        "simulated": True, "command": "python validation/refine_gradient.py " + " ".join(sys.argv[1:]),
        "what": "gradient of the refinement's image loss at the simulator's true BRDF and albedo, in skin's and "
                "beard's unconstrained glossy parameters (SIMULATED capture, ground-truth geometry)",
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "variant": mi.variant(),
                    "mitsuba": mi.__version__},
        "seed": args.seed, "image": args.image, "texture_resolution": args.resolution, "repeats": args.repeats,
        "delta": args.delta, "lights": lights, "cases": cases})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
