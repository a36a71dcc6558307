"""The population report of a batch: how the fitted reflectance varies across subjects.

:func:`population` reads the ``report.json`` of every measured capture
(:func:`mifaces.pipeline.measure.measure`) and gives, per BRDF model and region,
the distribution of each fitted parameter across subjects (median, spread
as the scaled median absolute deviation, range) with the subjects beyond
:data:`OUTLIER_MADS` deviations flagged; the same for each region's diffuse
albedo; how the fits ended (:mod:`mifaces.runtime.status`); the time per capture;
and, for simulated captures, the error against the ground truth across
subjects. Only regions fitted on their own samples enter the parameter
statistics (a ``prior`` region copies another's BRDF); all enter the status
counts. :func:`write_population` writes it as ``population.{json,md,png}``.

Robust statistics (Hampel's rule, e.g. Leys et al., "Detecting outliers: do
not use standard deviation around the mean, use absolute deviation around
the median", J. Exp. Soc. Psychol. 49(4), 2013): ``MAD = 1.4826 ·
median(|x - median(x)|)`` estimates the standard deviation of normal data;
a value is an outlier where ``|x - median| > 3 MAD``.
"""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write, save_figure, write_json
from ..runtime.status import NOT_FITTED

#: Scale that makes the median absolute deviation estimate a normal distribution's σ.
MAD_SCALE = 1.4826
#: Values further than this many (scaled) MADs from the median are flagged.
OUTLIER_MADS = 3.0
#: Fewer subjects than this give no outliers (no distribution to stand out from).
MIN_SUBJECTS = 3
#: Names of a three-channel parameter's components.
CHANNELS = ("r", "g", "b")


def robust_summary(values: dict[str, float]) -> dict:
    """Median, scaled MAD, range and outliers of ``{subject: value}`` (non-finite values left out).

    Returns
    -------
    dict
        ``n``, ``median``, ``mad``, ``min``, ``max``, ``values`` and
        ``outliers`` (``{subject: value}`` beyond :data:`OUTLIER_MADS` MADs,
        with at least :data:`MIN_SUBJECTS` subjects).
    """
    values = {subject: float(v) for subject, v in values.items() if np.isfinite(v)}
    x = np.array(list(values.values()))
    if x.size == 0:
        return {"n": 0, "median": None, "mad": None, "min": None, "max": None, "values": {}, "outliers": {}}
    median = float(np.median(x))
    mad = MAD_SCALE * float(np.median(np.abs(x - median)))
    outliers = {subject: v for subject, v in values.items()
                if x.size >= MIN_SUBJECTS and abs(v - median) > OUTLIER_MADS * mad}
    return {"n": int(x.size), "median": median, "mad": mad, "min": float(x.min()), "max": float(x.max()),
            "values": values, "outliers": outliers}


def components(name: str, value) -> list[tuple[str, float]]:
    """A parameter as scalars: itself, ``name.r/g/b`` for three channels, else ``name[i]``."""
    flat = np.ravel(np.asarray(value, dtype=float))
    if flat.size == 1:
        return [(name, float(flat[0]))]
    if flat.size == len(CHANNELS):
        return [(f"{name}.{c}", float(v)) for c, v in zip(CHANNELS, flat)]
    return [(f"{name}[{i}]", float(v)) for i, v in enumerate(flat)]


def _nested():
    return defaultdict(_nested)


