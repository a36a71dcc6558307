"""Writes ``docs/results.md`` from the committed results in ``validation/results/*.json``.

Every number in ``docs/results.md`` is read from a JSON here; nothing is typed by
hand. One section per result file, in file-name order: what was measured (the
first paragraph of the script's docstring), the command (the JSON's
``command`` field where it holds a ``python validation/...`` command, else the
``Run:``/usage line of the script's docstring), whether the data are SIMULATED
or real, a table of the key numbers, and the picture
``validation/results/<name>.png`` where one exists. A file of a layout this
script does not know gets one line listing its top-level keys; a key missing
from a known layout shows as "—". The tables are drawn by one function per layout in
``results_tables_pipeline.py``, ``results_tables_fits.py`` and ``results_tables_design.py``, with the
number formats of ``results_format.py``; this file maps result files to them and writes the page.

Run:  python validation/results_doc.py [--results DIR] [--out FILE] [--check]

**Tables in the hand-written pages.** A page beside FILE (``docs/*.md``) may hold a result's table
between ``<!-- generated: NAME.json -->`` and ``<!-- end generated -->``: the same table as NAME's
section of FILE, rewritten with it (``embed``), so a page quotes a table without copying it by hand.

``--check`` writes nothing and exits 1 when FILE or an embedded table differs from what would be
written (for CI and ``tests/test_results_doc.py``), or when a figure of the
hand-written pages beside FILE (``README.md`` above its folder, the other pages
in it) is backed by no result in DIR its section names, is no setting it names,
and is not marked as a citation (``doc_figures.py``, ``tests/test_doc_figures.py``).
Standard library only.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import sys
import tempfile
from pathlib import Path


import doc_figures  # noqa: E402  (the figures of the hand-written docs, checked with --check)
from results_format import DASH, get  # noqa: E402  (the formatting helpers)
from results_tables_design import sec_design_metrics  # noqa: E402  (the redesign issue's measuring stick)
from results_tables_studies import (sec_interreflection_rounds, sec_light_balance_limit,  # noqa: E402
                                    sec_normal_step_tol, sec_real_yaleb_repeat, sec_reflectance_bias,
                                    sec_reflectance_coverage, sec_refine_judge, sec_region_seams)
from results_tables_fits import (  # noqa: E402  (one function per result layout)
    sec_albedo_rounds, sec_albedo_rounds_cost, sec_albedo_rounds_exact, sec_depth_cameras, sec_floor_depth, sec_multi_camera,
    sec_joint_outline, sec_light_balance_measure, sec_light_calibration_bias, sec_refine, sec_refine_gradient,
    sec_refine_seeds, sec_refine_shape_default, sec_shape_depth, sec_shape_estimation, sec_silhouette_depth,
    sec_truths, sec_uncertainty_cost, sec_uncertainty_measure, sec_uncertainty_texel_albedo, sec_unknown,
)
from results_tables_pipeline import (  # noqa: E402  (one function per result layout)
    sec_bench_brdf_fit, sec_bench_bsdf, sec_bench_commits, sec_bench_face_render, sec_bench_pipeline, sec_bench_shape_kernels,
    sec_bench_simulate, sec_brdf_energy, sec_brdf_fit_stiff, sec_brdf_recovery, sec_environment_lights,
    sec_environment_lights_tuning, sec_export, sec_model_span, sec_mutations, sec_normals_faces, sec_pareto,
    sec_real_diligent, sec_real_yaleb, sec_unknown_lights, sec_unknown_lights_simulated,
)

ROOT = Path(__file__).resolve().parent.parent


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


# result-file name (exact, or followed by _suffix) -> (title, label where the file says none, section)
LAYOUTS = {
    "albedo_rounds": ("The region fit alternated with the texel albedo", "SIMULATED", sec_albedo_rounds),
    "albedo_rounds_cost": ("The region fit alternated with the texel albedo: cost", "timing (SIMULATED)",
                           sec_albedo_rounds_cost),
    "albedo_rounds_exact": ("The alternated fit's intervals against refitting each replicate", "SIMULATED",
                            sec_albedo_rounds_exact),
    "bench_brdf_fit": ("The BRDF fit against scipy", "SIMULATED (synthetic reflectance samples)", sec_bench_brdf_fit),
    "bench_bsdf": ("BSDF plugins and the BRDF array API: speed", "timing (synthetic scene)", sec_bench_bsdf),
    "bench_commits": ("The main job at two commits, side by side", "timing (SIMULATED default capture)",
                      sec_bench_commits),
    "bench_commits_normal_step": ("The main job before and after the normal step's tolerance, side by side",
                                  "timing (SIMULATED default capture)", sec_bench_commits),
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
    "mutations": ("Mutations: whether the tests catch the bugs they name", "no data: a check of the test suite", sec_mutations),
    "normals_faces": ("Per-texel normals on faces", "SIMULATED", sec_normals_faces),
    "reflectance_bias": ("Where the uncorrected fit's bias on skin's lobe comes from", "SIMULATED", sec_reflectance_bias),
    "reflectance_coverage": ("Do the default fit's intervals hold the truth? Four models' truths", "SIMULATED",
                             sec_reflectance_coverage),
    "region_seams": ("Region outlines in fitted renders: faces with one BRDF everywhere", "SIMULATED",
                     sec_region_seams),
    "interreflection_rounds": ("How the bounced light is taken out: rounds and render sizes", "SIMULATED",
                               sec_interreflection_rounds),
    "normal_step_tol": ("The per-texel normal step's tolerance: time and figures", "SIMULATED",
                        sec_normal_step_tol),
    "light_balance_limit": ("When the given lights are balanced: failed lamps and a calibration's spread",
                            "real photographs and SIMULATED", sec_light_balance_limit),
    "pareto": ("Error against run time of the whole pipeline", "SIMULATED", sec_pareto),
    "real_diligent": ("Normals with the fitted BRDF: the DiLiGenT ball", "real photographs", sec_real_diligent),
    "real_yaleb": ("Held-out relighting on the Yale face database", "real photographs", sec_real_yaleb),
    "real_yaleb_repeat": ("Held-out relighting on the Yale face database, run twice: run-to-run spread",
                          "real photographs", sec_real_yaleb_repeat),
    "refine": ("Refinement by differentiable rendering", "SIMULATED", sec_refine),
    "refine_judge": ("The shape refinement's judges on development seeds", "SIMULATED", sec_refine_judge),
    "light_calibration_bias": ("The texture-space fit with calibrated and true lights", "SIMULATED",
                               sec_light_calibration_bias),
    "light_balance_measure": ("The main job with the given lights balanced", "SIMULATED", sec_light_balance_measure),
    "refine_gradient": ("The refinement loss's gradient at the truth", "SIMULATED", sec_refine_gradient),
    "refine_seeds": ("The refinement's schedule on training and test captures", "SIMULATED", sec_refine_seeds),
    "refine_shape_default": ("Shape refinement on the default capture", "SIMULATED", sec_refine_shape_default),
    "shape_depth": ("Where the fitted faces lie in depth", "SIMULATED", sec_shape_depth),
    "floor_depth": ("How much of the shape floor is each photograph's depth", "SIMULATED", sec_floor_depth),
    "design_metrics": ("The redesign's measuring stick (issue 49)", "no data: a count over the source",
                       sec_design_metrics),
    "depth_cameras": ("What the clicks pin of a face's depth, with one camera or two", "SIMULATED", sec_depth_cameras),
    "multi_camera": ("The shape fit with one camera and with three calibrated cameras", "SIMULATED",
                     sec_multi_camera),
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


#: Written by ``validation/reproduce.py``: the result files that were never reproduced, whose rerun differed
#: or whose code changed since (with why: each gets a warning at the top of its section), and when each
#: file was last reproduced and at which commit.
STALE, REPRODUCED = "stale.json", "reproduced.json"


def read_files(path: Path) -> dict:
    """The ``files`` entry of one of reproduce.py's records (empty when absent or unreadable)."""
    try:
        return json.loads(path.read_text(encoding="utf-8")).get("files", {})
    except (OSError, ValueError):
        return {}


