"""Tables of ``docs/results.md`` for one-question studies (used by ``validation/results_doc.py``):
the shape refinement's judges (``refine_judge.json``, ``validation/refine_judge.py``) and the region
outlines in fitted renders (``region_seams.json``, ``validation/region_seams.py``)."""

from __future__ import annotations

from results_format import get, items, rows_of, table, text


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
