"""Mitsuba 3 BSDF plugins of mifaces, written in Python.

One plugin per model of :data:`mifaces.brdf.MODELS`, each the generic
:class:`~mifaces.plugins.analytic.AnalyticBSDF` built from the model's
description, and ``skinboundary`` (:mod:`mifaces.plugins.boundary`), the
boundary of the subsurface ground truth. ``register()`` makes them known to Mitsuba's scene loader under
their XML names in the current variant; :func:`mifaces.set_variant` calls it.
"""

from __future__ import annotations

import mitsuba as mi

from mifaces.brdf import MODELS

from .analytic import behaviour
from .boundary import SkinBoundary

#: Plugins that are not BRDF models: XML name -> behaviour class.
OTHERS = {"skinboundary": SkinBoundary}

_classes: dict[tuple[str, str], type] = {}


def plugin_class(name: str) -> type:
    """The BSDF class registered under the XML name ``name`` in the current
    variant: the plugin's behaviour combined with that variant's ``mi.BSDF``
    (a class derived from another variant's ``BSDF`` would be refused by the
    C++ side, e.g. by a shape in ``scalar_rgb``)."""
    key = (name, mi.variant())
    if key not in _classes:
        klass = OTHERS[name] if name in OTHERS else behaviour(MODELS[name])
        # nanobind types take a single base: copy the behaviour's methods in.
        namespace = {}
        for base in reversed(klass.__mro__[:-1]):
            namespace.update({k: v for k, v in vars(base).items() if k not in ("__dict__", "__weakref__")})
        _classes[key] = type(klass.__name__, (mi.BSDF,), namespace)
    return _classes[key]


def register() -> None:
    """Register every mifaces BSDF in the current Mitsuba variant."""
    for name in [*MODELS, *OTHERS]:
        cls = plugin_class(name)
        mi.register_bsdf(name, lambda props, cls=cls: cls(props))


__all__ = ["plugin_class", "register"]