def _gather(reports: dict[str, dict]):
    """``{subject: value}`` leaves of the statistics, and the status counts."""
    values, statuses, shapes = _nested(), {}, Counter()
    for subject, report in reports.items():
        shapes.update(entry["status"] for entry in (report.get("shapes") or {}).values())
        for model, entry in report["models"].items():
            counts = statuses.setdefault(model, Counter())
            for region, fit in entry["fit"].items():
                counts[fit["status"]] += 1
                if fit["status"] in NOT_FITTED:
                    continue
                for key, value in entry["regions"][region].items():
                    for label, v in components(key, value):
                        values[model]["parameters"][region][label][subject] = v
                for label, v in components("diffuse_reflectance", fit["diffuse_reflectance"]):
                    values[model]["albedo"][region][label.split(".")[-1]][subject] = v
            truth = entry.get("ground_truth") or {}
            for region, errors in truth.get("regions", {}).items():
                for key, error in errors.items():
                    values[model]["ground_truth"]["parameters"][region][key][subject] = error
            for key, error in (truth.get("albedo") or {}).items():
                if not key.startswith("texels"):
                    values[model]["ground_truth"]["albedo"][key][subject] = error
    return values, statuses, shapes


def _summarise(tree):
    """The same nesting with each ``{subject: value}`` leaf replaced by its :func:`robust_summary`."""
    leaf = all(not isinstance(v, dict) for v in tree.values())
    return robust_summary(tree) if leaf else {key: _summarise(value) for key, value in tree.items()}


def _outliers(tree, path=()) -> list[dict]:
    if not isinstance(tree, dict):
        return []
    if "outliers" in tree and "median" in tree:
        return [{"where": " / ".join(path), "subject": s, "value": v, "median": tree["median"], "mad": tree["mad"]}
                for s, v in tree["outliers"].items()]
    return [o for key, value in tree.items() for o in _outliers(value, path + (key,))]


def population(reports: dict[str, dict], record: dict | None = None) -> dict:
    """The population statistics of ``reports`` (``{subject: report.json's content}``).

    Parameters
    ----------
    reports : dict
    record : dict, optional
        The batch's record (``batch.json``), for the wall time of each capture's task.

    Returns
    -------
    dict
        ``subjects``; ``models``: ``{model: {"parameters": {region: {parameter:
        summary}}, "albedo": {region: {channel: summary}}, "ground_truth":
        {"parameters": ..., "albedo": {error: summary}}, "status": {status:
        count}}}`` (summaries from :func:`robust_summary`); ``shape_status``;
        ``seconds`` (``measure``: :func:`mifaces.pipeline.measure.measure`'s total;
        ``task``: the batch task's wall time); ``outliers``, every flagged value
        (``where``: ``model / section / region / parameter`` or ``seconds / kind``).
    """
    values, statuses, shapes = _gather(reports)
    models = _summarise(values) if values else {}
    for model, counts in statuses.items():
        models.setdefault(model, {})["status"] = dict(counts)
    seconds = {"measure": robust_summary({s: r["seconds"]["total"] for s, r in reports.items()})}
    if record is not None:
        seconds["task"] = robust_summary({s: e["seconds"] for s, e in record["captures"].items()
                                          if s in reports and "seconds" in e and e.get("status") == "done"})
    return {"subjects": sorted(reports), "models": models, "shape_status": dict(shapes), "seconds": seconds,
            "outliers": _outliers({**models, "seconds": seconds})}


def write_population(out, reports: dict, record: dict | None = None) -> dict:
    """Write :func:`population` of ``reports`` as ``out/population.{json,md,png}``.

    Parameters
    ----------
    out : path
        Folder of the batch.
    reports : dict
        ``{subject: report}``, each a ``report.json`` path or its content.
    record : dict, optional
        The batch's record (see :func:`population`).

    Returns
    -------
    dict
        The paths written: ``{"json", "md", "png"}``.
    """
    out = Path(out)
    reports = {s: json.loads(Path(r).read_text()) if not isinstance(r, dict) else r for s, r in reports.items()}
    stats = population(reports, record)
    paths = {kind: out / f"population.{kind}" for kind in ("json", "md", "png")}
    write_json(paths["json"], stats)
    with atomic_write(paths["md"], "w") as f:
        f.write(markdown(stats))
    write_population_picture(paths["png"], stats)
    return {kind: str(path) for kind, path in paths.items()}


