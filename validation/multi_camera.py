"""The shape fit with one camera and with a rig of three calibrated cameras (SIMULATED; issue 46).

Per seed, the default simulated capture (:func:`mifaces.simulate`'s defaults but ``--resolution``)
is simulated twice: with the studio camera alone, and with ``cameras=3`` (the studio camera and two
more turned by :data:`mifaces.studio.scene.RIG_YAWS` about the head, every shot photographed by all
three). The same face, lights and poses; the default shape fit (:func:`mifaces.shape.fit_shape`)
on each. Per photograph: the mean distance from the truth over the front of the face in the world
frame, after a rigid alignment, the depth offset along the first camera's axis, the mean distance
over the whole head after a similarity alignment (what one camera can observe), and the fit's
status (:func:`mifaces.validation.shape_errors.capture_shape_errors`). Then the Cook–Torrance fit
(:func:`mifaces.reflectance.fit_brdf`, default options: a 512² texture) on those shapes, samples from
every photograph of every camera in one texture, and its albedo map against the truth's
(:func:`mifaces.validation.truth_errors.ground_truth_errors`): RMSE over the texels with samples,
over every face texel, and how many texels have samples. Nothing was tuned on these
seeds (``roles.py``: report seeds).

    python validation/multi_camera.py --seeds 2001 2002 --resolution 512 --work DIR

Writes ``validation/results/multi_camera.json`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

from mifaces import SimulationOptions, load_capture, simulate
from mifaces.io.atomic import write_json
from mifaces.shape.io import load_geometry
from mifaces.reflectance import fit_brdf
from shape_depth import fitted_shapes
from mifaces.validation.truth_errors import ground_truth_errors
from mifaces.validation.shape_errors import capture_shape_errors

RESULTS = Path(__file__).resolve().parent / "results"
#: The rigs compared: cameras per shot.
RIGS = (1, 3)
KEYS = ("world_mm", "aligned_mm", "depth_mm", "similarity_mm")


def rig_run(seed: int, cameras: int, resolution: int, work: Path) -> dict:
    folder = work / f"capture_{seed}_{cameras}"
    simulate(folder, SimulationOptions(seed=seed, cameras=cameras, resolution=(resolution, resolution)), progress=False,
             force=True)
    capture = load_capture(folder)
    face = mifaces.load_model()
    _, truth = load_geometry(capture, "ground-truth")
    fits, shapes, seconds = fitted_shapes(capture, face)  # the default fit, as shape_depth.py runs it
    errors = capture_shape_errors(face, shapes, truth, capture.camera)
    camera = {m.name: m.camera for m in capture.measurements}
    photographs = {fit.measurement: {"status": fit.status, "camera": camera[fit.measurement],
                                     **{k: round(float(errors[fit.measurement][k]), 3) for k in KEYS
                                        if fit.measurement in errors}}
                   for fit in fits}
    t = time.perf_counter()
    estimate = fit_brdf(capture, "cooktorrance", shapes, face_model=face, progress=False)
    albedo = {k: (round(v, 5) if isinstance(v, float) else v)
              for k, v in ground_truth_errors(estimate, capture)["albedo"].items()}
    albedo["fit_seconds"] = round(time.perf_counter() - t, 1)
    first = [name for name, p in photographs.items() if p["camera"] in ("c0", "camera") and "world_mm" in p]
    return {"cameras": cameras, "photographs": photographs, "converged": sum(f.converged for f in fits),
            "fits": len(fits), "fit_seconds": round(seconds, 1), "albedo": albedo,
            # each shot once (the first camera's photograph; the others share its face)
            "shots": {f"{stat}_{k}": round(float(fn([abs(photographs[n][k]) if k == "depth_mm" else photographs[n][k]
                                                      for n in first])), 3)
                      for k in KEYS for stat, fn in (("mean", np.mean), ("max", np.max))}}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[2001, 2002])
    parser.add_argument("--resolution", type=int, default=512)
    parser.add_argument("--work", type=Path, default=Path("out/multi_camera"))
    parser.add_argument("--out", type=Path, default=RESULTS / "multi_camera.json")
    args = parser.parse_args(argv)
    runs = []
    for seed in args.seeds:
        for cameras in RIGS:
            run = rig_run(seed, cameras, args.resolution, args.work)
            runs.append({"seed": seed, **run})
            print(f"seed {seed}, {cameras} camera(s): {run['converged']}/{run['fits']} converged, shots "
                  + ", ".join(f"{k} {v}" for k, v in run["shots"].items()), flush=True)
    pooled = {str(c): {k: round(float(np.mean([r["shots"][k] for r in runs if r["cameras"] == c])), 3)
                       for k in runs[0]["shots"]} for c in RIGS}
    for c in RIGS:
        pooled[str(c)].update({f"albedo_{k}": round(float(np.mean([r["albedo"][k] for r in runs if r["cameras"] == c])), 5)
                               for k in ("rmse_sampled", "rmse_face", "texels_sampled")})
    write_json(args.out, {
        "label": "SIMULATED", "command": "python validation/" + Path(__file__).name + " " + " ".join(sys.argv[1:]),
        "settings": {"seeds": args.seeds, "resolution": args.resolution, "rigs": list(RIGS)},
        "runs": runs, "mean_over_seeds": pooled})


if __name__ == "__main__":
    main()
