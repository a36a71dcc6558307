"""The tables of ``docs/results.md`` for the refinement, the shape fit and its depth, the albedo
rounds and the uncertainty (one function per result layout, used by ``validation/results_doc.py``)."""

from __future__ import annotations

from results_format import DASH, fixed, get, items, listed, mean, num, pct, rows_of, table, text


def sec_refine(d):
    capture = d.get("capture") or {}
    schedule = d.get("schedule") or {}
    lines = [f"{text(d.get('what'))}.", "",
             f"Capture: {text(capture.get('measurements'))} measurements at {text(capture.get('image'))}², texture "
             f"{text(capture.get('texture_resolution'))}²; {text(schedule.get('iterations'))} iterations at "
             f"{text(schedule.get('spp'))} spp.", ""]
    before = get(d, "errors", "texture_space", "regions") or {}
    after = get(d, "errors", "refined", "regions") or {}
    regions = list(before) + [r for r in after if r not in before]
    lines += table(["region", "ρs error, texture space", "ρs error, refined", "roughness error, texture space",
                    "roughness error, refined"],
                   [[region, pct(get(before, region, "specular_reflectance")),
                     pct(get(after, region, "specular_reflectance")), pct(get(before, region, "roughness")),
                     pct(get(after, region, "roughness"))] for region in regions])
    held = d.get("held_out_light_relative_rmse") or {}
    lines += table(["", "texture space", "refined"], [
        ["albedo RMSE", fixed(get(d, "errors", "texture_space", "albedo_rmse_sampled"), 4),
         fixed(get(d, "errors", "refined", "albedo_rmse_sampled"), 4)],
        ["held-out light relative RMSE", pct(held.get("texture-space")), pct(held.get("refined"))],
        ["image loss", num(get(d, "image_loss", "before")), num(get(d, "image_loss", "after"))],
        ["seconds", fixed(get(d, "cost", "texture_space_fit_seconds"), 1),
         fixed(get(d, "cost", "refine_seconds", "total"), 1)],
    ])
    return lines + listed("Targets met", d.get("targets_met"))


def sec_light_calibration_bias(d):
    lines = [f"Seeds {text(d.get('seeds'))} ({text(d.get('role'))}); Cook–Torrance truth, the default fit with the "
             "capture's calibrated lights, with them balanced by the face's one albedo (`balance_lights`, where "
             "the file has it), and with the simulator's true ones.", ""]
    rows = []
    for lights, v in items(d.get("summary")):
        if not isinstance(v, dict) or "pooled_coverage" not in v:  # the balance's sweep: below
            continue
        errors = v.get("skin_mean_abs_relative_error") or {}
        rows.append([lights, pct(errors.get("specular_reflectance")), pct(errors.get("roughness")),
                     pct(v.get("skin_coverage"), 0), pct(v.get("pooled_coverage"), 0)])
    lines += table(["lights", "skin ρs error", "skin m error", "skin coverage", "pooled coverage"], rows)
    sweep = get(d, "summary", "balance_sweep", default=None)
    if sweep:
        lines += [f"The balance's error against the true calibration errors (mean |log|), reading the samples whose "
                  f"half vector's cosine to the normal is at most the threshold (the default "
                  f"{text(get(d, 'summary', 'balance_max_half_cosine'))}):", ""]
        lines += table(["threshold", "mean error"], [[k, pct(v, 2)] for k, v in items(sweep)])
    per_seed = []
    for r in rows_of(d.get("rows")):
        skin = {(s.get("parameter"), s.get("channel")): s for s in r.get("skin") or []}
        rho = [v.get("fitted") for (p, _), v in skin.items() if p == "specular_reflectance"]
        truth = [v.get("truth") for (p, _), v in skin.items() if p == "specular_reflectance"]
        balance = r.get("light_balance") or {}
        errors = r.get("true_light_errors") or {}
        per_seed.append([text(r.get("seed")), text(r.get("lights")), num(mean(rho)) if rho else DASH,
                         num(mean(truth)) if truth else DASH,
                         ", ".join(f"{k} {num(v, 4)}" for k, v in balance.items()) or DASH,
                         ", ".join(f"{k} {num(v, 4)}" for k, v in errors.items()) or DASH])
    lines += table(["seed", "lights", "skin ρs (mean over channels)", "truth", "balance factors",
                    "true calibration errors"], per_seed)
    return lines


