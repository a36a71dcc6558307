"""The region fit alternated with the per-texel albedo (``FitOptions(albedo_rounds=k)``) against
the one region fit, on same-family truths (SIMULATED): skin's fitted parameters against the truth,
and how often the 95 % intervals hold the true values, per estimate and per region class (skin,
small regions, the others).

The captures are those of ``validation/uncertainty.py`` (its image size, photographs, samples and
texture), on its tuning seeds 100-104 (not the seeds it reports on), Cook–Torrance (skin drawn per
seed, :func:`uncertainty.skin_truth`) and Phong truths by default. The estimates: the jackknife and the
sandwich over texel tiles (with ``albedo_rounds`` > 0 they re-estimate the offsets in every replicate,
:mod:`mifaces.reflectance.fit.uncertainty`), Laplace, ``jackknife_known_offsets``: the jackknife with
the offsets taken as known (what the intervals were before; the same as ``jackknife`` without rounds),
and the jackknife over tiles of 16, 32 and 64 texels (at texture 128).

    python validation/albedo_rounds.py [--seeds 100 101 102 103 104] [--rounds 0 3] [--models cooktorrance phong]
        [--spp 16] [--image 256] [--texture 128] [--out albedo_rounds.json]
    python validation/albedo_rounds.py --rounds 0 texel --out texel_albedo_tuning.json   # the fit with an albedo
        per texel (FitOptions(texel_albedo=True)) against the one region fit
    python validation/albedo_rounds.py --cost 3     # only the cost: seconds['fit'] with and without intervals
    python validation/albedo_rounds.py --exact --seeds 101 --rounds 6   # one-step replicates against refits

Writes ``validation/results/albedo_rounds.json`` (``--cost``: ``albedo_rounds_cost.json``; ``--exact``:
``albedo_rounds_exact.json``).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
import warnings
from pathlib import Path
from unittest import mock

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

import uncertainty as U  # noqa: E402  (the captures and checks of validation/uncertainty.py)
from roles import SIMULATED, refuse_report_data  # noqa: E402

from mifaces.io.atomic import write_json  # noqa: E402
from mifaces.reflectance import FitOptions, capture_samples, fit_brdf  # noqa: E402
from mifaces.reflectance.fit import region_fit as fitting  # noqa: E402
from mifaces.reflectance.fit.intervals import _value_jacobian  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
#: Seeds of validation/uncertainty.py's tuning captures.
SEEDS = list(U.TUNING_SEEDS)
#: Estimates compared: name -> (method of fit_brdf's ``uncertainty``, tile side at texture 128 or None for
#: the default :data:`mifaces.reflectance.fit.uncertainty.TILE_AT_128`).
VARIANTS = {"jackknife": ("jackknife", None), "sandwich": ("sandwich", None), "laplace": ("laplace", None),
            "jackknife_known_offsets": ("jackknife", None), "jackknife_tile16": ("jackknife", 16),
            "jackknife_tile32": ("jackknife", 32), "jackknife_tile64": ("jackknife", 64)}
#: The ``--rounds`` value of the fit with an albedo per texel (``FitOptions(texel_albedo=True)``).
TEXEL = "texel"
#: Region classes the coverage is reported for.
CLASSES = {"skin": ("skin",), "small": U.SMALL}


def _known_offsets(*args, offsets=None, **kwargs):
    """:func:`mifaces.reflectance.fit.uncertainty.region_uncertainty` with the offsets taken as known."""
    return _REGION_UNCERTAINTY(*args, **kwargs)


_REGION_UNCERTAINTY = fitting.region_uncertainty
#: Seconds spent in region_uncertainty by the fits since last cleared (:func:`_timed`).
_SPENT: list = []


def _timed(*args, **kwargs):
    """:func:`mifaces.reflectance.fit.uncertainty.region_uncertainty`, its time added to :data:`_SPENT`."""
    t = time.perf_counter()
    out = _REGION_UNCERTAINTY(*args, **kwargs)
    _SPENT.append(time.perf_counter() - t)
    return out


def _fit(capture, face, shapes, samples, model, rounds, method, known_offsets=False, texture=None, tile=None):
    """``fit_brdf`` with ``rounds`` alternations, or :data:`TEXEL` for ``FitOptions(texel_albedo=True)``."""
    with warnings.catch_warnings(), mock.patch.object(
            fitting, "region_uncertainty", _known_offsets if known_offsets else _timed), \
            mock.patch.object(U.unc, "TILE_AT_128", U.unc.TILE_AT_128 if tile is None else tile):
        warnings.simplefilter("ignore")
        return fit_brdf(capture, model, shapes, face_model=face, samples=samples, progress=False,
                        options=FitOptions(resolution=texture or U.TEXTURE,
                                           albedo_rounds=0 if rounds == TEXEL else rounds,
                                           texel_albedo=rounds == TEXEL, uncertainty=method))


def _coverage(records, regions=None, exclude=()) -> dict:
    checked = [r["covered"] for r in records if r["covered"] is not None
               and (regions is None or r["region"] in regions) and r["region"] not in exclude]
    return {"coverage": float(np.mean(checked)) if checked else None, "intervals": len(checked)}


def _classes(records) -> dict:
    out = {"pooled": _coverage(records)}
    out.update({name: _coverage(records, regions) for name, regions in CLASSES.items()})
    out["others"] = _coverage(records, exclude=sum(CLASSES.values(), ()))
    return out


def run(model: str, seed: int, rounds, work: Path, spp: int = U.SPP) -> list[dict]:
    params = U.skin_truth(seed) if model == "cooktorrance" else None
    capture, face, shapes, samples = U._simulate(work / f"{model}_{seed}", seed, spp=spp, brdf=model,
                                                 brdf_params=params)
    truth = U._truth_of(capture, model)
    rows = []
    for k in rounds:
        variants, skin, seconds = {}, None, {}
        for variant, (method, tile) in VARIANTS.items():
            estimate = _fit(capture, face, shapes, samples, model, k, method, variant.endswith("known_offsets"),
                            tile=tile)
            seconds[variant] = estimate.seconds["fit"]
            records = U._checks(estimate, truth, variant, {"truth_model": model, "model": model, "seed": seed})
            variants[variant] = _classes(records)
            if variant == U.unc.METHODS[0]:
                skin = [{k2: r[k2] for k2 in ("parameter", "channel", "truth", "fitted", "lo", "hi", "covered")}
                        for r in records if r["region"] == "skin"]
        default = variants[U.unc.METHODS[0]]["pooled"]
        rows.append({"model": model, "seed": seed, "albedo_rounds": k, "seconds": seconds,
                     "coverage": default["coverage"], "intervals": default["intervals"], "variants": variants,
                     "skin": skin})
        print(f"{model} seed {seed} rounds {k}: "
              + ", ".join(f"{v} {e['pooled']['coverage']:.2f} (skin {e['skin']['coverage']:.2f})"
                          for v, e in variants.items())
              + "; skin " + ", ".join(f"{s['parameter']}[{s['channel']}] {s['fitted']:.3f} ({s['truth']:.3f})"
                                      for s in skin), flush=True)
    return rows


def summary(rows: list) -> dict:
    """Per truth and number of alternations: coverage per estimate and region class, pooled over the
    seeds (each interval one count), and skin's error: per parameter (the RGB ones as the mean over
    channels), the mean of (fitted - truth)/truth over the seeds and of its absolute value."""
    out = {}
    for model in sorted({r["model"] for r in rows}):
        for k in sorted({r["albedo_rounds"] for r in rows}, key=str):
            chosen = [r for r in rows if r["model"] == model and r["albedo_rounds"] == k]
            coverage = {}
            for variant in VARIANTS:
                coverage[variant] = {}
                for cls in ("pooled", *CLASSES, "others"):
                    parts = [r["variants"][variant][cls] for r in chosen]
                    n = sum(p["intervals"] for p in parts)
                    hits = sum(p["coverage"] * p["intervals"] for p in parts if p["intervals"])
                    coverage[variant][cls] = {"coverage": hits / n if n else None, "intervals": n}
            bias = {}
            for name in sorted({s["parameter"] for r in chosen for s in r["skin"]}):
                rel = [np.mean([s["fitted"] for s in r["skin"] if s["parameter"] == name])
                       / np.mean([s["truth"] for s in r["skin"] if s["parameter"] == name]) - 1 for r in chosen]
                bias[name] = {"mean_relative_error": float(np.mean(rel)),
                              "mean_abs_relative_error": float(np.mean(np.abs(rel))), "seeds": len(rel)}
            skin_all = [all(s["covered"] for s in r["skin"]) for r in chosen]
            out.setdefault(model, {})[str(k)] = {
                "seeds": [r["seed"] for r in chosen], "coverage": coverage, "skin_error": bias,
                "skin_all_covered": {"captures": int(sum(skin_all)), "of": len(skin_all)},
                "seconds_fit_median": {v: float(np.median([r["seconds"][v] for r in chosen])) for v in VARIANTS}}
    return out


def cost(seeds, textures=(128, 512), rounds=(0, 3), repeats: int = 3) -> dict:
    """``seconds['fit']`` of Cook–Torrance and Phong fits without intervals and with the default one,
    per number of alternations and texture: the best of ``repeats`` interleaved runs after one of each;
    and ``intervals``, the time the fits with intervals spent computing them (the best of the repeats;
    on shared cores the difference of the totals is noisier than the step itself)."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            capture, face, shapes, _ = U._simulate(Path(tmp) / f"cost_{seed}", seed)
            for texture in textures:
                samples = capture_samples(capture, shapes, face, texture, progress=False)
                for model in ("cooktorrance", "phong"):
                    for k in rounds:
                        times = {}
                        for i, method in enumerate((None, U.unc.METHODS[0]) * (repeats + 1)):
                            _SPENT.clear()
                            t = _fit(capture, face, shapes, samples, model, k, method, texture=texture).seconds["fit"]
                            if i >= 2:
                                times[str(method)] = min(times.get(str(method), np.inf), t)
                                if method is not None:
                                    times["intervals"] = min(times.get("intervals", np.inf), sum(_SPENT))
                        rows.append({"seed": seed, "texture": texture, "model": model, "albedo_rounds": k,
                                     "samples": int(len(samples)), "without": times["None"],
                                     "with": times[U.unc.METHODS[0]], "intervals": times["intervals"]})
                        print(rows[-1], flush=True)
    table = {}
    for texture in textures:
        for k in rounds:
            chosen = [r for r in rows if r["texture"] == texture and r["albedo_rounds"] == k]
            one_fit = [r for r in rows if r["texture"] == texture and r["albedo_rounds"] == 0]
            table[f"{texture}_{k}"] = {
                "texture": texture, "albedo_rounds": k,
                "without_median": float(np.median([r["without"] for r in chosen])),
                "with_median": float(np.median([r["with"] for r in chosen])),
                "overhead_median": float(np.median([r["with"] / r["without"] - 1 for r in chosen])),
                "intervals_median": float(np.median([r["intervals"] for r in chosen])),
                "intervals_share_median": float(np.median([r["intervals"] / r["without"] for r in chosen])),
                "against_one_region_fit_median": float(np.median(
                    [r["with"] / o["without"] for r, o in zip(chosen, one_fit)]))}
    return {"method": U.unc.METHODS[0], "repeats": repeats, "summary": table, "fits": rows}