#: reproduce.py's status of a rerun, in words.
OUTCOMES = {"matches": "it matched the committed file", "rerun": "the committed file is that rerun",
            "differs": "it differed from the committed file", "failed": "it failed"}


def reproduced_line(name: str, stale: dict, reproduced: dict) -> str:
    """When ``name`` was last reproduced, and whether it is stale."""
    last = reproduced.get(name)
    done = "never rerun by `validation/reproduce.py`"
    if last:
        done = (f"rerun by `python validation/reproduce.py {Path(name).stem}` on {last['date']} at commit "
                f"`{(last.get('commit') or '?')[:7]}`: {OUTCOMES.get(last['status'], last['status'])}")
    if name in stale:
        return f"**Stale**: {stale[name]}. **Reproduced**: {done}."
    return f"**Reproduced**: {done}; its code has not changed since."


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
    stale, reproduced = read_files(results / STALE), read_files(results / REPRODUCED)
    names = [p.name for p in sorted(results.glob("*.json")) if p.name not in (STALE, REPRODUCED)]
    current = [n for n in names if n in reproduced and n not in stale]
    lines += [f"**Reproduction** (`validation/reproduce.py`, which reruns a result's command in a copy of the tree "
              f"and compares): {len(current)} of {len(names)} result files were reproduced at their current code; "
              f"{len(stale)} are stale (never reproduced, their rerun differed, or their code changed since). "
              "Each section says which, when and at which commit.", ""]
    sections = []
    for path in sorted(results.glob("*.json")):
        stem = path.stem
        if path.name in (STALE, REPRODUCED):
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
        body = [reproduced_line(path.name, stale, reproduced), ""]
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


