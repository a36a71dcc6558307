"""The tables of ``docs/results.md`` for the benchmarks, the BRDF plugins and fits, the export, the
model, the whole pipeline's error against time, the real photographs and the lights (one function per
result layout, used by ``validation/results_doc.py``)."""

from __future__ import annotations

from results_format import (DASH, finite, fixed, get, items, mean, num, pct, ranked_with_ties, rows_of, spread,
                            table, text)


def sec_bench_brdf_fit(d):
    lines = [f"{text(d.get('samples'))} reflectance samples, {text(d.get('threads'))} threads, "
             f"1-minute load average {text(d.get('load_average_1min'))}. `loss / best`: the loss over the best "
             "any method reached; `× scipy`: speed-up over scipy's LM; `over limit`: wall time over the "
             "physical limit (full-data passes × one pass's time).", ""]
    rows = [[text(r.get("model")), text(r.get("method")), fixed(r.get("seconds"), 2), num(r.get("loss_over_best"), 8),
             fixed(r.get("speedup_vs_scipy"), 1), text(r.get("passes")), text(r.get("full_data_passes")),
             fixed(r.get("seconds_over_limit"), 1), text(r.get("status"))] for r in rows_of(d.get("rows"))]
    return lines + table(["model", "method", "seconds", "loss / best", "× scipy", "passes", "full-data passes",
                          "over limit", "status"], rows)


def sec_bench_bsdf(d):
    setup = d.get("render_setup") or {}
    lines = [f"Variant {text(d.get('variant'))}; renders at {text(setup.get('res'))}², {text(setup.get('spp'))} spp, "
             f"best of {text(setup.get('repeats'))}. `ratio`: the plugin's time over `roughplastic`'s.", ""]
    lines += table(["plugin", "seconds", "roughplastic seconds", "ratio"],
                   [[text(r.get("plugin")), fixed(r.get("seconds"), 3), fixed(r.get("roughplastic_seconds"), 3),
                     fixed(r.get("ratio"), 2)] for r in rows_of(d.get("render"))])
    lines += table(["model", "samples", "Dr.Jit eval/s", "NumPy eval/s", "× NumPy (eval)", "× NumPy (eval + grad)"],
                   [[text(r.get("model")), text(r.get("samples")), num(r.get("drjit_fwd_per_s")),
                     num(r.get("numpy_fwd_per_s")), fixed(r.get("ratio_fwd"), 1), fixed(r.get("ratio_fwdbwd"), 1)]
                    for r in rows_of(d.get("array_api"))])
    return lines


def sec_bench_face_render(d):
    lines = [f"Scene: {text(d.get('scene'))}; {text(d.get('resolution'))}², {text(d.get('spp'))} spp, "
             f"{text(d.get('repeats'))} repeats, {text(d.get('threads'))} threads, Mitsuba {text(d.get('mitsuba'))}, "
             f"1-minute load average {text(d.get('load_average_1min'))}.", ""]
    lines += table(["BSDF", "load (s)", "render (s)"],
                   [[k, fixed(get(v, "load_s"), 2), fixed(get(v, "render_s"), 2)] for k, v in items(d.get("bsdfs"))])
    lines += table(["Cook–Torrance plugin over", "render", "load and render"],
                   [[k, fixed(get(v, "render"), 2), fixed(get(v, "load_and_render"), 2)]
                    for k, v in items(d.get("ratios"))])
    return lines


def sec_bench_commits(d):
    summary = d.get("summary") or {}
    caches = d.get("caches") or "warm"
    how = "cold runs (empty caches: a new HOME and MIFACES_CACHE each)" if caches == "cold" else "warm runs"
    lines = [f"This tree against `{text(d.get('base'))}`, {how} in turns ({text(d.get('order'))}; "
             f"{text(d.get('rounds'))} round(s)). The report's figures agree between the two within "
             f"{fixed(d.get('figure_atol'), 3)}: {text(d.get('figures_agree'))}.", ""]
    lines += table(["", "runs (s)", "mean (s)", "spread (s)"],
                   [[side, ", ".join(fixed(w, 1) for w in (get(summary, side, "wall_s") or [])),
                     fixed(get(summary, side, "mean_s"), 1), fixed(get(summary, side, "spread_s"), 1)]
                    for side in ("this", "base")])
    lines += [f"Ratio of the means, this tree over the base: {fixed(d.get('ratio_this_over_base'), 3)}."]
    runs = d.get("runs") or {}
    models = list(get((runs.get("base") or [{}])[0], "heldout_rmse") or {})
    if models:
        lines += ["", "The report's figures in each run: the held-out lights' relative RMSE on the fitted faces, and the "
                      "ranking by it.", ""]
        lines += table(["side", "wall (s)", *models, "ranking"],
                       [[side, fixed(get(r, "wall_s"), 1), *[pct(get(r, "heldout_rmse", m), 2) for m in models],
                         ", ".join(get(r, "ranking") or [])] for side in ("this", "base") for r in runs.get(side) or []])
    stages = list((get((runs.get("this") or [{}])[0], "stages_s") or {}))
    if stages:
        lines += ["", "Mean time per stage (s):", ""]
        lines += table(["stage", "this", "base"],
                       [[stage, *[fixed(mean([get(r, "stages_s", stage) for r in runs.get(side) or []]), 1)
                                  for side in ("this", "base")]] for stage in stages])
    return lines


