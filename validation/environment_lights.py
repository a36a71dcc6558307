"""What not knowing an environment costs: simulated captures lit by the studio and by the sky.

For each environment (``mifaces simulate --environment studio|sky``: eight head turns under one
map, the photographs rendered with exactly the map the capture states) and each seed, the
capture is measured twice with ``mifaces measure`` (Cook-Torrance, the truth's family, fitted
faces, ``--refine``): once with the map given, once with the light hidden
(``{"name", "unknown": true, "kind": "environment"}``: the map is estimated with the face,
``mifaces.light_estimation.unknown.estimate_environments``, and refined with the BRDF). Reported per run:

* skin's BRDF error against the truth (the validation's relative BRDF RMSE) and its fitted
  parameters' errors;
* the held-out-light error (novel pose, the validation's held-out directional lights) and the
  environment error (novel pose, the studio and sky), raw; the estimated run's reflectance is
  relative, so the validation compares it after one factor (``reflectance_scale``: the median
  ratio of true to fitted skin albedo, what a colour chart would give);
* the ratio of the hidden-light run's held-out error to the given-map run's (target: at most 1.5);
* the estimated map against the true one: the relative error of the irradiance it gives normals
  facing the camera's half-space (scale removed), before and after the refinement;
* the extra seconds the estimate costs (``measure``'s timings).

The defaults of the estimate were set on seed 11 (both environments), which the report leaves
out: restarting the glossy parameters under a map with ``--tuning``; the map size, smoothness,
floor and refinement rates in development runs not committed. Reported seeds default to 1 and 2.

    python validation/environment_lights.py --out out/environment_lights [--seeds 1 2]
    python validation/environment_lights.py --tuning --out out/environment_lights_tuning

Writes ``validation/results/environment_lights.{json,png}``. SIMULATED.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

from mifaces.capture import MANIFEST, load_capture, read_ground_truth
from mifaces.lights.environment import LUMINANCE, irradiance, texel_directions
from mifaces.io.atomic import save_figure, write_json
from mifaces.io.image_files import read_exr
from mifaces.shape.io import load_geometry
from mifaces.light_estimation.unknown import LIGHTS_FOLDER
from mifaces.pipeline.measure import measure
from mifaces.studio import SimulationOptions, simulate
from mifaces.studio.environment_light import ENVIRONMENTS
from mifaces.reflectance import FitOptions, fit_brdf
from mifaces.refine import RefineSchedule, refine_estimate
from roles import SIMULATED, refuse_report_data

RESULTS = Path(__file__).resolve().parent / "results"
#: Target of issue 26: the hidden-light run's held-out error over the given-map run's.
RATIO_TARGET = 1.5
#: The BRDF model measured: the truth's family.
MODEL = "cooktorrance"
#: The seed the estimate's defaults were set on, not reported.
TUNING_SEED = 11
#: Photographs per capture, their size and samples per pixel, the texture resolution.
MEASUREMENTS, IMAGE, SPP, RESOLUTION = 8, 256, 32, 256


def hide_lights(capture: Path, out: Path) -> Path:
    """A copy of ``capture`` whose lights are unknown environment maps (same names)."""
    shutil.copytree(capture, out)
    data = json.loads((out / MANIFEST).read_text())
    data["lights"] = [{"name": light["name"], "unknown": True, "kind": "environment"} for light in data["lights"]]
    (out / MANIFEST).write_text(json.dumps(data, indent=1))
    return out


def irradiance_error(true_map: np.ndarray, estimate: np.ndarray) -> float:
    """Relative RMS error of the unoccluded irradiance ``estimate`` gives the normals of the
    camera's half-space (the map frame's z > 0.2) against ``true_map``'s, the scale removed."""
    h, w = estimate.shape[:2]
    d, _ = texel_directions(w, h)
    front = d[d[:, 2] > 0.2]
    e_true, e_fit = irradiance(true_map, front), irradiance(estimate, front)
    e_fit *= (e_true @ LUMINANCE).mean() / (e_fit @ LUMINANCE).mean()
    return float(np.sqrt(np.mean((e_fit - e_true) ** 2) / np.mean(e_true ** 2)))


