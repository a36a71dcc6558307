"""Are the error bars honest? Coverage of the fits' 95 % intervals on simulated captures.

1. **Same family.** For each model, simulated captures (one per seed) whose
   ground truth is that model; the model fitted on the true geometry; per
   region, parameter and channel, whether the 95 % interval contains the true
   value. The Cook-Torrance truth's skin parameters are drawn per seed from a
   seeded RNG within plausible ranges (:data:`SKIN_RANGES`), not chosen here.
2. **Out of family.** Truths the models cannot express (``roughplastic``,
   ``principled``, the spatially varying Cook-Torrance): the "true value" of
   a model's parameter is its best fit to the same capture rendered without
   sensor noise at :data:`REFERENCE_SPP` samples per pixel (same seed: same
   face, lights and poses).
3. **Methods.** Every fit's intervals by each estimate of
   :mod:`mifaces.reflectance.fit.uncertainty` (the sandwich over texel tiles, over
   single texels, the Laplace approximation, the bootstrap). The tile size was
   chosen on the tuning seeds (:data:`TUNING_SEEDS`), which the coverage
   tables leave out.
   Items 1-3 use the region fit (one albedo per region, ``texel_albedo=False``).
4. **Cost** (``--cost N``). The region fits' time with and without the
   default estimate, on N Cook-Torrance captures, texture 128², 256² and 512²
   (fit_brdf's default); with ``--texel-albedo``, of the fit with an albedo per texel.
5. **The default fit** (``--texel-albedo`` alone). The same seeds and truths, the
   jackknife of the region fit beside that of the fit with an albedo per texel
   (``FitOptions(texel_albedo=True)``, the default, over its own tiles).

Run:  python validation/uncertainty.py [--seeds 20] [--other-seeds 20] [--out-seeds 6] [--tune] [--cost N]
      [--texel-albedo]
Writes validation/results/uncertainty.json (the tables), uncertainty_records.json
(every interval checked) and uncertainty.png (with
``--tune``, uncertainty_tuning.json; with ``--cost``, uncertainty_cost[_texel_albedo].json;
with ``--texel-albedo`` alone, uncertainty_texel_albedo.{json,png} and uncertainty_records_texel_albedo.json).
Simulated captures go to a temporary folder.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

import numpy as np

from mifaces.capture import load_capture, read_ground_truth
from mifaces.io.atomic import atomic_write, save_figure, write_json
from mifaces.shape.io import load_geometry
from mifaces.reflectance import FitOptions, capture_samples, fit_brdf
from mifaces.reflectance.fit import intervals
from mifaces.reflectance.fit import uncertainty as unc
from mifaces.runtime.status import DEFAULTS, PRIOR
from mifaces.studio import SimulationOptions, photograph, simulate
from roles import SIMULATED, refuse_report_data

RESULTS = Path(__file__).resolve().parent / "results"
#: Capture size: photographs (px), measurements, samples per pixel, texture resolution.
IMAGE, MEASUREMENTS, SPP, TEXTURE = (256, 256), 6, 16, 128
#: Samples per pixel of the noise-free reference of an out-of-family truth.
REFERENCE_SPP = 128
#: Plausible skin ranges the Cook-Torrance truth's skin is drawn from (uniform; grey lobe).
SKIN_RANGES = {"specular_reflectance": (0.5, 1.5), "roughness": (0.2, 0.5)}
#: :func:`measure_check` draws seed S's skin as :func:`skin_truth` (S + this offset): draws the coverage
#: tables do not use.
MEASURE_SEED_OFFSET = 1000
#: Seeds the first tile size was chosen on (not in the tables; validation/results/uncertainty_tuning.json).
TUNING_SEEDS = range(100, 105)
#: Seeds the tiles are chosen on with ``--tune-tiles`` (not in the tables): every model, 20 captures each.
TILE_TUNING_SEEDS = range(100, 120)
#: Tilings compared: (tile side at resolution 128, fewest tiles per region; see
#: :func:`mifaces.reflectance.fit.uncertainty.tile_clusters`).
TILE_CANDIDATES = ((8, 1), (8, 8), (16, 1), (16, 8), (32, 1), (32, 8))
#: The estimates shown in the tables, at the default tiling (laplace has no clusters; sandwich_texel
#: clusters single texels).
SHOWN = ("jackknife", "sandwich", "sandwich_texel", "laplace", "bootstrap")


def tiled(method: str, tile: int, floor: int) -> str:
    """The name of ``method`` over tiles of ``tile`` texels at 128² with at least ``floor`` per region."""
    return f"{method}_t{tile}_m{floor}"


def default_variant(method: str = "jackknife") -> str:
    """The name of ``method`` at the library's tiling (:data:`unc.TILE_AT_128`, :data:`unc.MIN_TILES`)."""
    return tiled(method, unc.TILE_AT_128, unc.MIN_TILES)


