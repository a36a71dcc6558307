"""One declaration per option: :func:`option` makes a dataclass field whose metadata says what the
option means (``help``), which values it takes (``bounds`` or ``choices``) and how the command
line spells it (``flag``). From it, :func:`check` validates a value on construction (called in
``__post_init__``; the error names the field), :func:`record` writes the value as a JSON object
and :func:`from_record` reads it back, equal; :func:`mifaces.cli.options.option_flags` makes the
commands' flags.

A field with ``help`` is a user option (it gets a flag); one with only ``bounds`` or ``choices``
is validated, not offered on the command line. ``form`` says how the command line writes a value
that is not one number, word or ``--x/--no-x`` switch (several numbers, an image size, a file).
Options that contradict each other raise :class:`Conflict`, which names them by field here and by
flag on the command line. ``nested`` names the options class a field holds
(:class:`~mifaces.options.measure.MeasureOptions`'s ``fit`` holds a
:class:`~mifaces.reflectance.FitOptions`), whose own options are then flattened into the flags;
with ``switch``, the field is None unless ``--<name>`` is given, and its options' flags are
prefixed with ``--<name>-`` (``--refine-shape``, ``--refine-shape-judged``).
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import MISSING

import numpy as np


def option(default=MISSING, *, help: str | None = None, bounds: tuple | None = None, choices: tuple | None = None,
           flag: str | None = None, form=None, factory=MISSING, nested: type | None = None, switch: bool = False):
    """A dataclass field described for validation, records and the command line.

    Parameters
    ----------
    default, factory
        The field's default value, or a function making it (``dataclasses.field``'s
        ``default_factory``).
    help : str, optional
        What the option does, as the command's help shows it; without it, the field is no flag.
    bounds : (low, high), optional
        Closed range of a number; None for an open end. An int bound makes an integer option.
    choices : tuple, optional
        The values it takes (None among them: ``none`` on the command line, unless None is the
        default: leaving the flag out gives it). A tuple default: the option takes several of them
        (``--brdf phong --brdf ward``).
    flag : str, optional
        The long flag, if not ``--`` and the field's name with dashes (``models``: ``--brdf``).
    form : optional
        How the command line writes the value, where not as its default's type: a type (``float``
        for an option whose default is None), a tuple of types (``(float, float, float)``: that many
        numbers), ``'WxH'`` (an image size, ``512x512``: a (width, height) tuple), ``'file'`` (an
        existing file's path), ``'json'`` (an existing JSON file, read as the value) or ``'flag'``
        (a bool that its flag alone sets, no ``--no-`` form).
    nested : type, optional
        The options class the field holds; its options are the flags.
    switch : bool
        With ``nested``: None unless ``--<name>`` is given (its flags then prefixed by the name).
    """
    metadata = {key: value for key, value in (("help", help), ("bounds", bounds), ("choices", choices),
                                              ("flag", flag), ("form", form), ("nested", nested))
                if value is not None}
    if switch:
        metadata["switch"] = True
    if factory is not MISSING:
        return dataclasses.field(default_factory=factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def default_of(field: dataclasses.Field):
    """A field's default value (made anew where it has a factory)."""
    return field.default_factory() if field.default_factory is not MISSING else field.default


def several(field: dataclasses.Field) -> bool:
    """Whether the option takes several of its choices (a tuple)."""
    return "choices" in field.metadata and isinstance(default_of(field), tuple)


def check(value) -> None:
    """Validate every described field of options ``value`` (a dataclass instance).

    Raises
    ------
    ValueError
        Naming the class and field, the values it takes and the one given.
    """
    owner = type(value).__name__
    for field in dataclasses.fields(value):
        given, meta = getattr(value, field.name), field.metadata
        where = f"{owner}.{field.name}"
        if "choices" in meta:
            items = tuple(given) if several(field) and isinstance(given, (tuple, list)) else (given,)
            bad = [item for item in items if item not in meta["choices"]]
            if bad or not items:
                shown = ", ".join("None" if c is None else repr(c) for c in meta["choices"])
                raise ValueError(f"{where} must be {'one or more' if several(field) else 'one'} of {shown}, got "
                                 f"{given!r}")
        if "bounds" in meta and not (given is None and default_of(field) is None):
            _check_number(where, given, meta["bounds"])


def _check_number(where: str, given, bounds: tuple) -> None:
    low, high = bounds
    integer = all(isinstance(b, int) for b in bounds if b is not None)
    kind = numbers.Integral if integer else numbers.Real
    inside = (isinstance(given, kind) and not isinstance(given, (bool, np.bool_))
              and (low is None or given >= low) and (high is None or given <= high))
    if not inside:
        span = f"[{'-inf' if low is None else low}, {'inf' if high is None else high}]"
        raise ValueError(f"{where} must be {'an integer' if integer else 'a number'} in {span}, got {given!r}")


class Conflict(ValueError):
    """Options of ``owner`` (an options class) that contradict each other: ``message`` with a
    ``{}`` for each of ``fields``, their names. Its text names them as fields of ``owner``;
    :meth:`naming` as the caller names them (the command line: by their flags)."""

    def __init__(self, owner: type, message: str, *fields: str):
        self.owner, self.message, self.fields = owner, message, fields
        super().__init__(f"{owner.__name__}: {message.format(*fields)}")

    def naming(self, name) -> str:
        """The message with each field named ``name(owner, field)``."""
        return self.message.format(*(name(self.owner, field) for field in self.fields))


def record(value) -> dict:
    """Options ``value`` as a JSON object: every field, nested options as objects, tuples as lists."""
    return {field.name: _plain(getattr(value, field.name)) for field in dataclasses.fields(value)}


def _plain(value):
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return record(value)
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def from_record(cls: type, data: dict):
    """The options value of class ``cls`` that :func:`record` wrote as ``data``.

    Raises
    ------
    ValueError
        For a key ``cls`` has no field for (a record of other options), or values it refuses.
    """
    if not isinstance(data, dict):
        raise ValueError(f"a {cls.__name__} record must be a JSON object, got {data!r}"[:300])
    fields = {field.name: field for field in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(f"{cls.__name__} has no option(s) {unknown}")
    values = {}
    for name, value in data.items():
        nested = fields[name].metadata.get("nested")
        if nested is not None and isinstance(value, dict):
            value = from_record(nested, value)
        elif isinstance(value, list) and isinstance(default_of(fields[name]), tuple):
            value = tuple(value)
        values[name] = value
    return cls(**values)


__all__ = ["option", "default_of", "several", "check", "Conflict", "record", "from_record"]