def sec_refine_gradient(d):
    cases = list(items(d.get("cases")))
    lines = [f"{text(d.get('what'))}; seed {text(d.get('seed'))}, {text(d.get('image'))}², "
             f"{text(d.get('repeats'))} Monte Carlo seeds per photograph. The loss's minimum along each parameter "
             "alone (a Newton step from the truth):", ""]
    first = cases[0][1].get("variables") if cases else {}
    rows = []
    for key, v in items(first):
        channel = v.get("channel")
        label = f"{text(v.get('region'))} {text(v.get('parameter'))}" + (f" [{channel}]" if channel is not None else "")
        rows.append([label, num(v.get("true_value"), 4)]
                    + [num(get(c, "variables", key, "value_at_minimum"), 4) for _, c in cases])
    lines += table(["parameter", "truth", *[f"`{name}`" for name, _ in cases]], rows)
    lines += ["Photograph over render at the truth, per photograph (mean over channels):", ""]
    photos = list(items(cases[0][1].get("photograph_over_render"))) if cases else []
    lines += table(["case", *[name for name, _ in photos]],
                   [[f"`{name}`", *[num(mean(get(c, "photograph_over_render", p)), 4) for p, _ in photos]]
                    for name, c in cases])
    return lines


def sec_refine_seeds(d):
    role = text(d.get("role"))
    lines = [f"{text(d.get('what'))}.", "",
             f"Seeds {', '.join(text(s.get('seed')) for s in d.get('seeds') or [])} ({role} captures"
             + ("; they chose the defaults" if role == "training" else "; they played no part in choosing the "
                "defaults") + f"), images {text(d.get('image'))}², texture {text(d.get('texture_resolution'))}²; "
             f"the default schedule is the variant `{text(d.get('default_variant'))}`. Mean over the seeds of the "
             "relative errors against the truth:", ""]
    columns = [("skin", "specular_reflectance"), ("skin", "roughness"), ("beard", "specular_reflectance"),
               ("lips", "specular_reflectance"), ("eyebrows", "specular_reflectance"), ("hair", "specular_reflectance"),
               ("eyes", "roughness")]
    rows = []
    for name, v in items(d.get("summary")):
        rows.append([f"`{name}`", *[pct(get(v, "regions", r, p)) for r, p in columns],
                     pct(get(v, "novel_light_relative_rmse"), 2), text(v.get("kept", "–"))])
    lines += table(["variant", *[f"{r} {'ρs' if p == 'specular_reflectance' else 'm'}" for r, p in columns],
                    "novel light RMSE", "kept"], rows)
    gains = []
    for s in d.get("seeds") or []:
        true = s.get("true_light_gains") or {}
        for name, v in items(s.get("variants")):
            if (v.get("light_gains") or {}) and any(abs(g - 1.0) > 0 for g in v["light_gains"].values()):
                gains.append([text(s.get("seed")), f"`{name}`", ", ".join(
                    f"{light} {num(g, 4)} ({num(true.get(light), 4)})" for light, g in v["light_gains"].items())])
    if gains:
        lines += ["Fitted light gains (the calibrated lights' true irradiance error at the face in brackets):", ""]
        lines += table(["seed", "variant", "gains"], gains)
    return lines


