"""Where the uncorrected fit's bias on skin's lobe comes from, one cause at a time (SIMULATED; issue 48).

Every capture here is the issue's: 10 measurements, 384² photographs, 64 samples per pixel, a
Cook–Torrance truth whose skin is drawn per seed over the plausible range
(:data:`SKIN_RANGES`: ρ_s, roughness; the skin's albedo is the simulator's draw for the seed), fitted
with ``fit_brdf``'s defaults before this study (:data:`UNCORRECTED`: the bounced light left in, the
lights as calibrated; both corrections are the defaults now) on the **true** shape, so that no shape error enters. Development seeds
only (:data:`roles.SIMULATED`): nothing here is a report figure of the fit's accuracy.

**Captures.** Per breakdown seed, one capture as the simulator makes it (``as_captured``: light
bounced between parts of the face, the albedo map's detail, sensor noise, the truth's η the published
one the fit holds, lights from the steel spheres) and one with every effect
off (``ideal``: the path tracer's depth 2, so direct light only; each region's albedo constant, its
mean; no sensor noise). Then each effect is switched on alone in the ideal capture (same face, lights,
poses and random draws):

``bounces``        the path tracer's depth 4 (light bounced once and twice off the face);
``albedo_detail``  the albedo map as drawn (freckles, blotches, tone gradients);
``camera_noise``   photon and read noise (:func:`mifaces.studio.photograph.camera_noise`);
``eta``            the truth's index of refraction :data:`ETA_SHIFT` above the published one the
                   Cook–Torrance fit holds (Fresnel with a fixed η);
``light_calibration``  the lights located by the steel spheres, as every fit does, against
                   the simulator's true positions (:func:`mifaces.capture.with_true_lights`; the
                   ideal fit uses the true ones). The white target's value is exact in every
                   simulated capture, so its scale is not a cause here.

Monte Carlo noise of the photographs (64 spp) is in every capture, ideal included: the ideal's
residual bias bounds it.

**Fits.** On ``as_captured``, the uncorrected fit against the same fit with one thing changed:
``no_normals`` (the true shape's normals, an albedo per texel in the glossy fit), ``region_albedo``
(one albedo per region, the paper's), ``uniform_weights`` (every sample weight 1 in place of
eq. 9/10), ``no_erosion`` and ``erosion_2`` (the valid-texel mask eroded by 0 or 2 texels, default 1),
``texture_256`` (texture 256² in place of 512²), ``interreflection`` (the bounced light taken out,
``FitOptions(interreflection=True)``).

**Spread.** The uncorrected fit and :data:`CANDIDATE` (today's default) on ``as_captured`` of every spread seed: the bias's spread from
capture to capture, and how often the 95 % intervals hold the truth.

    python validation/reflectance_bias.py [--breakdown-seeds 100 ...] [--spread-seeds 100 ...] [--work DIR]

Writes ``validation/results/reflectance_bias.json``. Machine: 2 CPU cores; about 7 minutes per
breakdown seed and 1 per spread seed.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import time
import warnings
from dataclasses import replace
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

from provenance import write_result  # noqa: E402
from roles import SIMULATED, refuse_report_data  # noqa: E402

import mifaces.reflectance.resampling as resampling  # noqa: E402
import mifaces.studio.scene as studio_scene  # noqa: E402
from mifaces.brdf.materials import REFRACTIVE_INDEX  # noqa: E402
from mifaces.capture import load_capture, read_ground_truth, with_true_lights  # noqa: E402
from mifaces.model import load_model  # noqa: E402
from mifaces.model.regions import REGIONS  # noqa: E402
from mifaces.reflectance import FitOptions, fit_brdf  # noqa: E402
from mifaces.reflectance.fit import intervals  # noqa: E402
from mifaces.studio import photograph  # noqa: E402
from mifaces.studio.varying import texel_regions  # noqa: E402

#: The simulator's module (``mifaces.studio.simulate`` the attribute is its function).
simulate_module = importlib.import_module("mifaces.studio.simulate")
SimulationOptions = simulate_module.SimulationOptions

RESULTS = Path(__file__).resolve().parent / "results"
#: The issue's capture: measurements, photograph side (px), samples per pixel.
MEASUREMENTS, SIDE, SPP = 10, 384, 64
#: Plausible skin (uniform draws; a grey lobe).
SKIN_RANGES = {"specular_reflectance": (0.45, 1.3), "roughness": (0.2, 0.5)}
#: The ``eta`` effect's truth: every region's η this far above the published value the fit holds.
ETA_SHIFT = 0.06
BREAKDOWN_SEEDS = tuple(range(100, 105))
SPREAD_SEEDS = tuple(range(100, 120))
#: Capture effects, each switched on alone in the ideal capture (``light_calibration`` is the fit's).
EFFECTS = ("bounces", "albedo_detail", "camera_noise", "eta", "light_calibration")
#: The effects of a capture as the simulator makes it: its truth has the published η the fit holds, so
#: ``eta`` is not among them (the lights come from the steel spheres in every fit but the ideal's).
AS_SIMULATED = {"bounces", "albedo_detail", "camera_noise"}
#: The reference fit of every run (``default`` in the JSON): ``fit_brdf``'s defaults as they were before
#: this study, without the two corrections it led to (both now on by default). Every variant below
#: changes it, so the breakdown measures each cause against the same uncorrected fit.
UNCORRECTED = {"interreflection": False, "balance_lights": False}
#: Fit variants on ``as_captured``: FitOptions fields, or a patch of the sampling (:func:`_patched_fit`).
FIT_VARIANTS = {"no_normals": {"normals": False}, "region_albedo": {"normals": False, "texel_albedo": False},
                "uniform_weights": {}, "no_erosion": {}, "erosion_2": {}, "texture_256": {"resolution": 256},
                "interreflection": {"interreflection": True}, "balance_lights": {"balance_lights": True},
                "interreflection_balance": {"interreflection": True, "balance_lights": True}}
#: The fit variant proposed for the default (now ``fit_brdf``'s defaults), fitted on every spread capture
#: beside the uncorrected fit.
CANDIDATE = "interreflection_balance"
#: Regions whose fits are recorded (lips only where they have this many samples: the issue's rule).
REGIONS_RECORDED, LIPS_MIN_SAMPLES = ("skin", "lips"), 5000


def skin_truth(seed: int) -> dict:
    """The truth's skin of ``seed``, drawn from :data:`SKIN_RANGES`."""
    rng = np.random.default_rng([48, seed])
    rho = float(rng.uniform(*SKIN_RANGES["specular_reflectance"]))
    m = float(rng.uniform(*SKIN_RANGES["roughness"]))
    return {"specular_reflectance": [round(rho, 4)] * 3, "roughness": round(m, 4)}


