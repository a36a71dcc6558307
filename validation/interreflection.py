"""Where skin's glossy bias comes from, and what taking the bounced light out does. (SIMULATED)

The captures of ``validation/uncertainty.py`` (256² photographs, 6 of them, 16 spp, texture 128²,
the true geometry), Cook-Torrance truth with skin drawn per seed (:func:`uncertainty.skin_truth`).
Per seed, skin's fitted ρ_s (per channel) and m against the truth, and whether the 95 % intervals
(the default jackknife) hold them, for:

* ``default``: ``fit_brdf`` as it is by default;
* ``interreflection``: ``FitOptions(interreflection=True)``
  (:mod:`mifaces.reflectance.interreflection`);
* ``no_bounces``: the default fit of the same capture rendered with direct light only (the path
  tracer's depth 2 instead of 4: same face, lights, poses and noise draws): what a perfect removal
  of the bounced light would give;
* ``true_lights``: the default fit with the simulator's true light positions in place of the
  steel spheres' calibration (reflectance samples recomputed), on the same capture as ``default``;
* ``texel_albedo``, ``interreflection_texel_albedo``, ``no_bounces_texel_albedo``: ``default``,
  ``interreflection`` and ``no_bounces`` with an albedo per texel in the glossy fit
  (``FitOptions(texel_albedo=True)``).

No parameter of the correction was tuned here (its depth, render size, samples and blur were set
before these runs). Seeds 100-104 are the uncertainty's tuning seeds, 0-9 reported.

    python validation/interreflection.py [--seeds 0 1 ...]

Writes ``validation/results/interreflection.json``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

import uncertainty as U  # noqa: E402  (the captures and checks of validation/uncertainty.py)

import mifaces.studio.scene as studio_scene  # noqa: E402
from mifaces.io.atomic import write_json  # noqa: E402
from mifaces.capture import with_true_lights  # noqa: E402
from mifaces.reflectance import capture_samples  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
SEEDS = list(range(100, 105)) + list(range(10))
MODES = ("default", "interreflection", "no_bounces", "true_lights", "texel_albedo", "interreflection_texel_albedo",
         "no_bounces_texel_albedo")
#: The modes whose time is recorded (the same capture and samples).
TIMED = ("default", "interreflection", "texel_albedo", "interreflection_texel_albedo")


def _skin(estimate, truth: dict) -> dict:
    records = [r for r in U._checks(estimate, {"skin": truth}, "jackknife", {}) if r["region"] == "skin"]
    rho = [r for r in records if r["parameter"] == "specular_reflectance"]
    m = next(r for r in records if r["parameter"] == "roughness")
    return {"rho_s_error": [r["fitted"] / r["truth"] - 1 for r in rho], "m_error": m["fitted"] / m["truth"] - 1,
            "covered": {f"{r['parameter']}{'' if r['channel'] is None else r['channel']}": r["covered"]
                        for r in records}}


def _fit(capture, face, shapes, samples, interreflection=False, texel_albedo=False):
    return U._fit(capture, face, shapes, samples, "cooktorrance", interreflection=interreflection,
                  texel_albedo=texel_albedo)


def run(seed: int, work: Path) -> dict:
    params = U.skin_truth(seed)
    truth = params["regions"]["skin"]
    capture, face, shapes, samples = U._simulate(work / f"c{seed}", seed, brdf="cooktorrance", brdf_params=params)
    out, seconds = {}, {}
    for mode in TIMED:
        t = time.perf_counter()
        out[mode] = _skin(_fit(capture, face, shapes, samples, mode.startswith("interreflection"),
                               mode.endswith("texel_albedo")), truth)
        seconds[mode] = time.perf_counter() - t
    true_capture = with_true_lights(capture)
    true_samples = capture_samples(true_capture, shapes, face, U.TEXTURE, progress=False)
    out["true_lights"] = _skin(_fit(true_capture, face, shapes, true_samples), truth)
    default = studio_scene.INTEGRATOR
    studio_scene.INTEGRATOR = {**default, "max_depth": 2}
    try:
        direct = U._simulate(work / f"d{seed}", seed, brdf="cooktorrance", brdf_params=params)
    finally:
        studio_scene.INTEGRATOR = default
    out["no_bounces"] = _skin(_fit(*direct), truth)
    out["no_bounces_texel_albedo"] = _skin(_fit(*direct, texel_albedo=True), truth)
    return {"seed": seed, "tuning": seed in U.TUNING_SEEDS, "truth": truth, "fits": out, "seconds": seconds}


def summary(runs: list) -> dict:
    out = {}
    for split, rows in (("tuning", [r for r in runs if r["tuning"]]), ("reported", [r for r in runs if not r["tuning"]])):
        if not rows:
            continue
        out[split] = {}
        for mode in MODES:
            rho = np.array([np.mean(r["fits"][mode]["rho_s_error"]) for r in rows])
            m = np.array([r["fits"][mode]["m_error"] for r in rows])
            covered = [v for r in rows for v in r["fits"][mode]["covered"].values() if v is not None]
            out[split][mode] = {"seeds": len(rows), "rho_s_error_mean": float(rho.mean()),
                                "rho_s_error_sd": float(rho.std(ddof=1)) if len(rho) > 1 else None,
                                "rho_s_error_mean_abs": float(np.abs(rho).mean()),
                                "m_error_mean": float(m.mean()), "m_error_mean_abs": float(np.abs(m).mean()),
                                "skin_coverage": float(np.mean(covered)) if covered else None,
                                "skin_all_covered": sum(all(v for v in r["fits"][mode]["covered"].values())
                                                        for r in rows)}
        out[split]["seconds_median"] = {mode: float(np.median([r["seconds"][mode] for r in rows]))
                                        for mode in TIMED}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=SEEDS)
    args = parser.parse_args()
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            t = time.perf_counter()
            runs.append(run(seed, Path(tmp)))
            print(f"seed {seed}: {time.perf_counter() - t:.1f} s "
                  + ", ".join(f"{k} rho_s {np.mean(v['rho_s_error']):+.3f} m {v['m_error']:+.3f}"
                              for k, v in runs[-1]["fits"].items()), flush=True)
            write_json(RESULTS / "interreflection.json", {
                "label": "SIMULATED", "command": "python validation/interreflection.py", "image": U.IMAGE,
                "measurements": U.MEASUREMENTS, "spp": U.SPP, "texture": U.TEXTURE, "modes": list(MODES),
                "summary": summary(runs), "runs": runs})


if __name__ == "__main__":
    main()