def shown_variants() -> dict:
    """The tables' estimates: their names in the tables -> the records' variant names."""
    return {name: name if name in ("laplace", "sandwich_texel") else default_variant(name) for name in SHOWN}


#: Estimates compared: name -> (method, tile at resolution 128 or None, fewest tiles per region or None).
VARIANTS = ({tiled(m, t, f): (m, t, f) for t, f in TILE_CANDIDATES for m in ("jackknife", "sandwich", "bootstrap")}
            | {"sandwich_texel": ("sandwich", 1, 1), "laplace": ("laplace", None, None)})
#: With ``--texel-albedo`` (uncertainty_texel_albedo.json): the region fit beside the fit with an albedo per
#: texel (``FitOptions(texel_albedo=True)``, the default, its own tiles); name -> (method, tile, floor, options).
TEXEL_VARIANTS = {"region": (unc.METHODS[0], None, None, {"texel_albedo": False}),
                  "texel_albedo": (unc.METHODS[0], None, None, {"texel_albedo": True})}
MODELS = ("cooktorrance", "phong", "ward", "lafortune")
OUT_OF_FAMILY = {"roughplastic": dict(brdf="roughplastic"), "principled": dict(brdf="principled"),
                 "varying": dict(brdf="cooktorrance", varying=True)}
#: The fields of a record (one interval checked), in the order of the rows of uncertainty_records.json.
FIELDS = ("truth_model", "model", "seed", "variant", "region", "parameter", "channel", "samples", "truth", "fitted",
          "lo", "hi", "status", "covered")
#: Regions reported as small.
SMALL = ("lips", "eyebrows")


def skin_truth(seed: int) -> dict:
    """The Cook-Torrance truth's skin of ``seed``: drawn from :data:`SKIN_RANGES`."""
    rng = np.random.default_rng(10_000 + seed)
    s = float(rng.uniform(*SKIN_RANGES["specular_reflectance"]))
    m = float(rng.uniform(*SKIN_RANGES["roughness"]))
    return {"model": "cooktorrance", "regions": {"skin": {"specular_reflectance": [round(s, 4)] * 3,
                                                          "roughness": round(m, 4)}}}


def noise_free(values, rng, **_):
    """:func:`mifaces.studio.photograph.camera_noise` without the noise (same random draws)."""
    rng.standard_normal(np.shape(values))
    return np.clip(np.asarray(values, np.float64), 0.0, 1.0).astype(np.float32)


def _simulate(folder: Path, seed: int, spp: int = SPP, clean: bool = False, **options):
    original = photograph.camera_noise
    if clean:
        photograph.camera_noise = noise_free
    try:
        simulate(folder, SimulationOptions(resolution=IMAGE, measurements=MEASUREMENTS, spp=spp, seed=seed, **options),
                 progress=False, force=True)
    finally:
        photograph.camera_noise = original
    capture = load_capture(folder)
    face, shapes = load_geometry(capture, "ground-truth")
    return capture, face, shapes, capture_samples(capture, shapes, face, TEXTURE, progress=False)


def _fit(capture, face, shapes, samples, model, method=unc.METHODS[0], tile=None, floor=None, texture=TEXTURE,
         **options):
    """``fit_brdf`` of ``model`` with the uncertainty ``method`` over tiles of ``tile`` (at 128²) and at least
    ``floor`` per region (None: the library's), warnings silenced; ``options``: more :class:`FitOptions`."""
    default = unc.TILE_AT_128, unc.MIN_TILES
    unc.TILE_AT_128 = default[0] if tile is None else tile
    unc.MIN_TILES = default[1] if floor is None else floor
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fit_brdf(capture, model, shapes, face_model=face, samples=samples, progress=False,
                            options=FitOptions(resolution=texture, uncertainty=method, **options))
    finally:
        unc.TILE_AT_128, unc.MIN_TILES = default


#: The fit the tables of uncertainty.json compare estimates on: one albedo per region.
REGION_FIT = {"texel_albedo": False}


def _options(options: list) -> dict:
    """The :class:`FitOptions` of a variant's optional fourth entry (none: :data:`REGION_FIT`)."""
    return dict(options[0]) if options else dict(REGION_FIT)


