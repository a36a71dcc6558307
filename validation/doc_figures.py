"""Finds the figures in the hand-written docs that no committed result backs (issue 47).

Every measured number quoted in ``README.md`` or ``docs/*.md`` must come from a result file in
``validation/results/`` that its section names, be a setting of the code that its section names, or
be marked as someone else's (a citation). ``docs/results.md`` is left out: ``results_doc.py``
generates it from the JSON as a whole. ``python validation/results_doc.py --check`` runs this check
(``tests/test_doc_figures.py``); ``python validation/doc_figures.py [PAGE ...]`` prints its list
alone, one ``page:line: figure`` a line, and exits 1 if there is one (``--all``: every figure with
what backs it).

**Figures.** Outside fenced code blocks, inline code spans, link targets, URLs and HTML comments:

- a number followed by a unit: ``%``; ``points``/``pp`` (percentage points: a decimal or signed
  number, one followed by ``lower``, ``higher``, ``worse``, ``over``, ``of``..., or one after ``by`` or
  ``within``; ``68 points`` is a count); ``mm``, ``cm``, ``m``, ``µm``; ``s``, ``ms``, ``µs``, ``min``,
  ``h`` (and ``seconds``, ``minutes``, ``hours``); ``px``/``pixels``; ``°``/``deg``/``degrees``;
  ``KiB``, ``MiB``, ``GiB``, ``kB``, ``MB``, ``GB``; ``sd``/``σ``; ``×`` written against the number
  (``13.4×``, not ``512×512`` or ``2 × height``). In a chain of numbers joined by ``–``, ``-``, ``/``,
  ``,``, ``to``, ``and``, ``or``, ``→`` or ``->`` every member takes the unit of the last
  (``2.2 and 2.6 mm``, ``10.0–10.3 %``, ``3.47 -> 2.20 %``);
- a number with a decimal point or an exponent, with or without a unit (``0.286``, ``RMSE 0.338``).

Not figures: integers without a unit (counts, seeds, iterations, image sizes such as ``512²``,
sample counts such as ``64 spp``, years, issue numbers); numbers inside words and names (``m01``,
``cz_2``, ``yaleB01``, ``A+035E+40``); section, equation, figure, table, part and issue numbers
(after ``sec.``, ``section``, ``§``, ``eq.``, ``fig.``, ``table``, ``part``, ``issue``, ``#``, also in a
list: ``sections 4.1 and 4.4``); versions (after ``v``, ``version``, ``Python``, ``LLVM``, ``CUDA``,
``glTF``, ``>=``, ``<=``, ``==``). The line before counts when the number opens a line.

**Backed by a result.** A figure is backed when a result file its section names holds a value that
rounds to it at its printed precision: ``3.0 %`` by a value in [2.95, 3.05] stored as a percentage
or in [0.0295, 0.0305] stored as a fraction; an integer with trailing zeros (``89,000``) at the
precision of its last non-zero digit; a signed figure also by its magnitude (``fell by 19.6 %``
against ``-0.196``). A file's values are its numbers, its numeric keys, the numbers written in its
strings, and, for an object holding a number ``fitted`` and a number ``truth``, the fit's relative
error ``fitted / truth - 1`` (``-3.4 %`` for 1.2247 against 1.2684). Each value has the unit its key
states (``world_mm``, ``angle_deg``, ``wall_s``, ``seconds``, ``feature_rms_px``, ``peak_rss_mib``,
``scale_pct``, ``error_percent``: the nearest key up the path that states one; ``_s`` and ``_ms``
only as a suffix, so ``rho_s`` is no time) or that its string writes after it (``-19.6 %``), else
none. A figure with a unit is backed only by a value of the same kind or of no stated unit: a
percentage by a percentage or a fraction (×100); ``mm`` by ``mm`` or an unstated value in mm or in
metres (×1000), ``cm``, ``m`` and ``µm`` likewise; ``ms``, ``min``, ``h`` by seconds (×1000, ÷60,
÷3600); ``GiB``, ``MB``, ``GB`` by MiB or bytes. A figure without a unit is backed by any value.
Statistics a page computes from a file (a median over fits, a ratio of two runs) are not in it:
quote the file's own values, or say it in words.

**Sections.** A section runs from a heading to the next heading of any level. It sees what its own
text names and what the text of each heading above it names before that heading's first subheading
(so a page's introduction names files for the whole page). A result file is named by ``foo.json``
or ``validation/results/foo.json`` in prose, code spans or links (``{a,b}`` and ``[_x]`` expanded:
``refine_shape_default_512_tuning{,_full}.json``, ``uncertainty_measure[_texel_albedo].json``), by a
link to its section of ``results.md`` (``results.md#...-foojson``), or by a comment
``<!-- figures: foo.json bar.json -->``. Names that are not files of ``validation/results/``
(``brdf.json``, ``report.json``) name nothing.

**Inputs.** A setting is not a measurement. A figure is an input, and needs no result, when its
section names, in a code span, the code it comes from, and that code holds a literal equal to the
figure as printed (with the scales above: ``95 %`` is ``0.95``, ``1.2 m`` is ``1200.0`` mm). A span
names a setting by a constant (``LEVEL``), the last part of a dotted name (``intervals.LEVEL``,
``ShapeOptions.facing_min``), a keyword (``facing_min=``), a flag (``--spp``) or a test's name; a
plain word (``seed``, ``albedo``) names nothing, being too common. The settings, in ``mifaces/``,
``plugins/``, ``validation/``, ``tests/`` and ``tools/``: a module or class constant or field (every
literal of the bound expression, so ``REFRACTIVE_INDEX = {"skin": 1.38, ...}`` gives 1.38), a
keyword default (``def fit(spp=64)``: ``spp`` and ``fit`` both name 64), a flag's default
(``add_argument("--spp", default=64)``), and every literal of a test function (its bounds:
``test_gltf_brdf_matches_mitsubas_principled_lobe`` asserts ``rtol=0.01``). A figure is an input
too when a code span of its section sets it (a command's flag, ``--iterations 0.25``, or
``facing_min=0.5``), or when a code span on its own line names a function with that literal in its
body (the simulator's ``head_pose`` jitters a sitter's yaw by 3°: a setting written inline).

**Citations.** A figure from the literature or another project (the paper, Weyrich et al., Dask's
defaults) is marked by an HTML comment ``<!-- cite: SOURCE -->`` after it, on its line and in its
clause, ``SOURCE`` saying who is cited: the marker covers the figures before it back to the end of
the previous sentence or clause (``.``, ``;``, ``!`` or ``?`` before a space, not in ``et al.``,
``e.g.``, ``sec.``) or table cell (``|``); a full stop just before the marker is its own. It is for
other people's numbers only: a figure measured here is backed by its result, or removed. A figure
from a development run that left no result (the docs say "development run, not kept") is not
backed by anything: say what the run decided, without its figures.

**What the check cannot see.** It checks that a figure's section names a result holding a value
that rounds to the figure, not that the value is the quantity the sentence means. A section that
names a large file (``truths.json``, ``uncertainty_records.json``) holds values of every size, and a
figure printed to two significant digits is matched by one of them by chance more often than not
(of the committed docs' backed figures, about three in four would still be backed multiplied by
1.13, 1.37 or 0.71): a stale figure beside a large file can pass. It catches figures whose section names no
result, and figures that contradict a small one.

Standard library only.
"""

