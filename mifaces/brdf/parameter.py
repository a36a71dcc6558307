"""One parameter of a BRDF model, described once: its name, kind, range and
start (:class:`Parameter`), the error of a value outside it
(:class:`ParameterError`), and a value as Mitsuba's ``rgb`` dict (:func:`rgb`).
The models (:mod:`mifaces.brdf.model`) list their parameters with it; the
plugins, the fitters and the readers of ``brdf.json`` check values by it."""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

#: Relative slack at a range's ends, so that a float32 round trip of a value
#: at its bound (a fit's optimum at the bound) stays valid.
_RANGE_SLACK = 1e-6


class ParameterError(ValueError):
    """A BRDF parameter that is not a finite number (or colour) within its
    :class:`Parameter`'s physical range, or that the model does not have."""


@dataclass(frozen=True)
class Parameter:
    """One parameter of a BRDF model.

    Attributes
    ----------
    name : str
        The name used by the plugin (XML, ``mi.traverse``) and in ``brdf.json``.
    kind : str
        ``'rgb'`` (three channels) or ``'float'``.
    default : float
        Value used when a scene does not give one.
    lower, upper : float
        The physically valid range, for fitting and validation.
    doc : str
        One line for the docs.
    start : float, optional
        Value a fit starts from when it knows nothing better: a weak lobe of
        medium width, far from any sharp minimum (default: ``default``).
    """

    name: str
    kind: str
    default: float
    lower: float
    upper: float
    doc: str
    start: float | None = None

    def check(self, value, where: str = ""):
        """``value`` as plain floats (three for an RGB parameter), or a
        :class:`ParameterError` naming ``where``, the parameter and the value.

        A value must be a finite number (an RGB parameter also a triple of
        them; no booleans, strings or objects) within [:attr:`lower`,
        :attr:`upper`]. Dr.Jit values (``mi.Float``, ``mi.Color3f``) are read
        back, so check them where they are set, not in a kernel."""
        prefix = f"{where}: " if where else ""
        shape = "a colour (one number or three)" if self.kind == "rgb" else "a number"
        try:
            if isinstance(value, (bool, str, bytes, dict)) or (
                    isinstance(value, (list, tuple)) and any(isinstance(v, (bool, str)) for v in value)):
                raise TypeError
            values = np.array(dr.detach(value) if dr.is_array_v(value) else value, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise ParameterError(f"{prefix}{self.name} = {value!r} is not {shape}"[:300]) from None
        if values.size not in ((1, 3) if self.kind == "rgb" else (1,)):
            raise ParameterError(f"{prefix}{self.name} = {value!r} is not {shape}"[:300])
        slack = _RANGE_SLACK * max(1.0, abs(self.lower), abs(self.upper))
        if not np.all(np.isfinite(values)) or np.any(values < self.lower - slack) \
                or np.any(values > self.upper + slack):
            shown = values.tolist() if values.size > 1 else float(values[0])
            raise ParameterError(f"{prefix}{self.name} = {shown} is outside [{self.lower}, {self.upper}] "
                                 "or not finite")
        return [float(v) for v in np.broadcast_to(values, 3)] if self.kind == "rgb" else float(values[0])

    def start_value(self):
        """:attr:`start` (or :attr:`default`): a float, or three for an RGB parameter."""
        value = float(self.default if self.start is None else self.start)
        return [value] * 3 if self.kind == "rgb" else value


def rgb(value) -> dict:
    """A Mitsuba ``rgb`` spectrum dict from a number or an RGB triple."""
    v = np.broadcast_to(np.asarray(value, np.float64), 3)
    return {"type": "rgb", "value": [float(x) for x in v]}


__all__ = ["Parameter", "ParameterError", "rgb"]
