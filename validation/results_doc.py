"""Writes ``docs/results.md`` from the committed results in ``validation/results/*.json``.

Every number in ``docs/results.md`` is read from a JSON here; nothing is typed by
hand. One section per result file, in file-name order: what was measured (the
first paragraph of the script's docstring), the command (the JSON's
``command`` field where it holds a ``python validation/...`` command, else the
``Run:``/usage line of the script's docstring), whether the data are SIMULATED
or real, a table of the key numbers, and the picture
``validation/results/<name>.png`` where one exists. A file of a layout this
script does not know gets one line listing its top-level keys; a key missing
from a known layout shows as "—".

Run:  python validation/results_doc.py [--results DIR] [--out FILE] [--check]

``--check`` writes nothing and exits 1 when FILE differs from what would be
written (for CI and ``tests/test_results_doc.py``). Standard library only.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import os
import re
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DASH = "—"
_MISSING = object()


# --------------------------------------------------------------------------- helpers


def get(data, *path, default=_MISSING):
    """``data[path[0]][path[1]]...``, or ``default`` (None) where any step is missing."""
    for key in path:
        try:
            data = data[key]
        except (KeyError, IndexError, TypeError):
            return None if default is _MISSING else default
    return data


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def num(x, digits: int = 3) -> str:
    """A number with ``digits`` significant digits (plain notation in a sensible range)."""
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if not _finite(x):
        return DASH if x is None or not isinstance(x, float) else str(x)
    if x == 0:
        return "0"
    if abs(x) >= 10 ** digits:
        return f"{x:.0f}"
    if abs(x) < 1e-3:
        return f"{x:.{max(digits - 1, 0)}e}"
    decimals = max(digits - 1 - int(math.floor(math.log10(abs(x)))), 0)
    return f"{x:.{decimals}f}"


def fixed(x, decimals: int = 1) -> str:
    return f"{x:.{decimals}f}" if _finite(x) else DASH


def pct(x, decimals: int = 1) -> str:
    """A fraction as a percentage."""
    return f"{100 * x:.{decimals}f} %" if _finite(x) else DASH


def text(x) -> str:
    if x is None:
        return DASH
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float) and _finite(x) and 1e-3 <= abs(x) < 1e4:
        return f"{x:.4g}"
    if isinstance(x, (int, float)):
        return num(x)
    if isinstance(x, (list, tuple)):
        return ", ".join(text(v) for v in x) if x else DASH
    if isinstance(x, dict):
        return ", ".join(f"{k}={text(v)}" for k, v in x.items()) if x else DASH
    return str(x).replace("|", "\\|").replace("\n", " ")


def mean(x):
    """The mean of a list of numbers (an RGB triple), or the number itself."""
    if isinstance(x, list):
        values = [v for v in x if _finite(v)]
        return sum(values) / len(values) if values else None
    return x if _finite(x) else None


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    if not rows:
        return ["(no rows)", ""]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        cells = [DASH if c in (None, "") else str(c) for c in row]
        cells += [DASH] * (len(header) - len(cells))
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def items(x):
    """(key, value) pairs of a dict, or nothing."""
    return list(x.items()) if isinstance(x, dict) else []


def rows_of(x):
    """The dicts of a list, or nothing."""
    return [r for r in x if isinstance(r, dict)] if isinstance(x, list) else []


def data_label(data, default: str) -> str:
    """SIMULATED or real, from the file's own ``label``/``data``/``simulated`` where it says."""
    if isinstance(data, dict):
        label = data.get("label")
        if isinstance(label, str) and label:
            return label
        if data.get("simulated") is True:
            return "SIMULATED"
        described = data.get("data")
        if isinstance(described, str):
            if "SIMULATED" in described.upper():
                return "SIMULATED"
            if "real" in described.lower() or "diligent" in described.lower():
                return f"real data ({described})"
    return default


# --------------------------------------------------------------------------- scripts and commands


def script_for(stem: str, scripts: dict[str, str]) -> str | None:
    """The validation script that writes result ``stem``: the longest script name it starts with."""
    best = None
    for name in scripts:
        if stem == name or stem.startswith(name + "_"):
            if best is None or len(name) > len(best):
                best = name
    return best


def read_docstrings(folder: Path) -> dict[str, str]:
    docs = {}
    for path in sorted(folder.glob("*.py")):
        try:
            doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        except (SyntaxError, UnicodeDecodeError, OSError):
            doc = ""
        docs[path.stem] = doc
    return docs


def summary(doc: str) -> str:
    first = doc.strip().split("\n\n")[0] if doc.strip() else ""
    return " ".join(first.split())


def docstring_command(name: str, doc: str) -> str | None:
    """The ``Run:`` line of a docstring, or its first line that runs the script."""
    lines = doc.splitlines()
    for i, line in enumerate(lines):
        match = re.match(r"\s*Run:\s*(python .*)", line)
        if match:
            command = match.group(1).strip()
            # a Run: line may continue on the next, indented line
            while i + 1 < len(lines) and lines[i + 1].startswith("      ") and lines[i + 1].strip().startswith("["):
                i += 1
                command += " " + lines[i].strip()
            return command
    for line in lines:
        stripped = line.strip()
        if stripped.startswith(f"python validation/{name}.py"):
            return stripped.split("  #")[0].strip()
    return None


def pareto_command(data) -> str | None:
    """The command that makes ``pareto.json``'s grid (the file records the grid, not the command)."""
    grid = data.get("grid") if isinstance(data, dict) else None
    if not isinstance(grid, dict) or grid == data.get("full_grid"):
        return None
    parts = ["python validation/pareto.py"]
    for flag, key in (("--measurements", "measurements"), ("--resolutions", "resolutions"), ("--spp", "spp")):
        if isinstance(grid.get(key), list):
            parts.append(flag + " " + " ".join(str(v) for v in grid[key]))
    geometry = get(data, "options", "geometry")
    if isinstance(geometry, str):
        parts.append(f"--geometry {geometry}")
    if isinstance(data.get("seeds"), list):
        parts.append("--seeds " + " ".join(str(v) for v in data["seeds"]))
    return " ".join(parts)


def command_line(data, name: str | None, doc: str) -> str:
    recorded = data.get("command") if isinstance(data, dict) else None
    source = "as recorded in the file"
    if recorded is None and name == "pareto":
        recorded, source = pareto_command(data), "from the grid the file records"
    script_cmd = docstring_command(name, doc) if name else None
    if isinstance(recorded, str) and recorded.startswith("python "):
        return f"`{recorded}` ({source})"
    if script_cmd:
        extra = f"; it times `{recorded}`" if isinstance(recorded, str) and recorded else ""
        return f"`{script_cmd}`{extra}"
    if isinstance(recorded, str) and recorded:
        return f"`{recorded}`"
    return DASH


# --------------------------------------------------------------------------- sections


def sec_bench_brdf_fit(d):
    lines = [f"{text(d.get('samples'))} reflectance samples, {text(d.get('threads'))} threads, "
             f"1-minute load average {text(d.get('load_average_1min'))}. `loss / best`: the loss over the best "
             "any method reached; `× scipy`: speed-up over scipy's LM; `over limit`: wall time over the "
             "physical limit (full-data passes × one pass's time).", ""]
    rows = [[text(r.get("model")), text(r.get("method")), fixed(r.get("seconds"), 2), num(r.get("loss_over_best"), 8),
             fixed(r.get("speedup_vs_scipy"), 1), text(r.get("passes")), text(r.get("full_data_passes")),
             fixed(r.get("seconds_over_limit"), 1), text(r.get("status"))] for r in rows_of(d.get("rows"))]
    return lines + table(["model", "method", "seconds", "loss / best", "× scipy", "passes", "full-data passes",
                          "over limit", "status"], rows)


def sec_bench_bsdf(d):
    setup = d.get("render_setup") or {}
    lines = [f"Variant {text(d.get('variant'))}; renders at {text(setup.get('res'))}², {text(setup.get('spp'))} spp, "
             f"best of {text(setup.get('repeats'))}. `ratio`: the plugin's time over `roughplastic`'s.", ""]
    lines += table(["plugin", "seconds", "roughplastic seconds", "ratio"],
                   [[text(r.get("plugin")), fixed(r.get("seconds"), 3), fixed(r.get("roughplastic_seconds"), 3),
                     fixed(r.get("ratio"), 2)] for r in rows_of(d.get("render"))])
    lines += table(["model", "samples", "Dr.Jit eval/s", "NumPy eval/s", "× NumPy (eval)", "× NumPy (eval + grad)"],
                   [[text(r.get("model")), text(r.get("samples")), num(r.get("drjit_fwd_per_s")),
                     num(r.get("numpy_fwd_per_s")), fixed(r.get("ratio_fwd"), 1), fixed(r.get("ratio_fwdbwd"), 1)]
                    for r in rows_of(d.get("array_api"))])
    return lines