def sec_bench_pipeline(d):
    runs = items(d.get("runs"))
    machine = d.get("machine") or {}
    lines = [f"{text(d.get('note'))}", "",
             f"Machine: {text(machine.get('cores'))} cores, {text(machine.get('platform'))}, Python "
             f"{text(machine.get('python'))}; 1-minute load average at the end {fixed(d.get('load_average_1min_at_end'), 1)}.",
             ""]
    names = [name for name, _ in runs]
    lines += table(["", *names], [
        ["wall time (s)", *[fixed(get(r, "wall_s"), 1) for _, r in runs]],
        ["peak memory (MiB)", *[fixed(get(r, "peak_rss_mib"), 0) for _, r in runs]],
        ["skin Cook–Torrance ρs error", *[pct(get(r, "skin_cooktorrance_error", "specular_reflectance"), 2)
                                         for _, r in runs]],
        ["skin Cook–Torrance roughness error", *[pct(get(r, "skin_cooktorrance_error", "roughness"), 2)
                                                for _, r in runs]],
        ["shape floor under the held-out lights", *[pct(get(r, "shape_floor", "heldout_rmse"), 1) for _, r in runs]],
        ["noise floor under the held-out lights", *[pct(get(r, "noise_floor", "heldout_rmse"), 1) for _, r in runs]],
        ["shapes converged", *[text(sum(1 for s in (get(r, "shapes") or {}).values()
                                        if get(s, "status") == "converged")) + " / "
                               + text(len(get(r, "shapes") or {})) for _, r in runs]],
    ])
    models = [m for m in (get(runs[-1][1], "ranking") or [])] if runs else []
    if models:
        lines += ["", "The report's figures per model (the last run; ranked by the held-out lights): skin's BRDF error "
                      "over the hemisphere, relighting error on the fitted faces under the held-out lights and the "
                      "environments, and the same with the fitted reflectance on the true shapes.", ""]
        last = runs[-1][1]
        lines += table(["model", "skin BRDF", "held-out lights", "environments", "held-out, true shape",
                        "environments, true shape"],
                       [[m, *[pct(get(last, "models", m, key), 2) for key in
                              ("skin_brdf_rmse", "heldout_rmse", "environment_rmse", "heldout_rmse_true_shape",
                               "environment_rmse_true_shape")]] for m in models])
        lines.append("")
    refined = [(name, r) for name, r in runs if get(r, "shape_refinement")]
    if refined:
        lines += ["With `--refine-shape`:", ""]
        lines += table(["run", "refinement", "mean world error of the refined faces (mm)"],
                       [[name, text(get(r, "shape_refinement", "reason")),
                         fixed(get(r, "shape_errors_refined", "mean_world_mm"), 2)] for name, r in refined])
    stages = []
    for _, run in runs:
        for stage in get(run, "stages_s") or {}:
            if stage not in stages:
                stages.append(stage)
    lines += table(["stage (s)", *names], [[stage, *[fixed(get(r, "stages_s", stage), 1) for _, r in runs]]
                                           for stage in stages])
    return lines


def sec_bench_shape_kernels(d):
    lines = ["Per labelled run (`--label`) and measurement: launches per iteration, compiled kernels, compile "
             "time, the kernels' share of the timed fit's wall time, and the fit's errors against the truth.", ""]
    rows = []
    for label, run in items(d):
        for m in rows_of(get(run, "measurements")):
            rows.append([label, text(get(run, "iterations_factor")), text(m.get("measurement")),
                         text(m.get("iterations")), fixed(m.get("seconds"), 2), fixed(m.get("launches_per_iteration"), 1),
                         text(m.get("compiled")), fixed(m.get("compile_s"), 2), pct(m.get("execution_share"), 0),
                         fixed(m.get("feature_rms_px"), 2), fixed(m.get("vertex_rms_aligned_mm"), 2),
                         fixed(m.get("normal_deg"), 2)])
    return lines + table(["label", "schedule factor", "measurement", "iterations", "seconds", "launches / iteration",
                          "compiled", "compile (s)", "execution share", "landmarks (px)", "vertices aligned (mm)",
                          "normals (°)"], rows)


