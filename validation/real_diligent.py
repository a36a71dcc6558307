"""Normals and BRDFs of a real shiny object: the DiLiGenT ball.

From the training half of the 96 calibrated lights (the fixed split of
:func:`mifaces.importers.diligent.light_split`: even indices), estimate per
pixel normals and albedo together with each of the four analytic BRDFs
(:func:`mifaces.photometric_stereo.nonlambertian.fit_normals_and_brdf`, started from
Lambertian photometric stereo on the same lights), without reading the
ground-truth normals. Then

* relight the held-out half with each model and with Lambertian photometric
  stereo fitted to the same training lights, and compare with the held-out
  photographs: pooled relative RMSE sqrt(Σ err² / Σ photo²) over the mask,
  saturated pixels left out, over all held-out images and per light;
* score the normals against the ground truth (mean and median angular error
  over the mask), for the half and, for the model the training loss picks,
  for all 96 lights.

The normals written to ``DIR/normals.npy`` are those of the model with the
lowest training loss E (the held-out photographs and the ground truth play
no part in the choice); ``DIR/normals_all.npy`` the same model's from all 96
lights. Writes ``DIR/split.json``, ``DIR/heldout/<model>.npz`` (the
held-out predictions, (48, 162, 162, 3) float32, and their filenames),
``validation/results/real_diligent.json`` and ``real_diligent.png``.

Real photographs: these figures are not simulated.

    python validation/real_diligent.py --data ../shared/data/diligent_ball --out out/real_diligent
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

from mifaces import photometric_stereo as ps
from mifaces.brdf import NAMES
from mifaces.io.atomic import atomic_write, write_json
from mifaces.importers import diligent
from mifaces.photometric_stereo import nonlambertian as nm

RESULTS = Path(__file__).resolve().parent / "results"
LAMBERTIAN = "lambertian_ps"


def estimate(obj: diligent.DiligentObject, model: str, rounds: int) -> tuple[np.ndarray, nm.NormalsEstimate]:
    """Normals (H, W, 3) and the estimate of ``model`` from all of ``obj``'s lights, started from PS."""
    albedo, start = ps.fit(obj.images, obj.directions, obj.mask, obj.saturated)
    m = obj.mask
    values = obj.images[:, m]
    weights = nm.observation_weights(values, obj.saturated[:, m])
    t0 = time.perf_counter()
    result = nm.fit_normals_and_brdf(model, nm.LitPixels(values, obj.directions, weights), start[m], albedo[m],
                                     options=nm.AlternationOptions(rounds=rounds),
                                     progress=lambda e: print(f"    {model} round {e['round']}: E {e['loss']:.2f} "
                                                              f"({e['seconds']:.0f} s)", flush=True))
    print(f"  {model}: {time.perf_counter() - t0:.0f} s", flush=True)
    normals = np.zeros(m.shape + (3,), np.float32)
    normals[m] = result.normals
    return normals, result


def relighting_error(predicted: np.ndarray, held: diligent.DiligentObject) -> dict:
    """Pooled relative RMSE over the mask (saturated pixels left out), overall and per light."""
    valid = held.mask[None] & ~held.saturated
    err = np.where(valid[..., None], predicted - held.images, 0.0)
    photo = np.where(valid[..., None], held.images, 0.0)
    e2, p2 = np.sum(err ** 2, axis=(1, 2, 3)), np.sum(photo ** 2, axis=(1, 2, 3))
    return {"relative_rmse": float(np.sqrt(e2.sum() / p2.sum())), "per_light": np.sqrt(e2 / p2).tolist()}