from __future__ import annotations

import argparse
import ast
import bisect
import json
import math
import re
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "validation" / "results"
#: The generated page (``results_doc.py``), checked against the JSON as a whole.
GENERATED = "results.md"
#: The code whose bound literals are settings a page may quote (the tests' tolerances among them).
CODE = ("mifaces", "plugins", "validation", "tests", "tools")

_SPACE = "[ \u00a0\u2009\u202f]"
_SIGN = "[-+\u2212]"
# a number: optional sign, digits with optional thousands groups, optional decimals and exponent
_NUMBER = (_SIGN + r"?(?:\d{1,3}(?:(?:,|" + _SPACE + r")\d{3})+(?![\d.,])|\d+)(?:\.\d+)?(?:[eE]" + _SIGN
           + r"?\d+)?")
#: Printed unit -> the unit's name here.
UNITS = {
    "%": "%", "percent": "%", "points": "points", "point": "points", "pp": "points",
    "mm": "mm", "cm": "cm", "m": "m", "µm": "um", "μm": "um",
    "ms": "ms", "µs": "us", "μs": "us", "s": "s", "sec": "s", "seconds": "s", "second": "s",
    "min": "min", "minutes": "min", "minute": "min", "h": "h", "hours": "h", "hour": "h",
    "px": "px", "pixels": "px", "pixel": "px",
    "°": "deg", "deg": "deg", "degrees": "deg", "degree": "deg",
    "KiB": "KiB", "MiB": "MiB", "GiB": "GiB", "kB": "kB", "MB": "MB", "GB": "GB",
    "sd": "sd", "σ": "sd", "×": "x",
}
_UNIT = (r"(?:%|°|(?<=\d)×(?!" + _SPACE + r"?\d)|(?:"
         + "|".join(sorted((re.escape(u) for u in UNITS if u not in "%°×"), key=len, reverse=True))
         + r")(?![\w²³⁻]))")