def sec_bench_simulate(d):
    lines = []
    rows = []
    for key, run in items(d):
        if isinstance(run, dict) and "seconds_total" in run:
            rows.append([key, text(run.get("measurements")), text(run.get("lights")), fixed(run.get("seconds_total"), 1),
                         fixed(run.get("seconds_per_measurement"), 2), fixed(run.get("seconds_load_and_calibrate"), 2)])
    lines += table(["run", "measurements", "lights", "total (s)", "per measurement (s)", "load and calibrate (s)"], rows)
    cal = d.get("light_calibration_error_percent") or {}
    lines += [f"Light calibration from the steel spheres, error in % of the light's distance over "
              f"{text(cal.get('lights'))} lights: mean {fixed(cal.get('mean'), 3)} %, max {fixed(cal.get('max'), 3)} %.",
              ""]
    return lines


def sec_brdf_energy(d):
    lines = ["Largest hemispherical albedo of the glossy part (ρs = 1) over the angles and widths swept, and where.",
             ""]
    rows = [[text(v.get("model")), text(v.get("options")) if v.get("options") else "default",
             fixed(v.get("max_albedo"), 3), fixed(v.get("at_theta_deg"), 1), text(v.get("at_width")),
             text(v.get("at_exponent"))] for v in rows_of(d.get("variants"))]
    return lines + table(["model", "options", "max albedo", "at θi (°)", "at width", "at exponent"], rows)


def sec_brdf_fit_stiff(d):
    rows = [[text(r.get("case")), text(r.get("model")), text(r.get("samples")), text(r.get("status")),
             text(r.get("finite")), pct(r.get("max_relative_error"), 2), fixed(r.get("seconds"), 2)]
            for r in rows_of(d)]
    return ["`max error`: the largest relative error of a fitted parameter against the truth.", ""] + table(
        ["case", "model", "samples", "status", "finite", "max error", "seconds"], rows)


def sec_brdf_recovery(d):
    lines = [f"Texture {text(d.get('resolution'))}², photographs {text(d.get('image'))}², {text(d.get('spp'))} spp, "
             f"variant {text(d.get('variant'))}, ground-truth shapes.", "",
             "**Same family** (each model fitted to a face rendered with that model): per region the relative "
             "RMSE of the glossy part over the hemisphere, skin's parameter errors, albedo RMSE.", ""]
    same = rows_of(d.get("same_family"))
    regions = []
    for r in same:
        for region in get(r, "regions") or {}:
            if region not in regions:
                regions.append(region)
    rows = []
    for r in same:
        skin_errors = get(r, "regions", "skin", "relative_error") or {}
        rows.append([text(r.get("model")),
                     *[pct(get(r, "regions", region, "glossy_relative_rmse")) for region in regions],
                     ", ".join(f"{k} {pct(v)}" for k, v in skin_errors.items()) or DASH,
                     fixed(get(r, "albedo", "rmse_sampled"), 4), fixed(get(r, "fit_seconds", "total"), 1)])
    lines += table(["model", *[f"{region} glossy" for region in regions], "skin parameters", "albedo RMSE",
                    "fit (s)"], rows)
    lines += ["**Cross family** (every model fitted to a Cook–Torrance face): skin's BRDF error relative to the "
              "glossy part's RMS, overall and at grazing angles, and the relative RMSE on held-out photographs "
              "against the noise floor.", ""]
    rows = [[text(r.get("model")), pct(r.get("brdf_rmse_over_specular_rms")), num(r.get("brdf_rmse_grazing")),
             pct(r.get("heldout_image_relative_rmse")), pct(r.get("heldout_noise_floor")), fixed(r.get("fit_seconds"), 1)]
            for r in rows_of(d.get("cross_family"))]
    return lines + table(["model", "BRDF RMSE / glossy RMS", "BRDF RMSE grazing", "held-out image RMSE",
                          "noise floor", "fit (s)"], rows)


