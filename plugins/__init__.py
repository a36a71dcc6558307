"""Mitsuba 3 BSDF plugins of mifaces, written in Python.

``register()`` makes them known to Mitsuba's scene loader under their XML
names in the current variant; :func:`mifaces.set_variant` calls it.
"""

from __future__ import annotations

import importlib

import mitsuba as mi

#: XML plugin name -> module of this package that defines the plugin class.
PLUGINS = {
    "phong": "phong",
    "cooktorrance": "cooktorrance",
    "ward": "ward",
    "lafortune": "lafortune",
}


_classes: dict[tuple[str, str], type] = {}


def plugin_class(name: str) -> type:
    """The BSDF class registered under the XML name ``name`` in the current
    variant: the plugin's behaviour combined with that variant's ``mi.BSDF``
    (a class derived from another variant's ``BSDF`` would be refused by the
    C++ side, e.g. by a shape in ``scalar_rgb``)."""
    key = (name, mi.variant())
    if key not in _classes:
        behaviour = importlib.import_module(f"{__name__}.{PLUGINS[name]}").PLUGIN
        # nanobind types take a single base: copy the behaviour's methods in.
        namespace = {}
        for klass in reversed(behaviour.__mro__[:-1]):
            namespace.update({k: v for k, v in vars(klass).items() if k not in ("__dict__", "__weakref__")})
        _classes[key] = type(behaviour.__name__, (mi.BSDF,), namespace)
    return _classes[key]


def register() -> None:
    """Register every mifaces BSDF in the current Mitsuba variant."""
    for name in PLUGINS:
        try:
            cls = plugin_class(name)
        except ModuleNotFoundError:
            continue
        mi.register_bsdf(name, lambda props, cls=cls: cls(props))
