"""Tables of ``docs/results.md`` for one-question studies (used by ``validation/results_doc.py``):
the shape refinement's judges (``refine_judge.json``, ``validation/refine_judge.py``) and the region
outlines in fitted renders (``region_seams.json``, ``validation/region_seams.py``)."""

from __future__ import annotations

from results_format import DASH, fixed, get, items, pct, rows_of, table, text


def sec_refine_judge(d):
    """Per judge how often it kept, and by each measure whether rightly; per seed and judge the verdict."""
    lines = [f"Development seeds {text(d.get('seeds'))} (none of them reported elsewhere), {text(d.get('resolution'))}² "
             f"photographs, lit by a quick {text(d.get('lit_by'))} fit; the default judge: "
             f"`judged={text(d.get('default_judged'))}`. A refinement *helped* by distance when the faces' mean "
             "error after a rigid alignment fell, by normals when their mean normal error fell; a judge is *right* "
             "when it keeps what helped and rejects what did not.", ""]
    rows = []
    for judged, s in items(d.get("summary")):
        for measure in ("distance", "normals"):
            m = get(s, measure) or {}
            rows.append([text(judged), measure, f"{text(s.get('kept'))} of {text(s.get('runs'))}", text(m.get("helped")),
                         text(m.get("right")), text(m.get("kept_but_worse")), text(m.get("rejected_but_better"))])
    lines += table(["photographs judged", "measure", "kept", "helped", "right", "kept but worse",
                    "rejected but better"], rows)
    lines.append("")
    per_seed = []
    for run in rows_of(d.get("runs")):
        for judged, r in items(run.get("judges")):
            per_seed.append([text(run.get("seed")), text(judged), "kept" if r.get("accepted") else "rejected",
                             f"{r.get('aligned_before_mm', 0):.3f} → {r.get('aligned_refined_mm', 0):.3f}",
                             f"{r.get('normal_before_deg', 0):.2f} → {r.get('normal_refined_deg', 0):.2f}"])
    return lines + table(["seed", "judged", "verdict", "aligned error (mm)", "normal error (°)"], per_seed)


def sec_region_seams(d):
    """Per seed and fit, the borders whose step exceeds the noise, and the largest step."""
    lines = [f"Seeds {text(d.get('seeds'))}, {text(d.get('spp'))} spp; a seam: a step of log(fitted / true) across "
             f"a border beyond three standard errors plus {text(d.get('allowance'))}. `default`: border samples "
             "dropped, region parameters blended; `mixed_kept`: border samples kept; `glossy_step`: the control, "
             "3 × the skin's ρs on hard borders.", ""]
    rows = []
    for seed, run in items(d.get("runs")):
        for fit, r in items(run):
            found = ", ".join(f"{k} {100 * v:+.1f} %" for k, v in items(r.get("seams"))) or "none"
            rows.append([text(seed), fit, found, f"{text(r.get('max_abs_step_pct'))} %"])
    return lines + table(["seed", "fit", "seams", "largest step"], rows)


#: What each run of ``reflectance_bias.json`` is, in words (its reference in brackets).
BIAS_RUNS = {"as_captured": "the uncorrected fit (the default before issue 48) on the capture as simulated",
             "ideal": "every capture effect off, true lights",
             "effect:bounces": "+ light bounced off the face (path depth 4)",
             "effect:albedo_detail": "+ the albedo map's detail",
             "effect:camera_noise": "+ sensor noise",
             "effect:eta": "+ the truth's η above the fit's",
             "effect:light_calibration": "+ lights from the steel spheres",
             "fit:no_normals": "no per-texel normals",
             "fit:region_albedo": "one albedo per region",
             "fit:uniform_weights": "every sample weight 1",
             "fit:no_erosion": "valid mask not eroded",
             "fit:erosion_2": "valid mask eroded by 2 texels",
             "fit:texture_256": "texture 256²",
             "fit:interreflection": "bounced light taken out",
             "fit:balance_lights": "lights balanced against a quick fit",
             "fit:interreflection_balance": "bounced light taken out, then the lights balanced"}