def sec_shape_estimation(d):
    lines = ["Mean over each capture's measurements (the truth's vertices that face the camera); `aligned`: after "
             "a rigid alignment; `nn`: against the nearest true vertex.", ""]
    rows = []
    for capture, c in items(d.get("captures")):
        for method, s in items(get(c, "summary")):
            rows.append([f"{capture} ({text(get(c, 'model'))})", method, fixed(get(s, "landmark_px"), 2),
                         fixed(get(s, "normal_deg"), 2), fixed(get(s, "normal_aligned_nn_deg"), 2),
                         fixed(get(s, "vertex_rms_aligned_mm"), 2), fixed(get(s, "seconds"), 2),
                         text(get(s, "converged"))])
    lines += table(["capture (model)", "method", "landmarks (px)", "normals (°)", "normals aligned nn (°)",
                    "vertices aligned (mm)", "seconds", "converged"], rows)
    lines += ["BRDF fit (texture space) on the true and on the fitted shapes: relative errors of each region's "
              "parameters, albedo RMSE.", ""]
    rows = []
    for capture, b in items(d.get("brdf")):
        for shapes, r in items(b):
            for region, e in items(get(r, "regions")):
                rows.append([capture, shapes, region, pct(get(e, "specular_reflectance_rel")),
                             pct(get(e, "roughness_rel")), fixed(get(r, "albedo_rmse"), 4)])
    lines += table(["capture", "shapes", "region", "ρs error", "roughness error", "albedo RMSE"], rows)
    sweep = rows_of(d.get("sweep"))
    if sweep:
        lines += ["Schedule sweep (one measurement):", ""]
        lines += table(["resolution", "schedule factor", "iterations", "seconds", "landmarks (px)", "normals (°)",
                        "vertices aligned (mm)"],
                       [[text(s.get("resolution")), text(s.get("factor")), text(s.get("iterations")),
                         fixed(s.get("seconds"), 2), fixed(s.get("landmark_px"), 2), fixed(s.get("normal_deg"), 2),
                         fixed(s.get("vertex_rms_aligned_mm"), 2)] for s in sweep])
    return lines + listed("Targets", d.get("targets"))


def sec_truths(d):
    lines = [f"Machine: {text(d.get('machine'))}. Per truth and fitted model the report's validation: relative RMSE "
             "under the held-out lights and the environments (fitted shapes, and the fitted reflectance on the true "
             "shape), skin's BRDF error over the hemisphere, albedo RMSE. `shape floor`: the true reflectance on the "
             "fitted shapes. `noise floor`: the true face against itself rendered with other random numbers (the "
             "renders' Monte Carlo noise; the errors compare images rendered with the same random numbers, where "
             "most of it cancels); a dash where the run predates it.", ""]
    rows = []
    for name, t in items(d.get("truths")):
        floor = get(t, "shape_floor") or {}
        rows.append([name, "shape floor", pct(floor.get("heldout_rmse")), pct(floor.get("environment_rmse")), DASH,
                     DASH, DASH, DASH])
        noise = get(t, "noise_floor") or {}
        rows.append([name, "noise floor", pct(noise.get("heldout_rmse")), pct(noise.get("environment_rmse")), DASH,
                     DASH, DASH, DASH])
        for model, m in items(get(t, "models")):
            v = get(m, "validation") or {}
            rows.append([name, model, pct(v.get("heldout_rmse")), pct(v.get("environment_rmse")),
                         pct(v.get("heldout_rmse_true_shape")), pct(v.get("environment_rmse_true_shape")),
                         pct(get(v, "brdf_rmse", "skin")), fixed(v.get("albedo_rmse"), 4)])
    return lines + table(["truth", "model", "held-out", "environments", "held-out, true shape",
                          "environments, true shape", "skin BRDF", "albedo RMSE"], rows)


def sec_albedo_rounds(d):
    spp = f", {text(get(d, 'spp'))} samples per pixel" if get(d, "spp", default=None) is not None else ""
    lines = [f"Images {text(get(d, 'image'))}{spp}, {text(get(d, 'measurements'))} photographs, texture "
             f"{text(get(d, 'texture'))}², tuning seeds. Coverage of the 95 % intervals per truth, number of "
             "alternations and estimate, pooled over seeds, regions, parameters and channels (intervals in "
             "brackets), and on skin, small regions (lips, eyebrows) and the others; skin's mean relative error "
             "per parameter (RGB parameters as the mean over channels).", ""]
    rows = []
    for model, per_rounds in items(get(d, "summary")):
        for rounds, entry in items(per_rounds):
            error = ", ".join(f"{name} {pct(get(e, 'mean_relative_error'), 1)}"
                              for name, e in items(get(entry, "skin_error")))
            for variant, cov in items(get(entry, "coverage")):
                cells = [f"{pct(get(cov, c, 'coverage'), 0)} ({text(get(cov, c, 'intervals'))})"
                         for c in ("pooled", "skin", "small", "others")]
                rows.append([text(model), text(rounds), text(variant), *cells, error])
    lines += table(["truth and model", "alternations", "estimate", "pooled", "skin", "small", "others",
                    "skin error"], rows)
    rows = []
    for row in rows_of(get(d, "rows")):
        skin = ", ".join(f"{s.get('parameter')}{'' if s.get('channel') is None else '[' + str(s.get('channel')) + ']'}"
                         f" {fixed(s.get('fitted'), 3)} ({fixed(s.get('truth'), 3)})"
                         for s in rows_of(get(row, "skin")))
        rows.append([text(get(row, "model")), text(get(row, "seed")), text(get(row, "albedo_rounds")),
                     pct(get(row, "coverage"), 0), text(get(row, "intervals")), skin])
    return lines + ["Per capture, the default estimate:", ""] + table(
        ["truth and model", "seed", "alternations", "coverage", "intervals", "skin"], rows)