def sec_export(d):
    capture = d.get("capture") or {}
    lines = [f"{text(d.get('what'))}.", "",
             f"Truth {text(d.get('truth'))}, geometry {text(d.get('geometry'))}, {text(capture.get('measurements'))} "
             f"measurements at {text(capture.get('resolution'))}², texture {text(d.get('texture'))}², hemisphere grid "
             f"{text(d.get('hemisphere_grid'))}; machine: {text(d.get('machine'))}.", ""]
    models = items(d.get("models"))
    regions = []
    for _, m in models:
        for region in get(m, "regions") or {}:
            if region not in regions:
                regions.append(region)
    lines += table(["model", *[f"{region} RMSE" for region in regions], "skin glossy RMSE", ".glb (MB)", "export (s)"],
                   [[name, *[pct(get(m, "regions", region, "rmse")) for region in regions],
                     pct(get(m, "rmse_specular_skin")),
                     fixed(get(m, "glb_bytes") / 1e6, 2) if finite(get(m, "glb_bytes")) else DASH,
                     fixed(get(m, "export_seconds"), 2)] for name, m in models])
    return lines


def sec_model_span(d):
    target, met = d.get("target") or {}, d.get("target_met") or {}
    lines = [f"Model {text(d.get('model'))} ({text(d.get('model_modes'))} modes) fitted to {text(d.get('faces'))} "
             f"random faces of {text(d.get('reference'))}: test seed {text(d.get('test_seed'))}, on which the figures "
             f"are reported; training seed {text(d.get('train_seed'))}, on which the mode counts are chosen (the "
             f"fewest within {text(d.get('enough_mm'))} mm of all {text(d.get('model_modes'))}). Target "
             f"({text(target.get('from'))}): a mean of at most {text(target.get('mean_mm'))} mm with no coefficient "
             f"beyond {text(target.get('max_abs_coefficient_sd'))} sd on the test faces.", "",
             f"**Landmarks** ({text(d.get('landmarks'))} landmarks, prior weight {text(d.get('prior_weight_mm2'))} "
             "mm²): "
             f"modes chosen on the training faces: {text(d.get('chosen_on_train'))}; the shape fit's default: "
             f"{text(d.get('fit_shape_modes'))} modes ({text(d.get('fit_shape_modes_note'))}) Target met, by modes: "
             f"{text(met.get('landmarks'))}. Test faces:", ""]
    rows = [[k, fixed(get(v, "mean_residual_mm"), 2), fixed(get(v, "inner_mean_residual_mm"), 2),
             fixed(get(v, "worst_face_residual_mm"), 2), fixed(get(v, "mean_max_abs_coefficient_sd"), 2),
             fixed(get(v, "max_abs_coefficient_sd"), 2)] for k, v in items(d.get("test"))]
    lines += table(["modes", "mean residual (mm)", "inner points (mm)", "worst face (mm)",
                    "mean largest coefficient (sd)", "largest coefficient (sd)"], rows)
    surface = d.get("surface")
    if not isinstance(surface, dict):
        return lines
    region, weights = surface.get("region") or {}, surface.get("prior_weight_mm2") or {}
    fits = list(weights)
    lines += [f"**Surface**: from the landmark fit, the identity and a rigid pose fitted to the Surrey face's "
              f"surface ({text(surface.get('rounds'))} point-to-plane rounds) over the face region: "
              f"{text(region.get('vertices'))} vertices, {fixed(region.get('area_mm2'), 0)} mm², labels "
              f"{text(region.get('labels'))}, whose closest "
              f"point on the Surrey mean face lies within {text(region.get('depth_mm'))} mm and at least "
              f"{text(region.get('margin_mm'))} mm from its border. Reported: the area-weighted mean distance from "
              "the fitted face to the Surrey surface, with each prior weight (mm²): "
              f"{text(weights)}. Modes chosen on the training faces: {text(surface.get('chosen_on_train'))}. Target "
              "met, by modes: " + "; ".join(f"{name}: {text(met.get('surface_' + name))}" for name in fits)
              + ". Test faces (`border`: the largest share of the region's area whose closest point lies on the "
              "Surrey mesh's border, on any face):", ""]
    rows = [[k, fixed(get(v, "landmark_fit_distance_mm"), 2),
             *[cell for name in fits for cell in (fixed(get(v, name, "mean_distance_mm"), 2),
                                                   fixed(get(v, name, "worst_face_distance_mm"), 2),
                                                   fixed(get(v, name, "max_abs_coefficient_sd"), 2),
                                                   pct(get(v, name, "max_border_area_share")))]]
            for k, v in items(surface.get("test"))]
    header = [f"{name}: {label}" for name in fits
              for label in ("mean (mm)", "worst face (mm)", "largest coefficient (sd)", "border")]
    return lines + table(["modes", "after the landmark fit (mm)", *header], rows)