def sec_reflectance_bias(d):
    """The bias breakdown: per run, skin's ρs and roughness errors over the breakdown seeds and the shift
    from its reference; then the spread of the default fit and its intervals' coverage."""
    capture = get(d, "capture") or {}
    ranges = "; ".join(f"{'ρs' if k == 'specular_reflectance' else k} in [{text(v)}]" for k, v in items(d.get("skin_ranges")))
    lines = [f"Cook–Torrance truths, skin drawn per seed ({ranges}), "
             f"{text(capture.get('measurements'))} measurements, {text(get(capture, 'image', 0))}² photographs, "
             f"{text(capture.get('spp'))} spp, fitted on the true shape with the defaults as they were before this study "
             "(no bounced light taken out, the lights as calibrated: both are now on by default); development seeds "
             f"{text(d.get('breakdown_seeds'))}. ρs: the mean over channels of fitted / true − 1. Each effect is "
             "switched on alone in the ideal capture, its shift measured from `ideal`; each fit variant changes "
             "one thing of that uncorrected fit on the capture as simulated, its shift measured from `as_captured`.", ""]
    rows = []
    for run, s in items(d.get("breakdown")):
        shift = s.get("rho_s_shift_mean")
        rows.append([f"`{run}`", BIAS_RUNS.get(run, ""), f"{pct(s.get('rho_s_error_mean'), 1)} ± {pct(s.get('rho_s_error_sd'), 1)}",
                     "" if shift is None else f"{pct(shift, 1)} ± {pct(s.get('rho_s_shift_sd'), 1)}",
                     pct(s.get("roughness_error_mean"), 1), fixed(s.get("seconds_mean"), 0)])
    lines += table(["run", "what", "skin ρs error (mean ± sd)", "shift from its reference", "roughness error",
                    "fit (s)"], rows)
    for key, which in (("spread", "the uncorrected fit"), ("spread_candidate", None)):
        spread = get(d, key) or {}
        if not spread:
            continue
        which = which or f"the `{spread.get('fit')}` fit (today's default)"
        coverage = spread.get("coverage") or {}
        lines += ["", f"**Spread of {which}** over {text(spread.get('captures'))} captures (seeds "
                      f"{text(d.get('spread_seeds'))}): skin's ρs error {pct(spread.get('rho_s_error_mean'), 1)} ± "
                      f"{pct(spread.get('rho_s_error_sd'), 1)} (from {pct(spread.get('rho_s_error_min'), 1)} to "
                      f"{pct(spread.get('rho_s_error_max'), 1)}), within 3 % on {text(spread.get('rho_s_within_3_percent'))}"
                      + ("" if spread.get("roughness_within_3_percent") is None else
                         f", roughness within 3 % on {text(spread.get('roughness_within_3_percent'))}")
                      + f"; the 95 % intervals hold the truth for {pct(coverage.get('specular_reflectance'), 0)} of "
                      f"ρs channels and {pct(coverage.get('roughness'), 0)} of roughnesses."]
    return lines


#: The parameter families the coverage is pooled over: the lobe's scale and its width.
COVERAGE_FAMILIES = {**dict.fromkeys(("specular_reflectance", "cxy", "cz"), "scale (ρs; Lafortune's cxy, cz)"),
                     **dict.fromkeys(("roughness", "alpha", "exponent"), "width (roughness, α, exponent)")}


