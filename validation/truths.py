"""``mifaces measure`` on ground truths the fit cannot copy (SIMULATED).

For each truth, simulate a capture (6 measurements, seed 0: the same face,
lights and noise draws for every truth; ``--resolution`` and ``--spp``,
the simulator's defaults 512 and 64, or 256 and 32 to fit this machine, as
the subsurface truth needs) and run the main job on it with its defaults
(shapes fitted with the default built-in model, all four BRDF models,
texture 512²):

``cooktorrance``
    the default truth, one of the fitted families (the inverse crime: the
    reference the others are compared with);
``roughplastic``, ``principled``
    Mitsuba's built-ins (:mod:`mifaces.brdf.builtin`), outside every fitted family;
``varying``
    Cook–Torrance with per-texel scale and roughness maps (oily T-zone, drier
    cheeks; :mod:`mifaces.studio.varying`), compared per region with the maps' means;
``detail``
    the Cook–Torrance face with wrinkles, pores and asymmetry outside the
    model's span (:mod:`mifaces.studio.detail`);
``eta``
    the default Cook–Torrance truth with every region's index of refraction
    :data:`ETA_SHIFT` above the published value (:data:`mifaces.brdf.materials.REFRACTIVE_INDEX`)
    that the Cook–Torrance fit holds: the default truth hands Cook–Torrance its
    true η, this one does not, so their difference is what sharing η is worth;
``subsurface``
    translucent skin (:mod:`mifaces.studio.subsurface`: a rough dielectric
    boundary over a medium with Jensen et al. 2001's Skin1 coefficients),
    rendered with the volumetric path tracer; its difference from
    ``cooktorrance`` at the same size and samples is the bias translucency causes.

Records per truth and model the report's numbers (``report.json``): the
validation that separates the models (``models.<model>.validation``,
:mod:`mifaces.validation.validator`: BRDF error per region, albedo error, held-out-light
and environment-lit image errors of a novel pose, on the fitted and on the
true shape) and the report's ranking, the relative RMSE of the fitted render
against the first photograph (a training image, labelled so), the albedo
errors against the truth's map, the relative parameter errors where the
truth is the fitted model, the skin parameters, and the fit times. Writes ``validation/results/truths.json`` and
``truths.png`` (entries of earlier runs of other truths are kept).

    python validation/truths.py [--truths roughplastic eta] [--resolution 256 --spp 32] [--work DIR]

Machine: 2 CPU cores shared with other jobs; times are indicative only.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np
from skimage.transform import resize

from mifaces.brdf.materials import REFRACTIVE_INDEX
from mifaces.capture import read_ground_truth
from mifaces.io.atomic import save_figure, write_json
from mifaces.io.image_files import read_exr
from mifaces.model import load_model
from mifaces.model.regions import REGIONS
from mifaces.pipeline.measure import measure
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate
from mifaces.studio.varying import texel_regions

RESULTS = Path(__file__).resolve().parent / "results"
#: The ``eta`` truth's indices of refraction lie this far above the published ones the fit holds.
ETA_SHIFT = 0.06
#: Truth name -> the options of its simulation (:class:`mifaces.studio.options.SimulationOptions`).
TRUTHS = {"cooktorrance": {}, "roughplastic": {"brdf": "roughplastic"}, "principled": {"brdf": "principled"},
          "varying": {"varying": True}, "detail": {"detail": True}, "subsurface": {"subsurface": True},
          "eta": {"brdf_params": {"regions": {region: {"eta": round(eta + ETA_SHIFT, 4)}
                                              for region, eta in REFRACTIVE_INDEX.items()}}}}


def run_truth(name: str, work: Path, size: int, spp: int) -> dict:
    """Simulate truth ``name`` (``size``² pixels, ``spp`` samples) and measure it; the report's numbers per model."""
    folder = work / f"{name}_{size}"
    options = dict(TRUTHS[name], resolution=(size, size), spp=spp)
    t0 = time.perf_counter()
    simulate(folder / "capture", SimulationOptions(**options), force=True, progress=False)
    simulated = time.perf_counter() - t0
    report = measure(folder / "measure", folder / "capture", progress=False)
    truth = read_ground_truth(folder / "capture")
    models = {}
    for model, entry in report["models"].items():
        gt = entry.get("ground_truth") or {}
        validation = {k: v for k, v in entry["validation"].items() if not k.startswith("per_condition")}
        models[model] = {"image_relative_rmse_first_photo_training": entry["training_rmse"],
                         "albedo": gt.get("albedo"), "parameter_relative_errors": gt.get("regions"),
                         "skin": entry["regions"].get("skin"), "fit_seconds": report["seconds"][f"fit_brdf_{model}"],
                         "validation": validation}
    fitted_skin_albedo(folder, models)
    return {"truth": truth.description, "truth_brdf_skin": truth.brdf["regions"]["skin"],
            "simulate_options": options,
            "simulate_seconds": simulated, "measure_seconds": report["seconds"], "models": models,
            "ranking": report["ranking"], "shape_floor": report["validation"]["shape_floor"],
            "noise_floor": report["validation"].get("noise_floor"),
            "shapes": report.get("shapes")}


