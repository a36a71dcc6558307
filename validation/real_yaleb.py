"""Held-out relighting on real photographs: the Extended Yale Face Database B.

For each subject: import its photographs as a capture with N training lights
(``mifaces import yaleb``, the default deterministic split), measure it
(``mifaces measure``: landmarks, shape fit, reflectance samples, the four BRDF
fits), and render every held-out light with every fitted model, in the
capture's camera and the photographs' units (8-bit code / 255). Compare with
the held-out photographs, and with two baselines fitted to the same training
photographs:

* Lambertian photometric stereo (:mod:`mifaces.photometric_stereo`): per
  pixel albedo x normal by least squares, predicting albedo max(0, n . l);
* each model's own diffuse-only prediction: its fitted albedo map on its
  fitted shape, without the glossy part.

With ``--refine``, each model is also fitted again on the same shapes and
samples and refined by differentiable rendering against the same training
photographs (``mifaces.refine.refine_estimate`` after ``fit_brdf``, directional lights as the
capture gives them; :mod:`mifaces.refine.reflectance`), and its held-out
renders are scored beside the unrefined ones (``<model>_refined``): same
split, same pixels. Results then go to ``real_yaleb[_trainN]_refine.json``
and ``.png``.

The error is the pooled relative RMSE over the face (the pixels the fitted
face covers), sqrt(sum err^2 / sum photo^2) over all held-out images,
saturated pixels (code 255) excluded; separately for the lights more than
``--shadow-angle`` degrees from the camera axis, which cast large shadows.

Writes ``DIR/<subject>/capture`` (with ``split.json``), ``DIR/<subject>/measure``,
``DIR/<subject>/heldout/<model>/<stem>.exr`` (linear, 0 outside the face; with
``--refine`` also ``DIR/<subject>/refined/<model>`` and ``heldout/<model>_refined``) and
``mask.png``, ``validation/results/real_yaleb.json`` and ``real_yaleb.png``.

Real photographs: these figures are not simulated.

    python validation/real_yaleb.py --data ../shared/data/yaleb --out out/real_yaleb [--subjects yaleB01] [--train 8]
        [--refine] [--refine-shape] [--normals] [--interreflection] [--texel-albedo] [--balance-lights]

With ``--refine-shape``, the fitted faces are refined by differentiable rendering against the
training photographs (``mifaces measure --refine-shape``) before the BRDFs are fitted, and the
held-out lights are rendered on the refined faces (``measure/shapes_refined``, where the refinement
was kept): results in ``real_yaleb[_trainN]_refine_shape.{json,png}``, whose figure shows the
refined geometry's cast shadows beside the photographs.

With ``--normals``, each subject is measured twice, without and with per-texel
normals (``mifaces measure --normals``), and the held-out errors of both are
written to ``validation/results/real_yaleb_normals.{json,png}`` (:func:`comparison`);
with ``--interreflection`` likewise without and with the bounced light taken out
(``mifaces measure --interreflection``): ``real_yaleb_interreflection.{json,png}``; with
``--texel-albedo``, without and with an albedo per texel in the glossy fit (``mifaces measure
--texel-albedo``): ``real_yaleb_texel_albedo.{json,png}``; with ``--balance-lights``, without and with the
given lights balanced by the face's one albedo, failed lamps left out
(``mifaces.reflectance.light_balance.FAILED_LIGHT_FACTOR``), and balanced whatever their factors'
spread (the default leaves lights that spread beyond ``BALANCE_LIMIT`` as given, as every Yale
subject's do): ``real_yaleb_balance_lights.{json,png}``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

from mifaces import photometric_stereo
from mifaces.brdf import NAMES
from mifaces.capture import Light, load_capture
from mifaces.io.atomic import save_figure, write_json
from mifaces.io.image_files import write_exr, write_png
from mifaces.lights.environment import Environment
from mifaces.shape.io import load_geometry
from mifaces.importers.yaleb import default_split, import_subject, read_subject
from mifaces.pipeline.measure import SHAPES, NoUsableShapeError, measure
from mifaces.reflectance import FitOptions, fit_brdf, load_estimate
from mifaces.reflectance import light_balance
from mifaces.refine.shape import ShapeRefineSchedule
from mifaces.render import FaceScene
from mifaces.render.face_pixels import texture_coordinates, texture_lookup
from mifaces.validation.validator import relative_rmse
from mifaces.reflectance.io import write_fitted
from mifaces.refine import refine_estimate

RESULTS = Path(__file__).resolve().parent / "results"
#: Lights farther than this from the camera axis (degrees) count as casting large shadows.
SHADOW_ANGLE = 50.0
#: A photograph's saturated code.
SATURATED = 1.0 - 0.5 / 255


def face_mask(scene: FaceScene, camera) -> np.ndarray:
    """Pixels the fitted face covers: a white diffuse face under a uniform environment."""
    white = {"model": "phong", "options": {}, "regions": {"skin": {"specular_reflectance": 0.0, "exponent": 1.0}}}
    image = scene.render(white, np.ones((8, 8, 3), np.float32), camera,
                         environment=Environment(np.ones((8, 16, 3), np.float32)), spp=16, max_depth=2)
    return image.mean(axis=2) > 0.05


def diffuse_only(brdf: dict) -> dict:
    """``brdf`` without its glossy part (a Phong lobe of zero weight over the same albedo)."""
    return {"model": "phong", "options": {}, "regions": {r: {"specular_reflectance": 0.0, "exponent": 1.0}
                                                         for r in brdf["regions"]}}


def albedo_detail(albedo_map: np.ndarray, reference: np.ndarray, uv: np.ndarray, region_map: np.ndarray,
                  valid: np.ndarray) -> float:
    """Pearson r between the detail of a fitted albedo map seen through the fitted face (``uv``: each
    pixel's texture coordinate, :func:`mifaces.render.face_pixels.texture_coordinates`) and a per-pixel
    ``reference`` albedo (photometric stereo's), each less its mean over each region's pixels, over the
    ``valid`` pixels. The map's grey value; NaN where either has no spread (a map constant per region)."""
    ours = texture_lookup(np.asarray(albedo_map, np.float64).mean(axis=2), uv)
    ref = np.asarray(reference, np.float64)
    ref = ref.mean(axis=2) if ref.ndim == 3 else ref
    valid = valid & np.isfinite(ref) & ~np.isnan(uv[..., 0])
    region = texture_lookup(region_map, uv)
    x, y = np.zeros_like(ours), np.zeros_like(ref)
    for label in np.unique(region[valid]):
        chosen = valid & (region == label)
        x[chosen] = ours[chosen] - ours[chosen].mean()
        y[chosen] = ref[chosen] - ref[chosen].mean()
    if np.std(x[valid]) == 0 or np.std(y[valid]) == 0:
        return float("nan")
    return float(np.corrcoef(x[valid], y[valid])[0, 1])


class Errors:
    """Pooled squared errors and squared photograph values over held-out images."""

    def __init__(self):
        self.sums = {}

    def add(self, key: str, group: str, prediction, photo, valid) -> None:
        for g in ("all", group):
            e, p, n = self.sums.setdefault(key, {}).setdefault(g, [0.0, 0.0, 0])
            self.sums[key][g] = [e + float(np.sum((prediction[valid] - photo[valid]) ** 2)),
                                 p + float(np.sum(photo[valid] ** 2)), n + 1]

    def relative_rmse(self) -> dict:
        return {key: {g: float(np.sqrt(e / p)) if p > 0 else None for g, (e, p, _) in groups.items()}
                for key, groups in self.sums.items()}


def refine_models(capture, face, shapes, models, out: Path, resolution: int) -> dict:
    """Each model fitted on ``shapes`` and refined against the training
    photographs, written to ``out/<model>``; model -> the refinement record
    (image loss before and after, the lights' fitted gains, seconds)."""
    records = {}
    for model in models:
        estimate = refine_estimate(fit_brdf(capture, model, shapes, face_model=face, progress=True,
                                            options=FitOptions(resolution=resolution)), capture, shapes, face)
        write_fitted(estimate, out / model, capture, face, shapes, force=True)
        record = estimate.refinement
        records[model] = {"loss_before": record["loss_before"], "loss_after": record["loss_after"],
                          "heldout_loss_before": record["heldout_loss_before"],
                          "heldout_loss_after": record["heldout_loss_after"],
                          "accepted": record["accepted"], "reason": record["reason"],
                          "regions": record["regions"], "light_gains": record["light_gains"],
                          "seconds": round(record["seconds"]["total"], 1)}
        print(f"  {model} refined ({'kept' if record['accepted'] else 'not kept'}): image loss "
              f"{record['loss_before']:.4f} -> {record['loss_after']:.4f}, held-out pixels "
              f"{record['heldout_loss_before']:.4f} -> {record['heldout_loss_after']:.4f} "
              f"({record['seconds']['total']:.0f} s)", flush=True)
    return records


def subject_run(subject_dir: Path, out: Path, train: int, models, spp: int, shadow_angle: float,
                resolution: int, normals: bool | None = None, refine: bool = False, refine_shape=False,
                unknown_lights: bool = False, interreflection: bool = False, texel_albedo: bool | None = None,
                balance_lights: bool | None = None) -> dict:
    """Import, measure and relight one subject; its errors and timings. With ``unknown_lights`` the
    capture hides its light directions (``mifaces import yaleb --unknown-lights``) and ``measure``
    estimates them (``validation/unknown_lights.py``); the held-out lights are rendered as known.
    ``normals``, ``texel_albedo`` and ``balance_lights`` None: :class:`FitOptions`' defaults (per-texel normals
    on, the lights balanced)."""
    t0 = time.perf_counter()
    name = subject_dir.name
    capture_dir = import_subject(subject_dir, out / "capture", train=train, force=True, unknown_lights=unknown_lights)
    images = {image.stem: image for image in read_subject(subject_dir)}
    train_images, heldout = default_split(list(images.values()), train)
    t_measure = time.perf_counter()
    report = measure(out / "measure", capture_dir, models=models, progress=True, refine_shape=refine_shape,
                     options=FitOptions(resolution=resolution, interreflection=interreflection,
                                        **{k: v for k, v in (("normals", normals), ("texel_albedo", texel_albedo),
                                                             ("balance_lights", balance_lights)) if v is not None}))
    seconds = {"import": t_measure - t0, "measure": time.perf_counter() - t_measure}
    capture = load_capture(capture_dir, detect=False)
    # the faces the BRDFs were fitted on: the refined ones where this run kept a refinement
    folder = (report.get("shape_refinement") or {}).get("shapes", SHAPES)
    face, shapes = load_geometry(capture, out / "measure" / folder)
    first = next(m.name for m in capture.measurements if m.name in shapes)
    scene = FaceScene(face, shapes[first])
    mask = face_mask(scene, capture.camera)
    camera = capture.camera
    refined = {}
    if refine:
        t_refine = time.perf_counter()
        refined = refine_models(capture, face, shapes, models, out / "refined", resolution)
        seconds["refine"] = time.perf_counter() - t_refine
    # photometric stereo on the same training photographs, over the face
    stack = np.stack([i.pixels for i in train_images])
    albedo_ps, normals_ps = photometric_stereo.fit(stack, np.stack([i.direction for i in train_images]), mask,
                                                   saturated=stack >= SATURATED)
    # the lights are equal: render in the photographs' units with the capture's (relative) irradiance
    irradiance = capture.light(capture.measurements[0].light).intensity
    errors = Errors()
    per_light = {}
    estimates = {m: load_estimate(out / "measure" / "brdf" / m) for m in models}
    # the albedo maps' detail against photometric stereo's, seen through the fitted face; and photometric
    # stereo's own residual on the first training photograph, beside each fit's (report.json's training_rmse)
    uv = texture_coordinates(scene, camera)
    detail = {m: albedo_detail(estimates[m]["albedo"], albedo_ps, uv, face.region_map, mask) for m in models}
    first_photo = next(i for i in train_images if i.stem == first)
    training_ps = relative_rmse(photometric_stereo.predict(albedo_ps, normals_ps, first_photo.direction)[..., None],
                                first_photo.pixels[..., None], mask & (first_photo.pixels < SATURATED))
    estimates.update({f"{m}_refined": load_estimate(out / "refined" / m) for m in refined})

    def lamp(image) -> Light:
        """The photograph's light, in the capture's frame and units."""
        return Light(image.stem, None, irradiance, direction=camera.rotation.T @ image.direction)

    def relit(data: dict, light: Light, brdf: dict | None = None) -> np.ndarray:
        """A fitted face (``brdf``, default its own) rendered under ``light``, grey (channels averaged)."""
        return scene.render(data if brdf is None else brdf, data["albedo"], camera, light, spp=spp,
                            normals=data.get("normals"), specular=data.get("specular")).mean(axis=2)

    t_render = time.perf_counter()
    for model in estimates:
        write_png(out / "heldout" / model / "mask.png", np.repeat(mask[:, :, None], 3, axis=2).astype(np.float32),
                  srgb=False)
    for image in heldout:
        photo = image.pixels
        valid = mask & (photo < SATURATED)
        angle = np.degrees(np.arccos(np.clip(-image.direction[2], -1, 1)))
        group = "large_shadows" if angle > shadow_angle else "small_shadows"
        held_out = lamp(image)
        predictions = {"photometric_stereo": photometric_stereo.predict(albedo_ps, normals_ps, image.direction)}
        for model, data in estimates.items():
            rendered = relit(data, held_out)
            rendered[~mask] = 0.0
            write_exr(out / "heldout" / model / f"{image.stem}.exr", rendered[:, :, None].repeat(3, axis=2))
            predictions[model] = rendered
            if model.endswith("_refined"):
                continue
            predictions[f"{model}_diffuse_only"] = relit(data, held_out, diffuse_only(data))
        for key, prediction in predictions.items():
            errors.add(key, group, prediction, photo, valid)
        per_light[image.stem] = {"azimuth": image.azimuth, "elevation": image.elevation, "group": group,
                                 **{k: float(np.sqrt(np.sum((p[valid] - photo[valid]) ** 2) /
                                                     max(np.sum(photo[valid] ** 2), 1e-12)))
                                    for k, p in predictions.items()}}
    # every training photograph predicted as the held-out ones are: the fits' own residual, by which the best
    # model is chosen (the first photograph alone, report.json's training_rmse, favours a frontal light)
    training = Errors()
    for image in train_images:
        valid = mask & (image.pixels < SATURATED)
        training.add("photometric_stereo", "training",
                     photometric_stereo.predict(albedo_ps, normals_ps, image.direction), image.pixels, valid)
        for model, data in estimates.items():
            training.add(model, "training", relit(data, lamp(image)), image.pixels, valid)
    seconds["relight"] = time.perf_counter() - t_render
    seconds["total"] = time.perf_counter() - t0
    poses = {}
    for path in sorted((out / "measure" / "shapes").glob("*.json")):
        fit = json.loads(path.read_text())
        if "yaw_pitch_roll_deg" in fit:
            poses[fit["measurement"]] = fit["yaw_pitch_roll_deg"]
    return {"subject": name, "train": [i.stem for i in train_images], "heldout": len(heldout),
            "fitted_yaw_pitch_roll_deg": poses,
            "training_rmse": {m: report["models"][m].get("training_rmse") for m in models},
            "training_rmse_photometric_stereo": training_ps, "albedo_detail_r": detail,
            "training_relative_rmse": {k: v["all"] for k, v in training.relative_rmse().items()},
            "face_pixels": int(mask.sum()), "relative_rmse": errors.relative_rmse(), "per_light": per_light,
            "shapes": report.get("shapes"), "refinement": refined or None,
            "shape_refinement": report.get("shape_refinement"), "seconds": seconds, "errors": errors,
            "training_errors": training}


def spread(values) -> dict:
    """Mean, standard deviation (n - 1), least and largest of per-subject figures (NaN left out)."""
    values = np.asarray([v for v in values if v is not None and np.isfinite(v)], np.float64)
    if not len(values):
        return {"mean": None, "sd": None, "min": None, "max": None, "n": 0}
    return {"mean": float(values.mean()), "sd": float(values.std(ddof=1)) if len(values) > 1 else None,
            "min": float(values.min()), "max": float(values.max()), "n": int(len(values))}


def _pooled(errors: list[Errors]) -> dict:
    """The relative RMSE of several subjects' errors pooled: their sums added, per predictor and group."""
    total = Errors()
    for one in errors:
        for key, groups in one.sums.items():
            for g, (e, p, n) in groups.items():
                s = total.sums.setdefault(key, {}).setdefault(g, [0.0, 0.0, 0])
                total.sums[key][g] = [s[0] + e, s[1] + p, s[2] + n]
    return total.relative_rmse()


def summary(results: list[dict], models) -> dict:
    """Pooled over subjects: relative RMSE per predictor and group."""
    overall = _pooled([r["errors"] for r in results])
    # the best model by its error on the training photographs, all of them pooled over the subjects as the
    # held-out error is (never by the held-out error it is scored on)
    pooled = _pooled([r["training_errors"] for r in results])
    training = {m: float(np.mean([r["training_rmse"][m] for r in results])) for m in models}
    best = min(models, key=lambda m: pooled[m]["all"])
    pitch = [p[1] for r in results for p in r.get("fitted_yaw_pitch_roll_deg", {}).values()]
    out = {"relative_rmse": overall, "best_model": best,
           "best_model_chosen_by": "pooled relative RMSE over every training photograph",
           "training_relative_rmse": {k: v["all"] for k, v in pooled.items()},
           "best_model_by_first_photograph": min(models, key=lambda m: training[m]),
           "training_rmse": training, "lowest_heldout_model": min(models, key=lambda m: overall[m]["all"]),
           "fitted_pitch_deg": {"mean": float(np.mean(pitch)), "max_abs": float(np.max(np.abs(pitch)))}
           if pitch else None,
           "best_vs_photometric_stereo": overall[best]["all"] / overall["photometric_stereo"]["all"],
           "training_rmse_photometric_stereo": float(np.mean([r["training_rmse_photometric_stereo"] for r in results])),
           # the spread over subjects (each subject's own pooled error), and the albedo maps' detail
           "per_subject": {key: spread([r["relative_rmse"][key]["all"] for r in results]) for key in overall},
           "albedo_detail_r": {m: spread([r["albedo_detail_r"][m] for r in results]) for m in models}}
    if f"{best}_refined" in overall:
        out["refined_vs_unrefined"] = {m: {g: overall[f"{m}_refined"][g] / overall[m][g] for g in overall[m]}
                                       for m in models}
        out["best_refined_vs_photometric_stereo"] = (overall[f"{best}_refined"]["all"]
                                                     / overall["photometric_stereo"]["all"])
    return out


def figure(results: list[dict], out: Path, data_dir: Path, run_dir: Path, best: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mifaces.io.image_files import read_exr

    r = results[0]
    lights = sorted(r["per_light"], key=lambda s: r["per_light"][s]["azimuth"])
    chosen = [lights[len(lights) // 5], lights[len(lights) // 2], lights[4 * len(lights) // 5]]
    images = {i.stem: i for i in read_subject(data_dir / r["subject"])}
    fig = plt.figure(figsize=(12, 3.2 * len(chosen) + 3.5))
    grid = fig.add_gridspec(len(chosen) + 1, 4, height_ratios=[1] * len(chosen) + [1.1])
    for row, stem in enumerate(chosen):
        photo = images[stem].pixels
        predicted = read_exr(run_dir / r["subject"] / "heldout" / best / f"{stem}.exr")[:, :, 0]
        info = r["per_light"][stem]
        last = (None, "")
        if f"{best}_refined" in info:  # --refine: the refined model's render beside it
            refined = read_exr(run_dir / r["subject"] / "heldout" / f"{best}_refined" / f"{stem}.exr")[:, :, 0]
            last = (refined, f"{best} refined (rel. RMSE {info[f'{best}_refined']:.2f})")
        for col, (img, title) in enumerate([(photo, f"photograph {stem[-9:]}"),
                                            (predicted, f"{best} (rel. RMSE {info[best]:.2f})"),
                                            (np.abs(predicted - photo), "|difference|"), last]):
            if img is None:
                continue
            ax = fig.add_subplot(grid[row, col])
            ax.imshow(np.clip(img, 0, 1), cmap="gray", vmin=0, vmax=1)
            ax.set_title(title, fontsize=9)
            ax.axis("off")
    for col, key in enumerate([best, "photometric_stereo"]):
        ax = fig.add_subplot(grid[len(chosen), 2 * col:2 * col + 2])
        az = [v["azimuth"] for res in results for v in res["per_light"].values()]
        el = [v["elevation"] for res in results for v in res["per_light"].values()]
        err = [v[key] for res in results for v in res["per_light"].values()]
        points = ax.scatter(az, el, c=np.clip(err, 0, 1.5), cmap="viridis", vmin=0, vmax=1.5, s=28)
        ax.set_xlabel("light azimuth (deg)")
        ax.set_ylabel("elevation (deg)")
        ax.set_title(f"held-out relative RMSE per light: {key}", fontsize=9)
        fig.colorbar(points, ax=ax)
    refinement = r.get("shape_refinement") or {}
    geometry = ("; faces refined by differentiable rendering" if refinement.get("accepted") else
                f"; shape refinement not kept: {refinement['reason']}" if refinement else "")
    fig.suptitle(f"Real photographs (Extended Yale B, {r['subject']}): held-out lights, predicted from "
                 f"{len(r['train'])} training photographs{geometry}", fontsize=10)
    fig.tight_layout()
    save_figure(fig, out, dpi=80)


def comparison(args, subjects, models, argv, option: str = "normals") -> int:
    """Each subject measured without and with ``option`` of :class:`FitOptions` (``normals``: per-texel
    normals; ``interreflection``: the bounced light taken out; ``texel_albedo``: an albedo per texel in the glossy
    fit; ``balance_lights``: the given lights balanced; ``measure(..., options=FitOptions(<option>=True))``,
    into ``DIR/<subject>`` and ``DIR/<subject>_<option>``): held-out relative RMSE of both, pooled and per
    subject, in ``real_yaleb_<option>.{json,png}``. A subject with no usable face shape is left out of both
    (``failed_subjects``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if option == "balance_lights":  # balanced whatever the factors' spread: what the default's limit refuses
        light_balance.BALANCE_LIMIT = np.inf
    runs, failed = {}, {}
    for label, on in (("without", False), ("with", True)):
        results = []
        for subject in [s for s in subjects if s not in failed]:
            print(f"== {subject} ({label} {option})", flush=True)
            folder = args.out / (subject + (f"_{option}" if on else ""))
            try:
                results.append(subject_run(args.data / subject, folder, args.train, models, args.spp,
                                           args.shadow_angle, args.resolution, **{option: on}))
            except NoUsableShapeError as error:  # one subject's failure is recorded; the others go on
                failed[subject] = str(error).split("; ")[0][:400]
                print(f"{subject}: no usable face shape, left out: {failed[subject]}", flush=True)
        results = [r for r in results if r["subject"] not in failed]
        runs[label] = {"overall": summary(results, models),
                       "subjects": {r["subject"]: r["relative_rmse"] for r in results},
                       "seconds": {r["subject"]: r["seconds"] for r in results}}
    subjects = [s for s in subjects if s not in failed]
    best = runs["without"]["overall"]["best_model"]
    document = {"data": "Extended Yale Face Database B (cropped), real photographs", "train_lights": args.train,
                "models": list(models), "spp": args.spp, "texture_resolution": args.resolution, "option": option,
                "command": "python validation/real_yaleb.py " + " ".join(argv if argv is not None else sys.argv[1:]),
                "best_model_without": best, "runs": runs,
                "failed_subjects": [{"subject": s, "error": e} for s, e in failed.items()],
                "best_model_error": {k: runs[k]["overall"]["relative_rmse"][best]["all"] for k in runs}}
    write_json(args.results / f"real_yaleb_{option}.json", document)
    fig, ax = plt.subplots(figsize=(8, 4))
    names = subjects + ["pooled"]
    x = np.arange(len(names))
    bars = {"photometric stereo": [runs["without"]["subjects"][s]["photometric_stereo"]["all"] for s in subjects]
            + [runs["without"]["overall"]["relative_rmse"]["photometric_stereo"]["all"]]}
    for k in runs:
        bars[f"{best}, {k} {option}"] = ([runs[k]["subjects"][s][best]["all"] for s in subjects]
                                        + [runs[k]["overall"]["relative_rmse"][best]["all"]])
    for i, (label, values) in enumerate(bars.items()):
        ax.bar(x + (i - 1) * 0.27, values, 0.27, label=label)
    ax.set_xticks(x, names)
    ax.set_ylabel("held-out relative RMSE")
    ax.set_title(f"Yale B, real photographs: held-out relighting ({args.train} training lights)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, args.results / f"real_yaleb_{option}.png", dpi=110)
    print(f"{best}: {document['best_model_error']['without']:.4f} without, {document['best_model_error']['with']:.4f} "
          f"with {option}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/yaleb")
    parser.add_argument("--out", type=Path, default=Path("out/real_yaleb"))
    parser.add_argument("--subjects", default=None, help="comma-separated subject folders (default: all)")
    parser.add_argument("--train", type=int, default=8)
    parser.add_argument("--models", default=",".join(NAMES))
    parser.add_argument("--spp", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=256, help="texture resolution of the fits")
    parser.add_argument("--shadow-angle", type=float, default=SHADOW_ANGLE)
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--normals", action="store_true",
                        help="measure without and with per-texel normals; write real_yaleb_normals.{json,png}")
    parser.add_argument("--interreflection", action="store_true",
                        help="measure without and with the bounced light taken out; write "
                             "real_yaleb_interreflection.{json,png}")
    parser.add_argument("--texel-albedo", action="store_true",
                        help="measure without and with an albedo per texel in the glossy fit; write "
                             "real_yaleb_texel_albedo.{json,png}")
    parser.add_argument("--balance-lights", action="store_true",
                        help="measure without and with the given lights balanced; write "
                             "real_yaleb_balance_lights.{json,png}")
    parser.add_argument("--refine", action="store_true",
                        help="also refine each fit by differentiable rendering and score it beside the unrefined")
    parser.add_argument("--refine-shape", action="store_true",
                        help="refine the fitted faces by differentiable rendering (measure --refine-shape)")
    parser.add_argument("--refine-shape-judged", type=int, default=ShapeRefineSchedule.judged,
                        help="photographs held out of the shape refinement to judge it by (measure "
                             "--refine-shape-judged); above 0 the results' name ends in _judged")
    parser.add_argument("--refine-shape-early-stop", action="store_true",
                        help="half of the shape refinement's held-out pixels choose its iteration (measure "
                             "--refine-shape-early-stop); the results' name ends in _early_stop")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"no Yale data at {args.data}: nothing to validate", file=sys.stderr)
        return 1
    subjects = args.subjects.split(",") if args.subjects else sorted(p.name for p in args.data.iterdir() if p.is_dir())
    models = tuple(args.models.split(","))
    if args.normals:
        return comparison(args, subjects, models, argv, "normals")
    if args.interreflection:
        return comparison(args, subjects, models, argv, "interreflection")
    if args.texel_albedo:
        return comparison(args, subjects, models, argv, "texel_albedo")
    if args.balance_lights:
        return comparison(args, subjects, models, argv, "balance_lights")
    results, failed = [], []
    for subject in subjects:
        print(f"== {subject}", flush=True)
        try:
            results.append(subject_run(args.data / subject, args.out / subject, args.train, models, args.spp,
                                       args.shadow_angle, args.resolution, refine=args.refine,
                                       refine_shape=args.refine_shape
                                       and ShapeRefineSchedule(judged=args.refine_shape_judged,
                                                               early_stop=args.refine_shape_early_stop)))
        except NoUsableShapeError as error:  # one subject's failure is recorded; the others go on
            failed.append({"subject": subject, "error": str(error).split("; ")[0][:400]})
            print(f"{subject}: no usable face shape, left out: {failed[-1]['error']}", flush=True)
            continue
        print({k: round(v["all"], 4) for k, v in results[-1]["relative_rmse"].items()}, flush=True)
    if not results:
        print("no subject could be measured", file=sys.stderr)
        return 1
    overall = summary(results, models)
    document = {"data": "Extended Yale Face Database B (cropped), real photographs", "train_lights": args.train,
                "models": list(models), "spp": args.spp, "texture_resolution": args.resolution,
                "shadow_angle_deg": args.shadow_angle, "refine": args.refine, "refine_shape": args.refine_shape,
                "refine_shape_judged": args.refine_shape_judged if args.refine_shape else None,
                "refine_shape_early_stop": args.refine_shape_early_stop if args.refine_shape else None,
                "command": "python validation/real_yaleb.py " + " ".join(argv if argv is not None else sys.argv[1:]),
                "overall": overall, "failed_subjects": failed,
                "subjects": [{k: v for k, v in r.items() if k not in ("errors", "training_errors")} for r in results]}
    suffix = (("" if args.train == 8 else f"_train{args.train}") + ("_refine" if args.refine else "")
              + ("_refine_shape" if args.refine_shape else "")
              + ("_judged" if args.refine_shape and args.refine_shape_judged else "")
              + ("_early_stop" if args.refine_shape and args.refine_shape_early_stop else ""))
    write_json(args.results / f"real_yaleb{suffix}.json", document)
    figure(results, args.results / f"real_yaleb{suffix}.png", args.data, args.out, overall["best_model"])
    print(f"best model {overall['best_model']}: {overall['relative_rmse'][overall['best_model']]['all']:.4f} "
          f"against photometric stereo {overall['relative_rmse']['photometric_stereo']['all']:.4f}")
    if args.refine:
        print("refined / unrefined held-out relative RMSE: "
              + ", ".join(f"{m} {v['all']:.4f}" for m, v in overall["refined_vs_unrefined"].items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