def run_summary(report: dict) -> dict:
    """What one ``measure`` run says: skin's errors, the novel-pose errors, times."""
    entry = report["models"][MODEL]
    validation = entry["validation"]
    truth = entry.get("ground_truth", {}).get("regions", {}).get("skin", {})
    refinement = entry.get("refinement", {})
    return {"skin_brdf_rmse": validation["brdf_rmse"]["skin"],
            "skin_parameter_errors": {k: v for k, v in truth.items() if isinstance(v, (int, float, list))},
            "skin": entry["regions"]["skin"],
            "heldout_rmse": validation["heldout_rmse"], "environment_rmse": validation["environment_rmse"],
            "heldout_rmse_true_shape": validation.get("heldout_rmse_true_shape"),
            "reflectance_scale": validation["reflectance_scale"],
            "shape_floor": report["validation"]["shape_floor"],
            "refinement_accepted": refinement.get("accepted"), "seconds": report["seconds"]}


def one(environment: str, seed: int, out: Path) -> dict:
    """Both runs of one environment and seed."""
    folder = out / f"{environment}_{seed}"
    if folder.exists():
        shutil.rmtree(folder)
    capture = folder / "capture"
    simulate(capture, SimulationOptions(environment=environment, seed=seed, measurements=MEASUREMENTS,
                                        resolution=(IMAGE, IMAGE), spp=SPP), progress=False)
    hidden = hide_lights(capture, folder / "capture_hidden")
    runs = {}
    for name, source in (("given", capture), ("estimated", hidden)):
        t = time.perf_counter()
        report = measure(folder / name, source, models=(MODEL,), refine=True, progress=False,
                         options=FitOptions(resolution=RESOLUTION))
        runs[name] = run_summary(report)
        print(f"{environment} seed {seed}, map {name}: held-out {runs[name]['heldout_rmse']:.4f}, skin BRDF "
              f"{runs[name]['skin_brdf_rmse']:.4f} ({time.perf_counter() - t:.0f} s)", flush=True)
    true_map = load_capture(capture, detect=False).lights[0].envmap
    light = json.loads((folder / "estimated" / "lights.json").read_text())["lights"][0]
    estimate = read_exr(folder / "estimated" / light["map"])[..., :3]
    brdf = json.loads((folder / "estimated" / "brdf" / MODEL / "brdf.json").read_text())
    # the map the BRDF was fitted under: refined where the refinement was kept
    refined = (brdf.get("refinement") or {}).get("environment_maps", {}).get(light["name"])
    runs["map"] = {"name": light["name"], "size": light["size"], "residual": light.get("residual"),
                   "irradiance_error": irradiance_error(true_map, estimate),
                   "irradiance_error_refined": irradiance_error(true_map, estimate if refined is None
                                                                else np.asarray(refined)),
                   "refined": refined is not None,
                   "file": str(folder / "estimated" / LIGHTS_FOLDER / f"{light['name']}.exr")}
    runs["heldout_ratio"] = runs["estimated"]["heldout_rmse"] / runs["given"]["heldout_rmse"]
    runs["extra_seconds"] = runs["estimated"]["seconds"]["total"] - runs["given"]["seconds"]["total"]
    return runs