def _checks(estimate, truth: dict, variant: str, meta: dict) -> list[dict]:
    """One record per region, parameter and channel with a true value: interval, truth, covered."""
    out = []
    for region, fit in estimate.fits.items():
        if fit.status == PRIOR or region not in truth:
            continue
        for name, value in truth[region].items():
            entry = fit.uncertainty.get(name, {})
            if entry.get("status") == intervals.FIXED:
                continue
            channels = range(3) if np.ndim(value) else [None]
            for c in channels:
                true = float(value[c] if c is not None else value)
                # a region left without a lobe (``no_lobe``) has a scalar 0 for an RGB parameter
                fitted = float(np.broadcast_to(fit.params[name], np.shape(value))[c] if c is not None
                               else fit.params[name])
                status = entry.get("status") or (fit.status if fit.status == DEFAULTS else None)
                status = status[c] if isinstance(status, list) else status
                if "interval95" in entry and status in (None, intervals.ESTIMATED):
                    lo, hi = entry["interval95"]
                    lo, hi = (lo[c], hi[c]) if c is not None else (lo, hi)
                    covered = bool(lo <= true <= hi)
                else:
                    lo = hi = None
                    covered = None
                out.append({**meta, "variant": variant, "region": region, "parameter": name, "channel": c,
                            "samples": fit.samples, "truth": true, "fitted": fitted, "lo": lo, "hi": hi,
                            "status": status or intervals.ESTIMATED, "covered": covered})
    return out


def _truth_of(capture, model) -> dict:
    truth = read_ground_truth(capture).brdf
    return {r: {k: v for k, v in p.items() if k != "eta"} for r, p in truth["regions"].items()} \
        if truth["model"] == model else {}


def same_family(model: str, seeds, tmp: Path, variants=VARIANTS) -> list:
    records = []
    for seed in seeds:
        t = time.perf_counter()
        params = skin_truth(seed) if model == "cooktorrance" else None
        capture, face, shapes, samples = _simulate(tmp / f"{model}_{seed}", seed, brdf=model, brdf_params=params)
        truth = _truth_of(capture, model)
        for variant, (method, tile, floor, *options) in variants.items():
            estimate = _fit(capture, face, shapes, samples, model, method, tile, floor, **_options(options))
            records += _checks(estimate, truth, variant, {"truth_model": model, "model": model, "seed": seed})
        print(f"{model} seed {seed}: {time.perf_counter() - t:.1f} s", flush=True)
    return records


def cost(seeds, tmp: Path, textures=(128, 256, 512), repeats: int = 5, **options) -> dict:
    """The region fits' time (``seconds['fit']``) without and with the default estimate, per model,
    capture and texture resolution: the best of ``repeats`` interleaved runs, after one run of each
    (the first in the process, which compiles the kernels, is recorded apart); ``options``: more
    :class:`FitOptions` of both."""
    rows, first = [], {}
    for seed in seeds:
        capture = _simulate(tmp / f"cost_{seed}", seed)[:3]
        for texture in textures:
            samples = capture_samples(capture[0], capture[2], capture[1], texture, progress=False)
            for model in MODELS:
                times = {}
                for i, method in enumerate((None, unc.METHODS[0]) * (repeats + 1)):
                    seconds = _fit(*capture, samples, model, method, texture=texture, **options).seconds["fit"]
                    if i < 2:
                        first.setdefault(f"{model}_{method}", seconds)
                        continue
                    times[str(method)] = min(times.get(str(method), np.inf), seconds)
                rows.append({"seed": seed, "texture": texture, "model": model, "samples": int(len(samples)),
                             "without": times["None"], "with": times[unc.METHODS[0]]})
                print(rows[-1], flush=True)
    ratio = np.array([r["with"] / r["without"] - 1 for r in rows])
    by_texture = {t: float(np.median([r["with"] / r["without"] - 1 for r in rows if r["texture"] == t]))
                  for t in textures}
    return {"method": unc.METHODS[0], "options": options, "overhead_median": float(np.median(ratio)),
            "overhead_median_by_texture": by_texture, "first_call_seconds": first, "fits": rows}


def out_of_family(name: str, seeds, tmp: Path, variants=VARIANTS) -> list:
    records = []
    for seed in seeds:
        t = time.perf_counter()
        ref = _simulate(tmp / f"{name}_{seed}_ref", seed, spp=REFERENCE_SPP, clean=True, **OUT_OF_FAMILY[name])
        noisy = _simulate(tmp / f"{name}_{seed}", seed, **OUT_OF_FAMILY[name])
        for model in MODELS:
            truths = {}  # per fit options: the same fit's best parameters on the reference
            for variant, (method, tile, floor, *options) in variants.items():
                key = json.dumps(_options(options), sort_keys=True)
                if key not in truths:
                    reference = _fit(*ref, model, None, **_options(options))
                    truths[key] = {r: {k: v for k, v in f.params.items() if k != "eta"}
                                   for r, f in reference.fits.items() if f.status != PRIOR}
                truth = truths[key]
                estimate = _fit(*noisy, model, method, tile, floor, **_options(options))
                records += _checks(estimate, truth, variant, {"truth_model": name, "model": model, "seed": seed})
        print(f"{name} seed {seed}: {time.perf_counter() - t:.1f} s", flush=True)
    return records