def sec_mutations(d):
    mutations = rows_of(d.get("mutations"))
    caught = sum(1 for m in mutations if m.get("caught") is True)
    missed = d.get("missed")
    lines = [f"{caught} of {len(mutations)} mutations caught; missed: {text(missed) if missed else 'none'}."]
    if "tests" in d:  # (a file of the BRDF-only layout: one list of tests for every mutation)
        lines[0] = f"Tests run: {text(d.get('tests'))}. " + lines[0]
    lines.append("")
    if items(d.get("areas")):
        lines += ["Per area: what it covers, the tests run against its mutants, and how many they caught.", ""]
        lines += table(["area", "what", "tests", "mutations", "caught", "kill rate", "missed"],
                       [[name, text(get(a, "what")), ", ".join(f"`{t}`" for t in get(a, "tests") or []) or DASH,
                         text(get(a, "mutations")), text(get(a, "caught")), pct(get(a, "kill_rate"), 0),
                         ", ".join(get(a, "missed") or []) or "none"] for name, a in items(d.get("areas"))])
    return lines + table(["id", "area", "file", "mutation", "caught"],
                         [[text(m.get("id")), text(m.get("area")), f"`{text(m.get('file'))}`", text(m.get("mutation")),
                           text(m.get("caught"))] for m in mutations])


def sec_normals_faces(d):
    lines = [f"Capture resolution {text(d.get('resolution'))}² texture; skin's fitted parameters against the truth "
             "per run (true or fitted shapes, with or without per-texel normals or albedo offsets).", ""]
    rows = [[name, pct(get(r, "specular_reflectance_rel")), pct(get(r, "roughness_rel")),
             fixed(get(r, "skin_normal_error_deg"), 2), fixed(get(r, "normal_refinement", "mean_tilt_deg"), 2),
             text(get(r, "rounds")), fixed(get(r, "seconds"), 1)] for name, r in items(d.get("runs"))]
    return lines + table(["run", "skin ρs error", "skin roughness error", "normal error (°)", "mean tilt (°)", "rounds",
                          "seconds"], rows)


def sec_pareto(d):
    model = d.get("model") if isinstance(d.get("model"), str) else None
    default = d.get("default") or {}
    grid = d.get("grid") or {}
    options = d.get("options") or {}
    lines = [f"Grid: measurements {text(grid.get('measurements'))} × resolution {text(grid.get('resolutions'))} × "
             f"spp {text(grid.get('spp'))}; geometry {text(options.get('geometry'))}, texture "
             f"{text(options.get('texture'))}², model {text(model)}; each setting on the seeds "
             f"{text(d.get('seeds'))} (each seed another face, poses, lamps and noise). The defaults: "
             f"{text(default.get('measurements'))} / {text(default.get('resolution'))} / {text(default.get('spp'))}. "
             "Errors: the mean over the seeds, the least and largest in brackets; wall time: the mean. A front "
             "through the means of a few seeds orders two settings only where their ranges do not overlap.", ""]

    def spread(entry, key, as_pct, decimals):
        show = (lambda x: pct(x, decimals)) if as_pct else (lambda x: fixed(x, decimals))
        e = get(entry, key)
        return f"{show(get(e, 'mean'))} ({show(get(e, 'min'))}–{show(get(e, 'max'))})"

    rows = []
    for p in rows_of(d.get("summary")):
        key = f"{text(p.get('measurements'))} / {text(p.get('resolution'))} / {text(p.get('spp'))}"
        if all(p.get(k) == default.get(k) for k in ("measurements", "resolution", "spp")) and default:
            key += " (defaults)"
        rows.append([key, fixed(p.get("wall_s"), 0), spread(p, "brdf_skin", True, 2), spread(p, "albedo_rmse", False, 4),
                     spread(p, "heldout_rmse", True, 1), spread(p, "environment_rmse", True, 1)])
    lines += table(["measurements / px / spp", "wall (s)", "skin BRDF RMSE", "albedo RMSE", "held-out RMSE",
                    "environment RMSE"], rows)
    lines += table(["error", "front through the means (measurements / px / spp)", "defaults on it"],
                   [[name, "; ".join(" / ".join(text(v) for v in point) for point in (get(f, "front") or []))
                     or DASH, text(get(f, "default_on_front"))] for name, f in items(d.get("fronts"))])
    return lines


def sec_real_diligent(d):
    lines = [f"Split: {text(d.get('split'))}. Chosen model {text(d.get('chosen_model'))}, {text(d.get('rounds'))} "
             "rounds. Normals: angular error against the ground truth.", ""]
    rows = []
    for key, label in (("normals_all", "all lights"), ("normals_half", "training half")):
        for method, r in items(d.get(key)):
            rows.append([label, method, fixed(get(r, "mean"), 2), fixed(get(r, "median"), 2),
                         pct(get(r, "within_5deg"))])
    lines += table(["lights", "method", "mean (°)", "median (°)", "within 5°"], rows)
    lines += ["Held-out half of the lights: relative RMSE of the predicted photographs.", ""]
    lines += table(["predictor", "relative RMSE"], [[k, fixed(get(v, "relative_rmse"), 4)]
                                                    for k, v in items(d.get("heldout"))])
    return lines