def tuning(environment: str, out: Path) -> dict:
    """The choice of ``RefineSchedule.restart_under_maps`` on the tuning seed: the given map, the
    true faces, the refinement started from the texture-space fit's glossy parameters and from the
    model's start values; skin's parameters and the held-out pixels' loss of each."""
    capture_dir = out / f"tuning_{environment}" / "capture"
    if capture_dir.parent.exists():
        shutil.rmtree(capture_dir.parent)
    simulate(capture_dir, SimulationOptions(environment=environment, seed=TUNING_SEED, measurements=MEASUREMENTS,
                                            resolution=(IMAGE, IMAGE), spp=SPP), progress=False)
    capture = load_capture(capture_dir)
    truth = read_ground_truth(capture).brdf["regions"]["skin"]
    rows = {"truth": truth}
    for restart in (False, True):
        t = time.perf_counter()
        face, shapes = load_geometry(capture, "ground-truth")
        estimate = refine_estimate(fit_brdf(capture, MODEL, shapes, face_model=face, progress=False,
                                            options=FitOptions(resolution=RESOLUTION)),
                                   capture, shapes, face, RefineSchedule(restart_under_maps=restart), progress=False)
        record = estimate.refinement
        rows["restarted" if restart else "from_the_fit"] = {
            "skin": {k: v for k, v in estimate.fits["skin"].params.items() if k in truth},
            "heldout_loss_before": record["heldout_loss_before"], "heldout_loss_after": record["heldout_loss_after"],
            "accepted": record["accepted"], "seconds": time.perf_counter() - t}
        print(f"tuning {environment}, restart {restart}: {rows['restarted' if restart else 'from_the_fit']}",
              flush=True)
    return rows