def sec_albedo_rounds_cost(d):
    lines = [f"The region fits' time (`seconds['fit']`, best of {text(get(d, 'repeats'))} interleaved runs) without "
             f"and with the {text(get(d, 'method'))} intervals, medians over captures and models; `intervals`: the "
             "time spent computing them, and its share of the fit without; `against one fit`: with intervals, over "
             "the one region fit without.", ""]
    rows = [[text(get(e, "texture")), text(get(e, "albedo_rounds")), fixed(get(e, "without_median"), 3),
             fixed(get(e, "with_median"), 3), pct(get(e, "overhead_median"), 0), fixed(get(e, "intervals_median"), 3),
             pct(get(e, "intervals_share_median"), 1), fixed(get(e, "against_one_region_fit_median"), 2)]
            for _, e in items(get(d, "summary"))]
    return lines + table(["texture", "alternations", "fit without (s)", "with (s)", "difference", "intervals (s)",
                          "intervals' share", "against one fit"], rows)


def sec_albedo_rounds_exact(d):
    lines = [f"{text(get(d, 'model'))} truth, seed {text(get(d, 'seed'))}, {text(get(d, 'albedo_rounds'))} "
             f"alternations, {text(get(d, 'region'))} ({text(get(d, 'samples'))} samples, {text(get(d, 'tiles'))} "
             "tiles): the standard deviation of each fitted parameter by the one-step replicates of the intervals "
             "against the jackknife that reruns the alternation with each tile left out.", ""]
    rows = [[text(get(e, "parameter")) + ("" if get(e, "channel") is None else f"[{get(e, 'channel')}]"),
             fixed(get(e, "fitted"), 4), fixed(get(e, "truth"), 4), fixed(get(e, "std_one_step"), 5),
             fixed(get(e, "std_exact"), 5)] for e in rows_of(get(d, "entries"))]
    return lines + table(["parameter", "fitted", "truth", "std, one step", "std, refits"], rows)


def sec_refine_shape_default(d):
    k = get(d, "downsample")
    lines = [f"Capture {text(get(d, 'resolution'))}², seed {text(get(d, 'seed'))}"
             + ("" if k is None else f", rendered at 1/{k} of its resolution") + "; refinement "
             f"{'kept' if get(d, 'accepted') else 'not kept'}: {text(get(d, 'reason'))}; "
             f"{fixed(get(d, 'seconds', 'refine'), 0)} s to refine. World-frame errors of the faces against the "
             "truth (mm, front of the face):", ""]
    rows = []
    for label, key in (("model fit", "model_fit"), ("returned by the refinement", "refined"),
                       ("displaced, kept or not", "displaced")):
        summary_ = get(d, "shape_errors", key, "summary") or {}
        if not summary_:
            continue
        rows.append([label, fixed(summary_.get("mean_world_mm"), 2), fixed(summary_.get("max_world_mm"), 2),
                     fixed(summary_.get("mean_aligned_mm"), 2), fixed(summary_.get("max_abs_depth_mm"), 2),
                     fixed(summary_.get("mean_normal_deg"), 2)])
    return lines + table(["faces", "world, mean", "world, max", "after rigid alignment, mean",
                          "largest depth offset", "normals, mean (°)"], rows)


