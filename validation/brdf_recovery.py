"""BRDF estimation on simulated captures: is the ground truth recovered?

1. **Same family.** For each model, simulate a capture whose ground truth is
   that model (:func:`mifaces.studio.truth.default_brdf`), fit the same model
   with the ground-truth geometry, and report per region the relative error
   of every glossy parameter and the albedo RMSE against the ground-truth map.
2. **Cross family.** Simulate with Cook-Torrance, hold out the last light
   condition, fit every model (and Lafortune with two lobes) to the others,
   and report for skin the BRDF-space RMSE of π f over the hemisphere
   (θ <= 80°) against the truth, and the image RMSE of renders of the fitted
   face against the held-out photographs (with the noise floor: the same
   renders with the ground-truth BRDF). Compare the ordering with the
   paper's sec. 6.1: Cook-Torrance or Ward preferred, Phong misses grazing
   highlights, Lafortune prone to over-fitting.

Run:  python validation/brdf_recovery.py [--resolution 512] [--image 384] [--quick]
Writes validation/results/brdf_recovery.json and brdf_recovery.png and
prints two tables. Simulated captures go to a temporary folder.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
import warnings
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

import mitsuba as mi
import numpy as np
from skimage.transform import resize

from mifaces import brdf
from mifaces.shape.io import load_geometry
from mifaces.reflectance import FitOptions, fit_brdf, render_estimate
from mifaces.validation.truth_errors import ground_truth_errors
from mifaces.capture import load_capture, read_ground_truth
from mifaces.io.atomic import write_json
from mifaces.model.regions import REGIONS
from mifaces.render import face_meshes, mitsuba_sensor
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate

OUT = Path(__file__).resolve().parent / "results"
MODELS = ["cooktorrance", "ward", "phong", "lafortune"]
#: Regions reported (the others have too few samples to say much).
REPORTED = ("skin", "beard", "hair", "lips", "eyebrows")


def same_family(work: Path, args) -> list[dict]:
    rows = []
    for model in MODELS:
        capture_dir = work / f"same_{model}"
        t0 = time.perf_counter()
        simulate(capture_dir, SimulationOptions(brdf=model, measurements=6, resolution=(args.image, args.image),
                                                spp=args.spp, seed=11), progress=False)
        t_sim = time.perf_counter() - t0
        truth = read_ground_truth(capture_dir).brdf
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            estimate = fit_brdf(capture_dir, model, progress=False, options=FitOptions(resolution=args.resolution))
        errors = ground_truth_errors(estimate, capture_dir)
        row = {"model": model, "simulation_seconds": t_sim, "fit_seconds": estimate.seconds,
               "samples": estimate.samples, "albedo": errors["albedo"], "regions": {}}
        light, view = hemisphere_directions()
        for region in REPORTED:
            fit = estimate.fits.get(region)
            if region not in errors["regions"]:
                continue  # not fitted on its own samples
            # the glossy parts compared over the hemisphere (θ <= 80°): parameters can trade off
            # (Lafortune's C and n) while the BRDF stays the same
            black = {"diffuse_reflectance": [0.0] * 3}
            true_glossy = reflectance(model, truth["options"], {**truth["regions"][region], **black}, light, view)
            fit_glossy = reflectance(model, estimate.options, {**fit.params, **black}, light, view)
            glossy_error = float(np.sqrt(np.mean((fit_glossy - true_glossy) ** 2) / np.mean(true_glossy ** 2)))
            row["regions"][region] = {"samples": fit.samples, "status": fit.status,
                                      "glossy_relative_rmse": glossy_error,
                                      "relative_error": errors["regions"][region],
                                      "fitted": {k: v for k, v in fit.params.items() if k != "diffuse_reflectance"},
                                      "truth": truth["regions"][region]}
        rows.append(row)
        skin = row["regions"]["skin"]
        print(f"  {model:13s} skin " + ", ".join(f"{k} {100 * v:.1f}%" for k, v in skin["relative_error"].items())
              + f"; glossy BRDF RMSE {100 * skin['glossy_relative_rmse']:.1f}%"
              + f"; albedo RMSE {row['albedo']['rmse_sampled']:.4f} (sampled texels)")
    return rows


def hemisphere_directions(n: int = 12):
    """Light and view directions on a grid over the hemisphere, θ <= 80°, all pairs."""
    theta = np.radians(np.linspace(2.0, 80.0, n))
    phi = np.radians(np.arange(0.0, 360.0, 30.0))
    t, p = np.meshgrid(theta, phi)
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(len(d)), np.arange(len(d)))
    return d[i.ravel()], d[j.ravel()]


def reflectance(model_name: str, options: dict, params: dict, light, view) -> np.ndarray:
    model = brdf.model(model_name, **options)
    values = {}
    for p in model.parameters():
        v = params[p.name]
        values[p.name] = mi.Color3f(*(float(x) for x in np.broadcast_to(v, 3))) if p.kind == "rgb" else mi.Float(float(v))
    f = model.eval(mi.Vector3f(light.T.astype(np.float32)), mi.Vector3f(view.T.astype(np.float32)), values)
    return np.pi * np.array(f).T


def cross_family(work: Path, args) -> list[dict]:
    capture_dir = work / "cross_cooktorrance"
    simulate(capture_dir, SimulationOptions(brdf="cooktorrance", measurements=9, resolution=(args.image, args.image),
                                            spp=args.spp, seed=5), progress=False)
    capture = load_capture(capture_dir)
    face, shapes = load_geometry(capture)
    held_light = capture.measurements[-1].light
    train = [m.name for m in capture.measurements if m.light != held_light]
    held = [m for m in capture.measurements if m.light == held_light]
    ground_truth = read_ground_truth(capture)
    truth, gt_albedo = ground_truth.brdf, ground_truth.albedo
    light, view = hemisphere_directions()
    rows = []

    # the noise floor: the held-out photographs rendered again with the true BRDF
    texture = mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(gt_albedo), "raw": True,
                            "filter_type": "bilinear", "wrap_mode": "clamp"})

    def image_error(render) -> float:
        errors, scale = [], []
        for m in held:
            lamp = capture.light(m.light)
            image = render(m, lamp)
            mask = m.image.pixels.mean(axis=2) > 0.02 * m.image.pixels.max()
            errors.append(np.mean((image[mask] - m.image.pixels[mask]) ** 2))
            scale.append(np.mean(m.image.pixels[mask]))
        return float(np.sqrt(np.mean(errors)) / np.mean(scale))

    def truth_render(m, lamp):
        scene = {"type": "scene", "integrator": {"type": "path", "max_depth": 4},
                 "sensor": mitsuba_sensor(capture.camera, args.spp),
                 "light": {"type": "point", "position": lamp.position.tolist(),
                           "intensity": {"type": "rgb", "value": lamp.intensity.tolist()}},
                 **face_meshes(face, shapes[m.name], truth, texture)}
        return np.array(mi.render(mi.load_dict(scene), spp=args.spp, seed=7), dtype=np.float32)[..., :3]

    floor = image_error(truth_render)
    print(f"  noise floor (truth re-rendered): held-out image relative RMSE {100 * floor:.2f}%")
    skin_truth = dict(truth["regions"]["skin"])
    for model, lobes in [("cooktorrance", 1), ("ward", 1), ("phong", 1), ("lafortune", 1), ("lafortune", 2)]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            estimate = fit_brdf(capture, model, measurements=train, progress=False,
                                options=FitOptions(lobes=lobes, resolution=args.resolution))
        skin = estimate.fits["skin"]
        mask = estimate.albedo.samples > 0
        skin_albedo = resize(gt_albedo, estimate.albedo.albedo.shape, anti_aliasing=True, order=1)[
            mask & (estimate.region_map == REGIONS["skin"])].mean(axis=0)
        r_true = reflectance("cooktorrance", truth["options"], {**skin_truth, "diffuse_reflectance": skin_albedo},
                             light, view)
        r_fit = reflectance(model, estimate.options, skin.params, light, view)
        brdf_rmse = float(np.sqrt(np.mean((r_fit - r_true) ** 2)))
        specular = r_true - skin_albedo  # the glossy part alone, where models differ
        spec_rel = float(np.sqrt(np.mean((r_fit - r_true) ** 2)) / np.sqrt(np.mean(specular ** 2)))
        grazing = (light[:, 2] < 0.34) & (view[:, 2] < 0.34)
        grazing_rmse = float(np.sqrt(np.mean((r_fit[grazing] - r_true[grazing]) ** 2)))
        image = image_error(lambda m, lamp: render_estimate(estimate, face, shapes[m.name], capture.camera, lamp,
                                                            spp=args.spp, seed=7))
        label = model if lobes == 1 else f"{model} ({lobes} lobes)"
        rows.append({"model": label, "skin_loss": skin.loss, "skin_samples": skin.samples,
                     "brdf_rmse": brdf_rmse, "brdf_rmse_over_specular_rms": spec_rel,
                     "brdf_rmse_grazing": grazing_rmse, "heldout_image_relative_rmse": image,
                     "heldout_noise_floor": floor, "fit_seconds": estimate.seconds["fit"],
                     "params": {k: v for k, v in skin.params.items() if k != "diffuse_reflectance"}})
        print(f"  {label:22s} BRDF RMSE {brdf_rmse:.4f} ({100 * spec_rel:.0f}% of the glossy part's RMS; "
              f"grazing {grazing_rmse:.4f}), held-out image RMSE {100 * image:.2f}%")
    return rows


def plot(same: list[dict], cross: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    ax = axes[0]
    width = 0.8 / len(REPORTED)
    for k, region in enumerate(REPORTED):
        values = [max(row["regions"].get(region, {}).get("relative_error", {"": np.nan}).values())
                  if region in row["regions"] else np.nan for row in same]
        ax.bar(np.arange(len(same)) + k * width, 100 * np.array(values), width, label=region)
    ax.set_xticks(np.arange(len(same)) + 0.4 - width / 2, [r["model"] for r in same])
    ax.set_ylabel("largest relative parameter error (%)")
    ax.set_title("simulated captures, same family: fitted vs ground truth")
    ax.legend(fontsize=8)
    ax = axes[1]
    names = [r["model"] for r in cross]
    ax.bar(np.arange(len(cross)) - 0.2, [r["brdf_rmse"] for r in cross], 0.4, label="BRDF RMSE (skin, r = π f)")
    ax2 = ax.twinx()
    ax2.bar(np.arange(len(cross)) + 0.2, [100 * r["heldout_image_relative_rmse"] for r in cross], 0.4,
            color="tab:orange", label="held-out image RMSE (%)")
    ax2.axhline(100 * cross[0]["heldout_noise_floor"], color="tab:orange", ls="--", lw=1, label="noise floor")
    ax.set_xticks(np.arange(len(cross)), names, rotation=20, fontsize=8)
    ax.set_ylabel("BRDF RMSE")
    ax2.set_ylabel("held-out image RMSE (%)")
    ax.set_title("simulated captures, cross family: Cook-Torrance truth")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=3)
    fig.tight_layout()
    from mifaces.io.atomic import save_figure

    save_figure(fig, path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", type=int, default=512, help="texture resolution R")
    parser.add_argument("--image", type=int, default=384, help="simulated image size")
    parser.add_argument("--spp", type=int, default=32)
    parser.add_argument("--quick", action="store_true", help="small images and textures (a smoke run)")
    parser.add_argument("--replot", action="store_true", help="only redraw the figure from the saved JSON")
    args = parser.parse_args()
    if args.replot:
        saved = json.loads((OUT / "brdf_recovery.json").read_text())
        plot(saved["same_family"], saved["cross_family"], OUT / "brdf_recovery.png")
        return
    if args.quick:
        args.resolution, args.image, args.spp = 128, 160, 8
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        print(f"same family ({args.image}² images, texture {args.resolution}²):")
        same = same_family(work, args)
        print("cross family (Cook-Torrance truth, last light held out):")
        cross = cross_family(work, args)
    result = {"variant": mi.variant(), "resolution": args.resolution, "image": args.image, "spp": args.spp,
              "same_family": same, "cross_family": cross}
    if not args.quick:
        write_json(OUT / "brdf_recovery.json", result)
        plot(same, cross, OUT / "brdf_recovery.png")
        print(f"wrote {OUT / 'brdf_recovery.json'} and brdf_recovery.png")


if __name__ == "__main__":
    main()
