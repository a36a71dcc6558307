"""Run-to-run spread of the Yale figures (real photographs): ``validation/real_yaleb.py``'s default run,
repeated.

The shape fit's float sums are added by several threads in an order that changes from run to run, so two
runs of one commit fit faces that differ in the fifth digit; on a real face the BRDF fits can amplify that
(Phong on yaleB04). Each development subject is imported, measured with the defaults and relit as
``real_yaleb.py`` does it (8 training lights, texture 256², 8 spp), :data:`REPEATS` times, with Phong (the
best model by training error in ``real_yaleb.json``) and Lafortune (its lowest held-out error). Per run:
each model's pooled held-out relative RMSE and per subject; then, per model, the pooled figure's range over
the runs and each subject's largest change. Subjects without a fitted face are left out, as there.

    python validation/real_yaleb_repeat.py [--data ../shared/data/yaleb] [--out DIR]

Machine: 2 CPU cores; about 25 minutes.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

from provenance import write_result  # noqa: E402
from real_yaleb import SHADOW_ANGLE, subject_run, summary  # noqa: E402

from mifaces.pipeline.measure import NoUsableShapeError  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
#: Runs of the whole default.
REPEATS = 2
MODELS = ("phong", "lafortune")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/yaleb")
    parser.add_argument("--out", type=Path, default=Path("out/real_yaleb_repeat"))
    args = parser.parse_args()
    subjects = sorted(p.name for p in args.data.iterdir() if p.is_dir())
    t0 = time.perf_counter()
    runs, failed = [], {}
    for k in range(REPEATS):
        results = []
        for subject in [s for s in subjects if s not in failed]:
            try:
                results.append(subject_run(args.data / subject, args.out / f"run{k}" / subject, 8, MODELS, 8,
                                           SHADOW_ANGLE, 256))
            except NoUsableShapeError as error:  # no face: left out of every run
                failed[subject] = str(error).split("; ")[0][:300]
            print(f"run {k} {subject} ({time.perf_counter() - t0:.0f} s)", flush=True)
        results = [r for r in results if r["subject"] not in failed]
        chosen = summary(results, MODELS)
        overall = chosen["relative_rmse"]
        runs.append({"pooled": {m: overall[m]["all"] for m in (*MODELS, "photometric_stereo")},
                     "best_model": chosen["best_model"], "training_relative_rmse": chosen["training_relative_rmse"],
                     "subjects": {r["subject"]: {m: r["relative_rmse"][m]["all"] for m in MODELS} for r in results}})
        print(f"run {k}: " + ", ".join(f"{m} {v:.4f}" for m, v in runs[-1]["pooled"].items()), flush=True)
    common = sorted(set.intersection(*(set(r["subjects"]) for r in runs)))
    spread = {m: {"pooled_min": min(r["pooled"][m] for r in runs), "pooled_max": max(r["pooled"][m] for r in runs),
                  "largest_subject_change": max(max(r["subjects"][s][m] for r in runs)
                                                - min(r["subjects"][s][m] for r in runs) for s in common),
                  "subject_of_largest_change": max(common, key=lambda s: max(r["subjects"][s][m] for r in runs)
                                                   - min(r["subjects"][s][m] for r in runs))}
              for m in MODELS}
    result = {"label": "real photographs", "subjects": common, "repeats": REPEATS, "models": list(MODELS),
              "train_lights": 8, "texture_resolution": 256, "spp": 8, "runs": runs, "spread": spread,
              "failed_subjects": [{"subject": s, "error": e} for s, e in failed.items()],
              "seconds": round(time.perf_counter() - t0, 1)}
    write_result(RESULTS / "real_yaleb_repeat.json", result, script=__file__, subjects=common, inputs=(args.data,))
    for m, s in spread.items():
        print(f"{m}: pooled {s['pooled_min']:.4f}-{s['pooled_max']:.4f}; largest change on one subject "
              f"{s['largest_subject_change']:.4f} ({s['subject_of_largest_change']})")


if __name__ == "__main__":
    main()
