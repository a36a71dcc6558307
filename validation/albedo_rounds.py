"""The region fit alternated with the per-texel albedo (``fit_brdf(..., albedo_rounds=k)``) against
the one region fit, on same-family truths (SIMULATED): skin's fitted parameters against the truth,
and how often the 95 % intervals (the default jackknife) hold the true values.

The captures are those of ``validation/uncertainty.py`` (its image size, photographs, samples and
texture), on its tuning seeds 100-102 (not the seeds it reports on), Cook–Torrance (skin drawn per
seed, :func:`uncertainty.skin_truth`) and Phong truths.

    python validation/albedo_rounds.py [--seeds 100 101 102] [--rounds 0 3]

Writes ``validation/results/albedo_rounds.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import uncertainty as U  # noqa: E402  (the captures and checks of validation/uncertainty.py)

from mifaces.files import write_json  # noqa: E402
from mifaces.reflectance import fit_brdf  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def run(model: str, seed: int, rounds, work: Path) -> list[dict]:
    params = U.skin_truth(seed) if model == "cooktorrance" else None
    capture, face, shapes, samples = U._simulate(work / f"{model}_{seed}", seed, brdf=model, brdf_params=params)
    truth = U._truth_of(capture, model)
    rows = []
    for k in rounds:
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            estimate = fit_brdf(capture, model, shapes, face_model=face, resolution=U.TEXTURE, samples=samples,
                                progress=False, albedo_rounds=k)
        seconds = time.perf_counter() - t
        records = U._checks(estimate, truth, U.unc.METHODS[0], {"truth_model": model, "model": model, "seed": seed})
        covered = [r["covered"] for r in records if r["covered"] is not None]
        skin = [{k2: r[k2] for k2 in ("parameter", "channel", "truth", "fitted", "lo", "hi", "covered")}
                for r in records if r["region"] == "skin"]
        rows.append({"model": model, "seed": seed, "albedo_rounds": k, "seconds": seconds,
                     "coverage": float(np.mean(covered)) if covered else None, "intervals": len(covered),
                     "skin": skin})
        print(f"{model} seed {seed} rounds {k}: coverage {rows[-1]['coverage']:.2f}, skin "
              + ", ".join(f"{s['parameter']}[{s['channel']}] {s['fitted']:.3f} ({s['truth']:.3f})" for s in skin),
              flush=True)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102])
    parser.add_argument("--rounds", type=int, nargs="+", default=[0, 3])
    parser.add_argument("--models", nargs="+", default=["cooktorrance", "phong"])
    parser.add_argument("--work", type=Path, default=Path("out/albedo_rounds"))
    args = parser.parse_args(argv)
    rows = [row for model in args.models for seed in args.seeds for row in run(model, seed, args.rounds, args.work)]
    write_json(RESULTS / "albedo_rounds.json", {
        "label": "SIMULATED", "command": "python validation/albedo_rounds.py " + " ".join(argv or sys.argv[1:]),
        "image": list(U.IMAGE), "measurements": U.MEASUREMENTS, "texture": U.TEXTURE,
        "interval_method": U.unc.METHODS[0], "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