def sec_light_balance_measure(d):
    seeds = ", ".join(text(r.get("seed")) for r in rows_of(d.get("seeds")))
    lines = [f"Seeds {seeds or DASH} "
             f"({text(d.get('role'))}); `mifaces measure` on the default capture with the lights as given and balanced "
             "(`--balance-lights`). Means over the seeds; in brackets, on how many seeds the balance lowered the "
             "figure.", ""]
    given, balanced = get(d, "summary", "given") or {}, get(d, "summary", "balanced") or {}
    lower = get(d, "summary", "balanced_lower_on_seeds") or {}
    rows = []
    for model, g in items(given):
        b, n = balanced.get(model) or {}, lower.get(model) or {}
        rows.append([text(model)] + [f"{pct(g.get(k), 2)} → {pct(b.get(k), 2)} ({text(n.get(k))})"
                                     for k in ("skin_brdf_rmse", "heldout_rmse", "environment_rmse",
                                               "heldout_rmse_true_shape")])
    return lines + table(["model", "skin BRDF error", "held-out lights", "environments",
                          "held-out lights, true shape"], rows)


def sec_floor_depth(d):
    lines = [f"Default capture (512², six photographs), seeds {text(', '.join(map(str, get(d, 'seeds') or [])))}; "
             "the shape floor (the true reflectance on a face, in a novel pose under the held-out lights; the "
             "report validates the first photograph) of each photograph's fitted face, of that face moved along "
             "the camera's axis by its depth offset, of it rigidly aligned onto the truth, and of the true face "
             f"moved by the fitted depth offset. Aim: {pct(get(d, 'floor_target'), 0)}.", ""]
    rows, sums = [], []
    for run in rows_of(get(d, "runs")):
        for name, p in items(get(run, "photographs")):
            rows.append([text(run.get("seed")), text(name), fixed(get(p, "fitted", "depth_mm"), 2),
                         *(pct(get(p, key, "shape_floor"), 1) for key in
                           ("fitted", "depth_removed", "aligned", "truth_at_fitted_depth", "truth_1mm_deeper")),
                         pct(get(p, "noise_floor"), 1)])
        for key, s in items(get(run, "summary")):
            sums.append([text(run.get("seed")), text(key), pct(s.get("mean_shape_floor"), 1),
                         pct(s.get("max_shape_floor"), 1)])
    return (lines + table(["seed", "photograph", "depth offset (mm)", "as fitted", "depth offset removed",
                           "rigidly aligned", "true face at the fitted depth", "true face 1 mm deeper",
                           "noise floor"], rows)
            + ["", "Over the photographs:", ""] + table(["seed", "face", "mean", "largest"], sums))


def sec_depth_cameras(d):
    settings = d.get("settings") or {}
    seen = [n for r in rows_of(d.get("runs")) for n in (r.get("feature_points_seen") or [])]
    lines = [f"Seeds {text([r.get('seed') for r in rows_of(d.get('runs'))])}, {text(settings.get('measurements'))} "
             f"poses each, {text(seen and min(seen))}–{text(seen and max(seen))} feature points clicked with "
             f"{text(settings.get('click_px_at_512'))} px noise at {text(settings.get('resolution'))}², "
             f"{text(settings.get('draws'))} draws; the second camera turned by the angle about the head's vertical "
             f"axis at the same {text(settings.get('camera_distance_mm'))} mm. Errors of the feature points' "
             "centroid along the first camera's axis, mean over the seeds.", ""]
    rows = [[text(key), fixed(e.get("depth_sd_mm"), 2), fixed(e.get("depth_mean_abs_mm"), 2),
             fixed(e.get("point_error_mm"), 2)] for key, e in items(d.get("mean_over_seeds"))]
    return lines + table(["estimate", "depth, standard deviation (mm)", "depth, mean absolute (mm)",
                          "feature points, mean error (mm)"], rows)


