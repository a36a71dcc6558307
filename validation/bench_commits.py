"""The main job's time at two commits, side by side: is this tree slower than ``--base``?

A refactor must leave ``mifaces measure`` no slower (issue 49), and this machine's times drift from
run to run and day to day by more than such a change could cost: two warm runs of one commit, ten
minutes apart, took 172 s and 189 s (a development look, 2026-12-07). So the two commits are timed
in turns on one machine, in the order ABBA (this tree, the base, the base, this tree; ``--rounds`` such
quadruples), each run a warm ``validation/bench_pipeline.py --no-cold --warm 1`` (the caches of the
runs before it; with ``--warm-up``, one untimed run of each side first) or, with ``--cold``, a cold
``validation/bench_pipeline.py --warm 0`` (empty caches: a new HOME and MIFACES_CACHE per run). The base's library is ``git
archive`` of ``--base`` in a temporary folder, put first on ``PYTHONPATH``; the measuring script and
the BSDF plugins are this tree's (the plugins must be the same at both commits).

    python validation/bench_commits.py --base 74ca5cd [--rounds 1] [--warm-up | --cold] [--args "..."] [--name NAME]

Writes ``validation/results/<NAME>.json`` (default ``bench_commits``; ``bench_commits_cold`` for the cold runs): each run's wall time and stages, each side's mean
and spread, the ratio of the means (this tree over the base) and whether the report's figures (the
held-out relative RMSE per model, the ranking) agree between the sides within ``FIGURE_ATOL``.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

from provenance import write_result

REPO = Path(__file__).resolve().parent.parent
RESULTS = REPO / "validation" / "results"
#: Two runs of one commit differ by up to about 0.3 points of relative RMSE (float32 sums in threads).
FIGURE_ATOL = 0.005


def base_tree(repo: Path, commit: str, into: Path) -> Path:
    """``commit``'s files extracted into ``into`` (refused where its plugins differ from this tree's)."""
    plugins = subprocess.run(["git", "diff", "--quiet", commit, "--", "plugins"], cwd=repo)
    if plugins.returncode != 0:
        raise SystemExit(f"the plugins differ between {commit} and this tree: the base would run this tree's")
    archive = subprocess.run(["git", "archive", "--format=tar", commit], cwd=repo, check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    return into


def timed_run(library: Path | None, name: str, work: Path, extra: str, cold: bool = False) -> dict:
    """One ``bench_pipeline.py`` run, warm (or ``cold``: empty caches), with ``library`` first on the
    path (None: this tree's)."""
    env = dict(os.environ)
    if library is not None:  # the base's package first; else this tree's (the editable install, or the
        # scratch copy that validation/reproduce.py puts on PYTHONPATH)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(library), env.get("PYTHONPATH")]))
    argv = [sys.executable, str(REPO / "validation" / "bench_pipeline.py"),
            *(["--warm", "0"] if cold else ["--no-cold", "--warm", "1"]), "--results", str(work), "--name", name]
    if extra:
        argv += ["--args", extra]
    subprocess.run(argv, cwd=work, env=env, check=True, stdout=subprocess.DEVNULL)
    run = json.loads((work / f"{name}.json").read_text())["runs"]["cold" if cold else "warm"]
    return {"wall_s": run["wall_s"], "stages_s": run["stages_s"], "ranking": run["ranking"],
            "heldout_rmse": {m: v["heldout_rmse"] for m, v in run["models"].items()}}


def summary(runs: list[dict]) -> dict:
    walls = [r["wall_s"] for r in runs]
    return {"wall_s": walls, "mean_s": statistics.fmean(walls),
            "spread_s": (max(walls) - min(walls)) if len(walls) > 1 else 0.0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="the commit to compare with")
    parser.add_argument("--repo", type=Path, default=REPO, help="the git checkout holding --base (default: this one)")
    parser.add_argument("--rounds", type=int, default=1, help="ABBA rounds: each times both sides twice")
    parser.add_argument("--warm-up", action="store_true", help="one untimed run of each side first")
    parser.add_argument("--cold", action="store_true", help="cold runs (empty caches) instead of warm ones")
    parser.add_argument("--args", default="", help="extra arguments of mifaces measure")
    parser.add_argument("--name", default="bench_commits", help="stem of the result file in validation/results/")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    if args.cold and args.warm_up:
        parser.error("--warm-up is for warm runs: a cold run starts from empty caches")
    with tempfile.TemporaryDirectory(prefix="mifaces-bench-commits-") as tmp:
        tmp = Path(tmp)
        base = base_tree(args.repo, args.base, Path(tempfile.mkdtemp(dir=tmp, prefix="base-")))
        sides = {"this": None, "base": base}
        for side, library in sides.items() if args.warm_up else ():
            print(f"warm-up: {side}", flush=True)
            timed_run(library, f"warmup_{side}", tmp, args.args)
        runs: dict[str, list] = {"this": [], "base": []}
        for r in range(args.rounds):
            for i, side in enumerate(("this", "base", "base", "this")):
                run = timed_run(sides[side], f"{side}_{r}_{i}", tmp, args.args, args.cold)
                runs[side].append(run)
                print(f"round {r + 1}: {side} {run['wall_s']:.1f} s", flush=True)
    means = {side: summary(found) for side, found in runs.items()}
    figures_agree = all(
        run["ranking"] == runs["base"][0]["ranking"]
        and all(abs(v - runs["base"][0]["heldout_rmse"][m]) <= FIGURE_ATOL for m, v in run["heldout_rmse"].items())
        for run in runs["this"] + runs["base"])
    ratio = means["this"]["mean_s"] / means["base"]["mean_s"]
    data = {"base": args.base, "order": "ABBA per round: this, base, base, this", "rounds": args.rounds,
            "caches": "cold" if args.cold else "warm", "warm_up": args.warm_up,
            "measure_args": shlex.split(args.args), "runs": runs, "summary": means, "ratio_this_over_base": ratio,
            "figures_agree": figures_agree, "figure_atol": FIGURE_ATOL}
    write_result(RESULTS / f"{args.name}.json", data, argv=argv and [sys.argv[0], *argv])
    print(f"this tree {means['this']['mean_s']:.1f} s, base {args.base} {means['base']['mean_s']:.1f} s: "
          f"ratio {ratio:.3f}; the report's figures {'agree' if figures_agree else 'DIFFER'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
