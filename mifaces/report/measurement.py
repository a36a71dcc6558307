"""The measurement report: errors against a simulated capture's ground truth,
and the report's picture and Markdown text."""

from __future__ import annotations

import numbers
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write, save_figure
from ..runtime.status import CONVERGED
from ..validation.validator import TRUE_SHAPE


#: The validation's image errors the report ranks the models by, and their labels: the fitted faces, and
#: the fitted reflectance on the true shape (where the validation has it).
RANKED = {"heldout_rmse": "held-out lights", "environment_rmse": "environments",
          f"heldout_rmse{TRUE_SHAPE}": "held-out lights, on the true shape",
          f"environment_rmse{TRUE_SHAPE}": "environments, on the true shape"}


def ranking(models: dict) -> dict:
    """Measure -> model names, best (smallest error) first, for each of
    :data:`RANKED` the validations hold; ``models`` is the report's
    ``models`` with their ``validation``."""
    return {key: sorted(models, key=lambda m: models[m]["validation"][key]) for key in RANKED
            if all(key in entry["validation"] for entry in models.values())}


def ties(models: dict, order: dict) -> dict:
    """Measure -> one record per neighbouring pair of ``order`` (:func:`ranking`): ``better``, ``worse``,
    ``margin`` (the worse model's error less the better's) and ``noise``, and ``tie``.

    Each image error is measured twice, with every render's random numbers drawn anew the second time
    (the validation's ``replicate``), so each pair's difference is measured twice. ``noise`` is how far
    the two measurements of it disagree, twice the standard error of their mean; a pair is a ``tie``
    when the mean difference is not larger than that (a second draw could order the two the other way).
    A validation without ``replicate`` (older reports) has ``noise`` None and no ties."""
    out = {}
    for key, names in order.items():
        pairs = []
        for better, worse in zip(names, names[1:]):
            a, b = models[better]["validation"], models[worse]["validation"]
            margin = b[key] - a[key]
            again = (b["replicate"][key] - a["replicate"][key]
                     if key in a.get("replicate", {}) and key in b.get("replicate", {}) else None)
            noise = None if again is None else abs(margin - again)
            mean = margin if again is None else 0.5 * (margin + again)
            pairs.append({"better": better, "worse": worse, "margin": margin, "noise": noise,
                          "tie": noise is not None and mean <= noise})
        out[key] = pairs
    return out


def _show(ax, image, title, scale) -> None:
    ax.imshow(np.clip(np.clip(image * scale, 0, 1) ** (1 / 2.2), 0, 1))
    ax.set_title(title, fontsize=8)
    ax.axis("off")