def sec_multi_camera(d):
    settings = d.get("settings") or {}
    lines = [f"The default capture at {text(settings.get('resolution'))}², seeds "
             f"{text(', '.join(map(str, settings.get('seeds') or [])))} (report seeds), photographed by one camera "
             "and by a rig of three (`simulate --cameras 3`); the default shape fit, then the Cook–Torrance fit. "
             "Shots: each head pose once (mm; the depth offset as an absolute value along the first camera's axis); "
             "the albedo map against the truth's.", ""]
    rows = []
    for run in rows_of(d.get("runs")):
        s, a = run.get("shots") or {}, run.get("albedo") or {}
        rows.append([text(run.get("seed")), text(run.get("cameras")), f"{text(run.get('converged'))}/{text(run.get('fits'))}",
                     f"{fixed(s.get('mean_world_mm'), 2)}, {fixed(s.get('max_world_mm'), 2)}",
                     f"{fixed(s.get('mean_aligned_mm'), 2)}, {fixed(s.get('max_aligned_mm'), 2)}",
                     f"{fixed(s.get('mean_depth_mm'), 2)}, {fixed(s.get('max_depth_mm'), 2)}",
                     fixed(s.get("mean_similarity_mm"), 2), fixed(a.get("rmse_sampled"), 4), text(a.get("texels_sampled"))])
    return lines + table(["seed", "cameras", "converged", "world (mm): mean, worst", "rigidly aligned: mean, worst",
                          "depth: mean, worst", "similarity-aligned, whole head", "albedo RMSE (sampled texels)",
                          "texels with samples"], rows)


def sec_shape_depth(d):
    lines = [f"Default capture (512², six photographs), seeds {text(', '.join(map(str, get(d, 'seeds') or [])))}; "
             "the fitted faces against the truth over the front of the face (mm). `size`: the fitted face's size "
             "against the true one's; `after that size`: the error left after the true face is scaled by that "
             "ratio about the camera's centre (a pinhole camera cannot tell a face s times larger and s times "
             f"farther). Aim without alignment: {fixed(get(d, 'world_target_mm'), 1)} mm.", ""]
    rows = []
    for run in rows_of(get(d, "runs")):
        for name, e in items(get(run, "shape_errors")):
            if name == "summary":
                continue
            rows.append([text(run.get("seed")), text(name), fixed(e.get("world_mm"), 2), fixed(e.get("depth_mm"), 2),
                         f"{fixed(e.get('scale_pct'), 2)} %", fixed(e.get("scaled_mm"), 2),
                         fixed(e.get("aligned_mm"), 2)])
    held = get(d, "summary_focal_held") or {}
    notes = ["", f"With the calibrated focal length held (`fit_focal=False`): world error up to "
             f"{fixed(held.get('max_world_mm'), 2)} mm, size off by up to {fixed(held.get('max_abs_scale_pct'), 2)} %.",
             ""]
    variants = (("default fit (one identity)", ()), ("focal length held", ("focal_held",)),
                ("true identity held, each photograph on its own", ("true_identity",)),
                ("true identity and expression held (the pose fit's floor)", ("true_face",)),
                ("default fit, near-silhouette samples left out", ("with_facing_cut", "default")),
                ("true face held, near-silhouette samples left out", ("with_facing_cut", "true_face")))
    what = []
    for label, path in variants:
        for run in rows_of(get(d, "runs")):
            r = run
            for key in path:
                r = get(r, key) or {}
            e = get(r, "shape_errors") or {}
            if not e:
                continue
            depths = [v.get("depth_mm") for k, v in items(e) if k != "summary"]
            summary = e.get("summary") or {}
            what.append([text(label), text(run.get("seed")), fixed(summary.get("mean_world_mm"), 2),
                         fixed(summary.get("max_world_mm"), 2),
                         fixed(sum(depths) / len(depths) if depths else None, 2),
                         fixed(summary.get("mean_scaled_mm"), 2),
                         fixed(summary.get("mean_aligned_mm"), 2)])
    if len(what) > len(rows_of(get(d, "runs"))):
        notes += [f"What limits the depth (the cut leaves out samples the camera sees at a cosine below "
                  f"{fixed(get(d, 'facing_cut'), 2)}; mm, means over the photographs):", ""]
        notes += table(["fit", "seed", "world mean", "world max", "mean depth offset", "after that size",
                              "after rigid alignment"],
                       what) + [""]
    return lines + table(["seed", "photograph", "world", "depth", "size", "after that size",
                          "after rigid alignment"], rows) + (notes if held else [])