def measure_check(seeds, tmp: Path, extra: tuple = ()) -> dict:
    """The issue's literal check: per seed, the default simulated capture (``mifaces simulate``: 512²,
    6 photographs, 64 spp) with a Cook-Torrance truth whose skin :func:`skin_truth` draws, measured by
    ``mifaces measure --geometry ground-truth --brdf cooktorrance``; whether every fitted skin
    parameter's 95 % interval in ``brdf.json`` holds the truth (``extra``: more options of measure)."""
    command = Path(sys.executable).with_name("mifaces")
    rows = []
    for seed in seeds:
        t = time.perf_counter()
        truth = skin_truth(MEASURE_SEED_OFFSET + seed)
        folder, out = tmp / f"measure_{seed}", tmp / f"measure_{seed}_out"
        (tmp / f"skin_{seed}.json").write_text(json.dumps(truth))
        subprocess.run([str(command), "simulate", str(folder), "--seed", str(seed), "--brdf", "cooktorrance",
                        "--brdf-params", str(tmp / f"skin_{seed}.json"), "--force"], check=True,
                       stdout=subprocess.DEVNULL)
        subprocess.run([str(command), "measure", str(folder), "--out", str(out), "--geometry", "ground-truth",
                        "--brdf", "cooktorrance", *extra], check=True, stdout=subprocess.DEVNULL)
        fitted = json.loads((out / "brdf" / "cooktorrance" / "brdf.json").read_text())
        # every region's same-family truth: skin's drawn, the others' the simulator's published values
        regions = {r: {k: v for k, v in p.items() if k != "eta"}
                   for r, p in read_ground_truth(load_capture(folder)).brdf["regions"].items()}
        checks = {region: _json_checks(fitted, region, regions[region])
                  for region in fitted["uncertainty"] if region in regions}
        skin = checks.pop("skin")
        others = [dict(c, region=region) for region, cs in checks.items() for c in cs if c["covered"] is not None]
        rows.append({"seed": seed, "truth": truth["regions"]["skin"], "parameters": skin,
                     "all_covered": all(c["covered"] for c in skin), "other_regions": others,
                     "seconds": time.perf_counter() - t})
        print(rows[-1], flush=True)
    pooled = [c["covered"] for r in rows for c in r["parameters"] + r["other_regions"] if c["covered"] is not None]
    return {"command": "mifaces simulate OUT --seed S --brdf cooktorrance --brdf-params SKIN.json; "
                       "mifaces measure OUT --geometry ground-truth --brdf cooktorrance " + " ".join(extra),
            "skin_seed_offset": MEASURE_SEED_OFFSET, "tile_at_128": unc.TILE_AT_128, "min_tiles": unc.MIN_TILES,
            "captures": len(rows), "all_covered": sum(r["all_covered"] for r in rows),
            "pooled_coverage": {"coverage": float(np.mean(pooled)) if pooled else None, "intervals": len(pooled),
                                "regions": "every region with an estimated interval, skin included"},
            "runs": rows}


def _json_checks(fitted: dict, region: str, truth: dict) -> list[dict]:
    """Per parameter and channel of ``truth`` (one region's true values), the fitted value of
    ``brdf.json`` (``fitted``), its 95 % interval and whether it holds the truth (None: no interval)."""
    params, entries = fitted["regions"][region], fitted["uncertainty"][region]
    checks = []
    for name, value in truth.items():
        entry = entries.get(name, {})
        for c in (range(3) if np.ndim(value) else [None]):
            pick = (lambda v: v[c]) if c is not None else (lambda v: v)
            status = entry.get("status", intervals.ESTIMATED)
            status = pick(status) if isinstance(status, list) else status
            lo, hi = (pick(b) for b in entry["interval95"]) if "interval95" in entry else (None, None)
            estimated = lo is not None and status == intervals.ESTIMATED
            true = float(pick(value))
            checks.append({"parameter": name, "channel": c, "truth": true, "fitted": float(pick(params[name])),
                           "lo": lo, "hi": hi, "status": status,
                           "covered": bool(lo <= true <= hi) if estimated else None})
    return checks


def coverage(records: list, **where) -> dict:
    """Coverage of the records matching ``where`` (``regions`` a tuple of region names or None):
    intervals checked, contained, the fraction, and parameters held at a bound."""
    regions = where.pop("regions", None)
    chosen = [r for r in records if all(r[k] == v for k, v in where.items())
              and (regions is None or r["region"] in regions)]
    checked = [r for r in chosen if r["covered"] is not None]
    hits = sum(r["covered"] for r in checked)
    return {"intervals": len(checked), "covered": hits,
            "coverage": hits / len(checked) if checked else None,
            "without_interval": len(chosen) - len(checked)}