def write_validation_picture(path: Path, truth: dict, images: dict, report: dict) -> None:
    """``report.png`` of a simulated capture: per condition (the environments,
    then the held-out lights) a row of the true face and each fitted face in
    the novel pose, each fit titled with its relative image error. Labelled
    simulated, with the truth's BRDF family."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summary = report["validation"]
    names = summary["environments"] + [n for n in truth if n not in summary["environments"]]
    models = list(images)
    fig, axes = plt.subplots(len(names), 1 + len(models), figsize=(2.6 * (1 + len(models)), 2.5 * len(names)),
                             squeeze=False)
    for row, name in zip(axes, names):
        scale = 0.8 / max(float(np.percentile(truth[name], 99.5)), 1e-12)
        _show(row[0], truth[name], f"truth ({summary['truth_model']}): {name}", scale)
        for ax, model in zip(row[1:], models):
            validation = report["models"][model]["validation"]
            error, on_truth = validation["per_condition"][name], validation.get(f"per_condition{TRUE_SHAPE}", {})
            extra = f" ({100 * on_truth[name]:.1f}% on true shape)" if on_truth.get(name, error) != error else ""
            _show(ax, images[model][name], f"{model}: {100 * error:.1f}%{extra}", scale)
    fig.suptitle(f"SIMULATED capture, truth {summary['truth_model']}: true and fitted faces in a novel pose "
                 f"(yaw {summary['novel_pose'][0]:g}°, pitch {summary['novel_pose'][1]:g}°)\nunder lights and "
                 "environments the fit never saw; relative RMSE on the face (and of the fitted reflectance on the "
                 "true shape)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def write_fit_picture(path: Path, fitted, photo_name: str) -> None:
    """The fits against the photograph (``report.png``, or ``report_training.png``
    beside a validation): per fitted model (``fitted``, each a
    :class:`mifaces.pipeline.measure.FittedModel`) a row of the photograph
    ``photo_name``, the fitted face under its light, their difference and the
    fitted face under the novel light."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    show = _show
    fig, axes = plt.subplots(len(fitted), 4, figsize=(12, 3 * len(fitted)), squeeze=False)
    for row, fit in zip(axes, fitted):
        photo, rendered = fit.photo, fit.rendered
        scale = 0.8 / max(np.percentile(photo, 99.5), 1e-12)
        show(row[0], photo, f"photograph {photo_name}", scale)
        show(row[1], rendered, f"{fit.model}: fitted, same light", scale)
        show(row[2], 4 * np.abs(rendered - photo), "|difference| x 4", scale)
        show(row[3], fit.relit, f"{fit.model}: novel light", scale)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def write_markdown(path: Path, report: dict, photo_name: str) -> None:
    lines = ["# mifaces measurement report", "",
             f"Capture `{report['capture']}`: {report['measurements']} photographs, geometry {report['geometry']}, "
             f"texture {report['resolution']}².", "", "![report](report.png)", "",
             "Parameters as value ± half-width of the 95 % interval (asymmetric intervals: the larger half; "
             "see docs/uncertainty.md and ![uncertainty](report_uncertainty.png)).", "",
             "| model | region | samples | status | parameters | loss | error vs ground truth |",
             "|---|---|---|---|---|---|---|"]
    for model, entry in report["models"].items():
        truth = entry.get("ground_truth") or {}
        for region, params in entry["regions"].items():
            fit = entry["fit"][region]
            text = ", ".join(f"{k} {_with_interval(v, (entry.get('uncertainty') or {}).get(region, {}).get(k))}"
                             for k, v in params.items())
            err = (truth.get("regions") or {}).get(region)
            err_text = ", ".join(f"{k} {100 * v:.1f}%" for k, v in err.items()) if err else ""
            lines.append(f"| {model} | {region} | {fit['samples']} | {fit['status']} | {text} | "
                         f"{format_value(fit['loss'])} | {err_text} |")
    lines += fit_notes(report)
    if report.get("failed_lights"):
        lines += ["", "Lights left out of the fits, their photographs far darker or brighter than the face under the "
                  "other lights says (lamps that failed; factor against the median light's, >1: too dark): "
                  + ", ".join(f"{name} {factor:.3g}" for name, factor in report["failed_lights"].items()) + "."]
    if report.get("light_balance_refused"):
        lines += ["", f"The given lights were not balanced: their factors spread {report['light_balance_refused']:.3g} "
                  "times from the median light's, more than a calibration is off (the face's model misses the "
                  "photographs; `mifaces.reflectance.light_balance.BALANCE_LIMIT`)."]
    if "environment_note" in report:
        lines += ["", f"Note: {report['environment_note']}."]
    lines += shapes_markdown(report)
    lines += lights_markdown(report)
    lines += ["", "| model | training RMSE (first photograph, relative) | albedo RMSE vs ground truth | fit time (s) |",
              "|---|---|---|---|"]
    for model, entry in report["models"].items():
        truth = entry.get("ground_truth") or {}
        albedo = f"{truth['albedo']['rmse_sampled']:.4f}" if "albedo" in truth else ""
        lines.append(f"| {model} | {100 * entry['training_rmse']:.2f}% | {albedo} | "
                     f"{report['seconds'][f'fit_brdf_{model}']:.1f} |")
    if "validation" in report:
        lines += validation_markdown(report)
    lines += ["", "Times (s): " + ", ".join(f"{k} {v:.1f}" for k, v in report["seconds"].items()), ""]
    with atomic_write(path, "w") as f:
        f.write("\n".join(lines))