def sec_silhouette_depth(d):
    s = get(d, "summary") or {}
    lines = [f"Default capture (512², six photographs), seeds {text(', '.join(map(str, get(d, 'seeds') or [])))}; "
             "per photograph, the depth offset `dz` along the camera's ray (mm; positive: farther) at which the "
             "face's outline best matches the diffuse-light photograph's foreground (pixels where they disagree, "
             "rows above the middle of the nose), for the fitted face and the true face, beside the fitted face's depth error. "
             "An outline that pinned depth would give the true face 0 and the fitted face minus its depth error.", "",
             f"Means: |true face's dz| {fixed(s.get('mean_abs_true_best_dz_mm'), 2)} mm; fitted face's dz "
             f"{fixed(s.get('mean_fitted_best_dz_mm'), 1)} mm, off its depth error by "
             f"{fixed(s.get('mean_abs_fitted_dz_error_mm'), 1)} mm against a mean |depth error| of "
             f"{fixed(s.get('mean_abs_depth_mm'), 2)} mm; disagreement at dz 0: fitted face "
             f"{fixed(s.get('mean_fitted_disagreement_px'), 0)} px, true face "
             f"{fixed(s.get('mean_true_disagreement_px'), 0)} px. The least disagreement lay at an end of the "
             f"scan (it may lie beyond) for {text(s.get('fitted_at_scan_end'))} of {text(s.get('photographs'))} "
             f"fitted faces and {text(s.get('true_at_scan_end'))} true faces.", ""]
    rows = []
    for run in rows_of(get(d, "runs")):
        for name, r in items(get(run, "photographs")):
            rows.append([text(run.get("seed")), text(name), fixed(r.get("depth_mm"), 2),
                         fixed(r.get("fitted_best_dz_mm"), 1), fixed(r.get("true_best_dz_mm"), 2),
                         fixed(r.get("fitted_disagreement_px"), 0), fixed(r.get("fitted_least_disagreement_px"), 0),
                         fixed(r.get("true_disagreement_px"), 0)])
    return lines + table(["seed", "photograph", "depth error", "outline's dz, fitted face", "outline's dz, true face",
                          "disagreement (px), fitted", "least, fitted", "true face"], rows)


def sec_joint_outline(d):
    names = {"default": "default fit (each pose, then one identity averaged)",
             "from_default_fit_without_outline": "joint, from the default fit: feature points and distances",
             "from_default_fit_with_outline": "joint, from the default fit: with the outline",
             "from_truth_without_outline": "joint, from the truth: feature points and distances",
             "from_truth_with_outline": "joint, from the truth: with the outline",
             "from_truth_exact_points_with_outline": "joint, from the truth: with the outline, exact feature points"}
    lines = [f"Default capture (512², six photographs), seeds {text(', '.join(map(str, get(d, 'seeds') or [])))} "
             f"(settings set on seed {text(get(d, 'tuning_seed'))}): one identity and every photograph's rigid pose "
             "fitted together on the feature points, the metric distances and, with the outline, the head's outline "
             "in the diffuse companions above the middle of the nose. Started from the truth, an unbiased energy "
             "would stay there; a start that ends at a higher energy than the truth's run found a worse minimum "
             "(the truth's runs hold the true expressions, the default fit's runs its own). World-frame error over the front of the face, mm, without alignment.", ""]
    rows = []
    for run in rows_of(get(d, "runs")):
        for key, label in names.items():
            s = get(run, key, "summary") or {}
            if s:
                cost = get(run, key, "cost") or [None]
                rows.append([text(run.get("seed")), label, fixed(s.get("mean_world_mm"), 2),
                             fixed(s.get("max_world_mm"), 2), fixed(s.get("max_abs_depth_mm"), 2),
                             fixed(s.get("max_abs_scale_pct"), 2), fixed(s.get("mean_aligned_mm"), 2),
                             fixed(cost[-1], 1)])
    return lines + table(["seed", "fit", "world mean", "world max", "largest depth offset", "largest size error (%)",
                          "after rigid alignment", "energy at the end"], rows)