def summary(records: list) -> dict:
    """Coverage per truth, model and variant: pooled, small regions, per region, per parameter."""
    out = {}
    variants = list(dict.fromkeys(r["variant"] for r in records))
    for truth in sorted({r["truth_model"] for r in records}):
        for model in MODELS:
            for variant in variants:
                base = dict(truth_model=truth, model=model, variant=variant)
                pooled = coverage(records, **base)
                if not pooled["intervals"]:
                    continue
                regions = sorted({r["region"] for r in records if r["truth_model"] == truth})
                params = sorted({r["parameter"] for r in records if r["truth_model"] == truth and r["model"] == model})
                out.setdefault(truth, {}).setdefault(model, {})[variant] = {
                    "pooled": pooled, "small": coverage(records, **base, regions=SMALL),
                    "large": coverage(records, **base, regions=tuple(r for r in regions if r not in SMALL)),
                    "regions": {g: coverage(records, **base, regions=(g,)) for g in regions},
                    "parameters": {p: coverage(records, **base, parameter=p) for p in params}}
    return out


def skin_check(records: list, variant: str | None = None) -> list:
    """Per Cook-Torrance seed (``variant``; None: the default estimate): the drawn skin truth and whether
    every fitted skin parameter's interval holds it."""
    out = []
    variant = variant or default_variant()
    for seed in sorted({r["seed"] for r in records if r["truth_model"] == "cooktorrance"}):
        rows = [r for r in records if r["truth_model"] == "cooktorrance" and r["seed"] == seed
                and r["region"] == "skin" and r["variant"] == variant]
        out.append({"seed": seed, "truth": skin_truth(seed)["regions"]["skin"],
                    "all_covered": all(r["covered"] for r in rows),
                    "parameters": [{k: r[k] for k in ("parameter", "channel", "truth", "fitted", "lo", "hi",
                                                      "covered")} for r in rows]})
    return out


def markdown(result: dict, records: list) -> str:
    """The coverage tables of docs/uncertainty.md: per truth and model, the shown estimates' pooled
    coverage at the default tiling, and the default's on small regions, the others, skin, the glossy
    parameters and the diffuse albedo; then the jackknife's pooled coverage per tiling."""
    def pct(entry):
        return "n/a" if entry["coverage"] is None else f"{100 * entry['coverage']:.0f} % ({entry['intervals']})"

    shown = shown_variants()
    default = shown["jackknife"]
    lines = ["| truth | model | seeds | " + " | ".join(shown) + " | jackknife: small regions | others | skin | "
             "glossy | diffuse |", "|---" * (len(shown) + 8) + "|"]
    for truth, models in result["coverage"].items():
        for model, entry in models.items():
            d = entry[default]
            glossy = coverage([r for r in records if r["parameter"] != "diffuse_reflectance"],
                              truth_model=truth, model=model, variant=default)
            diffuse = d["parameters"].get("diffuse_reflectance", {"coverage": None, "intervals": 0})
            lines.append(f"| {truth} | {model} | {result['seeds'][truth]} | "
                         + " | ".join(pct(entry[v]["pooled"]) for v in shown.values())
                         + f" | {pct(d['small'])} | {pct(d['large'])} | {pct(d['regions']['skin'])} | {pct(glossy)} | "
                         + f"{pct(diffuse)} |")
    lines += ["", tile_markdown(result["coverage"]), "", skin_markdown(result)]
    return "\n".join(lines)


def skin_markdown(result: dict) -> str:
    """The skin check's table: per Cook-Torrance seed, the drawn skin, the fitted green ρ_s and m with
    their 95 % intervals, and whether every skin interval holds the truth."""
    lines = ["| seed | true ρs | true m | fitted ρs (green) [95 %] | fitted m [95 %] | all covered |",
             "|---|---|---|---|---|---|"]
    for row in result["skin_check"]:
        cells = {(p["parameter"], p["channel"]): p for p in row["parameters"]}
        rho, m = cells[("specular_reflectance", 1)], cells[("roughness", None)]
        lines.append(f"| {row['seed']} | {rho['truth']:.3f} | {m['truth']:.3f} | {rho['fitted']:.3f} "
                     f"[{rho['lo']:.3f}, {rho['hi']:.3f}] | {m['fitted']:.3f} [{m['lo']:.3f}, {m['hi']:.3f}] | "
                     f"{'yes' if row['all_covered'] else 'no'} |")
    return "\n".join(lines)


