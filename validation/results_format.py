"""Formatting helpers of ``validation/results_doc.py``: values read from a result file that may lack
them (:func:`get`), numbers as the tables print them, and Markdown tables. Standard library only."""

from __future__ import annotations

import math

DASH = "—"
_MISSING = object()


def get(data, *path, default=_MISSING):
    """``data[path[0]][path[1]]...``, or ``default`` (None) where any step is missing."""
    for key in path:
        try:
            data = data[key]
        except (KeyError, IndexError, TypeError):
            return None if default is _MISSING else default
    return data


def finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def num(x, digits: int = 3) -> str:
    """A number with ``digits`` significant digits (plain notation in a sensible range)."""
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if not finite(x):
        return DASH if x is None or not isinstance(x, float) else str(x)
    if x == 0:
        return "0"
    if abs(x) >= 10 ** digits:
        return f"{x:.0f}"
    if abs(x) < 1e-3:
        return f"{x:.{max(digits - 1, 0)}e}"
    decimals = max(digits - 1 - int(math.floor(math.log10(abs(x)))), 0)
    return f"{x:.{decimals}f}"


def fixed(x, decimals: int = 1) -> str:
    return f"{x:.{decimals}f}" if finite(x) else DASH


def pct(x, decimals: int = 1) -> str:
    """A fraction as a percentage."""
    return f"{100 * x:.{decimals}f} %" if finite(x) else DASH


def text(x) -> str:
    if x is None:
        return DASH
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float) and finite(x) and 1e-3 <= abs(x) < 1e4:
        return f"{x:.4g}"
    if isinstance(x, (int, float)):
        return num(x)
    if isinstance(x, (list, tuple)):
        return ", ".join(text(v) for v in x) if x else DASH
    if isinstance(x, dict):
        return ", ".join(f"{k}={text(v)}" for k, v in x.items()) if x else DASH
    return str(x).replace("|", "\\|").replace("\n", " ")


def mean(x):
    """The mean of a list of numbers (an RGB triple), or the number itself."""
    if isinstance(x, list):
        values = [v for v in x if finite(v)]
        return sum(values) / len(values) if values else None
    return x if finite(x) else None


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    if not rows:
        return ["(no rows)", ""]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        cells = [DASH if c in (None, "") else str(c) for c in row]
        cells += [DASH] * (len(header) - len(cells))
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def items(x):
    """(key, value) pairs of a dict, or nothing."""
    return list(x.items()) if isinstance(x, dict) else []


def rows_of(x):
    """The dicts of a list, or nothing."""
    return [r for r in x if isinstance(r, dict)] if isinstance(x, list) else []


def listed(label: str, pairs) -> list[str]:
    """A sentence ``label: key: value; ...`` of a dict's pairs, or nothing where it has none."""
    pairs = items(pairs)
    return [f"{label}: " + "; ".join(f"{k}: {text(v)}" for k, v in pairs) + ".", ""] if pairs else []


def spread(values) -> tuple[float, float] | None:
    """Mean and sample standard deviation of the finite ``values`` (None with fewer than two)."""
    v = [float(x) for x in values if finite(x)]
    if len(v) < 2:
        return None
    m = sum(v) / len(v)
    return m, math.sqrt(sum((x - m) ** 2 for x in v) / (len(v) - 1))


def ranked_with_ties(per_item: dict, decimals: int = 3) -> str:
    """``a 0.284 ≈ b 0.285 < c 0.301``: names ordered by their mean over the items (subjects or seeds);
    ``≈`` where the paired difference to the next is within twice its standard error over the items
    (the spread of the items, not a ranking's single draw). ``per_item``: name -> list of values, one per
    item, in the same item order for every name."""
    means = {k: mean(v) for k, v in per_item.items() if mean(v) is not None}
    order = sorted(means, key=means.get)
    out = ""
    for i, name in enumerate(order):
        if i:
            pairs = [(a, b) for a, b in zip(per_item[order[i - 1]], per_item[name]) if finite(a) and finite(b)]
            diff = spread([b - a for a, b in pairs])
            tie = diff is None or diff[0] <= 2 * diff[1] / math.sqrt(len(pairs))
            out += " ≈ " if tie else " < "
        out += f"{name} {fixed(means[name], decimals)}"
    return out