def lights_markdown(report: dict) -> list[str]:
    """The report's lines on lights estimated from the photographs (:mod:`mifaces.light_estimation.unknown`): each
    light's direction (world frame, towards the light), relative intensity and the spread of its
    photographs' estimates, the picture, and what stays ambiguous; none for given lights."""
    if "lights" not in report:
        return []
    lights = report["lights"]
    lines = ["", "## Lights estimated from the photographs", "", f"![lights]({lights['picture']})", "",
             f"Note: {lights['note']}."]
    directed = [e for e in lights["estimates"] if e["kind"] != "environment"]
    maps = [e for e in lights["estimates"] if e["kind"] == "environment"]
    if directed:
        lines += ["", "| light | direction (world, towards the light) | intensity (relative) | photographs | "
                  "spread (deg) |", "|---|---|---|---|---|"]
        lines += [f"| {e['name']} | {', '.join(f'{v:+.3f}' for v in e['direction'])} | {np.mean(e['intensity']):.3f} | "
                  f"{len(e.get('photographs', []))} | {e.get('spread_deg', 0.0):.1f} |" for e in directed]
    if maps:
        lines += ["", "| environment light | map | size | photographs | residual (relative RMS) |", "|---|---|---|---|---|"]
        lines += [f"| {e['name']} | [{e['map']}]({e['map']}) | {e['size'][0]}x{e['size'][1]} | "
                  f"{len(e.get('photographs', []))} | {e.get('residual', float('nan')):.3f} |" for e in maps]
    return lines


def shapes_markdown(report: dict) -> list[str]:
    """The report's lines on the fitted shapes: the identity modes the fit (and a simulated
    truth) used, and per photograph the fit's status, feature-point error and, against a
    simulated truth, its error in the world frame (``mifaces.validation.shape_errors``)."""
    face = report.get("face_model")
    if not face or "shapes" not in report:
        return []
    lines = ["", f"Face model `{face['name']}`: the fit used the leading {face['fit_shape_modes']} of its "
                 f"{face['model_shape_modes']} identity modes"
             + (f"; the simulated truth drew on {face['truth_shape_modes']}"
                + (" plus fine detail outside the span" if face.get("truth_detail") else "")
                + ", so it lies outside the fitted span by construction" if "truth_shape_modes" in face else "")
             + ".", "", "| photograph | status | feature RMS (px) | reprojection in its camera (px) "
                        "| photometric residual | world error (mm) "
                        "| after rigid alignment (mm) | depth (mm) | size against the truth (%) "
                        "| after that size about the camera (mm) | after a similarity alignment, whole head (mm) "
                        "| normals (°) |", "|---" * 12 + "|"]
    for name, entry in report["shapes"].items():
        e = entry.get("errors") or {}
        cells = [f"{e[k]:.2f}" if k in e else "" for k in ("world_mm", "aligned_mm", "depth_mm")]
        cells += [f"{e['scale_pct']:+.2f}" if "scale_pct" in e else ""]
        cells += [f"{e[k]:.2f}" if k in e else "" for k in ("scaled_mm", "similarity_mm", "normal_deg")]
        fit = [f"{entry[k]:.{d}f}" if entry.get(k) is not None else "" for k, d in (("feature_rms_px", 2),
                                                                                   ("reprojection_px", 2),
                                                                                   ("image_rms", 3))]
        lines.append(f"| {name} | {entry['status']} | " + " | ".join(fit + cells) + " |")
    return lines + cameras_markdown(report)


def cameras_markdown(report: dict) -> list[str]:
    """The report's lines on the cameras: each one's reprojection error, and for one camera how well
    the face's depth is known (:func:`mifaces.shape.views.depth_uncertainty`)."""
    lines = []
    cameras = report.get("cameras") or {}
    if len(cameras) > 1:
        lines += ["", "Reprojection error per camera (the fitted face's landmarks against each photograph's "
                      "feature points, in its own camera): " + ", ".join(
                          f"{camera} {entry['reprojection_px']:.2f} px ({entry['photographs']} photographs)"
                          for camera, entry in cameras.items())
                  + ". Several calibrated cameras fix the face's depth: the world-frame errors can be trusted."]
    depth = report.get("depth") or {}
    if depth:
        lines += ["", f"One camera: a face's depth and size are not observable from one camera (it sees a face "
                      f"twice as large and twice as far as the same picture). The fit's depth comes from "
                      f"{depth['size_from']}, known to {100 * depth['relative_size_sd']:.1f} % (1 sd), which "
                      f"leaves {depth['depth_sd_mm']:.1f} mm (1 sd) along the camera's axis at "
                      f"{depth['camera_distance_mm']:.0f} mm: no world-frame figure can be trusted to better than "
                      f"that. What one camera observes is the error after a similarity alignment."]
    return lines


