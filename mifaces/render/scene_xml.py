"""A Mitsuba scene dict as Mitsuba's XML (``scene.xml``), with parameters to override at load time."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping

import mitsuba as mi
import numpy as np

from .. import brdf as brdf_models


#: Mitsuba object type -> XML tag.
_TAGS = {mi.ObjectType.Shape: "shape", mi.ObjectType.BSDF: "bsdf", mi.ObjectType.Emitter: "emitter",
         mi.ObjectType.Sensor: "sensor", mi.ObjectType.Film: "film", mi.ObjectType.ReconstructionFilter: "rfilter",
         mi.ObjectType.Sampler: "sampler", mi.ObjectType.Integrator: "integrator",
         mi.ObjectType.Texture: "texture", mi.ObjectType.Medium: "medium", mi.ObjectType.Volume: "volume",
         mi.ObjectType.PhaseFunction: "phase"}


def _tag(plugin: str) -> str:
    """The XML tag of plugin ``plugin``; Python plugins are unknown to Mitsuba's
    plugin manager, and those of mifaces are BSDFs."""
    kind = mi.PluginManager.instance().plugin_type(plugin)
    if kind in _TAGS:
        return _TAGS[kind]
    if plugin in brdf_models.MODELS:
        return "bsdf"
    raise ValueError(f"unknown Mitsuba plugin {plugin!r}")


def _numbers(values) -> str:
    return ", ".join(repr(float(x)) for x in values)


def _element(key: str, value, path: tuple[str, ...], parameters: Mapping[tuple[str, ...], str],
             top: bool) -> ET.Element:
    """The XML element of ``value`` under name (or, at the top, id) ``key``."""
    name = {"id" if top else "name": key}
    if path in parameters:
        return ET.Element("integer" if isinstance(value, int) else "float", name=key, value=f"${parameters[path]}")
    if isinstance(value, dict) and value.get("type") == "ref":
        return ET.Element("ref", id=value["id"], name=key)
    if isinstance(value, dict) and value.get("type") == "rgb":
        v = np.broadcast_to(np.asarray(value["value"], np.float64), 3)
        return ET.Element("rgb", name=key, value=_numbers(v))
    if isinstance(value, dict):
        element = ET.Element(_tag(value["type"]), type=value["type"], **name)
        for k, v in value.items():
            if k != "type":
                element.append(_element(k, v, path + (k,), parameters, False))
        return element
    if isinstance(value, (bool, np.bool_)):
        return ET.Element("boolean", name=key, value=str(bool(value)).lower())
    if isinstance(value, (int, np.integer)):
        return ET.Element("integer", name=key, value=str(int(value)))
    if isinstance(value, (float, np.floating)):
        return ET.Element("float", name=key, value=repr(float(value)))
    if isinstance(value, str):
        return ET.Element("string", name=key, value=value)
    if isinstance(value, (list, tuple, np.ndarray)) and np.shape(value) == (3,):
        return ET.Element("point", name=key, value=_numbers(value))
    if isinstance(value, mi.ScalarTransform4f):
        element = ET.Element("transform", name=key)
        ET.SubElement(element, "matrix", value=" ".join(repr(float(x)) for x in np.ravel(value.matrix)))
        return element
    raise TypeError(f"{'.'.join(path)}: a {type(value).__name__} has no Mitsuba XML form (write it to a file "
                    "and name the file)")


def scene_xml(scene: dict, parameters: Mapping[str, tuple[str, ...]] | None = None, comment: str = "") -> str:
    """A Mitsuba scene dict (``mi.load_dict``'s layout) as Mitsuba XML text.

    Values may be nested plugin dicts, ``rgb`` and ``ref`` dicts, booleans,
    numbers, strings, 3-vectors (written as points) and
    ``mi.ScalarTransform4f``; meshes, bitmaps and other data must be named by
    file. Top-level keys become ids, nested keys names.

    Parameters
    ----------
    scene : dict
        ``{"type": "scene", ...}``.
    parameters : mapping, optional
        Name -> key path of a value that ``mi.load_file(path, name=...)`` may
        override, e.g. ``{"spp": ("sensor", "sampler", "sample_count")}``:
        written as ``<default name="spp" value="..."/>`` and ``$spp``.
    comment : str
        A comment written before the scene.
    """
    if scene.get("type") != "scene":
        raise ValueError(f"not a scene dict: type {scene.get('type')!r}")
    parameters = dict(parameters or {})
    root = ET.Element("scene", version="3.0.0")
    for name, path in parameters.items():
        value = scene
        for key in path:
            value = value[key]
        ET.SubElement(root, "default", name=name, value=str(value))
    by_path = {tuple(path): name for name, path in parameters.items()}
    for key, value in scene.items():
        if key != "type":
            root.append(_element(key, value, (key,), by_path, True))
    ET.indent(root, space="    ")
    header = f"<!-- {comment} -->\n" if comment else ""
    return header + ET.tostring(root, encoding="unicode") + "\n"


__all__ = ["scene_xml"]
