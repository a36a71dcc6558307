"""The main job as a user meets it: ``mifaces measure`` cold and warm.

Runs ``mifaces measure`` in fresh processes, first **cold** (an empty mifaces
cache, ``MIFACES_CACHE``, and an empty Dr.Jit kernel cache: ``HOME`` points
at an empty folder, so ``~/.drjit`` is new), then **warm** (the same caches,
filled by the cold run: the built-in default capture is then copied from
mifaces' cache, :mod:`mifaces.runtime.disk_cache`, and its ``simulate`` stage
is that copy). Records the wall time of the command, the time of
each stage from its ``report.json``, and the peak resident memory. Writes
``validation/results/bench_pipeline.json`` and ``bench_pipeline.png``.

    python validation/bench_pipeline.py [--warm 2] [--args "--geometry fitted"] [--picture docs/images/measure_report.png]

With ``--no-cold``, one or more warm runs only, with the caller's own caches
(``HOME`` and ``MIFACES_CACHE`` as they are, filled by earlier runs), written
to ``<--name>.json`` (for a check that must not cost a cold run too).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

from mifaces.io.atomic import save_figure, write_json
from mifaces.validation.validator import TRUE_SHAPE

RESULTS = Path(__file__).resolve().parent / "results"
#: Per model, the report's validation figures recorded beside the time.
MODEL_FIGURES = ("heldout_rmse", "environment_rmse", f"heldout_rmse{TRUE_SHAPE}", f"environment_rmse{TRUE_SHAPE}")
MIFACES = Path(sys.executable).parent / "mifaces"


def run(out: Path, home: Path, cache: Path, extra: list[str]) -> dict:
    """One ``mifaces measure`` in a fresh process; its wall time, stages and peak memory."""
    env = {**os.environ, "HOME": str(home), "MIFACES_CACHE": str(cache), "PYTHONUNBUFFERED": "1"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    done = subprocess.run([str(MIFACES), "measure", "--out", str(out), *extra], env=env, capture_output=True,
                          text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"mifaces measure failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    report = json.loads((out / "report.json").read_text())
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    skin = report["models"].get("cooktorrance", {}).get("ground_truth", {}) or {}
    return {"wall_s": round(wall, 1), "stages_s": {k: round(v, 1) for k, v in report["seconds"].items()},
            "peak_rss_mib": round(max(peak, before) / 1024, 1),
            "skin_cooktorrance_error": (skin.get("regions") or {}).get("skin"),
            # the report's figures per model: skin's BRDF error and relighting on the fitted faces (and with
            # the fitted reflectance on the true shapes), and the ranking by held-out lights
            "models": {name: {key: (entry.get("validation") or {}).get(key) for key in MODEL_FIGURES}
                       | {"skin_brdf_rmse": ((entry.get("validation") or {}).get("brdf_rmse") or {}).get("skin")}
                       for name, entry in report["models"].items()},
            "ranking": (report.get("ranking") or {}).get("heldout_rmse"),
            "face_model": report.get("face_model"), "shape_errors": report.get("shape_errors"),
            # the true reflectance on the fitted shapes, and the truth against itself with other random numbers
            "shape_floor": (report.get("validation") or {}).get("shape_floor"),
            "noise_floor": (report.get("validation") or {}).get("noise_floor"),
            "shapes": report.get("shapes"),
            # with --refine-shape: whether the refined faces were kept, and how far they lie from the truth
            **({"shape_refinement": {k: report["shape_refinement"].get(k)
                                     for k in ("accepted", "reason", "loss_before", "loss_after", "displacement_mm")},
                "shape_errors_refined": report.get("shape_errors_refined")} if "shape_refinement" in report else {})}


def figure(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = list(results)
    stages = [s for s in results[runs[0]]["stages_s"] if s != "total"]
    fig, ax = plt.subplots(figsize=(8, 2.4 + 0.6 * len(runs)))
    for i, name in enumerate(runs):
        left = 0.0
        for j, stage in enumerate(stages):
            width = results[name]["stages_s"].get(stage, 0.0)
            ax.barh(i, width, left=left, color=f"C{j}", label=stage if i == 0 else None)
            left += width
        ax.text(results[name]["wall_s"], i, f" {results[name]['wall_s']:.0f} s", va="center", fontsize=8)
    ax.set_yticks(range(len(runs)), runs)
    ax.set_xlabel("seconds (stage times from report.json; the label is the command's wall time)")
    ax.legend(fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.35))  # below: clear of the bars
    ax.set_title("mifaces measure on the built-in default (simulated capture)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--warm", type=int, default=1, help="warm runs after the cold one")
    parser.add_argument("--args", default="", help="extra arguments of mifaces measure")
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--no-cold", dest="cold", action="store_false",
                        help="warm runs only, with the caller's caches as they are")
    parser.add_argument("--name", default="bench_pipeline", help="stem of the result files")
    parser.add_argument("--picture", type=Path, default=None,
                        help="copy the last run's report.png here (the README's picture)")
    args = parser.parse_args(argv)
    extra = shlex.split(args.args)
    results = {}
    with tempfile.TemporaryDirectory(prefix="mifaces-bench-") as tmp:
        tmp = Path(tmp)
        home, cache = tmp / "home", tmp / "cache"
        home.mkdir()
        if not args.cold:
            home = Path(os.environ.get("HOME", Path.home()))
            cache = Path(os.environ.get("MIFACES_CACHE", home / ".cache" / "mifaces"))
        for i in range(0 if args.cold else 1, args.warm + 1):
            name = "cold" if i == 0 else f"warm{'' if args.warm == 1 else i}"
            print(f"{name} run ...", flush=True)
            results[name] = run(tmp / f"out{i}", home, cache, extra)
            print(f"  {results[name]['wall_s']} s: {results[name]['stages_s']}", flush=True)
        if args.picture is not None:
            import shutil

            shutil.copyfile(tmp / f"out{args.warm}" / "report.png", args.picture)
    document = {"command": f"mifaces measure {' '.join(extra)}".strip(),
                "machine": {"cores": os.cpu_count(), "platform": platform.platform(),
                            "python": platform.python_version()},
                "note": ("cold: empty MIFACES_CACHE and empty Dr.Jit kernel cache (a new HOME); warm: both filled "
                         "(the simulated default capture copied from MIFACES_CACHE, not rendered again)"
                         if args.cold else "warm only: the caller's MIFACES_CACHE and Dr.Jit kernel cache, filled"),
                "load_average_1min_at_end": os.getloadavg()[0], "runs": results}
    write_json(args.results / f"{args.name}.json", document)
    figure(results, args.results / f"{args.name}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