def fit_notes(report: dict) -> list[str]:
    """The report's lines on the fits that did not simply converge: each
    region's status and why (a parameter at its bound, a spike, values left
    at their start, a neighbour's or the model's defaults), so that no value
    that was not measured passes for one."""
    notes = [f"- {model} / {region}: **{fit['status']}**: {fit.get('reason', '')}"
             for model, entry in report["models"].items() for region, fit in entry["fit"].items()
             if fit["status"] != CONVERGED]
    return ["", "Fits that did not simply converge (their values are not measurements to trust as they stand):",
            ""] + notes if notes else []


def validation_markdown(report: dict) -> list[str]:
    """The report's lines on the validation (:mod:`mifaces.validation.validator`): what
    was compared, the table of the four measures, the rankings."""
    summary = report["validation"]
    lights = ", ".join(f"{light['angle_to_capture']:.0f}°" for light in summary["held_out_lights"])
    floor = summary["shape_floor"]
    floor_text = ("The fitted face model's texture space is not the truth's: no shape floor." if floor is None else
                  f"Shape floor (the true BSDF and albedo on the fitted shape): held-out "
                  f"{100 * floor['heldout_rmse']:.1f}%, environments {100 * floor['environment_rmse']:.1f}%"
                  + ("; the fitted reflectance on the true shape shows the reflectance's own error." if
                     floor["heldout_rmse"] > 0 else "."))
    noise = summary.get("noise_floor")
    if noise is not None:
        floor_text += (f" Noise floor (the true face against itself rendered with other random numbers: errors "
                       f"near it are Monte Carlo noise, not the fit): held-out {100 * noise['heldout_rmse']:.1f}%, "
                       f"environments {100 * noise['environment_rmse']:.1f}%. The errors below compare images "
                       f"rendered with the same random numbers, so most of that noise cancels in them.")
    lines = ["", "## Validation against the ground truth (simulated capture)", "",
             f"Truth: `{summary['truth_model']}`. The true face (true shape, BSDF and albedo) and each fitted face "
             f"(fitted shape, BRDF and albedo) are rendered in a novel pose (yaw {summary['novel_pose'][0]:g}°, "
             f"pitch {summary['novel_pose'][1]:g}°; {summary['novel_pose_angle_to_capture']:.0f}° from every "
             f"photographed pose) under {len(summary['held_out_lights'])} held-out point lights ({lights} from the "
             f"nearest capture light) and the environments {', '.join(summary['environments'])}, "
             f"{summary['render']['width']}x{summary['render']['height']} px at {summary['render']['spp']} spp, and "
             f"compared on the face mask, rendered with the same random numbers. {floor_text}", "",
             "| model | BRDF RMSE (skin, relative) | BRDF RMSE (all regions) | albedo RMSE | held-out-light RMSE | "
             "environment RMSE | same, fitted reflectance on the true shape | training RMSE |",
             "|---|---|---|---|---|---|---|---|"]
    for model in report["ranking"]["heldout_rmse"]:
        entry = report["models"][model]
        v = entry["validation"]
        regions = ", ".join(f"{k} {100 * e:.0f}%" for k, e in v["brdf_rmse"].items() if e is not None)
        skin = f"{100 * v['brdf_rmse']['skin']:.1f}%" if v["brdf_rmse"].get("skin") is not None else "n/a"
        true_shape = (f"{100 * v[f'heldout_rmse{TRUE_SHAPE}']:.2f}%, {100 * v[f'environment_rmse{TRUE_SHAPE}']:.2f}%"
                      if f"heldout_rmse{TRUE_SHAPE}" in v else "n/a")
        lines.append(f"| {model} | {skin} | {regions} | {v['albedo_rmse']:.4f} | {100 * v['heldout_rmse']:.2f}% | "
                     f"{100 * v['environment_rmse']:.2f}% | {true_shape} | {100 * entry['training_rmse']:.2f}% |")
    lines.append("")
    pairs = report.get("ties") or ties(report["models"], report["ranking"])
    for key, order in report["ranking"].items():
        sentence = ranking_sentence(report["models"], order, pairs.get(key, []), key)
        lines.append(f"- Ranked by {RANKED[key]}: {sentence}.")
    lines += ["", "![training photograph](report_training.png)"]
    return lines