def tile_markdown(table: dict) -> str:
    """The jackknife's pooled coverage (and on small regions) per tiling and same-family model."""
    models = [m for m in MODELS if m in table and m in table[m]]
    lines = ["| tile at 128² | fewest tiles per region | " + " | ".join(models) + " |",
             "|---" * (len(models) + 2) + "|"]
    for tile, floor in TILE_CANDIDATES:
        cells = []
        for m in models:
            e = table[m][m].get(tiled("jackknife", tile, floor))
            cells.append("n/a" if e is None or e["pooled"]["coverage"] is None else
                         f"{100 * e['pooled']['coverage']:.0f} % (small {100 * e['small']['coverage']:.0f} %)")
        mark = " (default)" if (tile, floor) == (unc.TILE_AT_128, unc.MIN_TILES) else ""
        lines.append(f"| {tile}{mark} | {floor} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def choose_tiling(records: list) -> dict:
    """The rule the tiling is chosen by, on the tuning seeds' records: the candidate whose worst
    same-family model is nearest the nominal 95 % (the smallest max_m |coverage_m - 0.95|; ties: the
    smaller tile, then the smaller floor)."""
    table = {}
    for tile, floor in TILE_CANDIDATES:
        v = tiled("jackknife", tile, floor)
        table[v] = {m: coverage(records, variant=v, model=m, truth_model=m) for m in MODELS}

    def distance(candidate):
        cells = table[tiled("jackknife", *candidate)].values()
        return max(abs(c["coverage"] - 0.95) for c in cells if c["coverage"] is not None)

    best = min(TILE_CANDIDATES, key=lambda c: (distance(c), c))
    return {"rule": choose_tiling.__doc__.split(":", 1)[1].strip().replace("\n   ", ""),
            "chosen": {"tile_at_128": best[0], "min_tiles": best[1]},
            "distance": {tiled("jackknife", *c): distance(c) for c in TILE_CANDIDATES}, "coverage": table}


def figure(result: dict, path: Path) -> None:
    """Coverage per model and estimate (bars pooled, dashes small regions): the same-family truths in
    one panel, each out-of-family truth in its own."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = result["coverage"]
    shown = shown_variants()
    panels = [("same family (truth = fitted model)", {m: table[m][m] for m in MODELS if m in table})]
    panels += [(f"truth {t} (out of family)", table[t]) for t in OUT_OF_FAMILY if t in table]
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), squeeze=False, sharey=True)
    width = 0.8 / len(shown)
    for ax, (title, models) in zip(axes.ravel(), panels):
        for i, (label, variant) in enumerate(shown.items()):
            for j, entry in enumerate(models.values()):
                ax.bar(j + i * width, entry[variant]["pooled"]["coverage"], width, color=f"C{i}",
                       label=label if j == 0 else None)
                small = entry[variant]["small"]["coverage"]
                if small is not None:
                    ax.plot(j + i * width, small, "k_", markersize=7)
        ax.axhspan(0.85, 0.99, color="0.9", zorder=0)
        ax.axhline(0.95, color="k", lw=0.8)
        ax.set_xticks(np.arange(len(models)) + 0.4 - width / 2, list(models), fontsize=8)
        ax.set_title(title, fontsize=9)
        ax.set_ylim(0, 1.02)
    for ax in axes.ravel()[len(panels):]:
        ax.axis("off")
    for ax in axes[:, 0]:
        ax.set_ylabel("coverage of the 95 % intervals")
    axes[0][0].legend(fontsize=7, loc="lower left", ncol=2)
    fig.suptitle("SIMULATED captures: how often the 95 % interval holds the true value (bars: pooled, "
                 f"dashes: lips and eyebrows; band 85-99 %)\ntiles of {unc.TILE_AT_128} texels at 128², "
                 f"at least {unc.MIN_TILES} per region", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def write_records(records: list, name: str = "uncertainty_records.json", kept=None) -> None:
    """The records the tables read (``kept`` variants; None: the shown estimates at the default tiling,
    the jackknife at every tiling), one compact row each (:data:`FIELDS`, values to 5 digits), to ``name``."""
    if kept is None:
        kept = set(shown_variants().values()) | {tiled("jackknife", t, f) for t, f in TILE_CANDIDATES}
    with atomic_write(RESULTS / name, "w") as f:
        rows = [[float(f"{r[k]:.5g}") if isinstance(r[k], float) else r[k] for k in FIELDS] for r in records
                if r["variant"] in kept]
        json.dump({"fields": FIELDS, "rows": rows}, f, separators=(",", ":"))


def read_records(name: str = "uncertainty_records.json") -> list:
    data = json.loads((RESULTS / name).read_text())
    return [dict(zip(data["fields"], row)) for row in data["rows"]]


TEXEL_RESULT, TEXEL_RECORDS = "uncertainty_texel_albedo.json", "uncertainty_records_texel_albedo.json"


def texel_table(args, tmp: Path, t0: float) -> None:
    """The coverage table of :data:`TEXEL_VARIANTS` (the region fit and the default fit with an albedo per
    texel) on the same seeds as uncertainty.json, to :data:`TEXEL_RESULT` and :data:`TEXEL_RECORDS`,
    saved after each truth."""
    result = {"variants": {k: [m, t, f, o] for k, (m, t, f, o) in TEXEL_VARIANTS.items()}, "image": IMAGE,
              "measurements": MEASUREMENTS, "spp": SPP, "texture": TEXTURE, "reference_spp": REFERENCE_SPP,
              "tile_at_128": {"region": unc.TILE_AT_128, "texel_albedo": unc.TEXEL_TILE_AT_128},
              "min_tiles": unc.MIN_TILES, "skin_ranges": SKIN_RANGES, "seeds": {}}

    def save(records):
        result.update(coverage=summary(records), seconds=time.perf_counter() - t0,
                      skin_check={v: skin_check(records, v) for v in TEXEL_VARIANTS})
        write_json(RESULTS / TEXEL_RESULT, result)
        write_records(records, TEXEL_RECORDS, set(TEXEL_VARIANTS))

    run_tables(args, tmp, TEXEL_VARIANTS, result, save)
    texel_figure(result, RESULTS / TEXEL_RESULT.replace(".json", ".png"))


def run_tables(args, tmp: Path, variants: dict, result: dict, save) -> None:
    """Every same-family truth (``--seeds`` Cook-Torrance and Phong captures, ``--other-seeds`` Ward and
    Lafortune), then every out-of-family truth (``--out-seeds`` each), fitted with ``variants``; the seeds
    counted in ``result["seeds"]``, ``save(records)`` after each truth, the pooled coverage printed."""
    records = []
    for model in MODELS:
        n = args.seeds if model in ("cooktorrance", "phong") else args.other_seeds
        result["seeds"][model] = n
        records += same_family(model, range(n), tmp, variants)
        save(records)
    for name in OUT_OF_FAMILY:
        result["seeds"][name] = args.out_seeds
        records += out_of_family(name, range(args.out_seeds), tmp, variants)
        save(records)
    print(json.dumps({t: {m: {v: (e["pooled"]["coverage"], e["small"]["coverage"]) for v, e in d.items()}
                          for m, d in table.items()} for t, table in result["coverage"].items()}, indent=1))


def texel_figure(result: dict, path: Path) -> None:
    """Coverage of the region fit and of the fit with an albedo per texel (the default) per truth and
    model: bars pooled, dots skin, dashes lips and eyebrows; the 85-99 % band shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = result["coverage"]
    truths = [t for t in (*MODELS, *OUT_OF_FAMILY) if t in table]
    cells = [(t, m) for t in truths for m in MODELS if m in table[t] and (t == m or t in OUT_OF_FAMILY)]
    fig, ax = plt.subplots(figsize=(14, 4.8))
    width = 0.38
    for i, (variant, label) in enumerate((("region", "region fit (one albedo per region)"),
                                          ("texel_albedo", "default: an albedo per texel"))):
        xs = np.arange(len(cells)) + (i - 0.5) * width
        entries = [table[t][m][variant] for t, m in cells]
        ax.bar(xs, [e["pooled"]["coverage"] for e in entries], width, color=f"C{i}", label=label)
        ax.plot(xs, [e["regions"].get("skin", {}).get("coverage", np.nan) for e in entries], "ko", ms=3,
                label="skin" if i else None)
        ax.plot(xs, [e["small"]["coverage"] if e["small"]["coverage"] is not None else np.nan for e in entries],
                "k_", ms=8, label="lips and eyebrows" if i else None)
    ax.axhspan(0.85, 0.99, color="0.9", zorder=0)
    ax.axhline(0.95, color="k", lw=0.8)
    ax.set_xticks(np.arange(len(cells)), [m if t == m else f"{m}\n({t})" for t, m in cells], fontsize=7)
    ax.set_ylim(0.5, 1.02)
    ax.set_ylabel("coverage of the 95 % intervals")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=4)
    ax.set_title("SIMULATED captures: how often the 95 % interval holds the true value; same family (left), "
                 "out of family (truth in brackets); band 85-99 %", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=20, help="seeds of the Cook-Torrance and Phong truths")
    parser.add_argument("--other-seeds", type=int, default=20, help="seeds of the Ward and Lafortune truths")
    parser.add_argument("--out-seeds", type=int, default=6, help="seeds of each out-of-family truth")
    parser.add_argument("--tune", action="store_true", help="only the first tuning seeds (tile size, 2 models)")
    parser.add_argument("--tune-tiles", action="store_true",
                        help="only the tile tuning seeds: every tiling's jackknife, every model, and the choice")
    parser.add_argument("--measure-check", type=int, default=0, metavar="N",
                        help="only the literal check: N default captures with a drawn Cook-Torrance skin, "
                             "measured on the true geometry (uncertainty_measure.json)")
    parser.add_argument("--interreflection", action="store_true",
                        help="with --measure-check: measure --interreflection (uncertainty_measure_interreflection.json)")
    parser.add_argument("--texel-albedo", action=argparse.BooleanOptionalAction, default=None,
                        help="with --measure-check: measure --texel-albedo or --no-texel-albedo (unsaid: the "
                             "library's default), the first written uncertainty_measure[_interreflection]"
                             "_texel_albedo.json, the second without the suffix; with --cost: the fit with an albedo "
                             "per texel (uncertainty_cost_texel_albedo.json); alone: the coverage table of the region "
                             "fit beside the fit with an albedo per texel (uncertainty_texel_albedo.json)")
    parser.add_argument("--summarize", action="store_true",
                        help="only the tables and the figure again, from the records uncertainty.json holds")
    parser.add_argument("--cost", type=int, default=0, metavar="N",
                        help="only the cost: fit times with and without the default estimate on N captures")
    args = parser.parse_args()
    if args.tune_tiles:
        refuse_report_data(parser, SIMULATED, TILE_TUNING_SEEDS, "the intervals' tiling (--tune-tiles)")
    if args.tune:
        refuse_report_data(parser, SIMULATED, TUNING_SEEDS, "the first tile size (--tune)")
    t0 = time.perf_counter()
    if args.summarize:
        result = json.loads((RESULTS / "uncertainty.json").read_text())
        records = read_records()
        result.update(default=default_variant(), tile_at_128=unc.TILE_AT_128, min_tiles=unc.MIN_TILES,
                      coverage=summary(records), skin_check=skin_check(records))
        write_records(records)
        write_json(RESULTS / "uncertainty.json", result)
        figure(result, RESULTS / "uncertainty.png")
        print(markdown(result, records))
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.cost:
            options = {"texel_albedo": True} if args.texel_albedo else REGION_FIT
            name = "uncertainty_cost" + ("_texel_albedo" if args.texel_albedo else "") + ".json"
            write_json(RESULTS / name, cost(range(args.cost), tmp, **options))
            return
        if args.measure_check:
            texel = FitOptions().texel_albedo if args.texel_albedo is None else args.texel_albedo
            extra = (("--interreflection",) if args.interreflection else ()) + \
                (("--texel-albedo",) if texel else ("--no-texel-albedo",))
            name = "uncertainty_measure" + "".join(f"_{flag[2:].replace('-', '_')}" for flag in extra
                                                   if not flag.startswith("--no-")) + ".json"
            write_json(RESULTS / name, measure_check(range(args.measure_check), tmp, extra))
            return
        if args.texel_albedo:  # alone
            texel_table(args, tmp, t0)
            return
        if args.tune_tiles:
            variants = {tiled("jackknife", t, f): ("jackknife", t, f) for t, f in TILE_CANDIDATES}
            records = []
            for model in MODELS:
                records += same_family(model, TILE_TUNING_SEEDS, tmp, variants)
                write_json(RESULTS / "uncertainty_tile_tuning.json",
                           {"seeds": list(TILE_TUNING_SEEDS), **choose_tiling(records)} if model == MODELS[-1]
                           else {"seeds": list(TILE_TUNING_SEEDS), "partial": True})
            print(json.dumps(choose_tiling(records), indent=1))
            return
        if args.tune:
            variants = ({f"sandwich_tile{t}": ("sandwich", t, 1) for t in (1, 4, 8, 16)}
                        | {f"jackknife_tile{t}": ("jackknife", t, 1) for t in (1, 4, 8, 16)}
                        | {"laplace": ("laplace", None, None), "bootstrap": ("bootstrap", None, None)})
            records = []
            for model in ("cooktorrance", "phong"):
                records += same_family(model, TUNING_SEEDS, tmp, variants)
            table = {v: {m: coverage(records, variant=v, model=m) for m in ("cooktorrance", "phong")}
                     for v in variants}
            write_json(RESULTS / "uncertainty_tuning.json", {"seeds": list(TUNING_SEEDS), "coverage": table})
            print(json.dumps(table, indent=1))
            return
        result = {"default": default_variant(), "image": IMAGE, "measurements": MEASUREMENTS, "spp": SPP,
                  "texture": TEXTURE,
                  "reference_spp": REFERENCE_SPP, "tile_at_128": unc.TILE_AT_128, "min_tiles": unc.MIN_TILES, "skin_ranges": SKIN_RANGES,
                  "variants": {k: list(v) for k, v in VARIANTS.items()}, "seeds": {}}

        def save(records):
            result.update(coverage=summary(records), skin_check=skin_check(records), seconds=time.perf_counter() - t0)
            write_json(RESULTS / "uncertainty.json", result)
            write_records(records)

        run_tables(args, tmp, VARIANTS, result, save)
    figure(result, RESULTS / "uncertainty.png")


if __name__ == "__main__":
    main()