def normal_errors(normals: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> dict:
    error = ps.angular_error(normals, truth, mask)
    return {"mean": float(np.mean(error)), "median": float(np.median(error)),
            "within_5deg": float(np.mean(error < 5.0))}


def _save_predictions(path: Path, predicted: np.ndarray, held: diligent.DiligentObject) -> None:
    with atomic_write(path) as f:
        np.savez_compressed(f, images=predicted.astype(np.float32), filenames=np.array(held.filenames))


def run(data: Path, out: Path, models, rounds: int) -> dict:
    obj = diligent.read_object(data)
    train_index, held_index = diligent.light_split(len(obj.filenames))
    train, held = obj.select(train_index), obj.select(held_index)
    write_json(out / "split.json", {"rule": diligent.SPLIT_RULE, "train": train.filenames, "heldout": held.filenames})
    m = obj.mask
    ps_albedo, ps_normals = ps.fit(train.images, train.directions, m, train.saturated)
    predictions = {LAMBERTIAN: np.stack([ps.predict(ps_albedo, ps_normals, d) for d in held.directions])}
    estimates, normal_maps = {}, {LAMBERTIAN: ps_normals}
    for model in models:
        normal_maps[model], estimates[model] = estimate(train, model, rounds)
        values = np.zeros(held.images.shape, np.float32)
        values[:, m] = nm.predict(model, estimates[model].brdf.params, estimates[model].albedo,
                                  estimates[model].normals, held.directions)
        predictions[model] = values
    out.joinpath("heldout").mkdir(parents=True, exist_ok=True)
    for name, predicted in predictions.items():
        _save_predictions(out / "heldout" / f"{name}.npz", predicted, held)
    chosen = min(estimates, key=lambda name: estimates[name].loss)
    np.save(out / "normals.npy", normal_maps[chosen])
    print(f"all 96 lights, {chosen}:", flush=True)
    all_normals, all_estimate = estimate(obj, chosen, rounds)
    np.save(out / "normals_all.npy", all_normals)
    _, ps_all = ps.fit(obj.images, obj.directions, m, obj.saturated)
    # the ground truth, read only now, for the scores
    truth = diligent.read_normals(data)
    heldout = {name: relighting_error(p, held) for name, p in predictions.items()}
    return {
        "data": str(data), "split": diligent.SPLIT_RULE, "chosen_model": chosen, "rounds": rounds,
        "normals_half": {name: normal_errors(n, truth, m) for name, n in normal_maps.items()},
        "normals_all": {LAMBERTIAN: normal_errors(ps_all, truth, m), chosen: normal_errors(all_normals, truth, m)},
        "heldout": heldout,
        "heldout_rank": sorted(heldout, key=lambda name: heldout[name]["relative_rmse"]),
        "heldout_directions": held.directions.tolist(),
        "brdf": {name: {"params": e.brdf.params, "status": e.brdf.status, "training_loss": e.loss,
                        "history": e.history} for name, e in estimates.items()},
        "brdf_all": {"model": chosen, "params": all_estimate.brdf.params, "training_loss": all_estimate.loss,
                     "history": all_estimate.history},
        "_maps": {"half": normal_maps[chosen], "all": all_normals, "ps_all": ps_all, "truth": truth, "mask": m},
    }


def figure(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = results["_maps"]
    chosen = results["chosen_model"]
    fig, axes = plt.subplots(1, 5, figsize=(22, 4.4), gridspec_kw={"width_ratios": [1, 1, 1, 1.6, 1.2]})
    panels = [("Lambertian PS, 96 lights", maps["ps_all"], results["normals_all"][LAMBERTIAN]),
              (f"{chosen}, 96 lights", maps["all"], results["normals_all"][chosen]),
              (f"{chosen}, 48 training lights", maps["half"], results["normals_half"][chosen])]
    for ax, (title, normals, score) in zip(axes, panels):
        error = np.full(maps["mask"].shape, np.nan)
        error[maps["mask"]] = ps.angular_error(normals, maps["truth"], maps["mask"])
        image = ax.imshow(error, vmin=0, vmax=10, cmap="magma")
        ax.set_title(f"{title}\nmean {score['mean']:.2f}°, median {score['median']:.2f}°", fontsize=9)
        ax.axis("off")
    fig.colorbar(image, ax=axes[2], fraction=0.046, label="angular error (degrees)")
    ax = axes[3]
    polar = np.degrees(np.arccos(np.asarray(results["heldout_directions"])[:, 2]))
    order = np.argsort(polar)
    for name, entry in results["heldout"].items():
        style = {"color": "k", "lw": 2} if name == LAMBERTIAN else {}
        ax.plot(polar[order], np.asarray(entry["per_light"])[order], ".-", label=name, **style)
    ax.set_xlabel("held-out light's angle from the view axis (degrees)")
    ax.set_ylabel("relative RMSE")
    ax.set_title("held-out relighting error per light (48 lights)", fontsize=9)
    ax.legend(fontsize=8)
    ax = axes[4]
    names = results["heldout_rank"]
    ax.barh(names[::-1], [results["heldout"][n]["relative_rmse"] for n in names[::-1]],
            color=["k" if n == LAMBERTIAN else "C0" for n in names[::-1]])
    ax.set_xlabel("held-out relative RMSE (pooled)")
    ax.set_title("models trained on the same 48 lights", fontsize=9)
    fig.tight_layout()
    with atomic_write(path) as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=Path("../shared/data/diligent_ball"))
    parser.add_argument("--out", type=Path, default=Path("out/real_diligent"))
    parser.add_argument("--models", nargs="+", default=list(NAMES), choices=NAMES)
    parser.add_argument("--rounds", type=int, default=8, help="Most rounds of BRDF fit + normal step.")
    args = parser.parse_args()
    if not args.data.is_dir():
        raise SystemExit(f"DiLiGenT object not found at {args.data}")
    t0 = time.perf_counter()
    results = run(args.data, args.out, args.models, args.rounds)
    results["seconds"] = time.perf_counter() - t0
    figure(results, RESULTS / "real_diligent.png")
    del results["_maps"]
    write_json(RESULTS / "real_diligent.json", results)
    for key in ("normals_half", "normals_all"):
        print(key, {k: round(v["mean"], 2) for k, v in results[key].items()})
    print("held-out relative RMSE", {k: round(results["heldout"][k]["relative_rmse"], 4)
                                     for k in results["heldout_rank"]})


if __name__ == "__main__":
    main()
