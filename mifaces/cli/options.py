"""The options of the ``mifaces`` command line (:mod:`mifaces.cli.commands`): the flags of an options
value made from its fields (:func:`option_flags`), the other defaults taken from the API, their
parsing callbacks, and the spellings of renamed options kept for one release."""

from __future__ import annotations

import dataclasses
import functools
import inspect
import json

import click

from ..options.fields import Conflict, default_of, several

#: How the command line spells None among an option's choices.
NONE = "none"


def default(function, name: str):
    """The default of parameter ``name`` of API ``function``: the CLI states no default of its own."""
    return inspect.signature(function).parameters[name].default


def option_flags(cls, name: str = "options", only: tuple[str, ...] | None = None):
    """A decorator of a command: a flag per user option of the options class ``cls`` (a field
    with ``help``, :func:`mifaces.options.fields.option`; nested options flattened, see there),
    its default, range or choices and help the field's; the command is called with the value
    built from them as keyword ``name`` (a ``ValueError`` of its validation ends the command with
    its message; a :class:`~mifaces.options.fields.Conflict` is a usage error naming the flags).
    ``only``: these fields of ``cls`` (the others at their defaults)."""
    flags = list(_flags(cls, only))
    named = {(owner, field): declarations[0].split("/")[0] for owner, field, declarations, _ in flags}

    def decorate(command):
        @functools.wraps(command)
        def wrapper(*args, **kwargs):
            try:
                kwargs[name] = _value(cls, kwargs, only)
            except Conflict as conflict:
                raise click.UsageError(conflict.naming(lambda owner, field: named.get((owner, field), field))) from None
            return command(*args, **kwargs)

        for _, _, declarations, attrs in reversed(flags):  # click lists options in the order they decorate
            wrapper = click.option(*declarations, **attrs)(wrapper)
        return wrapper

    return decorate


def _user_fields(cls, only):
    return [f for f in dataclasses.fields(cls) if "help" in f.metadata and (only is None or f.name in only)]


def _flags(cls, only=None, prefix: str = ""):
    """(the options class, the field's name, declarations, attributes of ``click.option``) of each
    user option of ``cls``."""
    for field in _user_fields(cls, only):
        meta, parameter, value = field.metadata, prefix + field.name, default_of(field)
        flag = "--" + (prefix + meta.get("flag", field.name)).replace("_", "-")
        nested, form = meta.get("nested"), meta.get("form")
        if nested is not None and meta.get("switch"):
            yield cls, field.name, (f"{flag}/--no-{flag[2:]}", parameter), dict(default=False, show_default=True,
                                                                                help=meta["help"])
            yield from _flags(nested, None, parameter + "_")
        elif nested is not None:
            yield from _flags(nested, None, prefix)
        elif form is not None:
            yield cls, field.name, (flag, parameter), dict(_written(form, value), help=meta["help"])
        elif several(field):
            yield cls, field.name, (flag, parameter), dict(multiple=True, type=click.Choice(meta["choices"]),
                                                           help=meta["help"])
        elif isinstance(value, bool):
            yield cls, field.name, (f"{flag}/--no-{flag[2:]}", parameter), dict(default=value, show_default=True,
                                                                                help=meta["help"])
        elif "choices" in meta and value is None:  # leaving the flag out gives None
            choices = tuple(c for c in meta["choices"] if c is not None)
            yield cls, field.name, (flag, parameter), dict(default=None, type=click.Choice(choices), help=meta["help"])
        elif "choices" in meta:
            choices = tuple(NONE if c is None else c for c in meta["choices"])
            yield cls, field.name, (flag, parameter), dict(default=value, show_default=True,
                                                           type=click.Choice(choices), help=meta["help"])
        else:
            yield cls, field.name, (flag, parameter), dict(default=value, show_default=value is not None,
                                                           type=_type(meta), help=meta["help"])


def _written(form, value) -> dict:
    """The attributes of ``click.option`` of a field of ``form`` (:func:`mifaces.options.fields.option`)
    and default ``value``."""
    if form == "flag":
        return dict(is_flag=True)
    if form == "WxH":
        return dict(default="{}x{}".format(*value), show_default=True, callback=width_x_height)
    if form in ("file", "json"):
        return dict(default=value, type=click.Path(exists=True, dir_okay=False),
                    callback=_json_file if form == "json" else None)
    return dict(default=value, type=form)  # a type, or a tuple of them


def _type(meta: dict):
    """The click type of an option with ``bounds`` (an int or float range), else None (click's guess)."""
    if "bounds" not in meta:
        return None
    low, high = meta["bounds"]
    integer = all(isinstance(b, int) for b in (low, high) if b is not None)
    return click.IntRange(low, high) if integer else click.FloatRange(low, high)


def _value(cls, kwargs: dict, only=None, prefix: str = ""):
    """The ``cls`` value of the command's flags (taken out of ``kwargs``)."""
    values = {}
    for field in _user_fields(cls, only):
        parameter, nested = prefix + field.name, field.metadata.get("nested")
        if nested is not None and field.metadata.get("switch"):
            on = kwargs.pop(parameter)
            schedule = _value(nested, kwargs, None, parameter + "_")
            values[field.name] = schedule if on else None
        elif nested is not None:
            values[field.name] = _value(nested, kwargs, None, prefix)
        else:
            given = kwargs.pop(parameter)
            if several(field) and not given:  # none given: the default
                continue
            values[field.name] = None if given == NONE and "choices" in field.metadata else given
    return cls(**values)


def _json_file(ctx, param, value: str | None):
    """The Click callback of a JSON file: its content (None for None)."""
    if value is None:
        return None
    try:
        with open(value) as f:
            return json.load(f)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise click.BadParameter(f"{value} is not valid JSON: {e}", param_hint=param.opts[0]) from None


def width_x_height(ctx, param, value: str) -> tuple[int, int]:
    """The Click callback of an image size ``WxH`` (e.g. ``512x512``): (width, height)."""
    try:
        width, height = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"must be WxH, e.g. 512x512, got {value!r}") from None
    return width, height


def renamed(old: str, new: str, name: str, **attrs):
    """A decorator of a command: the hidden option ``old``, the spelling of
    option ``new`` (parameter ``name``) before it was renamed, still sets
    ``name`` for one release, with a deprecation message on stderr naming
    ``new``. ``attrs`` are the option's (its type, ``multiple``); giving
    both spellings is a usage error. Put it right below the command's
    ``@main.command``."""
    hidden = f"_{name}_as_{old.lstrip('-').replace('-', '_')}"

    def decorate(command):
        @functools.wraps(command)
        def wrapper(*args, **kwargs):
            value = kwargs.pop(hidden)
            if value is not None and value != ():
                ctx = click.get_current_context()
                if ctx.get_parameter_source(name) is click.core.ParameterSource.COMMANDLINE:
                    raise click.UsageError(f"give {new}, not both {new} and {old} (its deprecated spelling)")
                click.echo(f"warning: {old} is deprecated and goes in the next release: use {new}", err=True)
                kwargs[name] = value
            return command(*args, **kwargs)

        return click.option(old, hidden, hidden=True, default=None, **attrs)(wrapper)

    return decorate


__all__ = ["default", "option_flags", "width_x_height", "renamed"]
