"""The table of ``docs/results.md`` for the redesign issue's measuring stick (``design_metrics.json``, written
by ``validation/design_metrics.py``; used by ``validation/results_doc.py``)."""

from __future__ import annotations

from results_format import DASH, get, items, listed, rows_of, table, text


def _target(metric: dict) -> str:
    target = metric.get("target")
    if target is None:
        return DASH
    shown = text(target) if isinstance(target, bool) or target == 0 else f"≤ {text(target)}"
    return f"{shown} (proposed)" if str(metric.get("target_from")).startswith("proposed") else shown


def sec_design_metrics(d):
    metrics = d.get("metrics") or {}
    lines = [f"Issue {text(d.get('issue'))}: its countable targets, counted with Python's `ast` over "
             f"{text(d.get('modules'))} modules and {text(d.get('functions'))} functions of `mifaces/` (the "
             "script's docstring states each rule; the JSON lists every site, file and line). `issue`: the issue's "
             "figure when it was written; a target marked *proposed* is this script's reading of the issue's "
             "direction, not a figure the issue gives.", ""]
    rows = [[text(m.get("label") or key), text(m.get("issue_count")), text(m.get("count")), _target(m),
             text(m.get("met"))] for key, m in items(metrics)]
    lines += table(["metric", "issue", "now", "target", "met"], rows)
    lines += listed("Branch sites on a light's kind, per file", get(metrics, "light_branches", "per_file"))
    lines += listed("Modules over 450 lines (lines)",
                    {m.get("file"): m.get("lines") for m in rows_of(get(metrics, "long_modules", "sites"))})
    flags = get(metrics, "duplicate_flags", "sites")
    lines += listed("CLI flags declared more than once (declarations)",
                    {flag: len(found) for flag, found in items(flags) if isinstance(found, list)})
    return lines