_JOIN = (r"(?:" + _SPACE + r"?(?:–|-|/|→|->)" + _SPACE + r"?|,?" + _SPACE + r"(?:to|and|or)" + _SPACE
         + r"|," + _SPACE + r")")
_LEFT = r"(?<![\w.\-+/#^\u2212±])"
_FIGURE = re.compile(_LEFT + r"(?P<chain>" + _NUMBER + r"(?:" + _JOIN + _NUMBER + r")*)"
                     r"(?!\.?\w)(?:" + _SPACE + r"?(?P<unit>" + _UNIT + r"))?")
_ONE = re.compile(r"(?<![\w.])(?P<num>" + _NUMBER + r")")
_IN_STRING = re.compile(_LEFT + r"(?P<num>" + _NUMBER + r")(?!\.?\w)(?:" + _SPACE + r"?(?P<unit>" + _UNIT + r"))?")
# what may precede a number that is not a figure: section, equation, figure, issue numbers; versions
_NOT_A_FIGURE_BEFORE = re.compile(
    r"(?:\bsec(?:tion)?s?\.?|§|\beqs?\.?|\bequations?|\bfigs?\.|\bfigures?|\btables?|\bchapters?|\bissues?|"
    r"\bparts?|#|\bversions?|\bv|\bpython|\bllvm|\bcuda|\bgltf|>=|<=|==|~=)"
    r"(?:\s*\d+(?:\.\d+)*\s*(?:,|and|or|to|–|-))*" + _SPACE + r"*$", re.IGNORECASE)
_CODE_SPAN = re.compile(r"(`+)(.+?)\1")
_LINK_TARGET = re.compile(r"\]\(([^)\s]*)\)")
_URL = re.compile(r"https?://\S+")
_COMMENT = re.compile(r"<!--(.*?)-->")
_CITE = re.compile(r"<!--\s*cite:\s*\S[^>]*?-->")
# where a citation's clause ends: a sentence or a clause, a table cell
_CLAUSE_END = re.compile(r"(?<!\bal)(?<!\bcf)(?<!\bvs)(?<!\bsec)(?<!\beq)(?<!\bfig)(?<!e\.g)(?<!i\.e)"
                         r"[.;!?](?=\s|$)|\|")
_FIGURES_COMMENT = re.compile(r"<!--\s*figures:\s*([^>]*?)\s*-->")
_HEADING = re.compile(r"^(#{1,6})\s+\S")
_FENCE = re.compile(r"^\s*(```|~~~)")
_JSON_NAME = re.compile(r"[\w{}\[\],*.-]*\.(?:json\b|\{json[^}]*\})")
_RESULTS_ANCHOR = re.compile(r"results\.md#([\w-]+?)json\b")
# percentage points, not feature points: a decimal, a sign, or a comparison after the word
_PERCENTAGE_POINTS = re.compile(r"[.+\-\u2212]\d|\bpoints?\s+(?:lower|higher|better|worse|above|below|over|under|"
                                r"more|less|off|short|up|down|apart|of\b)")