def sec_bench_face_render(d):
    lines = [f"Scene: {text(d.get('scene'))}; {text(d.get('resolution'))}², {text(d.get('spp'))} spp, "
             f"{text(d.get('repeats'))} repeats, {text(d.get('threads'))} threads, Mitsuba {text(d.get('mitsuba'))}, "
             f"1-minute load average {text(d.get('load_average_1min'))}.", ""]
    lines += table(["BSDF", "load (s)", "render (s)"],
                   [[k, fixed(get(v, "load_s"), 2), fixed(get(v, "render_s"), 2)] for k, v in items(d.get("bsdfs"))])
    lines += table(["Cook–Torrance plugin over", "render", "load and render"],
                   [[k, fixed(get(v, "render"), 2), fixed(get(v, "load_and_render"), 2)]
                    for k, v in items(d.get("ratios"))])
    return lines


def sec_bench_pipeline(d):
    runs = items(d.get("runs"))
    machine = d.get("machine") or {}
    lines = [f"{text(d.get('note'))}", "",
             f"Machine: {text(machine.get('cores'))} cores, {text(machine.get('platform'))}, Python "
             f"{text(machine.get('python'))}; 1-minute load average at the end {fixed(d.get('load_average_1min_at_end'), 1)}.",
             ""]
    names = [name for name, _ in runs]
    lines += table(["", *names], [
        ["wall time (s)", *[fixed(get(r, "wall_s"), 1) for _, r in runs]],
        ["peak memory (MiB)", *[fixed(get(r, "peak_rss_mib"), 0) for _, r in runs]],
        ["skin Cook–Torrance ρs error", *[pct(get(r, "skin_cooktorrance_error", "specular_reflectance"), 2)
                                         for _, r in runs]],
        ["skin Cook–Torrance roughness error", *[pct(get(r, "skin_cooktorrance_error", "roughness"), 2)
                                                for _, r in runs]],
        ["shape floor under the held-out lights", *[pct(get(r, "shape_floor", "heldout_rmse"), 1) for _, r in runs]],
        ["noise floor under the held-out lights", *[pct(get(r, "noise_floor", "heldout_rmse"), 1) for _, r in runs]],
        ["shapes converged", *[text(sum(1 for s in (get(r, "shapes") or {}).values()
                                        if get(s, "status") == "converged")) + " / "
                               + text(len(get(r, "shapes") or {})) for _, r in runs]],
    ])
    refined = [(name, r) for name, r in runs if get(r, "shape_refinement")]
    if refined:
        lines += ["With `--refine-shape`:", ""]
        lines += table(["run", "refinement", "mean world error of the refined faces (mm)"],
                       [[name, text(get(r, "shape_refinement", "reason")),
                         fixed(get(r, "shape_errors_refined", "mean_world_mm"), 2)] for name, r in refined])
    stages = []
    for _, run in runs:
        for stage in get(run, "stages_s") or {}:
            if stage not in stages:
                stages.append(stage)
    lines += table(["stage (s)", *names], [[stage, *[fixed(get(r, "stages_s", stage), 1) for _, r in runs]]
                                           for stage in stages])
    return lines


def sec_bench_shape_kernels(d):
    lines = ["Per labelled run (`--label`) and measurement: launches per iteration, compiled kernels, compile "
             "time, the kernels' share of the timed fit's wall time, and the fit's errors against the truth.", ""]
    rows = []
    for label, run in items(d):
        for m in rows_of(get(run, "measurements")):
            rows.append([label, text(get(run, "iterations_factor")), text(m.get("measurement")),
                         text(m.get("iterations")), fixed(m.get("seconds"), 2), fixed(m.get("launches_per_iteration"), 1),
                         text(m.get("compiled")), fixed(m.get("compile_s"), 2), pct(m.get("execution_share"), 0),
                         fixed(m.get("feature_rms_px"), 2), fixed(m.get("vertex_rms_aligned_mm"), 2),
                         fixed(m.get("normal_deg"), 2)])
    return lines + table(["label", "schedule factor", "measurement", "iterations", "seconds", "launches / iteration",
                          "compiled", "compile (s)", "execution share", "landmarks (px)", "vertices aligned (mm)",
                          "normals (°)"], rows)


def sec_bench_simulate(d):
    lines = []
    rows = []
    for key, run in items(d):
        if isinstance(run, dict) and "seconds_total" in run:
            rows.append([key, text(run.get("measurements")), text(run.get("lights")), fixed(run.get("seconds_total"), 1),
                         fixed(run.get("seconds_per_measurement"), 2), fixed(run.get("seconds_load_and_calibrate"), 2)])
    lines += table(["run", "measurements", "lights", "total (s)", "per measurement (s)", "load and calibrate (s)"], rows)
    cal = d.get("light_calibration_error_percent") or {}
    lines += [f"Light calibration from the steel spheres, error in % of the light's distance over "
              f"{text(cal.get('lights'))} lights: mean {fixed(cal.get('mean'), 3)} %, max {fixed(cal.get('max'), 3)} %.",
              ""]
    return lines


def sec_brdf_energy(d):
    lines = ["Largest hemispherical albedo of the glossy part (ρs = 1) over the angles and widths swept, and where.",
             ""]
    rows = [[text(v.get("model")), text(v.get("options")) if v.get("options") else "default",
             fixed(v.get("max_albedo"), 3), fixed(v.get("at_theta_deg"), 1), text(v.get("at_width")),
             text(v.get("at_exponent"))] for v in rows_of(d.get("variants"))]
    return lines + table(["model", "options", "max albedo", "at θi (°)", "at width", "at exponent"], rows)


def sec_brdf_fit_stiff(d):
    rows = [[text(r.get("case")), text(r.get("model")), text(r.get("samples")), text(r.get("status")),
             text(r.get("finite")), pct(r.get("max_relative_error"), 2), fixed(r.get("seconds"), 2)]
            for r in rows_of(d)]
    return ["`max error`: the largest relative error of a fitted parameter against the truth.", ""] + table(
        ["case", "model", "samples", "status", "finite", "max error", "seconds"], rows)


def sec_brdf_recovery(d):
    lines = [f"Texture {text(d.get('resolution'))}², photographs {text(d.get('image'))}², {text(d.get('spp'))} spp, "
             f"variant {text(d.get('variant'))}, ground-truth shapes.", "",
             "**Same family** (each model fitted to a face rendered with that model): per region the relative "
             "RMSE of the glossy part over the hemisphere, skin's parameter errors, albedo RMSE.", ""]
    same = rows_of(d.get("same_family"))
    regions = []
    for r in same:
        for region in get(r, "regions") or {}:
            if region not in regions:
                regions.append(region)
    rows = []
    for r in same:
        skin_errors = get(r, "regions", "skin", "relative_error") or {}
        rows.append([text(r.get("model")),
                     *[pct(get(r, "regions", region, "glossy_relative_rmse")) for region in regions],
                     ", ".join(f"{k} {pct(v)}" for k, v in skin_errors.items()) or DASH,
                     fixed(get(r, "albedo", "rmse_sampled"), 4), fixed(get(r, "fit_seconds", "total"), 1)])
    lines += table(["model", *[f"{region} glossy" for region in regions], "skin parameters", "albedo RMSE",
                    "fit (s)"], rows)
    lines += ["**Cross family** (every model fitted to a Cook–Torrance face): skin's BRDF error relative to the "
              "glossy part's RMS, overall and at grazing angles, and the relative RMSE on held-out photographs "
              "against the noise floor.", ""]
    rows = [[text(r.get("model")), pct(r.get("brdf_rmse_over_specular_rms")), num(r.get("brdf_rmse_grazing")),
             pct(r.get("heldout_image_relative_rmse")), pct(r.get("heldout_noise_floor")), fixed(r.get("fit_seconds"), 1)]
            for r in rows_of(d.get("cross_family"))]
    return lines + table(["model", "BRDF RMSE / glossy RMS", "BRDF RMSE grazing", "held-out image RMSE",
                          "noise floor", "fit (s)"], rows)


def sec_export(d):
    capture = d.get("capture") or {}
    lines = [f"{text(d.get('what'))}.", "",
             f"Truth {text(d.get('truth'))}, geometry {text(d.get('geometry'))}, {text(capture.get('measurements'))} "
             f"measurements at {text(capture.get('resolution'))}², texture {text(d.get('texture'))}², hemisphere grid "
             f"{text(d.get('hemisphere_grid'))}; machine: {text(d.get('machine'))}.", ""]
    models = items(d.get("models"))
    regions = []
    for _, m in models:
        for region in get(m, "regions") or {}:
            if region not in regions:
                regions.append(region)
    lines += table(["model", *[f"{region} RMSE" for region in regions], "skin glossy RMSE", ".glb (MB)", "export (s)"],
                   [[name, *[pct(get(m, "regions", region, "rmse")) for region in regions],
                     pct(get(m, "rmse_specular_skin")),
                     fixed(get(m, "glb_bytes") / 1e6, 2) if _finite(get(m, "glb_bytes")) else DASH,
                     fixed(get(m, "export_seconds"), 2)] for name, m in models])
    return lines