def _noise_free(values, rng, **_):
    """:func:`~mifaces.studio.photograph.camera_noise` without the noise (the same random draws)."""
    rng.standard_normal(np.shape(values))
    return np.clip(np.asarray(values, np.float64), 0.0, 1.0).astype(np.float32)


def _flat_subject(make_subject):
    """``make_subject`` whose albedo map holds each region's mean albedo (same random draws)."""
    def flat(face_model, rng, size, *args, **kwargs):
        subject = make_subject(face_model, rng, size, *args, **kwargs)
        labels = texel_regions(face_model, subject.albedo.shape[0])
        albedo = subject.albedo.copy()
        for label in np.unique(labels):
            albedo[labels == label] = albedo[labels == label].mean(axis=0)
        return replace(subject, albedo=albedo)
    return flat


@contextlib.contextmanager
def _capture_effects(on: set):
    """The simulator with the capture effects not in ``on`` switched off."""
    saved = studio_scene.INTEGRATOR, photograph.camera_noise, simulate_module.make_subject
    try:
        if "bounces" not in on:
            studio_scene.INTEGRATOR = dict(saved[0], max_depth=2)
        if "camera_noise" not in on:
            photograph.camera_noise = _noise_free
        if "albedo_detail" not in on:
            simulate_module.make_subject = _flat_subject(saved[2])
        yield
    finally:
        studio_scene.INTEGRATOR, photograph.camera_noise, simulate_module.make_subject = saved


def simulate_capture(folder: Path, seed: int, on: set) -> Path:
    """The seed's capture with the effects ``on`` (:data:`AS_SIMULATED` for ``as_captured``)."""
    regions = {"skin": skin_truth(seed)}
    if "eta" in on:
        regions = {region: dict(regions.get(region, {}), eta=round(eta + ETA_SHIFT, 4))
                   for region, eta in REFRACTIVE_INDEX.items()}
    with _capture_effects(on):
        simulate_module.simulate(folder, SimulationOptions(brdf_params={"model": "cooktorrance", "regions": regions},
                                                           measurements=MEASUREMENTS, resolution=(SIDE, SIDE), spp=SPP,
                                                           seed=seed), progress=False, force=True)
    return folder