def _yale_table(overall, subjects):
    """Rows per predictor: all / small / large shadows, the mean and spread over the subjects, then each
    subject's all; below, the predictors ranked by their mean over the subjects, with ties."""
    names = [text(s.get("subject", key)) if isinstance(s, dict) else key for key, s in subjects]
    rows, per_subject = [], {}
    for predictor, r in items(get(overall, "relative_rmse")):
        values = [get(s, "relative_rmse", predictor, "all") if get(s, "relative_rmse") is not None
                  else get(s, predictor, "all") for _, s in subjects]
        per_subject[predictor] = values
        over = spread(values)
        rows.append([predictor, fixed(get(r, "all"), 3), fixed(get(r, "small_shadows"), 3),
                     fixed(get(r, "large_shadows"), 3),
                     DASH if over is None else f"{over[0]:.3f} ± {over[1]:.3f}", *[fixed(v, 3) for v in values]])
    lines = table(["predictor", "all held-out", "small shadows", "large shadows", "mean ± sd over subjects",
                   *names], rows)
    full = {k: v for k, v in per_subject.items() if not k.endswith("_diffuse_only")}
    if len(subjects) > 1 and full:
        lines += [f"Ranked by the mean over the {len(subjects)} subjects: {ranked_with_ties(full)} (≈: the "
                  "paired difference over the subjects is within twice its standard error: a tie).", ""]
    return lines


#: Light elevation bands of the per-elevation breakdown (degrees, lower bound inclusive).
ELEVATION_BANDS = ((-90, -15, "below (−40° to −20°)"), (-15, 15, "level (−10° to +10°)"),
                   (15, 50, "above (+15° to +45°)"), (50, 91, "high (+50° to +90°)"))


def _yale_albedo_and_training(overall):
    """The albedo maps' detail against photometric stereo's, and the training residuals, over the subjects."""
    detail = items(overall.get("albedo_detail_r"))
    if not detail:
        return []
    lines = ["Albedo maps: Pearson r of each map's detail (seen through the fitted face in the frontal view, each "
             "region's mean removed) with photometric stereo's per-pixel albedo, over the subjects:", ""]
    lines += table(["model", "mean r", "sd", "least", "largest", "training RMSE (first photograph)",
                    "training RMSE (every training photograph, pooled)"],
                   [[m, fixed(get(v, "mean"), 3), fixed(get(v, "sd"), 3), fixed(get(v, "min"), 3),
                     fixed(get(v, "max"), 3), pct(get(overall, "training_rmse", m)),
                     pct(get(overall, "training_relative_rmse", m))] for m, v in detail])
    lines += [f"Photometric stereo's own residual on the same first training photograph: "
              f"{pct(overall.get('training_rmse_photometric_stereo'))}; on every training photograph, pooled: "
              f"{pct(get(overall, 'training_relative_rmse', 'photometric_stereo'))}. The best model is the one "
              f"with the lowest {text(overall.get('best_model_chosen_by'))}"
              + (f" (by the first photograph alone: {text(overall['best_model_by_first_photograph'])})"
                 if overall.get("best_model_by_first_photograph") else "") + ".", ""]
    return lines


def _yale_by_elevation(subjects, best):
    """Mean per-light relative RMSE of the best model and photometric stereo by the held-out light's elevation."""
    lights = [v for _, s in subjects for _, v in items(get(s, "per_light"))]
    if not lights or best is None:
        return []
    rows = []
    for low, high, name in ELEVATION_BANDS:
        chosen = [v for v in lights if isinstance(get(v, "elevation"), (int, float)) and low <= v["elevation"] < high]
        if not chosen:
            continue
        ours, peer = (mean([get(v, k) for v in chosen]) for k in (best, "photometric_stereo"))
        rows.append([name, str(len(chosen)), fixed(ours, 3), fixed(peer, 3),
                     fixed(ours / peer, 2) if finite(ours) and finite(peer) and peer > 0 else DASH])
    lines = [f"By the held-out light's elevation (mean per-light relative RMSE over the lights and subjects; best "
             f"model {text(best)}):", ""]
    return lines + table(["elevation", "held-out photographs", text(best), "photometric stereo", "ratio"], rows)