def sec_model_span(d):
    lines = [f"Model {text(d.get('model'))} ({text(d.get('model_modes'))} modes) fitted to {text(d.get('faces'))} "
             f"random faces of {text(d.get('reference'))} on {text(d.get('landmarks'))} landmarks; modes chosen on the "
             f"training faces: {text(d.get('chosen_on_train'))}; the shape fit's default: "
             f"{text(d.get('fit_shape_modes'))} modes. Test faces:", ""]
    rows = [[k, fixed(get(v, "mean_residual_mm"), 2), fixed(get(v, "inner_mean_residual_mm"), 2),
             fixed(get(v, "worst_face_residual_mm"), 2), fixed(get(v, "mean_max_abs_coefficient_sd"), 2),
             fixed(get(v, "max_abs_coefficient_sd"), 2)] for k, v in items(d.get("test"))]
    return lines + table(["modes", "mean residual (mm)", "inner points (mm)", "worst face (mm)",
                          "mean largest coefficient (sd)", "largest coefficient (sd)"], rows)


def sec_mutations(d):
    mutations = rows_of(d.get("mutations"))
    caught = sum(1 for m in mutations if m.get("caught") is True)
    missed = d.get("missed")
    lines = [f"Tests run: {text(d.get('tests'))}. {caught} of {len(mutations)} mutations caught; missed: "
             f"{text(missed) if missed else 'none'}.", ""]
    return lines + table(["id", "file", "mutation", "caught"],
                         [[text(m.get("id")), f"`{text(m.get('file'))}`", text(m.get("mutation")), text(m.get("caught"))]
                          for m in mutations])


def sec_normals_faces(d):
    lines = [f"Capture resolution {text(d.get('resolution'))}² texture; skin's fitted parameters against the truth "
             "per run (true or fitted shapes, with or without per-texel normals or albedo offsets).", ""]
    rows = [[name, pct(get(r, "specular_reflectance_rel")), pct(get(r, "roughness_rel")),
             fixed(get(r, "skin_normal_error_deg"), 2), fixed(get(r, "normal_refinement", "mean_tilt_deg"), 2),
             text(get(r, "rounds")), fixed(get(r, "seconds"), 1)] for name, r in items(d.get("runs"))]
    return lines + table(["run", "skin ρs error", "skin roughness error", "normal error (°)", "mean tilt (°)", "rounds",
                          "seconds"], rows)


def sec_pareto(d):
    model = d.get("model") if isinstance(d.get("model"), str) else None
    default = d.get("default") or {}
    grid = d.get("grid") or {}
    options = d.get("options") or {}
    lines = [f"Grid: measurements {text(grid.get('measurements'))} × resolution {text(grid.get('resolutions'))} × "
             f"spp {text(grid.get('spp'))}; geometry {text(options.get('geometry'))}, texture "
             f"{text(options.get('texture'))}², model {text(model)}; each setting on the seeds "
             f"{text(d.get('seeds'))} (each seed another face, poses, lamps and noise). The defaults: "
             f"{text(default.get('measurements'))} / {text(default.get('resolution'))} / {text(default.get('spp'))}. "
             "Errors: the mean over the seeds, the least and largest in brackets; wall time: the mean. A front "
             "through the means of a few seeds orders two settings only where their ranges do not overlap.", ""]

    def spread(entry, key, as_pct, decimals):
        show = (lambda x: pct(x, decimals)) if as_pct else (lambda x: fixed(x, decimals))
        e = get(entry, key)
        return f"{show(get(e, 'mean'))} ({show(get(e, 'min'))}–{show(get(e, 'max'))})"

    rows = []
    for p in rows_of(d.get("summary")):
        key = f"{text(p.get('measurements'))} / {text(p.get('resolution'))} / {text(p.get('spp'))}"
        if all(p.get(k) == default.get(k) for k in ("measurements", "resolution", "spp")) and default:
            key += " (defaults)"
        rows.append([key, fixed(p.get("wall_s"), 0), spread(p, "brdf_skin", True, 2), spread(p, "albedo_rmse", False, 4),
                     spread(p, "heldout_rmse", True, 1), spread(p, "environment_rmse", True, 1)])
    lines += table(["measurements / px / spp", "wall (s)", "skin BRDF RMSE", "albedo RMSE", "held-out RMSE",
                    "environment RMSE"], rows)
    lines += table(["error", "front through the means (measurements / px / spp)", "defaults on it"],
                   [[name, "; ".join(" / ".join(text(v) for v in point) for point in (get(f, "front") or []))
                     or DASH, text(get(f, "default_on_front"))] for name, f in items(d.get("fronts"))])
    return lines


def sec_real_diligent(d):
    lines = [f"Split: {text(d.get('split'))}. Chosen model {text(d.get('chosen_model'))}, {text(d.get('rounds'))} "
             "rounds. Normals: angular error against the ground truth.", ""]
    rows = []
    for key, label in (("normals_all", "all lights"), ("normals_half", "training half")):
        for method, r in items(d.get(key)):
            rows.append([label, method, fixed(get(r, "mean"), 2), fixed(get(r, "median"), 2),
                         pct(get(r, "within_5deg"))])
    lines += table(["lights", "method", "mean (°)", "median (°)", "within 5°"], rows)
    lines += ["Held-out half of the lights: relative RMSE of the predicted photographs.", ""]
    lines += table(["predictor", "relative RMSE"], [[k, fixed(get(v, "relative_rmse"), 4)]
                                                    for k, v in items(d.get("heldout"))])
    return lines


def _yale_table(overall, subjects):
    """Rows per predictor: all / small / large shadows, then each subject's all."""
    names = [text(s.get("subject", key)) if isinstance(s, dict) else key for key, s in subjects]
    rows = []
    for predictor, r in items(get(overall, "relative_rmse")):
        rows.append([predictor, fixed(get(r, "all"), 3), fixed(get(r, "small_shadows"), 3),
                     fixed(get(r, "large_shadows"), 3),
                     *[fixed(get(s, "relative_rmse", predictor, "all") if get(s, "relative_rmse") is not None
                             else get(s, predictor, "all"), 3) for _, s in subjects]])
    return table(["predictor", "all held-out", "small shadows", "large shadows", *names], rows)


def sec_real_yaleb(d):
    if isinstance(d.get("runs"), dict):  # --normals, --interreflection: runs without and with
        what = {"normals": "per-texel normals", "interreflection": "the bounced light taken out (interreflection)"}
        option = what.get(d.get("option", "normals"), text(d.get("option")))
        lines = [f"Training lights {text(d.get('train_lights'))}, models {text(d.get('models'))}, texture "
                 f"{text(d.get('texture_resolution'))}². Relative RMSE over the face pixels, without and with "
                 f"{option}.", ""]
        for name, run in items(d.get("runs")):
            lines += [f"*{name} {option}* (best model {text(get(run, 'overall', 'best_model'))}):", ""]
            lines += _yale_table(get(run, "overall"), items(get(run, "subjects")))
        return lines
    subjects = [(str(i), s) for i, s in enumerate(rows_of(d.get("subjects")))]
    overall = d.get("overall") or {}
    lines = [f"Training lights {text(d.get('train_lights'))}, models {text(d.get('models'))}, texture "
             f"{text(d.get('texture_resolution'))}², {text(d.get('spp'))} spp; large shadows: lights more than "
             f"{text(d.get('shadow_angle_deg'))}° from the camera axis. Pooled relative RMSE over the face pixels of the held-out lights; "
             f"best model {text(overall.get('best_model'))}, {fixed(overall.get('best_vs_photometric_stereo'), 2)}× "
             "photometric stereo's error.", ""]
    lines += _yale_table(overall, subjects)
    ratios = items(overall.get("refined_vs_unrefined"))
    if ratios:
        lines += ["Refined over unrefined error:", ""]
        lines += table(["model", "all", "small shadows", "large shadows"],
                       [[k, fixed(get(v, "all"), 3), fixed(get(v, "small_shadows"), 3),
                         fixed(get(v, "large_shadows"), 3)] for k, v in ratios])
    best = overall.get("best_model")
    gains = [(text(s.get("subject")), get(s, "refinement", best, "light_gains")) for _, s in subjects]
    gains = [(name, g) for name, g in gains if isinstance(g, dict) and g]
    if gains:
        lights = sorted({light for _, g in gains for light in g})
        lines += [f"Light gains the refinement fitted ({text(best)}):", ""]
        lines += table(["subject", *lights], [[name, *[num(g.get(light), 3) for light in lights]] for name, g in gains])
    return lines


def sec_unknown_lights(d):
    errors = d.get("angular_error_deg") or {}
    runs = d.get("runs") or {}
    lines = [f"Training lights {text(d.get('train_lights'))} per subject ({text(d.get('subjects'))}), hidden and estimated "
             f"with the face. Angle between each estimated direction and the calibrated one over "
             f"{text(errors.get('lights'))} lights: median {fixed(errors.get('median'), 1)}°, max "
             f"{fixed(errors.get('max'), 1)}° (targets {text(errors.get('median_target'))}° / "
             f"{text(errors.get('max_target'))}°: {'met' if errors.get('met') else 'not met'}).", ""]
    per = items(errors.get("per_subject"))
    names = list(get(per[0][1]) or {}) if per else []
    lines += table(["subject"] + names, [[s] + [fixed(get(v, n), 1) for n in names] for s, v in per])
    keys = list(get(runs, "calibrated", "relative_rmse") or {})
    lines += ["Held-out relighting, pooled relative RMSE over the three subjects (held-out lights rendered as known):", ""]
    lines += table(["predictor", "calibrated training lights", "estimated training lights"],
                   [[k, fixed(get(runs, "calibrated", "relative_rmse", k, "all"), 4),
                     fixed(get(runs, "unknown", "relative_rmse", k, "all"), 4)] for k in keys])
    seconds = items(d.get("seconds"))
    lines += table(["subject", "measure, calibrated (s)", "measure, estimated lights (s)"],
                   [[s, fixed(get(v, "measure_calibrated"), 0), fixed(get(v, "measure_unknown"), 0)] for s, v in seconds])
    return lines