def figure(document: dict, out: Path, path: Path) -> None:
    """Per environment (first seed): the true map, the estimate and the refined estimate; and per
    run the held-out errors with the map given and estimated."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = document["cases"]
    fig, axes = plt.subplots(len(ENVIRONMENTS), 4, figsize=(12, 2.6 * len(ENVIRONMENTS)), squeeze=False)
    for row, environment in enumerate(ENVIRONMENTS):
        keys = [k for k in cases if k.startswith(environment + "_")]
        if not keys:
            continue
        case = cases[keys[0]]
        folder = out / keys[0]
        true_map = load_capture(folder / "capture", detect=False).lights[0].envmap
        estimate = read_exr(case["map"]["file"])[..., :3]
        brdf = json.loads((folder / "estimated" / "brdf" / MODEL / "brdf.json").read_text())
        refined = (brdf.get("refinement") or {}).get("environment_maps", {}).get(case["map"]["name"])
        shown = [("true map", true_map), ("estimated", estimate)]
        if refined is not None:
            shown.append(("refined with the BRDF", np.asarray(refined)))
        for col, (title, image) in enumerate(shown):
            image = np.asarray(image, np.float64)
            axes[row, col].imshow(np.clip(image / np.percentile(image, 99.5), 0, 1) ** (1 / 2.2),
                                  extent=(-180, 180, -90, 90), interpolation="nearest")
            axes[row, col].set_title(f"{environment}: {title}", fontsize=8)
            axes[row, col].tick_params(labelsize=6)
        for col in range(len(shown), 3):
            axes[row, col].axis("off")
        ax = axes[row, 3]
        names = [k for k in keys]
        x = np.arange(len(names))
        ax.bar(x - 0.2, [cases[k]["given"]["heldout_rmse"] for k in names], 0.4, label="map given")
        ax.bar(x + 0.2, [cases[k]["estimated"]["heldout_rmse"] for k in names], 0.4, label="map estimated")
        ax.set_xticks(x, [k.split("_")[1] for k in names], fontsize=7)
        ax.set_xlabel("seed", fontsize=7)
        ax.set_ylabel("held-out relative RMSE", fontsize=7)
        ax.legend(fontsize=6)
    fig.suptitle("SIMULATED: environment maps estimated with the face (centre of a map: towards the camera)",
                 fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)


def summarise(cases: dict, environments) -> dict:
    """Per environment, over its seeds: the held-out errors and their worst ratio, also on the true
    shape (the reflectance alone: the two runs' shape fits differ, since a given map starts the
    shape fit's light where most of the map's light comes from and an unknown one frontal), skin's
    BRDF errors, the map's irradiance errors and the extra seconds."""
    summary = {}
    for environment in environments:
        mine = [c for k, c in cases.items() if k.startswith(environment + "_")]

        def average(*path):
            values = list(mine)
            for key in path:
                values = [v[key] for v in values]
            return float(np.mean(values))

        true_shape = [c["estimated"]["heldout_rmse_true_shape"] / c["given"]["heldout_rmse_true_shape"] for c in mine
                      if c["given"].get("heldout_rmse_true_shape")]
        refined = [c["map"]["irradiance_error_refined"] for c in mine if c["map"]["irradiance_error_refined"] is not None]
        summary[environment] = {
            "heldout_rmse_given": average("given", "heldout_rmse"),
            "heldout_rmse_estimated": average("estimated", "heldout_rmse"),
            "heldout_ratio_max": float(np.max([c["heldout_ratio"] for c in mine])),
            "heldout_rmse_true_shape_given": average("given", "heldout_rmse_true_shape"),
            "heldout_rmse_true_shape_estimated": average("estimated", "heldout_rmse_true_shape"),
            "heldout_ratio_true_shape_max": float(np.max(true_shape)) if true_shape else None,
            "shape_floor_given": average("given", "shape_floor", "heldout_rmse"),
            "shape_floor_estimated": average("estimated", "shape_floor", "heldout_rmse"),
            "skin_brdf_rmse_given": average("given", "skin_brdf_rmse"),
            "skin_brdf_rmse_estimated": average("estimated", "skin_brdf_rmse"),
            "irradiance_error": average("map", "irradiance_error"),
            "irradiance_error_refined": float(np.mean(refined)) if refined else None,
            "extra_seconds_max": float(np.max([c["extra_seconds"] for c in mine]))}
    return summary


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--environments", nargs="+", default=list(ENVIRONMENTS), choices=ENVIRONMENTS)
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--tuning", action="store_true",
                        help=f"instead: the choice of restart_under_maps on seed {TUNING_SEED}, true faces "
                             "(environment_lights_tuning.json)")
    args = parser.parse_args(argv)
    if args.tuning:
        refuse_report_data(parser, SIMULATED, [TUNING_SEED], "restart_under_maps (--tuning)")
        command = "python validation/environment_lights.py " + " ".join(argv if argv is not None else sys.argv[1:])
        document = {"simulated": True, "command": command, "model": MODEL, "seed": TUNING_SEED,
                    "geometry": "ground-truth", "measurements": MEASUREMENTS, "image": IMAGE, "spp": SPP,
                    "resolution": RESOLUTION,
                    "what": "the refinement's glossy start under a given map: the texture-space fit's, or the "
                            "model's start values (RefineSchedule.restart_under_maps)",
                    "environments": {e: tuning(e, args.out) for e in args.environments}}
        args.results.mkdir(parents=True, exist_ok=True)
        write_json(args.results / "environment_lights_tuning.json", document)
        return 0
    if TUNING_SEED in args.seeds:
        print(f"note: seed {TUNING_SEED} is the one the defaults were set on", flush=True)
    command = "python validation/environment_lights.py " + " ".join(argv if argv is not None else sys.argv[1:])
    cases = {}
    for environment in args.environments:
        for seed in args.seeds:
            cases[f"{environment}_{seed}"] = one(environment, seed, args.out)
    summary = summarise(cases, args.environments)
    document = {"simulated": True, "command": command, "model": MODEL, "seeds": args.seeds,
                "tuning_seed": TUNING_SEED, "measurements": MEASUREMENTS, "image": IMAGE, "spp": SPP,
                "resolution": RESOLUTION, "ratio_target": RATIO_TARGET,
                "ratio_met": all(s["heldout_ratio_max"] <= RATIO_TARGET for s in summary.values()),
                "ratio_met_true_shape": all((s["heldout_ratio_true_shape_max"] or np.inf) <= RATIO_TARGET
                                            for s in summary.values()),
                "summary": summary, "cases": cases}
    args.results.mkdir(parents=True, exist_ok=True)
    write_json(args.results / "environment_lights.json", document)
    figure(document, args.out, args.results / "environment_lights.png")
    for environment, s in summary.items():
        print(f"{environment}: held-out {s['heldout_rmse_given']:.4f} given, {s['heldout_rmse_estimated']:.4f} "
              f"estimated (worst ratio {s['heldout_ratio_max']:.2f}); skin BRDF {s['skin_brdf_rmse_given']:.4f} / "
              f"{s['skin_brdf_rmse_estimated']:.4f}; map irradiance error {s['irradiance_error']:.3f} -> "
              f"{s['irradiance_error_refined']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
