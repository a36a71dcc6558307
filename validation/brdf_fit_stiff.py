"""Stiff and extreme cases of the BRDF fit: does it return finite parameters
and say honestly how it ended?

Cases (synthetic samples, σ from eq. 9, 2 % noise unless said):
  sharp lobes        Cook-Torrance roughness 0.02, Ward α 0.02, Phong and
                     Lafortune exponent 10^4 (on 2·10^5 samples, few of
                     which see the highlight)
  grazing            90 % of samples with cos θl or cos θv below 0.2
  dark region        albedo 0.02, specular 1/10 of skin's
  saturated pixels   reflectance clipped at 0.6 (a saturated camera): fitted
                     as they are, and with the clipped samples dropped as
                     the sampling stage does (``reflectance_samples.unsaturated``)
  few samples        20 samples (below the 10-per-parameter minimum: the
                     region takes its neighbour's fit) and 80 samples
  multi-lobe         Lafortune with 2 and 3 lobes from the conservative start

Run:  python validation/brdf_fit_stiff.py
Writes validation/results/brdf_fit_stiff.json and prints a table.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import mitsuba as mi
import numpy as np

from mifaces import brdf
from mifaces.reflectance.fit.region_fit import RegionSamples, fit_region
from mifaces.reflectance.fit.regions import fit_regions
from mifaces.io.atomic import write_json
from mifaces.reflectance.samples import ReflectanceSamples, unsaturated

OUT = Path(__file__).resolve().parent / "results"
SKIN = [0.52, 0.36, 0.29]


def directions(rng, n, grazing_fraction=0.0):
    v = rng.normal(size=(8 * n, 3))
    v[:, 2] = np.abs(v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v = v[v[:, 2] > 0.02]
    low, high = v[v[:, 2] < 0.2], v[v[:, 2] >= 0.2]
    k = int(grazing_fraction * n)
    return np.concatenate([low[:k], high[: n - k]]) if grazing_fraction else high[:n]


def samples(model, truth, n, seed=0, noise=0.02, grazing=0.0, clip=None, drop_clipped=False):
    rng = np.random.default_rng(seed)
    light, view = directions(rng, n, grazing), directions(rng, n, grazing)
    p = {k: (mi.Color3f(*v) if isinstance(v, list) else mi.Float(v)) for k, v in truth.items()}
    f = np.array(model.eval(mi.Vector3f(light.T.astype(np.float32)), mi.Vector3f(view.T.astype(np.float32)), p)).T
    r = np.pi * f * (1 + noise * rng.normal(size=f.shape))
    sigma = 1.0 / (light[:, 2] ** 2 * view[:, 2])
    if clip is not None:
        r = np.minimum(r, clip)
        if drop_clipped:
            keep = unsaturated(r, clip)
            return light[keep], view[keep], r[keep], sigma[keep]
    return light, view, r, sigma


CASES = [
    ("sharp: cooktorrance m=0.02", "cooktorrance", {},
     {"diffuse_reflectance": SKIN, "specular_reflectance": [3.0] * 3, "roughness": 0.02, "eta": 1.38}, {}),
    ("sharp: ward alpha=0.02", "ward", {},
     {"diffuse_reflectance": SKIN, "specular_reflectance": [0.1] * 3, "alpha": 0.02}, {}),
    ("sharp: phong n=1e4", "phong", {},
     {"diffuse_reflectance": SKIN, "specular_reflectance": [0.1] * 3, "exponent": 1e4}, {}),
    ("sharp: lafortune n=1e4", "lafortune", {},
     {"diffuse_reflectance": SKIN, "cxy": [-1.0002] * 3, "cz": [1.0002] * 3, "exponent": 1e4}, {}),
    ("grazing: 90% below cos 0.2", "cooktorrance", {},
     {"diffuse_reflectance": SKIN, "specular_reflectance": [2.0] * 3, "roughness": 0.3, "eta": 1.38},
     {"grazing": 0.9}),
    ("dark region", "ward", {},
     {"diffuse_reflectance": [0.02, 0.015, 0.012], "specular_reflectance": [0.008] * 3, "alpha": 0.25}, {}),
    ("saturated at r=0.6, kept", "cooktorrance", {},
     {"diffuse_reflectance": SKIN, "specular_reflectance": [2.0] * 3, "roughness": 0.3, "eta": 1.38},
     {"clip": 0.6}),
    ("saturated at r=0.6, dropped", "cooktorrance", {},
     {"diffuse_reflectance": SKIN, "specular_reflectance": [2.0] * 3, "roughness": 0.3, "eta": 1.38},
     {"clip": 0.6, "drop_clipped": True}),
    ("80 samples", "phong", {},
     {"diffuse_reflectance": SKIN, "specular_reflectance": [0.1] * 3, "exponent": 30.0}, {"n": 80}),
    ("lafortune 2 lobes, poor start", "lafortune", {"lobes": 2},
     {"diffuse_reflectance": SKIN, "cxy": [-0.93] * 3, "cz": [0.93] * 3, "exponent": 25.0,
      "cxy_2": [0.3] * 3, "cz_2": [0.5] * 3, "exponent_2": 2.0}, {}),
    ("lafortune 3 lobes, poor start", "lafortune", {"lobes": 3},
     {"diffuse_reflectance": SKIN, "cxy": [-0.93] * 3, "cz": [0.93] * 3, "exponent": 25.0,
      "cxy_2": [0.3] * 3, "cz_2": [0.5] * 3, "exponent_2": 2.0,
      "cxy_3": [-0.6] * 3, "cz_3": [0.2] * 3, "exponent_3": 4.0}, {}),
]


def max_relative_error(params, truth):
    return max(float(np.max(np.abs(np.array(params[k]) - np.array(v)) / np.maximum(np.abs(np.array(v)), 1e-6)))
               for k, v in truth.items())


def main():
    rows = []
    for label, name, options, truth, extra in CASES:
        model = brdf.model(name, **options)
        n = extra.pop("n", 200_000)
        light, view, r, sigma = samples(model, truth, n, **extra)
        fit = fit_region(model, RegionSamples(light, view, r, sigma))
        finite = all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in fit.params.values())
        rows.append({"case": label, "model": name, "samples": len(sigma), "status": fit.status,
                     "reason": fit.reason, "finite": finite, "max_relative_error": max_relative_error(fit.params,
                                                                                                      truth),
                     "seconds": fit.seconds, "iterations": fit.iterations, "params": fit.params})
        print(f"{label:<32} {fit.status:<15} finite={finite!s:<5} max rel. error {rows[-1]['max_relative_error']:9.2e}"
              f"  {fit.seconds:6.2f} s  ({fit.reason})", flush=True)
    # a region of 20 samples beside a well-sampled one: the neighbour's fit, with a warning
    model = brdf.model("cooktorrance")
    truth = CASES[4][3]
    light, view, r, sigma = samples(model, truth, 20_020)
    region = np.zeros(len(sigma), int)
    region[:20] = 1
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        labelled = ReflectanceSamples(light, view, r, sigma, np.zeros(len(sigma), np.int32),
                                      np.zeros(len(sigma), np.int16), 1, label=region)
        fits = fit_regions(model, labelled, {0: "skin", 1: "lips"}, neighbours={"lips": ["skin"]})
    lips = fits["lips"]
    rows.append({"case": "20 samples (lips beside skin)", "model": "cooktorrance", "samples": 20,
                 "status": lips.status, "reason": lips.reason, "finite": True, "warning": str(caught[0].message)
                 if caught else None, "params": lips.params})
    print(f"{'20 samples (lips beside skin)':<32} {lips.status:<15} warning: {caught[0].message if caught else None}")
    write_json(OUT / "brdf_fit_stiff.json", rows)
    print(f"wrote {OUT / 'brdf_fit_stiff.json'}")


if __name__ == "__main__":
    main()