def sec_unknown_lights_simulated(d):
    lights = items(d.get("lights"))
    ambient = d.get("ambient", "unknown")
    lines = ["Each light's estimate (the mean over the photographs under it) against its true direction from the "
             "fitted head's centre, and how far its photographs' estimates lie from that mean. The hidden capture's "
             f"`ambient`: {text(ambient)} ("
             + ("held at zero in the shape fit" if ambient == "none" else "the shape fit fits an ambient term") + ").",
             ""]
    lines += table(["light", "angle to the truth (deg)", "before the alternation", "photographs", "their spread (deg)"],
                   [[name, fixed(get(v, "angle_deg"), 1), fixed(get(v, "angle_deg_first_pass", default=None), 1),
                     text(len(get(v, "photographs") or [])), fixed(get(v, "spread_deg"), 1)] for name, v in lights])
    lines += [f"Shape fit with the lights estimated: {fixed(get(d, 'seconds', 'fit_shape'), 0)} s.", ""]
    return lines


def sec_environment_lights(d):
    summary = items(d.get("summary"))
    lines = [f"{text(d.get('measurements'))} head turns per capture under one environment, Cook–Torrance fitted "
             f"on fitted faces and refined; seeds {text(d.get('seeds'))} (the defaults were set on seed "
             f"{text(d.get('tuning_seed'))}, not shown). Each capture is measured with its map given and with "
             "its light hidden (estimated with the face). The estimated run's reflectance is relative: the "
             "validation compares it after one factor (the median ratio of true to fitted skin albedo, "
             "the last column); the skin parameter errors are before that factor.", ""]
    lines += table(["environment", "held-out error, map given", "map estimated", "worst ratio (target <= "
                    f"{text(d.get('ratio_target'))})", "on the true shape: given", "estimated", "worst ratio",
                    "shape floor, given", "estimated"],
                   [[name, pct(get(v, "heldout_rmse_given")), pct(get(v, "heldout_rmse_estimated")),
                     fixed(get(v, "heldout_ratio_max"), 2), pct(get(v, "heldout_rmse_true_shape_given")),
                     pct(get(v, "heldout_rmse_true_shape_estimated")),
                     fixed(get(v, "heldout_ratio_true_shape_max", default=None), 2),
                     pct(get(v, "shape_floor_given", default=None)), pct(get(v, "shape_floor_estimated", default=None))]
                    for name, v in summary])
    lines += table(["environment", "skin BRDF error, map given", "map estimated", "map irradiance error",
                    "after refinement", "extra seconds (max)"],
                   [[name, pct(get(v, "skin_brdf_rmse_given")), pct(get(v, "skin_brdf_rmse_estimated")),
                     pct(get(v, "irradiance_error")), pct(get(v, "irradiance_error_refined")),
                     fixed(get(v, "extra_seconds_max"), 0)] for name, v in summary])
    cases = items(d.get("cases"))
    lines += table(["capture", "held-out, given", "held-out, estimated", "ratio", "skin ρs error, given",
                    "estimated", "skin roughness error, given", "estimated", "reflectance factor"],
                   [[name, pct(get(c, "given", "heldout_rmse")), pct(get(c, "estimated", "heldout_rmse")),
                     fixed(get(c, "heldout_ratio"), 2),
                     pct(mean(get(c, "given", "skin_parameter_errors", "specular_reflectance", default=None))),
                     pct(mean(get(c, "estimated", "skin_parameter_errors", "specular_reflectance", default=None))),
                     pct(get(c, "given", "skin_parameter_errors", "roughness", default=None)),
                     pct(get(c, "estimated", "skin_parameter_errors", "roughness", default=None)),
                     fixed(get(c, "estimated", "reflectance_scale"), 3)] for name, c in cases])
    return lines


def sec_environment_lights_tuning(d):
    lines = [f"Tuning seed {text(d.get('seed'))}, true faces, map given: {text(d.get('what'))}.", ""]
    rows = []
    for name, v in items(d.get("environments")):
        truth = get(v, "truth", "skin", default=None) or get(v, "truth") or {}
        for start in ("from_the_fit", "restarted"):
            skin = get(v, start, "skin") or {}
            rows.append([name, start.replace("_", " "), num(mean(skin.get("specular_reflectance"))),
                         num(skin.get("roughness")), num(mean(truth.get("specular_reflectance"))),
                         num(truth.get("roughness")), num(get(v, start, "heldout_loss_before"), 4),
                         num(get(v, start, "heldout_loss_after"), 4)])
    lines += table(["environment", "glossy start", "skin ρs (mean RGB)", "skin roughness", "true ρs", "true roughness",
                    "held-out loss, texture-space fit", "after refinement"], rows)
    return lines


def sec_refine(d):
    capture = d.get("capture") or {}
    schedule = d.get("schedule") or {}
    lines = [f"{text(d.get('what'))}.", "",
             f"Capture: {text(capture.get('measurements'))} measurements at {text(capture.get('image'))}², texture "
             f"{text(capture.get('texture_resolution'))}²; {text(schedule.get('iterations'))} iterations at "
             f"{text(schedule.get('spp'))} spp.", ""]
    before = get(d, "errors", "texture_space", "regions") or {}
    after = get(d, "errors", "refined", "regions") or {}
    regions = list(before) + [r for r in after if r not in before]
    lines += table(["region", "ρs error, texture space", "ρs error, refined", "roughness error, texture space",
                    "roughness error, refined"],
                   [[region, pct(get(before, region, "specular_reflectance")),
                     pct(get(after, region, "specular_reflectance")), pct(get(before, region, "roughness")),
                     pct(get(after, region, "roughness"))] for region in regions])
    held = d.get("held_out_light_relative_rmse") or {}
    lines += table(["", "texture space", "refined"], [
        ["albedo RMSE", fixed(get(d, "errors", "texture_space", "albedo_rmse_sampled"), 4),
         fixed(get(d, "errors", "refined", "albedo_rmse_sampled"), 4)],
        ["held-out light relative RMSE", pct(held.get("texture-space")), pct(held.get("refined"))],
        ["image loss", num(get(d, "image_loss", "before")), num(get(d, "image_loss", "after"))],
        ["seconds", fixed(get(d, "cost", "texture_space_fit_seconds"), 1),
         fixed(get(d, "cost", "refine_seconds", "total"), 1)],
    ])
    met = items(d.get("targets_met"))
    if met:
        lines += ["Targets met: " + "; ".join(f"{k}: {text(v)}" for k, v in met) + ".", ""]
    return lines


def sec_light_calibration_bias(d):
    lines = [f"Seeds {text(d.get('seeds'))} ({text(d.get('role'))}); Cook–Torrance truth, the default fit with the "
             "capture's calibrated lights, with them balanced by the face's one albedo (`balance_lights`, where "
             "the file has it), and with the simulator's true ones.", ""]
    rows = []
    for lights, v in items(d.get("summary")):
        if not isinstance(v, dict) or "pooled_coverage" not in v:  # the balance's sweep: below
            continue
        errors = v.get("skin_mean_abs_relative_error") or {}
        rows.append([lights, pct(errors.get("specular_reflectance")), pct(errors.get("roughness")),
                     pct(v.get("skin_coverage"), 0), pct(v.get("pooled_coverage"), 0)])
    lines += table(["lights", "skin ρs error", "skin m error", "skin coverage", "pooled coverage"], rows)
    sweep = get(d, "summary", "balance_sweep", default=None)
    if sweep:
        lines += [f"The balance's error against the true calibration errors (mean |log|), reading the samples whose "
                  f"half vector's cosine to the normal is at most the threshold (the default "
                  f"{text(get(d, 'summary', 'balance_max_half_cosine'))}):", ""]
        lines += table(["threshold", "mean error"], [[k, pct(v, 2)] for k, v in items(sweep)])
    per_seed = []
    for r in rows_of(d.get("rows")):
        skin = {(s.get("parameter"), s.get("channel")): s for s in r.get("skin") or []}
        rho = [v.get("fitted") for (p, _), v in skin.items() if p == "specular_reflectance"]
        truth = [v.get("truth") for (p, _), v in skin.items() if p == "specular_reflectance"]
        balance = r.get("light_balance") or {}
        errors = r.get("true_light_errors") or {}
        per_seed.append([text(r.get("seed")), text(r.get("lights")), num(mean(rho)) if rho else DASH,
                         num(mean(truth)) if truth else DASH,
                         ", ".join(f"{k} {num(v, 4)}" for k, v in balance.items()) or DASH,
                         ", ".join(f"{k} {num(v, 4)}" for k, v in errors.items()) or DASH])
    lines += table(["seed", "lights", "skin ρs (mean over channels)", "truth", "balance factors",
                    "true calibration errors"], per_seed)
    return lines