def sec_reflectance_coverage(d):
    """Per model and glossy parameter: the relative errors over skin and lips (channels pooled), how often
    the reported intervals hold the truth and how often the statistical part alone would; with
    ``--tune``, the systematic term chosen; for a capture or two, each parameter as fitted."""
    capture = get(d, "capture") or {}
    library = {m: p for m, p in items(d.get("systematic_in_library")) if p}
    lines = [f"Truths drawn per seed (seeds {text(d.get('seeds'))}: the model in turn, skin's lobe drawn over the "
             f"plausible range), {text(capture.get('measurements'))} measurements, {text(get(capture, 'image', 0))}² "
             f"photographs, {text(capture.get('spp'))} spp, fitted with the defaults on the true shape; skin and "
             "lips, channels pooled. *Coverage*: how often the intervals the fits reported hold the truth, "
             + ("the library's systematic term in (" + "; ".join(
                 f"{m}: " + ", ".join(f"{k} {pct(v, 1)}" for k, v in items(p)) for m, p in library.items()) + ")"
                if d.get("systematic_in_fits") and library else
                "the statistical part alone (the systematic term left out for this run, which chooses it: the "
                "smallest relative sd with which the widened intervals would hold at least 95 %)") + ".", ""]
    rows = []
    tuned = False
    for model, params in items(d.get("summary")):
        for name, r in items(params):
            tuned = tuned or "chosen_systematic" in r
            rows.append([model, name, text(r.get("entries")), pct(r.get("error_mean"), 1), pct(r.get("error_rms"), 1),
                         pct(r.get("coverage_reported"), 0)]
                        + ([pct(r.get("chosen_systematic"), 1) if r.get("chosen_systematic") is not None else "—"]
                           if "chosen_systematic" in r else []))
    lines += table(["model", "parameter", "values", "error (mean)", "error (rms)", "coverage"]
                   + (["systematic chosen"] if tuned else []), rows)
    families = {}
    for model, params in items(d.get("summary")):
        for name, r in items(params):
            family = COVERAGE_FAMILIES.get(name)
            if family and r.get("entries") and r.get("coverage_reported") is not None:
                held, n = families.get(family, (0.0, 0))
                families[family] = (held + r["coverage_reported"] * r["entries"], n + r["entries"])
    if families:
        lines += ["", "Per parameter family, every model pooled:", ""]
        lines += table(["family", "values", "coverage"],
                       [[family, text(n), pct(held / n, 1)] for family, (held, n) in families.items()])
    runs = rows_of(d.get("runs"))
    if 0 < len(runs) <= 2:
        detail = []
        for run in runs:
            for region, r in items(get(run, "fit", "regions")):
                for name, p in items(r):
                    if not isinstance(p, dict) or "fitted" not in p:
                        continue
                    interval = p.get("interval95")
                    span = "—" if not interval else ", ".join(
                        f"[{fixed(lo, 4)}, {fixed(hi, 4)}]" for lo, hi in zip(*interval))
                    detail.append([text(run.get("seed")), region, name, ", ".join(fixed(v, 4) for v in p["fitted"]),
                                   ", ".join(fixed(v, 4) for v in p["truth"]),
                                   ", ".join(pct(v, 1) for v in p["error"]), span,
                                   ", ".join("yes" if c else "no" for c in p.get("covered", []))])
        lines += [""] + table(["seed", "region", "parameter", "fitted", "truth", "error", "95 % interval", "holds"],
                              detail)
    return lines


def sec_normal_step_tol(d):
    """Per tolerance of the normal step: the four models' fit time against 1e-7's, and the largest change
    of a model's figures against 1e-7's."""
    lines = [f"The main job's default capture at development seeds {text(d.get('seeds'))}, fitted shapes; each "
             "model fitted with the defaults (per-texel normals on) at each tolerance of the normal step's "
             f"iterations, the fits timed in turns. The library's is {text(d.get('chosen'))}. Changes are against "
             "1e-7, the largest over seeds and models (held-out lights and environments in points of relative "
             "image RMSE; skin's BRDF error in its own units).", ""]
    rows = [[f"{tol}", fixed(get(row, "seconds"), 1), fixed(get(row, "time_ratio"), 3),
             fixed(get(row, "max_change_heldout_rmse_points"), 3), fixed(get(row, "max_change_environment_rmse_points"), 3),
             fixed(get(row, "max_change_skin_brdf_rmse"), 5)] for tol, row in items(d.get("summary"))]
    lines += table(["tolerance", "fits (s)", "time / 1e-7's", "held-out change (points)",
                    "environments change (points)", "skin BRDF change"], rows)
    detail = []
    for run in d.get("runs") or []:
        for model, fits in items(run.get("fits")):
            detail.append([text(run.get("seed")), model] + [f"{fixed(get(f, 'seconds'), 1)} s, {pct(get(f, 'heldout_rmse'), 2)}"
                                                            for f in fits.values()])
    if detail:
        lines += ["", "Per seed and model: the fit's time and held-out error at each tolerance.", ""]
        lines += table(["seed", "model", *[str(t) for t in d.get("tolerances") or []]], detail)
    return lines


def sec_interreflection_rounds(d):
    """Per way of taking the bounced light out: skin's and the lips' glossy errors over the seeds and
    channels (mean, largest magnitude)."""
    variants = {k: " then ".join(f"{'the photograph’s size' if w is None else f'{w} px'} at {n} spp" for w, n in v)
                for k, v in items(d.get("variants"))}
    lines = [f"Cook–Torrance captures of development seeds {text(d.get('seeds'))} (10 photographs of 384², the "
             "skin's lobe drawn per seed), fitted with the defaults on the true shape, the bounced light taken out "
             f"in each way; the library's is `{text(d.get('chosen'))}`. Errors: fitted / true − 1 over seeds and "
             "channels, mean (largest magnitude).", ""]
    columns = ("skin.specular_reflectance", "skin.roughness", "lips.specular_reflectance", "lips.roughness")
    rows = []
    for name, row in items(d.get("summary")):
        rows.append([f"`{name}`", variants.get(name, "—")]
                    + [f"{pct(get(row, c, 'mean'), 1)} ({pct(get(row, c, 'max_abs'), 1)})" for c in columns])
    lines += table(["variant", "rounds", "skin ρs", "skin roughness", "lips ρs", "lips roughness"], rows)
    return lines


