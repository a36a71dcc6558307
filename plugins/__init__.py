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


def plugin_class(name: str):
    """The BSDF class registered under the XML name ``name``."""
    module = importlib.import_module(f"{__name__}.{PLUGINS[name]}")
    return module.PLUGIN


def register() -> None:
    """Register every mifaces BSDF in the current Mitsuba variant."""
    for name in PLUGINS:
        try:
            cls = plugin_class(name)
        except ModuleNotFoundError:
            continue
        mi.register_bsdf(name, lambda props, cls=cls: cls(props))