_IDENTIFIER = re.compile(r"[A-Za-z_]\w*")
# how a code span names a setting: a constant (``LEVEL``), the last part of a dotted name
# (``ShapeOptions.facing_min``), a keyword (``facing_min=``), a test, a flag (``--spp``)
_SETTING_NAME = re.compile(r"(?<![\w.])(?:[A-Z][A-Z0-9_]{2,}|test_\w+)\b|\w+(?=\s*=)|(?<=\.)[A-Za-z_]\w*\b(?!\.)")
_FLAG = re.compile(r"(?<![\w-])--([a-z][\w-]*)")
# a value a code span sets: after a flag (``--iterations 0.25``, ``--seeds 3 4 5``) or an ``=``
_SET_IN_CODE = re.compile(r"(?:(?<![\w-])--[a-z][\w-]*[ =]|=\s*)(?P<values>" + _NUMBER + r"(?:[ ,]+" + _NUMBER + r")*)")


@dataclass(frozen=True)
class Scope:
    """What a section names: result files (stems), code names, and the numbers of its code spans."""

    results: frozenset[str] = frozenset()
    settings: frozenset[str] = frozenset()
    code_numbers: frozenset[float] = frozenset()

    def __or__(self, other: "Scope") -> "Scope":
        return Scope(self.results | other.results, self.settings | other.settings,
                     self.code_numbers | other.code_numbers)


@dataclass(frozen=True)
class Figure:
    """One figure on a page: where, as printed, its value, precision and unit, and its section's scope."""

    page: Path
    line: int
    text: str
    value: float
    decimals: int
    unit: str | None
    cited: bool
    scope: Scope
    #: the code its own line names in code spans (every identifier): a function there gives its literals
    line_code: frozenset[str] = frozenset()

    def where(self, root: Path = ROOT) -> str:
        try:
            page = self.page.resolve().relative_to(root.resolve()).as_posix()
        except ValueError:
            page = self.page.as_posix()
        return f"{page}:{self.line}"


# --------------------------------------------------------------------------- numbers


def parse_number(text: str) -> tuple[float, int]:
    """A printed number's value and its precision in decimals (negative: to tens, hundreds, ...)."""
    text = re.sub(_SPACE, "", text.replace("\u2212", "-").replace(",", ""))
    mantissa, _, exponent = text.lower().partition("e")
    value = float(text.lower())
    if "." in mantissa:
        decimals = len(mantissa.split(".")[1])
    else:
        digits = mantissa.lstrip("+-")
        decimals = -(len(digits) - len(digits.rstrip("0"))) if digits.strip("0") else 0
    if exponent:
        decimals -= int(exponent)
    return value, decimals


def _tolerance(decimals: int) -> float:
    return 0.5 * 10.0 ** (-decimals) * (1 + 1e-9) + 1e-12


# --------------------------------------------------------------------------- reading a page


def _blank(match: re.Match) -> str:
    return " " * len(match.group(0))


def prose(line: str) -> str:
    """``line`` with its code spans, link targets, URLs and HTML comments blanked (same length)."""
    line = _COMMENT.sub(_blank, line)
    line = _CODE_SPAN.sub(_blank, line)
    line = _LINK_TARGET.sub(lambda m: "](" + " " * len(m.group(1)) + ")", line)
    return _URL.sub(_blank, line)


def expand(name: str) -> list[str]:
    """``a{,_b}[_c].{json,png}`` -> the names it stands for that end in ``.json``."""
    match = re.search(r"\{([^}]*)\}|\[([^\]]*)\]", name)
    if match is None:
        return [name] if name.endswith(".json") else []
    options = match.group(1).split(",") if match.group(1) is not None else ["", match.group(2)]
    return [n for option in options for n in expand(name[:match.start()] + option + name[match.end():])]


def line_scope(line: str, stems: frozenset[str]) -> Scope:
    """What one line names: result files, code names and code-span numbers."""
    results = set()
    tokens = _JSON_NAME.findall(line)
    for listed in _FIGURES_COMMENT.findall(line):
        tokens += listed.split()
    for token in tokens:
        for name in expand(token.rsplit("/", 1)[-1]):
            if name[:-len(".json")] in stems:
                results.add(name[:-len(".json")])
    for slug in _RESULTS_ANCHOR.findall(line):
        results.update(stem for stem in stems if slug == stem or slug.endswith("-" + stem))
    settings, numbers = set(), set()
    for span in _CODE_SPAN.finditer(_COMMENT.sub(_blank, line)):
        code = span.group(2)
        settings.update(_SETTING_NAME.findall(code))
        settings.update(n.replace("-", "_") for n in _FLAG.findall(code))
        for match in _SET_IN_CODE.finditer(code):
            for one in _ONE.finditer(match.group("values")):
                numbers.add(parse_number(one.group("num"))[0])
    return Scope(frozenset(results), frozenset(settings), frozenset(numbers))