def fitted_skin_albedo(folder: Path, models: dict) -> None:
    """Add to each model's entry the mean of its fitted albedo map
    (``folder/measure/brdf/<model>/albedo.exr``) over the skin texels the fit filled, and the truth's
    mean over the same texels (``truth_albedo_skin_mean``): against each other, the bias per
    channel. Texels no photograph saw (the back of the head: about a third of the skin) hold 0 in the
    fitted map and are left out of both, and ``skin_texels_filled`` says what fraction remains."""
    model = load_model("builtin")
    truth = read_ground_truth(folder / "capture").albedo
    for name, entry in models.items():
        albedo = read_exr(folder / "measure" / "brdf" / name / "albedo.exr")
        true = truth if truth.shape == albedo.shape else resize(truth, albedo.shape, order=1, anti_aliasing=True)
        skin = texel_regions(model, albedo.shape[0]) == REGIONS["skin"]
        filled = skin & (albedo.sum(axis=-1) > 0)
        entry["albedo_skin_mean"] = [round(float(x), 5) for x in albedo[filled].mean(axis=0)]
        entry["truth_albedo_skin_mean"] = [round(float(x), 5) for x in true[filled].mean(axis=0)]
        entry["skin_texels_filled"] = round(float(filled.sum() / skin.sum()), 4)