def exact(model: str, seed: int, rounds: int, work: Path) -> dict:
    """Skin's jackknife done the long way against the one-step replicate of fit_brdf's intervals: per
    skin tile left out, the alternation (``rounds`` region fits with the texel albedo offsets
    re-estimated in between, as :func:`fit_brdf` runs it for skin) rerun on the other tiles; the
    standard deviation of every free entry from those replicates, mapped to the parameter's units."""
    from mifaces import brdf as brdf_models
    from mifaces.model.regions import REGIONS
    from mifaces.reflectance.maps.diffuse import AlbedoOffsets, refine_diffuse
    from mifaces.reflectance.fit.parameters import ParameterSpace

    params = U.skin_truth(seed) if model == "cooktorrance" else None
    capture, face, shapes, samples = U._simulate(work / f"{model}_{seed}", seed, brdf=model, brdf_params=params)
    truth = U._truth_of(capture, model)["skin"]
    label = samples.label if samples.label is not None else samples.region(samples.region_map)
    # skin's samples as region 1 of a one-region map
    skin = dataclasses.replace(samples, label=np.ones(len(samples), int)).select(label == REGIONS["skin"])
    cluster = U.unc.tile_clusters(skin.texel, U.TEXTURE)
    brdf = brdf_models.model(model)
    fixed = {**brdf.fixed_defaults(), **brdf.fixed_in_region("skin")}
    region_map = np.ones((U.TEXTURE, U.TEXTURE), int)

    def alternate(keep, method):
        part, cl = skin.select(keep), cluster[keep]
        l, v, rr, sg = part.light, part.view, part.reflectance, part.sigma
        options = fitting.RegionFitOptions(fixed=fixed)
        fit = fitting.fit_region(brdf, fitting.RegionSamples(l, v, rr, sg), options=options, uncertainty=None)
        for k in range(rounds):
            offsets = AlbedoOffsets.of(refine_diffuse(brdf, {1: fit.params}, part, region_map, shrinkage=False),
                                       part.texel, part.label)
            last = k == rounds - 1
            fit = fitting.fit_region(brdf, fitting.RegionSamples(l, v, rr - offsets.offsets, sg), options=options,
                                     uncertainty=fitting.Uncertainty(method, cl, offsets) if last and method else None)
        return fit

    t = time.perf_counter()
    full = alternate(np.ones(len(skin), bool), U.unc.METHODS[0])
    space = ParameterSpace(brdf, fixed)
    x = space.vector(full.params)
    tiles = np.unique(cluster)
    steps = np.array([space.vector(alternate(cluster != g, None).params) - x for g in tiles])
    g = len(tiles)
    jac = _value_jacobian(space, x)
    std = np.sqrt(np.diag(jac @ ((g - 1) / g * steps.T @ steps) @ jac.T))
    entries = []
    for k, f in enumerate(space.free):
        one_step = full.uncertainty[f.name]["std"]
        value = full.params[f.name]
        entries.append({"parameter": f.name, "channel": f.channel,
                        "fitted": value if f.channel is None else value[f.channel],
                        "truth": None if f.name not in truth else
                        (truth[f.name] if f.channel is None else truth[f.name][f.channel]),
                        "std_one_step": one_step if f.channel is None else one_step[f.channel],
                        "std_exact": float(std[k])})
        print(entries[-1], flush=True)
    return {"model": model, "seed": seed, "albedo_rounds": rounds, "region": "skin", "tiles": int(g),
            "samples": len(skin), "seconds": time.perf_counter() - t, "entries": entries}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=SEEDS)
    parser.add_argument("--rounds", type=lambda v: v if v == TEXEL else int(v), nargs="+", default=[0, 3],
                        help=f"numbers of alternations, or {TEXEL!r}: the fit with an albedo per texel")
    parser.add_argument("--spp", type=int, default=U.SPP, help="samples per pixel of the captures")
    parser.add_argument("--image", type=int, default=U.IMAGE[0], help="width and height of the photographs")
    parser.add_argument("--texture", type=int, default=U.TEXTURE, help="texture resolution of the fits")
    parser.add_argument("--out", default="albedo_rounds.json", help="the result file's name in validation/results")
    parser.add_argument("--models", nargs="+", default=["cooktorrance", "phong"])
    parser.add_argument("--work", type=Path, default=Path("out/albedo_rounds"))
    parser.add_argument("--cost", type=int, default=0, metavar="N", help="only the cost, on N captures")
    parser.add_argument("--exact", action="store_true",
                        help="only skin's jackknife by rerunning the alternation per tile left out, on the first "
                             "seed and model and the last number of rounds")
    args = parser.parse_args(argv)
    U.IMAGE, U.TEXTURE = (args.image, args.image), args.texture  # the captures' and fits' sizes
    refuse_report_data(parser, SIMULATED, args.seeds, "the albedo rounds and the texel albedo (--seeds)")
    command = "python validation/albedo_rounds.py " + " ".join(argv if argv is not None else sys.argv[1:])
    if args.cost:
        write_json(RESULTS / "albedo_rounds_cost.json", {
            "label": "SIMULATED (timing, 2 shared CPU cores)", "command": command,
            **cost([s for s in SEEDS[:args.cost]], rounds=args.rounds)})
        return 0
    if args.exact:
        write_json(RESULTS / "albedo_rounds_exact.json", {
            "label": "SIMULATED", "command": command, "texture": U.TEXTURE,
            **exact(args.models[0], args.seeds[0], args.rounds[-1], args.work)})
        return 0
    t0 = time.perf_counter()
    rows = [row for model in args.models for seed in args.seeds
            for row in run(model, seed, args.rounds, args.work, args.spp)]
    write_json(RESULTS / args.out, {
        "label": "SIMULATED", "command": command, "image": list(U.IMAGE), "measurements": U.MEASUREMENTS,
        "spp": args.spp,
        "texture": U.TEXTURE, "interval_method": U.unc.METHODS[0], "variants": VARIANTS,
        "summary": summary(rows), "seconds": time.perf_counter() - t0, "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