def _lines_outside_code(lines: list[str]):
    """(index, line, is_prose): fenced blocks and multi-line HTML comments are not prose."""
    in_fence = in_comment = False
    for number, line in enumerate(lines):
        if _FENCE.match(line):
            in_fence = not in_fence
            yield number, line, False
            continue
        if in_fence:
            yield number, line, False
            continue
        if in_comment:
            if "-->" not in line:
                yield number, line, False
                continue
            in_comment = False
            end = line.index("-->") + 3
            line = " " * end + line[end:]
        opened = line.rfind("<!--")
        if opened >= 0 and "-->" not in line[opened:]:
            in_comment = True
            line = line[:opened]
        yield number, line, True


def page_figures(page: Path, stems: frozenset[str], text: str | None = None) -> list[Figure]:
    """Every figure of a Markdown page, with what its section names."""
    lines = (page.read_text(encoding="utf-8") if text is None else text).splitlines()
    # the sections, heading to heading: (level, first line, what its own text names)
    blocks: list[list] = [[0, 0, Scope()]]
    for number, line, is_prose in _lines_outside_code(lines):
        heading = _HEADING.match(line) if is_prose else None
        if heading:
            blocks.append([len(heading.group(1)), number, Scope()])
        blocks[-1][2] = blocks[-1][2] | line_scope(lines[number], stems)
    scopes, stack = [], []
    for level, _, own in blocks:
        while stack and stack[-1][0] >= level:
            stack.pop()
        inherited = Scope()
        for _, parent in stack:
            inherited = inherited | parent
        scopes.append(inherited | own)
        stack.append((level, own))
    starts = [start for _, start, _ in blocks]

    figures = []
    previous = ""  # the line before, for a "sec." that ends it
    for number, line, is_prose in _lines_outside_code(lines):
        if not is_prose:
            previous = ""
            continue
        block = bisect.bisect_right(starts, number) - 1
        cites = [m.start() for m in _CITE.finditer(_CODE_SPAN.sub(_blank, line))]  # not one quoted in code
        visible = prose(line)
        line_code = frozenset(name for span in _CODE_SPAN.finditer(_COMMENT.sub(_blank, line))
                              for name in _IDENTIFIER.findall(span.group(2)))
        for match in _FIGURE.finditer(visible):
            before = visible[:match.start()]
            if _NOT_A_FIGURE_BEFORE.search(before if before.strip() else previous.rstrip() + " "):
                continue
            printed_unit = match.group("unit")
            if printed_unit in ("points", "point") and not _PERCENTAGE_POINTS.search(match.group(0) + visible[
                    match.end():match.end() + 12]) and not re.search(r"\b(?:by|within)\s*$", before):
                printed_unit = None  # feature points, not percentage points: a count
            unit = UNITS.get(printed_unit) if printed_unit else None
            cited = any(c >= match.end() and not _CLAUSE_END.search(visible[match.end():c].rstrip(" .;!?"))
                        for c in cites)
            for one in _ONE.finditer(match.group("chain")):
                raw = one.group("num").strip()
                if unit is None and not re.search(r"[.eE]", raw):
                    continue  # an integer without a unit: a count, not a figure
                value, decimals = parse_number(raw)
                figures.append(Figure(page, number + 1, f"{raw} {printed_unit}" if unit else raw, value,
                                      decimals, unit, cited, scopes[block], line_code))
        previous = visible
    return figures


# --------------------------------------------------------------------------- the results' values