def figure(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    truths = list(results["truths"])
    models = list(next(iter(results["truths"].values()))["models"])
    panels = (("heldout_rmse_true_shape", "held-out lights, novel pose, fitted reflectance on the true shape, %"),
              ("environment_rmse_true_shape", "studio and sky, novel pose, on the true shape, %"),
              ("albedo", "albedo RMSE vs truth (sampled texels)"))
    fig, axes = plt.subplots(1, len(panels), figsize=(16, 4))
    width = 0.8 / len(models)
    for k, model in enumerate(models):
        x = np.arange(len(truths)) + (k - (len(models) - 1) / 2) * width
        for ax, (key, _) in zip(axes, panels):
            entries = [results["truths"][t]["models"][model] for t in truths]
            values = ([e["albedo"]["rmse_sampled"] for e in entries] if key == "albedo" else
                      [100 * (e.get("validation", {}).get(key) or np.nan) for e in entries])
            ax.bar(x, values, width, label=model)
    for ax, (_, title) in zip(axes, panels):
        ax.set_xticks(range(len(truths)), [t.rsplit("_", 1)[0] for t in truths], rotation=20, fontsize=8)
        ax.set_title(f"SIMULATED: {title}", fontsize=8)
    axes[0].legend(fontsize=8)
    sizes = sorted({"{}² {} spp".format(e["simulate_options"]["resolution"][0], e["simulate_options"]["spp"])
                    for e in results["truths"].values()})
    fig.suptitle(f"SIMULATED: mifaces measure on truths outside the fit (6 measurements, {', '.join(sizes)}; "
                 "truth on the x axis)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def _rgb(values) -> str:
    return "" if values is None else "(" + ", ".join(f"{v:.3f}" for v in values) + ")"


def _percent(value) -> str:
    return "–" if value is None else f"{100 * value:.1f}%"


def table(results: dict) -> str:
    """The results as Markdown tables. Per truth and model: the validation (held-out-light and
    environment-lit image errors in the novel pose, on the fitted shape and on the true shape;
    skin BRDF error; albedo RMSE), the training-photo RMSE, and the skin's fitted parameters
    against the truth's albedo; then each truth's ranking."""
    lines = ["| truth | model | held-out lights | environments | held-out, true shape | environments, true shape "
             "| skin BRDF | albedo RMSE | training photo | skin albedo (truth) | skin parameters |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, entry in results["truths"].items():
        for model, m in entry["models"].items():
            v = m.get("validation", {})
            skin = ", ".join(f"{k} {np.mean(x):.3g}" for k, x in (m["skin"] or {}).items() if k != "eta")
            lines.append(f"| {name} | {model} | {_percent(v.get('heldout_rmse'))} | "
                         f"{_percent(v.get('environment_rmse'))} | {_percent(v.get('heldout_rmse_true_shape'))} | "
                         f"{_percent(v.get('environment_rmse_true_shape'))} | "
                         f"{_percent((v.get('brdf_rmse') or {}).get('skin'))} | {m['albedo']['rmse_sampled']:.4f} | "
                         f"{_percent(m['image_relative_rmse_first_photo_training'])} | "
                         f"{_rgb(m.get('albedo_skin_mean'))} ({_rgb(m.get('truth_albedo_skin_mean'))}) | {skin} |")
    lines += ["", "| truth | shape floor (held-out, environments) | ranking by held-out lights, true shape "
              "| ranking by environments, true shape |", "|---|---|---|---|"]
    for name, entry in results["truths"].items():
        floor, order = entry.get("shape_floor") or {}, entry.get("ranking", {})
        lines.append(f"| {name} | {_percent(floor.get('heldout_rmse'))}, {_percent(floor.get('environment_rmse'))} | "
                     f"{' < '.join(order.get('heldout_rmse_true_shape', []))} | "
                     f"{' < '.join(order.get('environment_rmse_true_shape', []))} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--truths", nargs="+", default=list(TRUTHS), choices=list(TRUTHS))
    parser.add_argument("--work", type=Path, default=Path("out/validation_truths"))
    parser.add_argument("--resolution", type=int, default=512, help="photograph size (square)")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel of the photographs")
    parser.add_argument("--summarize", action="store_true",
                        help="only recompute the skin albedo means of the recorded truths from --work, and the figure")
    args = parser.parse_args()
    path = RESULTS / "truths.json"
    results = json.loads(path.read_text()) if path.is_file() else {}
    if args.summarize:
        for key, entry in results["truths"].items():
            fitted_skin_albedo(args.work / key, entry["models"])
            entry.pop("truth_albedo_skin_mean", None)  # over every skin texel, seen or not: see fitted_skin_albedo
        write_json(path, results)
        figure(results, RESULTS / "truths.png")
        print(table(results))
        return
    results.update({"label": "SIMULATED", "command": "python validation/truths.py",
                    "machine": "2 CPU cores (LLVM), shared with other jobs: times indicative only"})
    results.setdefault("truths", {})
    for name in args.truths:
        key = f"{name}_{args.resolution}"
        print(f"truth {key} ...", flush=True)
        results["truths"][key] = run_truth(name, args.work, args.resolution, args.spp)
        for model, entry in results["truths"][key]["models"].items():
            print(f"  {model:13s} image {100 * entry['image_relative_rmse_first_photo_training']:.2f}%  "
                  f"albedo RMSE {entry['albedo']['rmse_sampled']:.4f} bias {entry['albedo']['bias_sampled']:+.4f}  "
                  f"skin {entry['skin']}", flush=True)
        write_json(path, results)
    figure(results, RESULTS / "truths.png")
    print(table(results))


if __name__ == "__main__":
    main()
