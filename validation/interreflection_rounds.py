"""How the bounced light is taken out: the rounds of ``without_bounced_light`` and the size of their
renders, chosen on development captures (SIMULATED; issue 48).

The captures are the Cook–Torrance ones among :mod:`reflectance_coverage`'s tuning seeds
(:data:`SEEDS`: 10 photographs of 384², 64 samples per pixel, the skin's lobe drawn per seed; light
bounced off the face, the albedo's detail, sensor noise and the sphere-located lamps all in). Each is
fitted with ``fit_brdf``'s defaults on its **true** shape, with the bounced light taken out in each of
:data:`VARIANTS` (``mifaces.reflectance.sample_stage.INDIRECT_ROUNDS`` set for the run): one round
at 128 pixels (the earlier default), two such rounds, one round at the photograph's size, and a
128-pixel round followed by one at the photograph's size (the library's). Skin's and the lips'
glossy parameters are recorded per channel, as errors relative to the truth.

    python validation/interreflection_rounds.py [--work DIR] [--reuse]

Machine: 2 CPU cores; about 12 minutes.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

from provenance import write_result  # noqa: E402
from reflectance_bias import skin_truth  # noqa: E402
from reflectance_coverage import simulate_capture  # noqa: E402
from roles import SIMULATED, refuse_report_data  # noqa: E402

from mifaces.capture import load_capture, read_ground_truth  # noqa: E402
from mifaces.reflectance import fit_brdf  # noqa: E402
from mifaces.reflectance import interreflection, sample_stage  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
#: Development seeds: the Cook–Torrance captures of the coverage study's tuning seeds.
SEEDS = (120, 124, 128)
#: name -> the rounds (render width or None for the photograph's, samples per pixel).
VARIANTS = {
    "one_coarse": ((128, 64),),
    "two_coarse": ((128, 64), (128, 64)),
    "one_full": ((None, 16),),
    "coarse_then_full": ((128, 64), (None, 16)),
}
#: The variant the library's ``INDIRECT_ROUNDS`` is.
CHOSEN = "coarse_then_full"
REGIONS = ("skin", "lips")
GLOSSY = ("specular_reflectance", "roughness")


def fit(folder: Path, rounds: tuple) -> dict:
    """Skin's and the lips' glossy errors (fitted / true - 1, per channel) with ``rounds``."""
    capture, truth = load_capture(folder), read_ground_truth(folder).brdf["regions"]
    kept = sample_stage.INDIRECT_ROUNDS
    sample_stage.INDIRECT_ROUNDS = rounds
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            estimate = fit_brdf(capture, "cooktorrance", "ground-truth", progress=False)
    finally:
        sample_stage.INDIRECT_ROUNDS = kept
    out = {"seconds": round(time.perf_counter() - t0, 1)}
    for region in REGIONS:
        fitted = estimate.fits[region]
        out[region] = {"samples": int(fitted.samples)}
        for name in GLOSSY:
            value = np.atleast_1d(np.asarray(fitted.params[name], float))
            out[region][name] = np.round(value / np.asarray(truth[region][name], float) - 1, 5).tolist()
    return out


def summarise(runs: list) -> dict:
    """Per variant, region and parameter: the mean and largest |error| over seeds and channels."""
    table = {}
    for variant in VARIANTS:
        table[variant] = {}
        for region in REGIONS:
            for name in GLOSSY:
                errors = np.concatenate([np.atleast_1d(r["fits"][variant][region][name]) for r in runs
                                         if variant in r.get("fits", {})] or [np.zeros(0)])
                if errors.size:
                    table[variant][f"{region}.{name}"] = {"mean": round(float(errors.mean()), 5),
                                                          "max_abs": round(float(np.abs(errors).max()), 5)}
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, default=Path("out/validation_reflectance_coverage"))
    parser.add_argument("--reuse", action="store_true", help="fit captures already simulated in --work")
    args = parser.parse_args()
    refuse_report_data(parser, SIMULATED, list(SEEDS), "how the bounced light is taken out")
    if interreflection.INDIRECT_ROUNDS != VARIANTS[CHOSEN]:
        parser.error(f"the library's INDIRECT_ROUNDS {interreflection.INDIRECT_ROUNDS} is not variant {CHOSEN!r}")
    t0 = time.perf_counter()
    runs = []
    for seed in SEEDS:
        skin_ct = skin_truth(seed)
        run = {"seed": seed, "skin_cook_torrance": skin_ct, "fits": {}}
        try:
            folder = simulate_capture(args.work / f"s{seed}_cooktorrance", seed, "cooktorrance", skin_ct, args.reuse)
            for variant, rounds in VARIANTS.items():
                run["fits"][variant] = fit(folder, rounds)
                print(f"seed {seed} {variant}: lips ρs {run['fits'][variant]['lips']['specular_reflectance']}, "
                      f"{time.perf_counter() - t0:.0f} s", flush=True)
        except Exception as error:  # one capture's failure is recorded, not fatal to the others
            run["error"] = repr(error)
        runs.append(run)
    result = {"label": "SIMULATED", "seeds": list(SEEDS), "chosen": CHOSEN,
              "variants": {k: [list(r) for r in v] for k, v in VARIANTS.items()},
              "summary": summarise(runs), "runs": runs, "seconds": round(time.perf_counter() - t0, 1)}
    write_result(RESULTS / "interreflection_rounds.json", result, script=__file__, seeds=list(SEEDS))
    print(f"wrote {RESULTS / 'interreflection_rounds.json'}")


if __name__ == "__main__":
    main()