@contextlib.contextmanager
def _sampling(variant: str):
    """The sampling as ``variant`` changes it (uniform weights, another erosion), else as it is."""
    saved = resampling.confidence_with_distance, resampling.valid_samples
    try:
        if variant == "uniform_weights":
            resampling.confidence_with_distance = lambda light_z, *_: np.ones(np.shape(light_z))
        elif variant in ("no_erosion", "erosion_2"):
            erosion = {"no_erosion": 0, "erosion_2": 2}[variant]

            def valid_samples(light_z, view_z, lit, visible, _erosion=None, *args, **kwargs):
                kwargs.pop("erosion", None)
                return saved[1](light_z, view_z, lit, visible, erosion, *args, **kwargs)
            resampling.valid_samples = valid_samples
        yield
    finally:
        resampling.confidence_with_distance, resampling.valid_samples = saved


def fit(folder: Path, variant: str = "default", true_lights: bool = False) -> dict:
    """The uncorrected fit (or ``variant`` of it) of the capture in ``folder`` on its true shape: per recorded
    region, each parameter's relative error and whether its 95 % interval holds the truth."""
    capture = load_capture(folder)
    if true_lights:
        capture = with_true_lights(capture)
    truth = read_ground_truth(folder).brdf["regions"]
    t0 = time.perf_counter()
    with _sampling(variant), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimate = fit_brdf(capture, "cooktorrance", "ground-truth", options=FitOptions(**{**UNCORRECTED, **FIT_VARIANTS.get(variant, {})}),
                            progress=False)
    out = {"seconds": round(time.perf_counter() - t0, 2)}
    for region in REGIONS_RECORDED:
        fitted = estimate.fits.get(region)
        if fitted is None or (region != "skin" and fitted.samples < LIPS_MIN_SAMPLES):
            continue
        out[region] = _errors(fitted, truth[region])
    return out


def _errors(fitted, truth: dict) -> dict:
    record = {"samples": int(fitted.samples), "status": fitted.status}
    for name in ("specular_reflectance", "roughness"):
        true = np.broadcast_to(np.asarray(truth[name], float), np.shape(fitted.params[name]))
        value = np.asarray(fitted.params[name], float)
        entry = fitted.uncertainty.get(name, {})
        record[name] = {"fitted": np.round(value, 5).tolist(), "truth": true.tolist(),
                        "error": np.round(value / true - 1, 5).tolist()}
        if "interval95" in entry and entry.get("status", intervals.ESTIMATED) == intervals.ESTIMATED:
            lo, hi = (np.asarray(b, float) for b in entry["interval95"])
            record[name]["interval95"] = [np.round(lo, 5).tolist(), np.round(hi, 5).tolist()]
            record[name]["covered"] = np.atleast_1d((lo <= true) & (true <= hi)).tolist()
    return record


def breakdown(seed: int, work: Path) -> dict:
    """Every capture and fit of the breakdown on ``seed``."""
    runs = {}
    as_captured = simulate_capture(work / f"s{seed}_as_captured", seed, AS_SIMULATED)
    runs["as_captured"] = fit(as_captured)
    for variant in FIT_VARIANTS:
        runs[f"fit:{variant}"] = fit(as_captured, variant)
    ideal = simulate_capture(work / f"s{seed}_ideal", seed, set())
    runs["ideal"] = fit(ideal, true_lights=True)
    runs["effect:light_calibration"] = fit(ideal)
    for effect in EFFECTS:
        if effect != "light_calibration":
            runs[f"effect:{effect}"] = fit(simulate_capture(work / f"s{seed}_{effect}", seed, {effect}),
                                           true_lights=True)
    return {"seed": seed, "truth": skin_truth(seed), "runs": runs}


def _rho(run: dict, region: str = "skin"):
    return None if region not in run else float(np.mean(run[region]["specular_reflectance"]["error"]))


