"""The measurement report: errors against a simulated capture's ground truth,
and the report's picture and Markdown text."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .capture import read_ground_truth
from .files import atomic_path, atomic_write
from .model.regions import REGIONS
from .status import PRIOR


def ground_truth_errors(estimate, capture) -> dict | None:
    """How far a fit is from a simulated capture's ground truth (``ground_truth/``).

    Returns None for a capture without ground truth, else ``{"truth_model",
    "regions": {region: {parameter: relative error, mean over channels}},
    "albedo": {...}}``. Parameter errors are given where the truth is the
    same model, for the regions fitted on their own samples (η, held at its
    published value, is left out); the albedo errors, RMSE and mean error of
    the refined map against the truth's (downsampled to the fit's
    resolution), on texels with samples and on all face texels, always.
    """
    from skimage.transform import resize

    ground_truth = read_ground_truth(capture)
    if ground_truth is None:
        return None
    truth = ground_truth.brdf
    regions = {}
    if truth["model"] == estimate.model:
        for name, fit in estimate.fits.items():
            if fit.status == PRIOR or name not in truth["regions"]:
                continue
            regions[name] = {key: float(np.mean(np.abs(np.asarray(fit.params[key], float) - np.asarray(value, float))
                                                / np.abs(np.asarray(value, float))))
                             for key, value in truth["regions"][name].items() if key != "eta"}
    r = estimate.resolution
    error = estimate.albedo.albedo - resize(ground_truth.albedo, (r, r, 3), anti_aliasing=True, order=1)
    seen = estimate.albedo.samples > 0
    face = estimate.region_map > 0
    skin = seen & (estimate.region_map == REGIONS["skin"])
    albedo = {"rmse_sampled": float(np.sqrt(np.mean(error[seen] ** 2))),
              "rmse_face": float(np.sqrt(np.mean(error[face] ** 2))),
              "skin_rmse_sampled": float(np.sqrt(np.mean(error[skin] ** 2))),
              "bias_sampled": float(error[seen].mean()), "texels_sampled": int(seen.sum()),
              "texels_face": int(face.sum())}
    return {"truth_model": truth["model"], "regions": regions, "albedo": albedo}



def write_picture(path: Path, panels, photo_name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def show(ax, image, title, scale):
        ax.imshow(np.clip((np.clip(image * scale, 0, 1)) ** (1 / 2.2), 0, 1))
        ax.set_title(title, fontsize=9)
        ax.axis("off")

    fig, axes = plt.subplots(len(panels), 4, figsize=(12, 3 * len(panels)), squeeze=False)
    for row, (model, photo, rendered, relit) in zip(axes, panels):
        scale = 0.8 / max(np.percentile(photo, 99.5), 1e-12)
        show(row[0], photo, f"photograph {photo_name}", scale)
        show(row[1], rendered, f"{model}: fitted, same light", scale)
        show(row[2], 4 * np.abs(rendered - photo), "|difference| x 4", scale)
        show(row[3], relit, f"{model}: novel light", scale)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)


def write_markdown(path: Path, report: dict, photo_name: str) -> None:
    lines = ["# mifaces measurement report", "",
             f"Capture `{report['capture']}`: {report['measurements']} photographs, geometry {report['geometry']}, "
             f"texture {report['resolution']}².", "", "![report](report.png)", "",
             "| model | region | samples | status | parameters | loss | error vs ground truth |",
             "|---|---|---|---|---|---|---|"]
    for model, entry in report["models"].items():
        truth = entry.get("ground_truth") or {}
        for region, params in entry["regions"].items():
            fit = entry["fit"][region]
            text = ", ".join(f"{k} {_fmt(v)}" for k, v in params.items())
            err = (truth.get("regions") or {}).get(region)
            err_text = ", ".join(f"{k} {100 * v:.1f}%" for k, v in err.items()) if err else ""
            lines.append(f"| {model} | {region} | {fit['samples']} | {fit['status']} | {text} | "
                         f"{_fmt(fit['loss'])} | {err_text} |")
    lines += ["", "| model | image RMSE (first photograph, relative) | albedo RMSE vs ground truth | fit time (s) |",
              "|---|---|---|---|"]
    for model, entry in report["models"].items():
        truth = entry.get("ground_truth") or {}
        albedo = f"{truth['albedo']['rmse_sampled']:.4f}" if "albedo" in truth else ""
        lines.append(f"| {model} | {100 * entry['image_relative_rmse']:.2f}% | {albedo} | "
                     f"{report['seconds'][f'fit_brdf_{model}']:.1f} |")
    lines += ["", "Times (s): " + ", ".join(f"{k} {v:.1f}" for k, v in report["seconds"].items()), ""]
    with atomic_write(path, "w") as f:
        f.write("\n".join(lines))


def _fmt(value) -> str:
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(f"{v:.3g}" for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)
