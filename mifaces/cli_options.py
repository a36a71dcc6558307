"""The options of the ``mifaces`` command line (:mod:`mifaces.cli`): their
defaults taken from the API, their parsing callbacks, and the spellings of
renamed options kept for one release."""

from __future__ import annotations

import functools
import inspect

import click

from .reflectance.options import FitOptions
from .refine.shape import ShapeRefineSchedule


def default(function, name: str):
    """The default of parameter ``name`` of API ``function``: the CLI states no default of its own."""
    return inspect.signature(function).parameters[name].default


def fit_flag(name: str, help: str):
    """The ``--NAME/--no-NAME`` option of the :class:`~mifaces.reflectance.FitOptions` field ``name``
    (``texel_albedo``: ``--texel-albedo``), its default the field's."""
    flag = name.replace("_", "-")
    return click.option(f"--{flag}/--no-{flag}", default=default(FitOptions, name), show_default=True, help=help)


def refine_shape_options(default_on: bool):
    """``--refine-shape/--no-refine-shape``, ``--refine-shape-judged N`` and
    ``--refine-shape-early-stop/--no-refine-shape-early-stop`` of ``measure`` and ``fit-shape`` (their
    defaults :class:`~mifaces.refine.shape.ShapeRefineSchedule`'s)."""
    def apply(command):
        command = click.option("--refine-shape-early-stop/--no-refine-shape-early-stop",
                               default=ShapeRefineSchedule.early_stop, show_default=True,
                               help="Let half of --refine-shape's held-out pixels choose its iteration, the other "
                                    "half judge it (docs/refine_shape.md).")(command)
        command = click.option("--refine-shape-judged", default=ShapeRefineSchedule.judged, show_default=True,
                               type=click.IntRange(0), help="Photographs held out of --refine-shape to judge it by "
                               "(the last ones; 0: held-out pixels only; docs/refine_shape.md).")(command)
        return click.option("--refine-shape/--no-refine-shape", default=default_on, show_default=True,
                            help="Refine the fitted faces beyond the model by differentiable rendering, lit by a "
                                 "quick Phong fit (minutes; kept only if it lowers the loss on pixels it did not "
                                 "fit: docs/refine_shape.md).")(command)
    return apply


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


__all__ = ["default", "fit_flag", "width_x_height", "renamed"]