def sec_real_yaleb(d):
    if isinstance(d.get("runs"), dict):  # --normals, --interreflection: runs without and with
        what = {"normals": "per-texel normals", "interreflection": "the bounced light taken out (interreflection)",
                "balance_lights": ("the given lights balanced whatever their factors' spread, failed lamps left "
                                   "out (balance_lights)")}
        option = what.get(d.get("option", "normals"), text(d.get("option")))
        lines = [f"Training lights {text(d.get('train_lights'))}, models {text(d.get('models'))}, texture "
                 f"{text(d.get('texture_resolution'))}². Relative RMSE over the face pixels, without and with "
                 f"{option}.", ""]
        for name, run in items(d.get("runs")):
            lines += [f"*{name} {option}* (best model {text(get(run, 'overall', 'best_model'))}):", ""]
            lines += _yale_table(get(run, "overall"), items(get(run, "subjects")))
        failed = rows_of(d.get("failed_subjects"))
        if failed:
            lines += ["Left out of both, their faces not fitted: "
                      + "; ".join(f"{text(f.get('subject'))}: {text(f.get('error'))}" for f in failed) + ".", ""]
        return lines
    subjects = [(str(i), s) for i, s in enumerate(rows_of(d.get("subjects")))]
    overall = d.get("overall") or {}
    lines = [f"Training lights {text(d.get('train_lights'))}, models {text(d.get('models'))}, texture "
             f"{text(d.get('texture_resolution'))}², {text(d.get('spp'))} spp; large shadows: lights more than "
             f"{text(d.get('shadow_angle_deg'))}° from the camera axis. Pooled relative RMSE over the face pixels of the held-out lights; "
             f"best model {text(overall.get('best_model'))}, {fixed(overall.get('best_vs_photometric_stereo'), 2)}× "
             "photometric stereo's error.", ""]
    lines += _yale_table(overall, subjects)
    lines += _yale_albedo_and_training(overall)
    lines += _yale_by_elevation(subjects, overall.get("best_model"))
    failed = rows_of(d.get("failed_subjects"))
    if failed:
        lines += ["Left out, their faces not fitted (`mifaces measure` stops on them too): "
                  + "; ".join(f"{text(f.get('subject'))}: {text(f.get('error'))}" for f in failed) + ".", ""]
    ratios = items(overall.get("refined_vs_unrefined"))
    if ratios:
        lines += ["Refined over unrefined error:", ""]
        lines += table(["model", "all", "small shadows", "large shadows"],
                       [[k, fixed(get(v, "all"), 3), fixed(get(v, "small_shadows"), 3),
                         fixed(get(v, "large_shadows"), 3)] for k, v in ratios])
    best = overall.get("best_model")
    gains = [(text(s.get("subject")), get(s, "refinement", best, "light_gains")) for _, s in subjects]
    gains = [(name, g) for name, g in gains if isinstance(g, dict) and g]
    if gains:
        lights = sorted({light for _, g in gains for light in g})
        lines += [f"Light gains the refinement fitted ({text(best)}):", ""]
        lines += table(["subject", *lights], [[name, *[num(g.get(light), 3) for light in lights]] for name, g in gains])
    return lines


def sec_unknown_lights(d):
    errors = d.get("angular_error_deg") or {}
    runs = d.get("runs") or {}
    lines = [f"Training lights {text(d.get('train_lights'))} per subject ({text(d.get('subjects'))}), hidden and estimated "
             f"with the face. Angle between each estimated direction and the calibrated one over "
             f"{text(errors.get('lights'))} lights: median {fixed(errors.get('median'), 1)}°, max "
             f"{fixed(errors.get('max'), 1)}° (targets {text(errors.get('median_target'))}° / "
             f"{text(errors.get('max_target'))}°: {'met' if errors.get('met') else 'not met'}).", ""]
    per = items(errors.get("per_subject"))
    names = list(get(per[0][1]) or {}) if per else []
    lines += table(["subject"] + names, [[s] + [fixed(get(v, n), 1) for n in names] for s, v in per])
    keys = list(get(runs, "calibrated", "relative_rmse") or {})
    lines += ["Held-out relighting, pooled relative RMSE over the three subjects (held-out lights rendered as known):", ""]
    lines += table(["predictor", "calibrated training lights", "estimated training lights"],
                   [[k, fixed(get(runs, "calibrated", "relative_rmse", k, "all"), 4),
                     fixed(get(runs, "unknown", "relative_rmse", k, "all"), 4)] for k in keys])
    seconds = items(d.get("seconds"))
    lines += table(["subject", "measure, calibrated (s)", "measure, estimated lights (s)"],
                   [[s, fixed(get(v, "measure_calibrated"), 0), fixed(get(v, "measure_unknown"), 0)] for s, v in seconds])
    return lines