def summary(breakdowns: list, spread: list) -> dict:
    """Per run kind: skin's mean ρ_s error (channel mean) and roughness error over seeds, mean and sd;
    and its difference from the reference (``ideal`` for the effects, ``as_captured`` for the fits)."""
    kinds = list(breakdowns[0]["runs"]) if breakdowns else []
    table = {}
    for kind in kinds:
        ref = "ideal" if kind.startswith("effect:") else "as_captured"
        rho = [_rho(b["runs"][kind]) for b in breakdowns]
        m = [b["runs"][kind]["skin"]["roughness"]["error"][0] if np.ndim(b["runs"][kind]["skin"]["roughness"]["error"])
             else b["runs"][kind]["skin"]["roughness"]["error"] for b in breakdowns]
        shift = [r - _rho(b["runs"][ref]) for r, b in zip(rho, breakdowns)]
        table[kind] = {"rho_s_error_mean": float(np.mean(rho)), "rho_s_error_sd": float(np.std(rho, ddof=1)) if len(rho) > 1 else None,
                       "roughness_error_mean": float(np.mean(m)),
                       "rho_s_shift_mean": float(np.mean(shift)) if kind not in ("ideal", "as_captured") else None,
                       "rho_s_shift_sd": (float(np.std(shift, ddof=1)) if len(shift) > 1 and kind not in
                                          ("ideal", "as_captured") else None),
                       "seconds_mean": float(np.mean([b["runs"][kind]["seconds"] for b in breakdowns]))}
    result = {"breakdown": table}
    if spread:
        result["spread"] = _spread([s["run"] for s in spread])
        candidate = [s["candidate"] for s in spread if "candidate" in s]
        if candidate:
            result["spread_candidate"] = {"fit": CANDIDATE, **_spread(candidate)}
    return result


def _spread(runs: list) -> dict:
    """Skin's ρ_s error over ``runs`` (one per capture): mean, sd, range, how many within 3 %, and
    the share of the 95 % intervals that hold the truth."""
    rho = np.array([np.mean(run["skin"]["specular_reflectance"]["error"]) for run in runs])
    m = np.array([np.ravel(run["skin"]["roughness"]["error"])[0] for run in runs])
    covered = {name: [c for run in runs for c in run["skin"][name].get("covered", [])]
               for name in ("specular_reflectance", "roughness")}
    return {"captures": len(runs), "rho_s_error_mean": float(rho.mean()),
            "rho_s_error_sd": float(rho.std(ddof=1)) if len(rho) > 1 else None,
            "rho_s_error_min": float(rho.min()), "rho_s_error_max": float(rho.max()),
            "rho_s_within_3_percent": int(np.sum(np.abs(rho) <= 0.03)),
            "roughness_error_mean": float(m.mean()), "roughness_within_3_percent": int(np.sum(np.abs(m) <= 0.03)),
            "coverage": {k: (float(np.mean(v)) if v else None) for k, v in covered.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--breakdown-seeds", type=int, nargs="*", default=list(BREAKDOWN_SEEDS))
    parser.add_argument("--spread-seeds", type=int, nargs="*", default=list(SPREAD_SEEDS))
    parser.add_argument("--work", type=Path, default=Path("out/validation_reflectance_bias"))
    args = parser.parse_args()
    refuse_report_data(parser, SIMULATED, args.breakdown_seeds + args.spread_seeds, "the bias breakdown")
    t0 = time.perf_counter()
    breakdowns = []
    for seed in args.breakdown_seeds:
        breakdowns.append(breakdown(seed, args.work))
        print(f"breakdown seed {seed}: {time.perf_counter() - t0:.0f} s", flush=True)
    done = {b["seed"]: (b["runs"]["as_captured"], b["runs"][f"fit:{CANDIDATE}"]) for b in breakdowns}
    spread = []
    for seed in args.spread_seeds:
        if seed not in done:
            folder = simulate_capture(args.work / f"s{seed}_as_captured", seed, AS_SIMULATED)
            done[seed] = fit(folder), fit(folder, CANDIDATE)
        run, candidate = done[seed]
        spread.append({"seed": seed, "truth": skin_truth(seed), "run": run, "candidate": candidate})
        print(f"spread seed {seed}: {time.perf_counter() - t0:.0f} s", flush=True)
    result = {"label": "SIMULATED",
              "capture": {"measurements": MEASUREMENTS, "image": [SIDE, SIDE], "spp": SPP},
              "skin_ranges": SKIN_RANGES, "eta_shift": ETA_SHIFT, "breakdown_seeds": args.breakdown_seeds,
              "spread_seeds": args.spread_seeds, **summary(breakdowns, spread),
              "breakdowns": breakdowns, "spread_runs": spread, "seconds": round(time.perf_counter() - t0, 1)}
    write_result(RESULTS / "reflectance_bias.json", result, script=__file__, seeds=sorted({*args.breakdown_seeds, *args.spread_seeds}))
    print(f"wrote {RESULTS / 'reflectance_bias.json'}")


if __name__ == "__main__":
    main()