def _g(value) -> str:
    return "" if value is None else f"{value:.4g}"


def _table(rows, header: str) -> list[str]:
    """Markdown rows of ``(name, summary)``: n, median, MAD, range, outliers."""
    lines = [f"| {header} | n | median | MAD | range | outliers |", "|---|---|---|---|---|---|"]
    for name, s in rows:
        outliers = ", ".join(f"{k} ({_g(v)})" for k, v in s["outliers"].items())
        lines.append(f"| {name} | {s['n']} | {_g(s['median'])} | {_g(s['mad'])} | {_g(s['min'])} – {_g(s['max'])} "
                     f"| {outliers} |")
    return lines + [""]


def markdown(stats: dict) -> str:
    """The population report as Markdown."""
    lines = ["# mifaces population report", "",
             f"{len(stats['subjects'])} captures: {', '.join(stats['subjects'])}. Spread is the scaled median "
             f"absolute deviation (MAD, σ for normal data); outliers lie beyond {OUTLIER_MADS:g} MAD of the median.",
             "", "![population](population.png)", "", "## Time per capture (s)", ""]
    lines += _table(stats["seconds"].items(), "time")
    if stats["shape_status"]:
        lines += ["Shape fits: " + ", ".join(f"{k} {v}" for k, v in stats["shape_status"].items()), ""]
    for model, entry in stats["models"].items():
        lines += [f"## {model}", "", "Fit status (regions × captures): "
                  + ", ".join(f"{k} {v}" for k, v in entry.get("status", {}).items()), ""]
        for title, key in (("Parameters", "parameters"), ("Diffuse albedo", "albedo")):
            rows = [(f"{region} {name}", s) for region, params in entry.get(key, {}).items() for name, s in params.items()]
            lines += [f"### {title}", ""] + _table(rows, "region parameter") if rows else []
        truth = entry.get("ground_truth", {})
        rows = [(f"{region} {name}", s) for region, errors in truth.get("parameters", {}).items()
                for name, s in errors.items()] + [(f"albedo {name}", s) for name, s in truth.get("albedo", {}).items()]
        if rows:
            lines += ["### Error against ground truth (relative for parameters, absolute for albedo)", ""]
            lines += _table(rows, "quantity")
    if stats["outliers"]:
        lines += ["## Outliers", ""] + [f"- {o['subject']}: {o['where']} = {_g(o['value'])} (median {_g(o['median'])},"
                                          f" MAD {_g(o['mad'])})" for o in stats["outliers"]] + [""]
    return "\n".join(lines)


def write_population_picture(path, stats: dict) -> None:
    """Strip plots: per model and parameter, each region's value per subject
    (outliers in red, the median as a bar), and the time per capture."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(f"{model}: {name}", {region: params[name] for region, params in entry.get("parameters", {}).items()
                                    if name in params})
              for model, entry in stats["models"].items()
              for name in dict.fromkeys(n for params in entry.get("parameters", {}).values() for n in params)]
    panels.append(("seconds per capture", stats["seconds"]))
    columns = min(4, len(panels))
    rows = -(-len(panels) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(3.6 * columns, 2.8 * rows), squeeze=False)
    for ax, (title, groups) in zip(axes.flat, panels):
        for i, (group, s) in enumerate(groups.items()):
            for subject, v in s["values"].items():
                ax.plot(i, v, "o", ms=4, color="tab:red" if subject in s["outliers"] else "tab:blue", alpha=0.7)
            if s["median"] is not None:
                ax.plot([i - 0.3, i + 0.3], [s["median"]] * 2, color="k", lw=1.5)
        ax.set_xticks(range(len(groups)), list(groups), rotation=45, fontsize=7)
        ax.set_title(title, fontsize=8)
        ax.tick_params(axis="y", labelsize=7)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)


__all__ = ["population", "write_population", "robust_summary", "components", "markdown",
           "write_population_picture"]