def sec_refine_gradient(d):
    cases = list(items(d.get("cases")))
    lines = [f"{text(d.get('what'))}; seed {text(d.get('seed'))}, {text(d.get('image'))}², "
             f"{text(d.get('repeats'))} Monte Carlo seeds per photograph. The loss's minimum along each parameter "
             "alone (a Newton step from the truth):", ""]
    first = cases[0][1].get("variables") if cases else {}
    rows = []
    for key, v in items(first):
        channel = v.get("channel")
        label = f"{text(v.get('region'))} {text(v.get('parameter'))}" + (f" [{channel}]" if channel is not None else "")
        rows.append([label, num(v.get("true_value"), 4)]
                    + [num(get(c, "variables", key, "value_at_minimum"), 4) for _, c in cases])
    lines += table(["parameter", "truth", *[f"`{name}`" for name, _ in cases]], rows)
    lines += ["Photograph over render at the truth, per photograph (mean over channels):", ""]
    photos = list(items(cases[0][1].get("photograph_over_render"))) if cases else []
    lines += table(["case", *[name for name, _ in photos]],
                   [[f"`{name}`", *[num(mean(get(c, "photograph_over_render", p)), 4) for p, _ in photos]]
                    for name, c in cases])
    return lines


def sec_refine_seeds(d):
    role = text(d.get("role"))
    lines = [f"{text(d.get('what'))}.", "",
             f"Seeds {', '.join(text(s.get('seed')) for s in d.get('seeds') or [])} ({role} captures"
             + ("; they chose the defaults" if role == "training" else "; they played no part in choosing the "
                "defaults") + f"), images {text(d.get('image'))}², texture {text(d.get('texture_resolution'))}²; "
             f"the default schedule is the variant `{text(d.get('default_variant'))}`. Mean over the seeds of the "
             "relative errors against the truth:", ""]
    columns = [("skin", "specular_reflectance"), ("skin", "roughness"), ("beard", "specular_reflectance"),
               ("lips", "specular_reflectance"), ("eyebrows", "specular_reflectance"), ("hair", "specular_reflectance"),
               ("eyes", "roughness")]
    rows = []
    for name, v in items(d.get("summary")):
        rows.append([f"`{name}`", *[pct(get(v, "regions", r, p)) for r, p in columns],
                     pct(get(v, "novel_light_relative_rmse"), 2), text(v.get("kept", "–"))])
    lines += table(["variant", *[f"{r} {'ρs' if p == 'specular_reflectance' else 'm'}" for r, p in columns],
                    "novel light RMSE", "kept"], rows)
    gains = []
    for s in d.get("seeds") or []:
        true = s.get("true_light_gains") or {}
        for name, v in items(s.get("variants")):
            if (v.get("light_gains") or {}) and any(abs(g - 1.0) > 0 for g in v["light_gains"].values()):
                gains.append([text(s.get("seed")), f"`{name}`", ", ".join(
                    f"{light} {num(g, 4)} ({num(true.get(light), 4)})" for light, g in v["light_gains"].items())])
    if gains:
        lines += ["Fitted light gains (the calibrated lights' true irradiance error at the face in brackets):", ""]
        lines += table(["seed", "variant", "gains"], gains)
    return lines


def sec_shape_estimation(d):
    lines = ["Mean over each capture's measurements (the truth's vertices that face the camera); `aligned`: after "
             "a rigid alignment; `nn`: against the nearest true vertex.", ""]
    rows = []
    for capture, c in items(d.get("captures")):
        for method, s in items(get(c, "summary")):
            rows.append([f"{capture} ({text(get(c, 'model'))})", method, fixed(get(s, "landmark_px"), 2),
                         fixed(get(s, "normal_deg"), 2), fixed(get(s, "normal_aligned_nn_deg"), 2),
                         fixed(get(s, "vertex_rms_aligned_mm"), 2), fixed(get(s, "seconds"), 2),
                         text(get(s, "converged"))])
    lines += table(["capture (model)", "method", "landmarks (px)", "normals (°)", "normals aligned nn (°)",
                    "vertices aligned (mm)", "seconds", "converged"], rows)
    lines += ["BRDF fit (texture space) on the true and on the fitted shapes: relative errors of each region's "
              "parameters, albedo RMSE.", ""]
    rows = []
    for capture, b in items(d.get("brdf")):
        for shapes, r in items(b):
            for region, e in items(get(r, "regions")):
                rows.append([capture, shapes, region, pct(get(e, "specular_reflectance_rel")),
                             pct(get(e, "roughness_rel")), fixed(get(r, "albedo_rmse"), 4)])
    lines += table(["capture", "shapes", "region", "ρs error", "roughness error", "albedo RMSE"], rows)
    sweep = rows_of(d.get("sweep"))
    if sweep:
        lines += ["Schedule sweep (one measurement):", ""]
        lines += table(["resolution", "schedule factor", "iterations", "seconds", "landmarks (px)", "normals (°)",
                        "vertices aligned (mm)"],
                       [[text(s.get("resolution")), text(s.get("factor")), text(s.get("iterations")),
                         fixed(s.get("seconds"), 2), fixed(s.get("landmark_px"), 2), fixed(s.get("normal_deg"), 2),
                         fixed(s.get("vertex_rms_aligned_mm"), 2)] for s in sweep])
    targets = items(d.get("targets"))
    if targets:
        lines += ["Targets: " + "; ".join(f"{k}: {text(v)}" for k, v in targets) + ".", ""]
    return lines


def sec_truths(d):
    lines = [f"Machine: {text(d.get('machine'))}. Per truth and fitted model the report's validation: relative RMSE "
             "under the held-out lights and the environments (fitted shapes, and the fitted reflectance on the true "
             "shape), skin's BRDF error over the hemisphere, albedo RMSE. `shape floor`: the true reflectance on the "
             "fitted shapes. `noise floor`: the true face against itself rendered with other random numbers (the "
             "renders' Monte Carlo noise; the errors compare images rendered with the same random numbers, where "
             "most of it cancels); a dash where the run predates it.", ""]
    rows = []
    for name, t in items(d.get("truths")):
        floor = get(t, "shape_floor") or {}
        rows.append([name, "shape floor", pct(floor.get("heldout_rmse")), pct(floor.get("environment_rmse")), DASH,
                     DASH, DASH, DASH])
        noise = get(t, "noise_floor") or {}
        rows.append([name, "noise floor", pct(noise.get("heldout_rmse")), pct(noise.get("environment_rmse")), DASH,
                     DASH, DASH, DASH])
        for model, m in items(get(t, "models")):
            v = get(m, "validation") or {}
            rows.append([name, model, pct(v.get("heldout_rmse")), pct(v.get("environment_rmse")),
                         pct(v.get("heldout_rmse_true_shape")), pct(v.get("environment_rmse_true_shape")),
                         pct(get(v, "brdf_rmse", "skin")), fixed(v.get("albedo_rmse"), 4)])
    return lines + table(["truth", "model", "held-out", "environments", "held-out, true shape",
                          "environments, true shape", "skin BRDF", "albedo RMSE"], rows)


def sec_albedo_rounds(d):
    spp = f", {text(get(d, 'spp'))} samples per pixel" if get(d, "spp", default=None) is not None else ""
    lines = [f"Images {text(get(d, 'image'))}{spp}, {text(get(d, 'measurements'))} photographs, texture "
             f"{text(get(d, 'texture'))}², tuning seeds. Coverage of the 95 % intervals per truth, number of "
             "alternations and estimate, pooled over seeds, regions, parameters and channels (intervals in "
             "brackets), and on skin, small regions (lips, eyebrows) and the others; skin's mean relative error "
             "per parameter (RGB parameters as the mean over channels).", ""]
    rows = []
    for model, per_rounds in items(get(d, "summary")):
        for rounds, entry in items(per_rounds):
            error = ", ".join(f"{name} {pct(get(e, 'mean_relative_error'), 1)}"
                              for name, e in items(get(entry, "skin_error")))
            for variant, cov in items(get(entry, "coverage")):
                cells = [f"{pct(get(cov, c, 'coverage'), 0)} ({text(get(cov, c, 'intervals'))})"
                         for c in ("pooled", "skin", "small", "others")]
                rows.append([text(model), text(rounds), text(variant), *cells, error])
    lines += table(["truth and model", "alternations", "estimate", "pooled", "skin", "small", "others",
                    "skin error"], rows)
    rows = []
    for row in rows_of(get(d, "rows")):
        skin = ", ".join(f"{s.get('parameter')}{'' if s.get('channel') is None else '[' + str(s.get('channel')) + ']'}"
                         f" {fixed(s.get('fitted'), 3)} ({fixed(s.get('truth'), 3)})"
                         for s in rows_of(get(row, "skin")))
        rows.append([text(get(row, "model")), text(get(row, "seed")), text(get(row, "albedo_rounds")),
                     pct(get(row, "coverage"), 0), text(get(row, "intervals")), skin])
    return lines + ["Per capture, the default estimate:", ""] + table(
        ["truth and model", "seed", "alternations", "coverage", "intervals", "skin"], rows)


