"""Is the texture-space fit's capture-wide skin bias the lights' calibration? (SIMULATED)

The captures of ``validation/uncertainty.py`` (its image size, photographs, samples and texture) on
its tuning seeds, Cook–Torrance truth with skin drawn per seed (:func:`uncertainty.skin_truth`), are
fitted three times with the default ``fit_brdf``: with the lights as the capture's steel spheres
calibrate them; with those lights balanced by the face's one albedo (``balance_lights=True``,
:func:`mifaces.reflectance.light_balance.balance_given_lights`; each light's factor recorded beside
the true one, ``true_light_errors``; ``balance_sweep``: the factors the balance finds reading the
samples at several distances from the highlights, and their mean error, which chose
``GIVEN_MAX_HALF_COSINE``); and with the simulator's true light positions (the reflectance
samples recomputed). Per fit:
skin's parameters against the truth, and how often the 95 % intervals (the default jackknife) hold
the true values, skin and pooled.

    python validation/light_calibration_bias.py [--seeds 100 101 102 103 104]

Writes ``validation/results/light_calibration_bias.json``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

import uncertainty as U  # noqa: E402  (the captures and checks of validation/uncertainty.py)
from roles import SIMULATED, refuse_report_data  # noqa: E402

from mifaces.capture import with_true_lights  # noqa: E402
from mifaces.io.atomic import write_json  # noqa: E402
from mifaces.reflectance import FitOptions, fit_brdf  # noqa: E402
from mifaces.reflectance.light_balance import GIVEN_MAX_HALF_COSINE, log_light_errors  # noqa: E402
from mifaces.reflectance.resampling import capture_samples  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
#: Half-vector cosines above which the balance's sweep leaves samples out (None: all samples).
SWEEP = (None, 0.9, 0.8, 0.7)


def run(seed: int, work: Path) -> list[dict]:
    capture, face, shapes, samples = U._simulate(work / f"cooktorrance_{seed}", seed, brdf="cooktorrance",
                                                 brdf_params=U.skin_truth(seed))
    truth = U._truth_of(capture, "cooktorrance")
    true_capture = with_true_lights(capture)
    true_samples = capture_samples(true_capture, shapes, face, U.TEXTURE, progress=False)
    errors = light_errors(capture, true_capture, shapes)
    sweep = {}
    for threshold in SWEEP:  # how far from the highlights the balance reads the samples
        names = [light.name for light in capture.lights]
        log_s = log_light_errors(capture, samples, names, max_half_cosine=threshold) or {}
        factors = {name: float(np.exp(v)) for name, v in log_s.items()}
        sweep[str(threshold)] = {"factors": factors, "mean_abs_error": float(np.mean(
            [abs(np.log(factors[n]) - np.log(errors[n])) for n in factors]))}
    rows = []
    for lights, cap, smp in (("calibrated", capture, samples), ("balanced", capture, samples),
                             ("true", true_capture, true_samples)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            estimate = fit_brdf(cap, "cooktorrance", shapes, face_model=face, samples=smp, progress=False,
                                options=FitOptions(resolution=U.TEXTURE, balance_lights=lights == "balanced"))
        records = U._checks(estimate, truth, U.unc.METHODS[0], {"seed": seed, "lights": lights})
        covered = [r["covered"] for r in records if r["covered"] is not None]
        skin = [r for r in records if r["region"] == "skin"]
        rows.append({"seed": seed, "lights": lights, "light_balance": estimate.light_balance,
                     "true_light_errors": errors, "balance_sweep": sweep if lights == "balanced" else None,
                     "coverage": float(np.mean(covered)) if covered else None, "intervals": len(covered),
                     "skin_covered": [r["covered"] for r in skin],
                     "skin": [{k: r[k] for k in ("parameter", "channel", "truth", "fitted", "lo", "hi", "covered")}
                              for r in skin]})
        print(f"seed {seed} {lights}: coverage {rows[-1]['coverage']:.2f}, skin "
              + ", ".join(f"{r['parameter'][:4]}[{r['channel']}] {r['fitted']:.3f} ({r['truth']:.3f})"
                          + ("" if r["covered"] else " miss") for r in skin), flush=True)
    return rows


def light_errors(capture, true_capture, shapes) -> dict:
    """Per light, the factor its calibrated irradiance at the faces' centre is off by against the
    true light's (the mean log over the lights 0, as the balance measures it)."""
    centre = np.mean([np.mean(v, axis=0) for v in shapes.values()], axis=0)
    ratio = {}
    for light in capture.lights:
        true = true_capture.light(light.name)
        ratio[light.name] = float(np.sum((true.position - centre) ** 2) / np.sum((light.position - centre) ** 2))
    mean = np.mean(np.log(list(ratio.values())))
    return {name: float(np.exp(np.log(v) - mean)) for name, v in ratio.items()}


def summary(rows: list[dict]) -> dict:
    out = {}
    for lights in ("calibrated", "balanced", "true"):
        mine = [r for r in rows if r["lights"] == lights]
        skin = [s for r in mine for s in r["skin"]]
        out[lights] = {
            "pooled_coverage": float(np.mean([r["coverage"] for r in mine])),
            "skin_coverage": float(np.mean([s["covered"] for s in skin if s["covered"] is not None])),
            "skin_mean_abs_relative_error": {
                p: float(np.mean([abs(s["fitted"] / s["truth"] - 1) for s in skin if s["parameter"] == p]))
                for p in sorted({s["parameter"] for s in skin})}}
    sweeps = [r["balance_sweep"] for r in rows if r.get("balance_sweep")]
    out["balance_sweep"] = {key: float(np.mean([s[key]["mean_abs_error"] for s in sweeps])) for key in sweeps[0]} \
        if sweeps else {}
    out["balance_max_half_cosine"] = GIVEN_MAX_HALF_COSINE
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102, 103, 104])
    parser.add_argument("--out", default=str(RESULTS / "light_calibration_bias.json"))
    parser.add_argument("--role", default="tuning seeds of validation/uncertainty.py")
    args = parser.parse_args()
    if args.role.startswith("tuning"):  # the balance's threshold is chosen on these
        refuse_report_data(parser, SIMULATED, args.seeds, "the lights' balance threshold (--role tuning…)")
    work = Path(tempfile.mkdtemp(prefix="light_bias_"))
    rows = [row for seed in args.seeds for row in run(seed, work)]
    result = {"label": "SIMULATED", "command": "python validation/light_calibration_bias.py "
              + " ".join(sys.argv[1:]), "seeds": args.seeds, "role": args.role,
              "rows": rows, "summary": summary(rows)}
    write_json(Path(args.out), result)
    print(result["summary"])


if __name__ == "__main__":
    main()