def key_unit(key: str) -> str | None:
    """The unit a JSON key states (``world_mm``: mm; ``per_s``: a rate, no unit of ours), or None."""
    tokens = re.split(r"[_\W]+", key.lower())
    for i, token in enumerate(tokens):
        before = tokens[i - 1] if i else ""
        last = i == len(tokens) - 1  # "s" and "ms" count only as a suffix: rho_s is no time
        if token in ("seconds", "second") or token.startswith("seconds") or (last and token in ("s", "sec")):
            return "rate" if before == "per" else "s"
        if last and token == "ms":
            return "s_ms"
        if token in ("mm", "deg", "px", "mib", "bytes"):
            return {"mib": "MiB"}.get(token, token)
        if token in ("pct", "percent"):
            return "%"
    return None


def _values_in(data, unit: str | None, out: dict[str | None, set[float]]) -> None:
    if isinstance(data, bool) or data is None:
        return
    if isinstance(data, (int, float)):
        if math.isfinite(data):
            out.setdefault(unit, set()).add(float(data))
    elif isinstance(data, str):
        for match in _IN_STRING.finditer(data):
            try:
                value = parse_number(match.group("num"))[0]
            except ValueError:
                continue
            printed = match.group("unit")
            out.setdefault(UNITS.get(printed) if printed else unit, set()).add(value)
    elif isinstance(data, dict):
        fitted, truth = data.get("fitted"), data.get("truth")
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in (fitted, truth)) and truth:
            out.setdefault(None, set()).add(fitted / truth - 1.0)  # the fit's relative error
        for key, value in data.items():
            key = str(key)
            if re.fullmatch(_NUMBER, key.strip()):
                out.setdefault(None, set()).add(parse_number(key.strip())[0])
            _values_in(value, key_unit(key) or unit, out)
    elif isinstance(data, list):
        for value in data:
            _values_in(value, unit, out)