def sec_albedo_rounds_cost(d):
    lines = [f"The region fits' time (`seconds['fit']`, best of {text(get(d, 'repeats'))} interleaved runs) without "
             f"and with the {text(get(d, 'method'))} intervals, medians over captures and models; `intervals`: the "
             "time spent computing them, and its share of the fit without; `against one fit`: with intervals, over "
             "the one region fit without.", ""]
    rows = [[text(get(e, "texture")), text(get(e, "albedo_rounds")), fixed(get(e, "without_median"), 3),
             fixed(get(e, "with_median"), 3), pct(get(e, "overhead_median"), 0), fixed(get(e, "intervals_median"), 3),
             pct(get(e, "intervals_share_median"), 1), fixed(get(e, "against_one_region_fit_median"), 2)]
            for _, e in items(get(d, "summary"))]
    return lines + table(["texture", "alternations", "fit without (s)", "with (s)", "difference", "intervals (s)",
                          "intervals' share", "against one fit"], rows)


def sec_albedo_rounds_exact(d):
    lines = [f"{text(get(d, 'model'))} truth, seed {text(get(d, 'seed'))}, {text(get(d, 'albedo_rounds'))} "
             f"alternations, {text(get(d, 'region'))} ({text(get(d, 'samples'))} samples, {text(get(d, 'tiles'))} "
             "tiles): the standard deviation of each fitted parameter by the one-step replicates of the intervals "
             "against the jackknife that reruns the alternation with each tile left out.", ""]
    rows = [[text(get(e, "parameter")) + ("" if get(e, "channel") is None else f"[{get(e, 'channel')}]"),
             fixed(get(e, "fitted"), 4), fixed(get(e, "truth"), 4), fixed(get(e, "std_one_step"), 5),
             fixed(get(e, "std_exact"), 5)] for e in rows_of(get(d, "entries"))]
    return lines + table(["parameter", "fitted", "truth", "std, one step", "std, refits"], rows)


def sec_refine_shape_default(d):
    k = get(d, "downsample")
    lines = [f"Capture {text(get(d, 'resolution'))}², seed {text(get(d, 'seed'))}"
             + ("" if k is None else f", rendered at 1/{k} of its resolution") + "; refinement "
             f"{'kept' if get(d, 'accepted') else 'not kept'}: {text(get(d, 'reason'))}; "
             f"{fixed(get(d, 'seconds', 'refine'), 0)} s to refine. World-frame errors of the faces against the "
             "truth (mm, front of the face):", ""]
    rows = []
    for label, key in (("model fit", "model_fit"), ("returned by the refinement", "refined"),
                       ("displaced, kept or not", "displaced")):
        summary_ = get(d, "shape_errors", key, "summary") or {}
        if not summary_:
            continue
        rows.append([label, fixed(summary_.get("mean_world_mm"), 2), fixed(summary_.get("max_world_mm"), 2),
                     fixed(summary_.get("mean_aligned_mm"), 2), fixed(summary_.get("max_abs_depth_mm"), 2),
                     fixed(summary_.get("mean_normal_deg"), 2)])
    return lines + table(["faces", "world, mean", "world, max", "after rigid alignment, mean",
                          "largest depth offset", "normals, mean (°)"], rows)


def sec_light_balance_measure(d):
    seeds = ", ".join(text(r.get("seed")) for r in rows_of(d.get("seeds")))
    lines = [f"Seeds {seeds or DASH} "
             f"({text(d.get('role'))}); `mifaces measure` on the default capture with the lights as given and balanced "
             "(`--balance-lights`). Means over the seeds; in brackets, on how many seeds the balance lowered the "
             "figure.", ""]
    given, balanced = get(d, "summary", "given") or {}, get(d, "summary", "balanced") or {}
    lower = get(d, "summary", "balanced_lower_on_seeds") or {}
    rows = []
    for model, g in items(given):
        b, n = balanced.get(model) or {}, lower.get(model) or {}
        rows.append([text(model)] + [f"{pct(g.get(k), 2)} → {pct(b.get(k), 2)} ({text(n.get(k))})"
                                     for k in ("skin_brdf_rmse", "heldout_rmse", "environment_rmse",
                                               "heldout_rmse_true_shape")])
    return lines + table(["model", "skin BRDF error", "held-out lights", "environments",
                          "held-out lights, true shape"], rows)


def sec_floor_depth(d):
    lines = [f"Default capture (512², six photographs), seeds {text(', '.join(map(str, get(d, 'seeds') or [])))}; "
             "the shape floor (the true reflectance on a face, in a novel pose under the held-out lights; the "
             "report validates the first photograph) of each photograph's fitted face, of that face moved along "
             "the camera's axis by its depth offset, of it rigidly aligned onto the truth, and of the true face "
             f"moved by the fitted depth offset. Aim: {pct(get(d, 'floor_target'), 0)}.", ""]
    rows, sums = [], []
    for run in rows_of(get(d, "runs")):
        for name, p in items(get(run, "photographs")):
            rows.append([text(run.get("seed")), text(name), fixed(get(p, "fitted", "depth_mm"), 2),
                         *(pct(get(p, key, "shape_floor"), 1) for key in
                           ("fitted", "depth_removed", "aligned", "truth_at_fitted_depth", "truth_1mm_deeper")),
                         pct(get(p, "noise_floor"), 1)])
        for key, s in items(get(run, "summary")):
            sums.append([text(run.get("seed")), text(key), pct(s.get("mean_shape_floor"), 1),
                         pct(s.get("max_shape_floor"), 1)])
    return (lines + table(["seed", "photograph", "depth offset (mm)", "as fitted", "depth offset removed",
                           "rigidly aligned", "true face at the fitted depth", "true face 1 mm deeper",
                           "noise floor"], rows)
            + ["", "Over the photographs:", ""] + table(["seed", "face", "mean", "largest"], sums))


def sec_shape_depth(d):
    lines = [f"Default capture (512², six photographs), seeds {text(', '.join(map(str, get(d, 'seeds') or [])))}; "
             "the fitted faces against the truth over the front of the face (mm). `size`: the fitted face's size "
             "against the true one's; `after that size`: the error left after the true face is scaled by that "
             "ratio about the camera's centre (a pinhole camera cannot tell a face s times larger and s times "
             f"farther). Aim without alignment: {fixed(get(d, 'world_target_mm'), 1)} mm.", ""]
    rows = []
    for run in rows_of(get(d, "runs")):
        for name, e in items(get(run, "shape_errors")):
            if name == "summary":
                continue
            rows.append([text(run.get("seed")), text(name), fixed(e.get("world_mm"), 2), fixed(e.get("depth_mm"), 2),
                         f"{fixed(e.get('scale_pct'), 2)} %", fixed(e.get("scaled_mm"), 2),
                         fixed(e.get("aligned_mm"), 2)])
    held = get(d, "summary_focal_held") or {}
    notes = ["", f"With the calibrated focal length held (`fit_focal=False`): world error up to "
             f"{fixed(held.get('max_world_mm'), 2)} mm, size off by up to {fixed(held.get('max_abs_scale_pct'), 2)} %.",
             ""]
    variants = (("default fit (one identity)", ()), ("focal length held", ("focal_held",)),
                ("true identity held, each photograph on its own", ("true_identity",)),
                ("true identity and expression held (the pose fit's floor)", ("true_face",)),
                ("default fit, near-silhouette samples left out", ("with_facing_cut", "default")),
                ("true face held, near-silhouette samples left out", ("with_facing_cut", "true_face")))
    what = []
    for label, path in variants:
        for run in rows_of(get(d, "runs")):
            r = run
            for key in path:
                r = get(r, key) or {}
            e = get(r, "shape_errors") or {}
            if not e:
                continue
            depths = [v.get("depth_mm") for k, v in items(e) if k != "summary"]
            summary = e.get("summary") or {}
            what.append([text(label), text(run.get("seed")), fixed(summary.get("mean_world_mm"), 2),
                         fixed(summary.get("max_world_mm"), 2),
                         fixed(sum(depths) / len(depths) if depths else None, 2),
                         fixed(summary.get("mean_scaled_mm"), 2),
                         fixed(summary.get("mean_aligned_mm"), 2)])
    if len(what) > len(rows_of(get(d, "runs"))):
        notes += [f"What limits the depth (the cut leaves out samples the camera sees at a cosine below "
                  f"{fixed(get(d, 'facing_cut'), 2)}; mm, means over the photographs):", ""]
        notes += table(["fit", "seed", "world mean", "world max", "mean depth offset", "after that size",
                              "after rigid alignment"],
                       what) + [""]
    return lines + table(["seed", "photograph", "world", "depth", "size", "after that size",
                          "after rigid alignment"], rows) + (notes if held else [])