def sec_light_balance_limit(d):
    """Per development Yale subject: its lights' balance factors against its median light's, the largest
    either way, and the failed photographs'; the simulated captures' lamps' factors, and the spread limit."""
    lines = [f"The development Yale subjects ({text(d.get('train_lights'))} training lights each, measured as "
             "`validation/real_yaleb.py` measures them, Phong balancing the lights) with no light taken for failed; "
             "each light's factor against its subject's median light's (above 1: the photograph darker than the "
             f"capture states). The library's limit: {text(d.get('chosen'))}; the largest sound factor, either way, "
             f"{fixed(d.get('largest_sound_deviation'), 3)}, the smallest failed one "
             f"{fixed(d.get('smallest_failed_deviation'), 1)} (failed by eye: {text(d.get('failed_photographs'))}); "
             f"the limit clears both by {text(d.get('margin'))} times: {text(d.get('separates'))}.", ""]
    rows = []
    for subject, run in items(d.get("runs")):
        factors = run.get("factors") or {}
        if not factors:
            rows.append([subject, DASH, DASH, text(run.get("error"))[:80]])
            continue
        rows.append([subject, fixed(min(factors.values()), 3), fixed(max(factors.values()), 3),
                     ", ".join(f"{k} {fixed(v, 1)}" for k, v in factors.items() if max(v, 1 / v) >= 2) or DASH])
    lines += table(["subject", "smallest factor", "largest factor", "beyond 2 either way"], rows)
    spread = d.get("spread") or {}
    lines += ["", f"The balance's limit: where the sound lights spread farther than {text(spread.get('chosen'))} "
              "from their median light's, either way, the lights are left as given. The default capture's calibrated "
              f"lamps at development seeds {text(d.get('seeds'))} (measured with the defaults, Phong first) spread "
              f"up to {fixed(spread.get('calibrated_largest'), 4)}; the Yale subjects' sound lights from "
              f"{fixed(spread.get('real_smallest'), 4)}; the limit clears both by {text(spread.get('margin'))} times: "
              f"{text(spread.get('separates'))}.", ""]
    sims = [[text(seed), ", ".join(f"{k} {fixed(v, 4)}" for k, v in items(run.get("factors"))) or text(run.get("error"))]
            for seed, run in items(d.get("simulated"))]
    return lines + table(["seed", "lamps' factors against the median lamp's"], sims)


def sec_real_yaleb_repeat(d):
    """Per model, the pooled held-out error of each run and the largest change on one subject; per subject and
    run, each model's error."""
    runs = d.get("runs") or []
    lines = [f"The default run of `validation/real_yaleb.py` repeated {text(d.get('repeats'))} times on the development "
             f"subjects {text(d.get('subjects'))} ({text(d.get('train_lights'))} training lights, texture "
             f"{text(d.get('texture_resolution'))}²): pooled held-out relative RMSE per run, and the largest change "
             "between runs on one subject.", ""]
    rows = [[m, *[fixed(get(r, "pooled", m), 4) for r in runs], fixed(get(sp, "largest_subject_change"), 4),
             text(get(sp, "subject_of_largest_change"))] for m, sp in items(d.get("spread"))]
    rows.append(["photometric stereo", *[fixed(get(r, "pooled", "photometric_stereo"), 4) for r in runs], DASH, DASH])
    lines += table(["predictor", *[f"run {k + 1}" for k in range(len(runs))], "largest change on a subject",
                    "on"], rows)
    if any(get(r, "best_model") for r in runs):  # the model each run chooses by its training photographs
        lines += ["Chosen by the pooled relative RMSE over every training photograph (`real_yaleb.summary`): "
                  + "; ".join(f"run {k + 1} {text(get(r, 'best_model'))} ("
                              + ", ".join(f"{m} {pct(v)}" for m, v in items(get(r, "training_relative_rmse")))
                              + ")" for k, r in enumerate(runs)) + "."]
    detail = [[s, *[", ".join(f"{m} {fixed(get(r, 'subjects', s, m), 3)}" for m in d.get("models") or []) for r in runs]]
              for s in d.get("subjects") or []]
    return lines + [""] + table(["subject", *[f"run {k + 1}" for k in range(len(runs))]], detail)