def sec_uncertainty_measure(d):
    lines = [f"`{text(get(d, 'command'))}` on the default simulated capture (512², six photographs, 64 spp) per "
             "seed, the Cook–Torrance truth's skin drawn per seed: skin's fitted parameters and their 95 % "
             f"intervals against the truth. Every skin interval held the truth in {text(get(d, 'all_covered'))} of "
             f"{text(get(d, 'captures'))} captures.", ""]
    pooled = get(d, "pooled_coverage") or {}
    if pooled:
        lines += [f"Every region's intervals (skin's and the other regions' same-family truths), pooled: "
                  f"{pct(pooled.get('coverage'), 0)} of {text(pooled.get('intervals'))} hold the truth.", ""]
    rows = []
    for run in rows_of(get(d, "runs")):
        for c in rows_of(get(run, "parameters")):
            name = f"{c.get('parameter')}{'' if c.get('channel') is None else '[' + str(c.get('channel')) + ']'}"
            rows.append([text(run.get("seed")), name, fixed(c.get("truth"), 4), fixed(c.get("fitted"), 4),
                         f"[{fixed(c.get('lo'), 4)}, {fixed(c.get('hi'), 4)}]", text(c.get("covered"))])
    return lines + table(["seed", "skin parameter", "truth", "fitted", "95 % interval", "holds the truth"], rows)


def sec_uncertainty_texel_albedo(d):
    variants = list(get(d, "variants") or {})
    tiles = get(d, "tile_at_128") or {}
    lines = [f"Captures of {'×'.join(map(str, get(d, 'image') or []))} px, {text(get(d, 'measurements'))} "
             f"photographs, {text(get(d, 'spp'))} spp, texture {text(get(d, 'texture'))}², the true geometry; one "
             "capture per seed. Coverage of the jackknife's 95 % intervals (intervals checked in brackets) of the "
             "region fit (one albedo per region) and of the fit with an albedo per texel, over tiles of "
             + ", ".join(f"{text(v)} texels at 128² ({k})" for k, v in items(tiles))
             + ". Out of family: the true value is the same fit's best on the capture rendered without noise at "
             f"{text(get(d, 'reference_spp'))} spp.", ""]

    def cell(e):
        return DASH if not e or e.get("coverage") is None else f"{pct(e.get('coverage'), 0)} ({text(e.get('intervals'))})"

    rows = []
    for truth, models in items(get(d, "coverage")):
        for model, entry in items(models):
            row = [text(truth), text(model), text(get(d, "seeds", truth, default=None))]
            for key in ("pooled", "small", "skin"):
                for v in variants:
                    e = get(entry, v, default={}) or {}
                    row.append(cell(e.get("regions", {}).get("skin") if key == "skin" else e.get(key)))
            rows.append(row)
    header = ["truth", "model", "seeds"] + [f"{key}: {v}" for key in ("pooled", "lips and eyebrows", "skin")
                                              for v in variants]
    checks = get(d, "skin_check", default={}) or {}
    notes = ["", "Cook–Torrance truths with a drawn skin: every skin interval holds the truth in "
             + "; ".join(f"{sum(bool(r.get('all_covered')) for r in rows_of(runs))} of {len(rows_of(runs))} "
                         f"captures ({v})" for v, runs in items(checks)) + ".", ""] if checks else []
    return lines + table(header, rows) + notes


def sec_uncertainty_cost(d):
    options = get(d, "options", default={}) or {}
    lines = [f"The region fits' time (`seconds['fit']`, best of interleaved runs) without and with the "
             f"{text(get(d, 'method'))} intervals, per capture, model and texture"
             + (f" ({', '.join(f'{k}={v}' for k, v in options.items())})" if options else "")
             + f". Median overhead: {pct(get(d, 'overhead_median'), 1)}; by texture: "
             + ", ".join(f"{k}²: {pct(v, 1)}" for k, v in items(get(d, "overhead_median_by_texture"))) + ".", ""]
    rows = [[text(r.get("seed")), text(r.get("texture")), text(r.get("model")), text(r.get("samples")),
             fixed(r.get("without"), 3), fixed(r.get("with"), 3),
             pct(r["with"] / r["without"] - 1 if r.get("without") else None, 1)] for r in rows_of(get(d, "fits"))]
    return lines + table(["seed", "texture", "model", "samples", "without (s)", "with (s)", "overhead"], rows)


def sec_unknown(d):
    if isinstance(d, dict):
        return [f"Layout not known to `validation/results_doc.py`; top-level keys: "
                f"{', '.join(f'`{k}`' for k in d) or DASH}.", ""]
    return [f"Layout not known to `validation/results_doc.py`: a {type(d).__name__}"
            + (f" of {len(d)} entries" if isinstance(d, list) else "") + ".", ""]