def sec_silhouette_depth(d):
    s = get(d, "summary") or {}
    lines = [f"Default capture (512², six photographs), seeds {text(', '.join(map(str, get(d, 'seeds') or [])))}; "
             "per photograph, the depth offset `dz` along the camera's ray (mm; positive: farther) at which the "
             "face's outline best matches the diffuse-light photograph's foreground (pixels where they disagree, "
             "rows above the middle of the nose), for the fitted face and the true face, beside the fitted face's depth error. "
             "An outline that pinned depth would give the true face 0 and the fitted face minus its depth error.", "",
             f"Means: |true face's dz| {fixed(s.get('mean_abs_true_best_dz_mm'), 2)} mm; fitted face's dz "
             f"{fixed(s.get('mean_fitted_best_dz_mm'), 1)} mm, off its depth error by "
             f"{fixed(s.get('mean_abs_fitted_dz_error_mm'), 1)} mm against a mean |depth error| of "
             f"{fixed(s.get('mean_abs_depth_mm'), 2)} mm; disagreement at dz 0: fitted face "
             f"{fixed(s.get('mean_fitted_disagreement_px'), 0)} px, true face "
             f"{fixed(s.get('mean_true_disagreement_px'), 0)} px. The least disagreement lay at an end of the "
             f"scan (it may lie beyond) for {text(s.get('fitted_at_scan_end'))} of {text(s.get('photographs'))} "
             f"fitted faces and {text(s.get('true_at_scan_end'))} true faces.", ""]
    rows = []
    for run in rows_of(get(d, "runs")):
        for name, r in items(get(run, "photographs")):
            rows.append([text(run.get("seed")), text(name), fixed(r.get("depth_mm"), 2),
                         fixed(r.get("fitted_best_dz_mm"), 1), fixed(r.get("true_best_dz_mm"), 2),
                         fixed(r.get("fitted_disagreement_px"), 0), fixed(r.get("fitted_least_disagreement_px"), 0),
                         fixed(r.get("true_disagreement_px"), 0)])
    return lines + table(["seed", "photograph", "depth error", "outline's dz, fitted face", "outline's dz, true face",
                          "disagreement (px), fitted", "least, fitted", "true face"], rows)


def sec_joint_outline(d):
    names = {"default": "default fit (each pose, then one identity averaged)",
             "from_default_fit_without_outline": "joint, from the default fit: feature points and distances",
             "from_default_fit_with_outline": "joint, from the default fit: with the outline",
             "from_truth_without_outline": "joint, from the truth: feature points and distances",
             "from_truth_with_outline": "joint, from the truth: with the outline",
             "from_truth_exact_points_with_outline": "joint, from the truth: with the outline, exact feature points"}
    lines = [f"Default capture (512², six photographs), seeds {text(', '.join(map(str, get(d, 'seeds') or [])))} "
             f"(settings set on seed {text(get(d, 'tuning_seed'))}): one identity and every photograph's rigid pose "
             "fitted together on the feature points, the metric distances and, with the outline, the head's outline "
             "in the diffuse companions above the middle of the nose. Started from the truth, an unbiased energy "
             "would stay there; a start that ends at a higher energy than the truth's run found a worse minimum "
             "(the truth's runs hold the true expressions, the default fit's runs its own). World-frame error over the front of the face, mm, without alignment.", ""]
    rows = []
    for run in rows_of(get(d, "runs")):
        for key, label in names.items():
            s = get(run, key, "summary") or {}
            if s:
                cost = get(run, key, "cost") or [None]
                rows.append([text(run.get("seed")), label, fixed(s.get("mean_world_mm"), 2),
                             fixed(s.get("max_world_mm"), 2), fixed(s.get("max_abs_depth_mm"), 2),
                             fixed(s.get("max_abs_scale_pct"), 2), fixed(s.get("mean_aligned_mm"), 2),
                             fixed(cost[-1], 1)])
    return lines + table(["seed", "fit", "world mean", "world max", "largest depth offset", "largest size error (%)",
                          "after rigid alignment", "energy at the end"], rows)


def sec_uncertainty_measure(d):
    lines = [f"`{text(get(d, 'command'))}` on the default simulated capture (512², six photographs, 64 spp) per "
             "seed, the Cook–Torrance truth's skin drawn per seed: skin's fitted parameters and their 95 % "
             f"intervals against the truth. Every skin interval held the truth in {text(get(d, 'all_covered'))} of "
             f"{text(get(d, 'captures'))} captures.", ""]
    pooled = get(d, "pooled_coverage") or {}
    if pooled:
        lines += [f"Every region's intervals (skin's and the other regions' same-family truths), pooled: "
                  f"{pct(pooled.get('coverage'), 0)} of {text(pooled.get('intervals'))} hold the truth.", ""]
    rows = []
    for run in rows_of(get(d, "runs")):
        for c in rows_of(get(run, "parameters")):
            name = f"{c.get('parameter')}{'' if c.get('channel') is None else '[' + str(c.get('channel')) + ']'}"
            rows.append([text(run.get("seed")), name, fixed(c.get("truth"), 4), fixed(c.get("fitted"), 4),
                         f"[{fixed(c.get('lo'), 4)}, {fixed(c.get('hi'), 4)}]", text(c.get("covered"))])
    return lines + table(["seed", "skin parameter", "truth", "fitted", "95 % interval", "holds the truth"], rows)


def sec_uncertainty_texel_albedo(d):
    variants = list(get(d, "variants") or {})
    tiles = get(d, "tile_at_128") or {}
    lines = [f"Captures of {'×'.join(map(str, get(d, 'image') or []))} px, {text(get(d, 'measurements'))} "
             f"photographs, {text(get(d, 'spp'))} spp, texture {text(get(d, 'texture'))}², the true geometry; one "
             "capture per seed. Coverage of the jackknife's 95 % intervals (intervals checked in brackets) of the "
             "region fit (one albedo per region) and of the fit with an albedo per texel, over tiles of "
             + ", ".join(f"{text(v)} texels at 128² ({k})" for k, v in items(tiles))
             + ". Out of family: the true value is the same fit's best on the capture rendered without noise at "
             f"{text(get(d, 'reference_spp'))} spp.", ""]

    def cell(e):
        return DASH if not e or e.get("coverage") is None else f"{pct(e.get('coverage'), 0)} ({text(e.get('intervals'))})"

    rows = []
    for truth, models in items(get(d, "coverage")):
        for model, entry in items(models):
            row = [text(truth), text(model), text(get(d, "seeds", truth, default=None))]
            for key in ("pooled", "small", "skin"):
                for v in variants:
                    e = get(entry, v, default={}) or {}
                    row.append(cell(e.get("regions", {}).get("skin") if key == "skin" else e.get(key)))
            rows.append(row)
    header = ["truth", "model", "seeds"] + [f"{key}: {v}" for key in ("pooled", "lips and eyebrows", "skin")
                                              for v in variants]
    checks = get(d, "skin_check", default={}) or {}
    notes = ["", "Cook–Torrance truths with a drawn skin: every skin interval holds the truth in "
             + "; ".join(f"{sum(bool(r.get('all_covered')) for r in rows_of(runs))} of {len(rows_of(runs))} "
                         f"captures ({v})" for v, runs in items(checks)) + ".", ""] if checks else []
    return lines + table(header, rows) + notes


def sec_uncertainty_cost(d):
    options = get(d, "options", default={}) or {}
    lines = [f"The region fits' time (`seconds['fit']`, best of interleaved runs) without and with the "
             f"{text(get(d, 'method'))} intervals, per capture, model and texture"
             + (f" ({', '.join(f'{k}={v}' for k, v in options.items())})" if options else "")
             + f". Median overhead: {pct(get(d, 'overhead_median'), 1)}; by texture: "
             + ", ".join(f"{k}²: {pct(v, 1)}" for k, v in items(get(d, "overhead_median_by_texture"))) + ".", ""]
    rows = [[text(r.get("seed")), text(r.get("texture")), text(r.get("model")), text(r.get("samples")),
             fixed(r.get("without"), 3), fixed(r.get("with"), 3),
             pct(r["with"] / r["without"] - 1 if r.get("without") else None, 1)] for r in rows_of(get(d, "fits"))]
    return lines + table(["seed", "texture", "model", "samples", "without (s)", "with (s)", "overhead"], rows)


def sec_unknown(d):
    if isinstance(d, dict):
        return [f"Layout not known to `validation/results_doc.py`; top-level keys: "
                f"{', '.join(f'`{k}`' for k in d) or DASH}.", ""]
    return [f"Layout not known to `validation/results_doc.py`: a {type(d).__name__}"
            + (f" of {len(d)} entries" if isinstance(d, list) else "") + ".", ""]