@lru_cache(maxsize=None)
def result_values(path: Path) -> dict[str | None, tuple[float, ...]]:
    """Every number a result file holds, by unit, sorted."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    out: dict[str | None, set[float]] = {}
    _values_in(data, None, out)
    return {unit: tuple(sorted(values)) for unit, values in out.items()}


#: A figure's unit -> (a stored value's unit, the factor from the stored value to the figure).
MATCHES = {
    "%": (("%", 1.0), (None, 100.0)),
    "points": (("%", 1.0), ("points", 1.0), (None, 100.0)),
    "mm": (("mm", 1.0), (None, 1.0), (None, 1000.0)),
    "cm": (("mm", 0.1), (None, 1.0), (None, 100.0)),
    "m": (("mm", 0.001), (None, 1.0)),
    "um": (("mm", 1000.0), (None, 1.0), (None, 1e6)),
    "s": (("s", 1.0), (None, 1.0)),
    "ms": (("s", 1000.0), ("s_ms", 1.0), ("ms", 1.0), (None, 1.0)),
    "us": (("s", 1e6), (None, 1.0)),
    "min": (("s", 1 / 60), ("min", 1.0), (None, 1.0)),
    "h": (("s", 1 / 3600), ("h", 1.0), (None, 1.0)),
    "deg": (("deg", 1.0), (None, 1.0)),
    "px": (("px", 1.0), (None, 1.0)),
    "KiB": (("MiB", 1024.0), ("bytes", 1 / 1024), (None, 1.0)),
    "MiB": (("MiB", 1.0), ("bytes", 1 / 2 ** 20), (None, 1.0)),
    "GiB": (("MiB", 1 / 1024), ("bytes", 1 / 2 ** 30), (None, 1.0)),
    "kB": (("bytes", 1e-3), (None, 1.0)),
    "MB": (("MiB", 2 ** 20 / 1e6), ("bytes", 1e-6), (None, 1.0)),
    "GB": (("MiB", 2 ** 20 / 1e9), ("bytes", 1e-9), (None, 1.0)),
    "sd": ((None, 1.0),),
    "x": ((None, 1.0),),
}


def _near(values: tuple[float, ...], target: float, tolerance: float) -> bool:
    i = bisect.bisect_left(values, target - tolerance)
    return i < len(values) and values[i] <= target + tolerance


def _matches(figure: Figure, values: dict[str | None, tuple[float, ...]]) -> bool:
    tolerance = _tolerance(figure.decimals)
    pairs = MATCHES.get(figure.unit) if figure.unit else tuple((unit, 1.0) for unit in values)
    for unit, factor in pairs:
        stored = values.get(unit, ())
        for target in {figure.value, -figure.value}:
            if _near(stored, target / factor, tolerance / factor):
                return True
    return False


def backing(figure: Figure, results: Path) -> str | None:
    """The result file (of those the figure's section names) that holds the figure, or None."""
    for stem in sorted(figure.scope.results):
        if _matches(figure, result_values(results / f"{stem}.json")):
            return f"{stem}.json"
    return None


# --------------------------------------------------------------------------- settings in the code


def _number_literal(node: ast.AST) -> float | None:
    """The value of a numeric literal (``0.95``, ``-20``), else None."""
    sign = 1.0
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        sign, node = -1.0, node.operand
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return sign * float(node.value)
    return None


def _literals(node: ast.AST | None) -> set[float]:
    """Every numeric literal in an expression."""
    if node is None:
        return set()
    return {v for sub in ast.walk(node) if (v := _number_literal(sub)) is not None}


def _target_names(target: ast.AST) -> list[str]:
    if isinstance(target, ast.Name):
        return [target.id]
    if isinstance(target, ast.Attribute):
        return [target.attr]
    if isinstance(target, (ast.Tuple, ast.List)):
        return [n for t in target.elts for n in _target_names(t)]
    return []


class _CodeScan(ast.NodeVisitor):
    """One pass over a module: the settings it binds by name, and every function's literals."""

    def __init__(self, settings: dict[str, set[float]], bodies: dict[str, set[float]]):
        self.settings, self.bodies = settings, bodies
        self.functions: list[str] = []  # the functions the visit is inside
        self.scopes = 0  # inside a function: assignments there are local variables, not settings

    def bind(self, name: str, values: set[float]) -> None:
        if values:
            self.settings.setdefault(name, set()).update(values)

    def generic_visit(self, node: ast.AST) -> None:
        value = _number_literal(node)
        if value is not None:
            for name in self.functions:
                self.bodies.setdefault(name, set()).add(value)
            return
        super().generic_visit(node)

    def visit_Assign(self, node: ast.Assign) -> None:
        if not self.scopes:
            values = _literals(node.value)
            for target in node.targets:
                for name in _target_names(target):
                    self.bind(name, values)
        self.generic_visit(node)

    def visit_AnnAssign(self, node: ast.AnnAssign) -> None:
        if not self.scopes:
            for name in _target_names(node.target):
                self.bind(name, _literals(node.value))
        self.generic_visit(node)

    def visit_FunctionDef(self, node: ast.FunctionDef) -> None:
        positional = node.args.posonlyargs + node.args.args
        pairs = list(zip(positional[len(positional) - len(node.args.defaults):], node.args.defaults))
        pairs += list(zip(node.args.kwonlyargs, node.args.kw_defaults))
        for arg, default in pairs:
            values = _literals(default)
            self.bind(arg.arg, values)
            self.bind(node.name, values)  # the function names its defaults too
        self.functions.append(node.name)
        self.scopes += 1
        self.generic_visit(node)
        self.scopes -= 1
        self.functions.pop()
        if node.name.startswith("test_"):  # a test: every literal of it (its bounds)
            self.bind(node.name, self.bodies.get(node.name, set()))

    visit_AsyncFunctionDef = visit_FunctionDef

    def visit_Call(self, node: ast.Call) -> None:
        if isinstance(node.func, ast.Attribute) and node.func.attr == "add_argument":
            default = next((k.value for k in node.keywords if k.arg == "default"), None)
            for flag in node.args:
                if isinstance(flag, ast.Constant) and isinstance(flag.value, str):
                    self.bind(flag.value.lstrip("-").replace("-", "_"), _literals(default))
        self.generic_visit(node)


@lru_cache(maxsize=None)
def scan_code(root: Path) -> tuple[dict[str, frozenset[float]], dict[str, frozenset[float]]]:
    """The code of ``CODE`` read once: name -> the literals bound to it as a setting (module and class
    constants and fields, keyword defaults under the argument's and the function's name,
    ``add_argument(..., default=...)``, a test's every literal), and a function's name -> every
    literal of its body."""
    settings: dict[str, set[float]] = {}
    bodies: dict[str, set[float]] = {}
    for folder in CODE:
        for path in sorted(p for p in (root / folder).rglob("*.py") if "node_modules" not in p.parts):
            try:
                tree = ast.parse(path.read_text(encoding="utf-8"))
            except (SyntaxError, UnicodeDecodeError, OSError, ValueError):
                continue
            _CodeScan(settings, bodies).visit(tree)
    return ({name: frozenset(v) for name, v in settings.items()},
            {name: frozenset(v) for name, v in bodies.items()})


#: A figure's unit -> the factors from a setting's literal to the figure (a fraction as a percentage;
#: metres as millimetres or centimetres, millimetres as centimetres or metres; seconds as milliseconds).
INPUT_FACTORS = {"%": (1.0, 100.0), "points": (1.0, 100.0), "mm": (1.0, 1000.0), "cm": (1.0, 100.0, 0.1),
                 "m": (1.0, 0.001), "ms": (1.0, 1000.0)}


def is_input(figure: Figure, root: Path) -> bool:
    """Whether the figure is, exactly, a setting its section names or sets in a code span, or a
    literal of a function its own line names."""
    settings, bodies = scan_code(root)
    candidates = set(figure.scope.code_numbers)
    for name in figure.scope.settings:
        candidates |= settings.get(name, frozenset())
    for name in figure.line_code:
        candidates |= bodies.get(name, frozenset())
    return any(math.isclose(abs(literal) * factor, abs(figure.value), rel_tol=1e-9, abs_tol=1e-12)
               for literal in candidates for factor in INPUT_FACTORS.get(figure.unit, (1.0,)))


# --------------------------------------------------------------------------- the check


def pages_beside(generated: Path) -> list[Path]:
    """The hand-written pages beside a generated page: the other ``*.md`` of its folder and the
    ``README.md`` of the folder above (``docs/results.md``: ``docs/*.md`` and ``README.md``)."""
    folder = generated.parent
    readme = folder.parent / "README.md"
    pages = [readme] if readme.is_file() else []
    return pages + sorted(p for p in folder.glob("*.md") if p.resolve() != generated.resolve())


def verdict(figure: Figure, results: Path, root: Path = ROOT) -> str:
    """``cited``, ``backed by X.json``, ``input`` or ``unbacked``."""
    if figure.cited:
        return "cited"
    found = backing(figure, results)
    if found:
        return f"backed by {found}"
    return "input" if is_input(figure, root) else "unbacked"


def figures(pages: list[Path], results: Path = RESULTS) -> list[Figure]:
    """Every figure of ``pages``, each with what its section names of ``results`` and of the code."""
    stems = frozenset(p.stem for p in results.glob("*.json"))
    return [f for page in pages for f in page_figures(page, stems)]


def check(pages: list[Path], results: Path = RESULTS, root: Path = ROOT) -> list[Figure]:
    """The figures of ``pages`` that are neither backed, inputs nor marked citations."""
    return [f for f in figures(pages, results) if verdict(f, results, root) == "unbacked"]


def report(unbacked: list[Figure], root: Path = ROOT) -> str:
    """The check's message: one ``page:line: figure`` a line."""
    return "\n".join(f"{f.where(root)}: {f.text}" for f in unbacked)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pages", nargs="*", type=Path, help="pages to check (default: README.md and docs/*.md)")
    parser.add_argument("--results", type=Path, default=RESULTS, help="folder of result JSON files")
    parser.add_argument("--all", action="store_true", help="list every figure with what backs it")
    args = parser.parse_args(argv)
    pages = args.pages or pages_beside(ROOT / "docs" / GENERATED)
    unbacked = 0
    for figure in figures(pages, args.results):
        said = verdict(figure, args.results)
        unbacked += said == "unbacked"
        if args.all:
            print(f"{figure.where()}: {figure.text}: {said}")
        elif said == "unbacked":
            print(f"{figure.where()}: {figure.text}")
    if unbacked:
        print(f"{unbacked} figure(s) neither backed by a result their section names, nor a setting it names, "
              "nor marked as a citation (validation/doc_figures.py says how)", file=sys.stderr)
    return 1 if unbacked else 0


if __name__ == "__main__":
    sys.exit(main())