def sec_unknown_lights_simulated(d):
    lights = items(d.get("lights"))
    ambient = d.get("ambient", "unknown")
    lines = ["Each light's estimate (the mean over the photographs under it) against its true direction from the "
             "fitted head's centre, and how far its photographs' estimates lie from that mean. The hidden capture's "
             f"`ambient`: {text(ambient)} ("
             + ("held at zero in the shape fit" if ambient == "none" else "the shape fit fits an ambient term") + ").",
             ""]
    lines += table(["light", "angle to the truth (deg)", "before the alternation", "photographs", "their spread (deg)"],
                   [[name, fixed(get(v, "angle_deg"), 1), fixed(get(v, "angle_deg_first_pass", default=None), 1),
                     text(len(get(v, "photographs") or [])), fixed(get(v, "spread_deg"), 1)] for name, v in lights])
    lines += [f"Shape fit with the lights estimated: {fixed(get(d, 'seconds', 'fit_shape'), 0)} s.", ""]
    return lines


def sec_environment_lights(d):
    summary = items(d.get("summary"))
    lines = [f"{text(d.get('measurements'))} head turns per capture under one environment, Cook–Torrance fitted "
             f"on fitted faces and refined; seeds {text(d.get('seeds'))} (the defaults were set on seed "
             f"{text(d.get('tuning_seed'))}, not shown). Each capture is measured with its map given and with "
             "its light hidden (estimated with the face). The estimated run's reflectance is relative: the "
             "validation compares it after one factor (the median ratio of true to fitted skin albedo, "
             "the last column); the skin parameter errors are before that factor.", ""]
    lines += table(["environment", "held-out error, map given", "map estimated", "worst ratio (target <= "
                    f"{text(d.get('ratio_target'))})", "on the true shape: given", "estimated", "worst ratio",
                    "shape floor, given", "estimated"],
                   [[name, pct(get(v, "heldout_rmse_given")), pct(get(v, "heldout_rmse_estimated")),
                     fixed(get(v, "heldout_ratio_max"), 2), pct(get(v, "heldout_rmse_true_shape_given")),
                     pct(get(v, "heldout_rmse_true_shape_estimated")),
                     fixed(get(v, "heldout_ratio_true_shape_max", default=None), 2),
                     pct(get(v, "shape_floor_given", default=None)), pct(get(v, "shape_floor_estimated", default=None))]
                    for name, v in summary])
    lines += table(["environment", "skin BRDF error, map given", "map estimated", "map irradiance error",
                    "after refinement", "extra seconds (max)"],
                   [[name, pct(get(v, "skin_brdf_rmse_given")), pct(get(v, "skin_brdf_rmse_estimated")),
                     pct(get(v, "irradiance_error")), pct(get(v, "irradiance_error_refined")),
                     fixed(get(v, "extra_seconds_max"), 0)] for name, v in summary])
    cases = items(d.get("cases"))
    lines += table(["capture", "held-out, given", "held-out, estimated", "ratio", "skin ρs error, given",
                    "estimated", "skin roughness error, given", "estimated", "reflectance factor"],
                   [[name, pct(get(c, "given", "heldout_rmse")), pct(get(c, "estimated", "heldout_rmse")),
                     fixed(get(c, "heldout_ratio"), 2),
                     pct(mean(get(c, "given", "skin_parameter_errors", "specular_reflectance", default=None))),
                     pct(mean(get(c, "estimated", "skin_parameter_errors", "specular_reflectance", default=None))),
                     pct(get(c, "given", "skin_parameter_errors", "roughness", default=None)),
                     pct(get(c, "estimated", "skin_parameter_errors", "roughness", default=None)),
                     fixed(get(c, "estimated", "reflectance_scale"), 3)] for name, c in cases])
    return lines


def sec_environment_lights_tuning(d):
    lines = [f"Tuning seed {text(d.get('seed'))}, true faces, map given: {text(d.get('what'))}.", ""]
    rows = []
    for name, v in items(d.get("environments")):
        truth = get(v, "truth", "skin", default=None) or get(v, "truth") or {}
        for start in ("from_the_fit", "restarted"):
            skin = get(v, start, "skin") or {}
            rows.append([name, start.replace("_", " "), num(mean(skin.get("specular_reflectance"))),
                         num(skin.get("roughness")), num(mean(truth.get("specular_reflectance"))),
                         num(truth.get("roughness")), num(get(v, start, "heldout_loss_before"), 4),
                         num(get(v, start, "heldout_loss_after"), 4)])
    lines += table(["environment", "glossy start", "skin ρs (mean RGB)", "skin roughness", "true ρs", "true roughness",
                    "held-out loss, texture-space fit", "after refinement"], rows)
    return lines