# result-file name (exact, or followed by _suffix) -> (title, label where the file says none, section)
LAYOUTS = {
    "albedo_rounds": ("The region fit alternated with the texel albedo", "SIMULATED", sec_albedo_rounds),
    "albedo_rounds_cost": ("The region fit alternated with the texel albedo: cost", "timing (SIMULATED)",
                           sec_albedo_rounds_cost),
    "albedo_rounds_exact": ("The alternated fit's intervals against refitting each replicate", "SIMULATED",
                            sec_albedo_rounds_exact),
    "bench_brdf_fit": ("The BRDF fit against scipy", "SIMULATED (synthetic reflectance samples)", sec_bench_brdf_fit),
    "bench_bsdf": ("BSDF plugins and the BRDF array API: speed", "timing (synthetic scene)", sec_bench_bsdf),
    "bench_face_render": ("The face photograph: plugin against built-in BSDFs", "timing (SIMULATED face)",
                          sec_bench_face_render),
    "bench_pipeline": ("The main job: time and memory", "SIMULATED (the built-in default capture)",
                       sec_bench_pipeline),
    "bench_shape_kernels": ("Shape fit: kernel launches and execution time", "SIMULATED", sec_bench_shape_kernels),
    "bench_simulate": ("The simulator: time and light calibration", "SIMULATED", sec_bench_simulate),
    "brdf_energy": ("Energy of the BRDF models", "analytic (Monte Carlo over the hemisphere)", sec_brdf_energy),
    "brdf_fit_stiff": ("Stiff and extreme BRDF fits", "SIMULATED (synthetic samples)", sec_brdf_fit_stiff),
    "brdf_recovery": ("BRDF recovery", "SIMULATED", sec_brdf_recovery),
    "export": ("Export: glTF's material against each fitted BRDF", "SIMULATED", sec_export),
    "model_span": ("The built-in model's span", "model samples (Surrey Face Model faces)", sec_model_span),
    "mutations": ("Mutations of the BRDF formulas", "no data: a check of the test suite", sec_mutations),
    "normals_faces": ("Per-texel normals on faces", "SIMULATED", sec_normals_faces),
    "pareto": ("Error against run time of the whole pipeline", "SIMULATED", sec_pareto),
    "real_diligent": ("Normals with the fitted BRDF: the DiLiGenT ball", "real photographs", sec_real_diligent),
    "real_yaleb": ("Held-out relighting on the Yale face database", "real photographs", sec_real_yaleb),
    "refine": ("Refinement by differentiable rendering", "SIMULATED", sec_refine),
    "light_calibration_bias": ("The texture-space fit with calibrated and true lights", "SIMULATED",
                               sec_light_calibration_bias),
    "light_balance_measure": ("The main job with the given lights balanced", "SIMULATED", sec_light_balance_measure),
    "refine_gradient": ("The refinement loss's gradient at the truth", "SIMULATED", sec_refine_gradient),
    "refine_seeds": ("The refinement's schedule on training and test captures", "SIMULATED", sec_refine_seeds),
    "refine_shape_default": ("Shape refinement on the default capture", "SIMULATED", sec_refine_shape_default),
    "shape_depth": ("Where the fitted faces lie in depth", "SIMULATED", sec_shape_depth),
    "floor_depth": ("How much of the shape floor is each photograph's depth", "SIMULATED", sec_floor_depth),
    "silhouette_depth": ("Whether the head's outline could pin each photograph's depth", "SIMULATED",
                         sec_silhouette_depth),
    "joint_outline": ("One identity over all photographs, with the head's outline", "SIMULATED", sec_joint_outline),
    "shape_depth_tuning": ("Where the fitted faces lie in depth: the seeds the image term's cut was chosen on",
                           "SIMULATED", sec_shape_depth),
    "unknown_lights": ("Lights nobody measured: the Yale face database with its lights hidden", "real photographs",
                       sec_unknown_lights),
    "environment_lights": ("Environment maps nobody measured: simulated captures under the studio and the sky",
                           "SIMULATED", sec_environment_lights),
    "environment_lights_tuning": ("Environment maps: the refinement's glossy start, chosen on the tuning seed",
                                  "SIMULATED", sec_environment_lights_tuning),
    "unknown_lights_simulated": ("Lights nobody measured: the simulated capture with its lights hidden", "SIMULATED",
                                 sec_unknown_lights_simulated),
    "shape_estimation": ("Shape estimation", "SIMULATED", sec_shape_estimation),
    "texel_albedo_tuning": ("The glossy fit with an albedo per texel, on the tuning captures", "SIMULATED",
                            sec_albedo_rounds),
    "texel_albedo_tuning_spp64": ("The glossy fit with an albedo per texel, on the tuning captures at 64 samples "
                                  "per pixel", "SIMULATED", sec_albedo_rounds),
    "texel_albedo_tuning_full": ("The glossy fit with an albedo per texel, on the tuning captures at measure's "
                                 "size (512², 64 spp, texture 512²)", "SIMULATED", sec_albedo_rounds),
    "uncertainty_measure": ("Skin's intervals on the default capture, measured on the true shapes", "SIMULATED",
                            sec_uncertainty_measure),
    "truths": ("`mifaces measure` on truths the fit cannot copy", "SIMULATED", sec_truths),
    "uncertainty_texel_albedo": ("Coverage of the intervals: the region fit against the fit with an albedo per "
                                 "texel", "SIMULATED", sec_uncertainty_texel_albedo),
    "uncertainty_cost": ("The intervals' cost", "timing (SIMULATED)", sec_uncertainty_cost),
}


def layout_for(stem: str):
    best = None
    for name in LAYOUTS:
        if stem == name or stem.startswith(name + "_"):
            if best is None or len(name) > len(best):
                best = name
    return best


#: The list of result files made before a change of the setup they depend on (the face model, say) and
#: not rerun since, with why: each gets a warning at the top of its section.
STALE = "stale.json"


def anchor(title: str) -> str:
    """GitHub's heading anchor."""
    slug = re.sub(r"[^\w\- ]", "", title.strip().lower())
    return slug.replace(" ", "-")


def render(results: Path, out: Path) -> str:
    scripts_dir = results.parent
    docstrings = read_docstrings(scripts_dir)
    try:
        shown = os.path.relpath(results, out.parent)
    except ValueError:
        shown = str(results)
    shown = Path(shown).as_posix()
    try:
        results_name = results.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        results_name = results.name
    lines = ["# Results", "",
             f"<!-- Generated by `python validation/results_doc.py` from `{results_name}/*.json`. "
             "Do not edit by hand: edit the script or re-run the validation, then regenerate. -->", "",
             f"*Generated by `validation/results_doc.py` from the committed JSON files in `{results_name}/`; "
             "every number below is read from them. `python validation/results_doc.py --check` fails when this "
             "file is out of date. What each validation script measures: "
             "[validation/README.md](../validation/README.md).*", "",
             "Labels: **SIMULATED** — rendered captures whose ground truth is known; **real photographs** — public "
             "data sets (Extended Yale B, DiLiGenT); timings are on the machine each file names.", ""]
    sections = []
    stale = {}
    stale_file = results / STALE
    if stale_file.is_file():
        try:
            stale = json.loads(stale_file.read_text(encoding="utf-8")).get("files", {})
        except (OSError, ValueError):
            stale = {}
    for path in sorted(results.glob("*.json")):
        stem = path.stem
        if path.name == STALE:
            continue
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as error:
            sections.append((f"`{stem}.json`", [f"Not readable as JSON: {type(error).__name__}.", ""]))
            continue
        layout = layout_for(stem)
        script = script_for(stem, docstrings)
        doc = docstrings.get(script, "") if script else ""
        if layout:
            title, default_label, section = LAYOUTS[layout]
            title = f"{title}: `{stem}.json`"
        else:
            title, default_label, section = f"`{stem}.json`", "not labelled", sec_unknown
        body = []
        if path.name in stale:
            body += [f"**Not rerun since the setup changed**: {stale[path.name]}", ""]
        what = summary(doc)
        if what:
            body.append(f"**What**: {what}")
            body.append("")
        body.append(f"**Command**: {command_line(data, script, doc)}. **Data**: {data_label(data, default_label)}.")
        body.append("")
        try:
            body += section(data)
        except Exception as error:  # a layout changed beyond what get() absorbs: say so, never crash
            body += [f"(The table could not be built: {type(error).__name__}; the file's layout changed.)", ""]
            body += sec_unknown(data)
        picture = path.with_suffix(".png")
        if picture.exists():
            body += [f"![{stem}]({shown}/{picture.name})", ""]
        elif isinstance(data, dict) and isinstance(data.get("figure"), str):
            figure = data["figure"]
            body += [f"Picture: [`{figure}`](../{figure})", ""]
        sections.append((title, body))
    lines += ["## Contents", ""]
    lines += [f"- [{title}](#{anchor(title)})" for title, _ in sections]
    lines.append("")
    for title, body in sections:
        lines += [f"## {title}", ""] + body
    while lines and lines[-1] == "":
        lines.pop()
    return "\n".join(lines) + "\n"


def write_atomic(path: Path, content: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            f.write(content)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=Path, default=ROOT / "validation" / "results",
                        help="folder of result JSON files (default: validation/results)")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "results.md",
                        help="the Markdown file to write (default: docs/results.md)")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if OUT differs from what would be written")
    args = parser.parse_args(argv)
    content = render(args.results, args.out)
    if args.check:
        try:
            current = args.out.read_text(encoding="utf-8")
        except OSError:
            current = None
        if current != content:
            print(f"{args.out} is out of date: run python validation/results_doc.py", file=sys.stderr)
            return 1
        return 0
    write_atomic(args.out, content)
    return 0


if __name__ == "__main__":
    sys.exit(main())