#: An embedded table: the opening comment naming its result file, the table, the closing comment.
EMBEDDED = re.compile(r"(?P<open><!-- generated: (?P<name>[\w.-]+)\.json -->\n)(?P<body>.*?)(?P<close><!-- end generated -->)",
                      re.S)


def embedded_table(name: str, results: Path) -> str:
    """The table of result ``name`` (a file stem) as a page embeds it: a line naming the file, then
    the lines its section of results.md has after the command."""
    path = results / f"{name}.json"
    layout = layout_for(name)
    if layout is None or not path.is_file():
        raise ValueError(f"an embedded table names {name}.json, which is no result file of a known layout "
                         f"in {results}")
    body = LAYOUTS[layout][2](json.loads(path.read_text(encoding="utf-8")))
    while body and body[-1] == "":
        body.pop()
    return "\n".join([f"*Generated by `python validation/results_doc.py` from `validation/results/{name}.json`; "
                      "do not edit by hand.*", "", *body]) + "\n"


def embed(text: str, results: Path) -> str:
    """``text`` (a page) with every embedded table rewritten from its result file."""
    return EMBEDDED.sub(lambda m: m["open"] + embedded_table(m["name"], results) + m["close"], text)


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
        failed = current != content
        if failed:
            print(f"{args.out} is out of date: run python validation/results_doc.py", file=sys.stderr)
        for page in doc_figures.pages_beside(args.out):
            text = page.read_text(encoding="utf-8")
            if embed(text, args.results) != text:
                failed = True
                print(f"{page}: an embedded table is out of date: run python validation/results_doc.py",
                      file=sys.stderr)
        unbacked = doc_figures.check(doc_figures.pages_beside(args.out), args.results)
        if unbacked:
            print(f"{len(unbacked)} figure(s) in the hand-written docs backed by no result their section names "
                  f"(validation/doc_figures.py says how to back or mark one):\n{doc_figures.report(unbacked)}",
                  file=sys.stderr)
        return 1 if failed or unbacked else 0
    write_atomic(args.out, content)
    for page in doc_figures.pages_beside(args.out):
        text = page.read_text(encoding="utf-8")
        if (updated := embed(text, args.results)) != text:
            write_atomic(page, updated)
    return 0


if __name__ == "__main__":
    sys.exit(main())
