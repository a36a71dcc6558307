"""Which data may choose a default and which only reports: the one place that says so.

A default (a schedule, a threshold, a mode count, an option left on) is chosen on **development** data;
the figures quoted for it come from **report** data, which played no part in choosing. Every script
that chooses calls :func:`require_development` on what it is about to choose on, and so refuses report
data (``tests/test_roles.py`` checks that each script in :data:`CHOOSERS` does).

Seeds are simulated captures' seeds (``mifaces simulate --seed``: face, poses, lamps, noise), except
where a kind says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Roles:
    """Development and report members of one kind of data (disjoint)."""

    kind: str
    development: frozenset
    report_rule: str  # in words: which members are report data

    def is_development(self, item) -> bool:
        return item in self.development


#: Simulated captures: seeds 100-199 (and 11, 12, chosen on before this file existed) are development
#: seeds; every other seed (0-10, 13-99, 200 and up: the main job's seed 0 among them) is a report seed.
SIMULATED = Roles("simulated capture seed", frozenset({11, 12, *range(100, 200)}),
                  "every seed outside 11, 12 and 100-199 (the main job's default capture is seed 0)")
#: Random Surrey Face Model faces (``validation/model_span.py``): faces drawn with seed 7 choose, seed
#: 2024's report.
SURREY_FACES = Roles("Surrey face seed", frozenset({7}), "every seed but 7 (the span is reported on 2024)")
#: Extended Yale B: the ten subjects in ``../shared/data/yaleb`` are for development; the other 28
#: subjects of the data set are held out for reporting.
YALE = Roles("Extended Yale B subject", frozenset(f"yaleB{i:02d}" for i in range(1, 11)),
             "every subject but yaleB01-yaleB10, none of which is in ../shared")

#: Scripts that choose a default, and what they choose. Each calls :func:`require_development` on the
#: data the choice is made on.
CHOOSERS = {
    "validation/model_span.py": "the mode counts it records as chosen on its training faces (the shape fit's "
                                "default, 50, predates it)",
    "validation/albedo_rounds.py": "the albedo rounds and the texel albedo",
    "validation/uncertainty.py": "the intervals' tiling (--tune, --tune-tiles)",
    "validation/environment_lights.py": "restart_under_maps (--tuning)",
    "validation/light_calibration_bias.py": "the lights' balance threshold (on the tuning seeds)",
    "validation/light_balance_measure.py": "--balance-lights off by default (--role tuning)",
    "validation/refine_seeds.py": "the refinement's held regions and light gains (--role training)",
    "validation/refine_shape_default.py": "the shape refinement's render size (--seed 11)",
    "validation/shape_depth.py": "the image term's silhouette cut (--seeds 11 12)",
    "validation/reflectance_coverage.py": "the intervals' systematic term per model and parameter (--tune)",
    "validation/interreflection_rounds.py": "the bounced light's rounds and render sizes (seeds 120, 124, 128)",
    "validation/normal_step_tol.py": "the per-texel normal step's tolerance (seeds 101, 102)",
    "validation/light_balance_limit.py": "the factor at which a given light counts as failed (yaleB01-yaleB10)",
    "validation/refine_judge.py": "the shape refinement's judge: the pixel loss or held-out photographs (seeds 11, "
                                  "12, 100-103)",
}


class ReportDataError(ValueError):
    """A script asked to choose a default on report data."""


def require_development(roles: Roles, items, what: str) -> list:
    """``items`` if every one is development data of ``roles``; otherwise a :class:`ReportDataError`
    naming the report items and what was to be chosen on them."""
    items = list(items)
    report = [i for i in items if not roles.is_development(i)]
    if report:
        raise ReportDataError(
            f"{what} is chosen on development data only; {', '.join(map(str, report))} "
            f"{'is a report' if len(report) == 1 else 'are report'} {roles.kind}{'' if len(report) == 1 else 's'} "
            f"({roles.report_rule}; validation/roles.py)")
    return items


def refuse_report_data(parser, roles: Roles, items, what: str) -> list:
    """:func:`require_development` for a script's command line: a report item ends it through
    ``parser.error`` (exit status 2, the message naming the items)."""
    try:
        return require_development(roles, items, what)
    except ReportDataError as error:
        parser.error(str(error))