def ranking_sentence(models: dict, order: list, pairs: list, key: str) -> str:
    """``a 14.20% < b 14.43% = c 14.50% …`` (``=``: within the noise, :func:`ties`), and who wins by how much."""
    errors = [models[m]["validation"][key] for m in order]
    text = f"{order[0]} {100 * errors[0]:.2f}%"
    for pair, model, error in zip(pairs, order[1:], errors[1:]):
        text += f" {'≈' if pair['tie'] else '<'} {model} {100 * error:.2f}%"
    if not pairs:
        return text
    first = pairs[0]
    noise = "" if first["noise"] is None else f", Monte Carlo noise {100 * first['noise']:.2f} points"
    if first["tie"]:
        return (f"{text}; {order[0]} and {order[1]} tie: {100 * first['margin']:.2f} points apart, within the "
                f"noise of the renders ({100 * first['noise']:.2f} points: the same comparison with other random "
                "numbers moves by that much)")
    return (f"{text}; {order[0]} wins by {100 * first['margin']:.2f} points "
            f"({100 * first['margin'] / errors[1]:.0f}% less error than {order[1]}{noise})")


def half_width(value, entry: dict | None):
    """The larger half of a parameter's 95 % interval around ``value`` (a float, or a list per
    channel), or its status (``fixed``, ``at_bound``, …), or None without an estimate."""
    if not entry:
        return None
    if "interval95" not in entry:
        return entry.get("status")
    lo, hi = entry["interval95"]
    if isinstance(value, (list, tuple)):
        return [None if a is None else max(v - a, b - v) for v, a, b in zip(value, lo, hi)]
    return max(value - lo, hi - value)


def _with_interval(value, entry: dict | None) -> str:
    """``value ± half-width`` (per channel for RGB), or the value and its status."""
    half = half_width(value, entry)
    if half is None:
        return format_value(value)
    if isinstance(half, str):
        return f"{format_value(value)} ({half.replace('_', ' ')})"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(f"{v:.3g}" + ("" if h is None else f" ± {h:.2g}") for v, h in zip(value, half)) + "]"
    return f"{value:.4g} ± {half:.2g}"


def write_uncertainty_picture(path: Path, report: dict) -> None:
    """``report_uncertainty.png``: per model a panel per glossy parameter, the fitted value of each
    region with its 95 % interval as an error bar (channel 0 of RGB parameters), regions with a status
    instead (borrowed, at a bound) marked x without a bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = list(report["models"])
    names = {m: list(next(iter(report["models"][m]["regions"].values()), {})) for m in models}
    width = max((len(v) for v in names.values()), default=1)
    fig, axes = plt.subplots(len(models), max(width, 1), figsize=(3.2 * max(width, 1), 2.6 * len(models)),
                             squeeze=False)
    for row, model in zip(axes, models):
        entry = report["models"][model]
        for ax, name in zip(row, names[model]):
            regions = list(entry["regions"])
            for i, region in enumerate(regions):
                value = entry["regions"][region][name]
                value = value[0] if isinstance(value, list) else value
                u = (entry.get("uncertainty") or {}).get(region, {}).get(name, {})
                if "interval95" in u:
                    lo, hi = (v[0] if isinstance(v, list) else v for v in u["interval95"])
                    if lo is not None:
                        ax.errorbar(i, value, yerr=[[value - lo], [hi - value]], fmt="o", color="C0", capsize=3)
                        continue
                ax.plot(i, value, "x", color="C3")
                ax.annotate(str(u.get("status", "")).replace("_", " "), (i, value), fontsize=6, rotation=90)
            ax.set_xticks(range(len(regions)), regions, rotation=60, fontsize=7)
            ax.set_title(f"{model}: {name}", fontsize=8)
            if name in ("roughness", "alpha", "exponent"):
                ax.set_yscale("log")
        for ax in row[len(names[model]):]:
            ax.axis("off")
    fig.suptitle("Fitted parameters per region with 95 % intervals (x: no interval, status given)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def format_value(value, digits: int = 4, list_digits: int = 3) -> str:
    """A parameter value, loss or status for a person to read: a number to
    ``digits`` significant digits, a list of numbers (an RGB value) to
    ``list_digits`` each, anything else (a status, None) as text. The
    report's Markdown and the command line's summaries write values so;
    :func:`mifaces.render.scene_xml` writes them in full, for Mitsuba."""
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(f"{v:.{list_digits}g}" for v in value) + "]"
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        return f"{value:.{digits}g}"
    return str(value)
