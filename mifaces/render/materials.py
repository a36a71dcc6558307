"""A ``brdf.json`` document's region as a Mitsuba BSDF dict, and the texture references renders share."""

from __future__ import annotations

from collections.abc import Mapping

from .. import brdf as brdf_models
from ..model.regions import region_entry


#: Id of the albedo texture in a face scene; its BSDFs refer to it.
ALBEDO = "albedo"


#: The reference to the albedo texture a region's BSDF holds as its diffuse reflectance.
ALBEDO_REF = {"type": "ref", "id": ALBEDO}


#: Id of the tangent-space normal map in a face scene with per-texel normals.
NORMALS = "normals"


#: Id of the per-texel specular reflectance map in a face scene.
SPECULAR = "specular"


def region_bsdf(truth: dict, region: str, texture, *, maps: Mapping | None = None) -> dict:
    """The Mitsuba BSDF dict of one region of a ``brdf.json`` document: its
    parameters over ``texture`` (a texture dict, a loaded texture, a reference,
    an ``rgb`` dict, or None for the plugin's own diffuse default). The
    simulator, the scene writer and the validation's BRDF comparison all build
    a region's BSDF here.

    ``truth["model"]`` is one of the analytic plugins
    (:data:`mifaces.brdf.MODELS`) or a Mitsuba built-in
    (:data:`mifaces.brdf.BUILTINS`: ``roughplastic``, ``principled``), whose
    albedo property (``diffuse_reflectance``, ``base_color``) takes
    ``texture``: :func:`mifaces.brdf.bsdf`'s ``region_plugin`` builds it.
    A region without an entry takes :data:`~mifaces.model.regions.FALLBACK_REGION`'s.
    ``maps`` (parameter name -> texture) puts spatially varying parameters in
    place of the region's values (a spatially varying ground truth,
    :mod:`mifaces.studio.varying`)."""
    model = truth["model"]
    options = truth.get("options", {})
    d = brdf_models.bsdf(model, **options).region_plugin(region_entry(truth["regions"], region), texture, options)
    for k, value in (maps or {}).items():
        if k not in d:
            raise ValueError(f"a {model} BSDF has no parameter {k!r} to take a map")
        d[k] = value
    return d


def with_textures(bsdf: dict, textures: dict) -> dict:
    """``bsdf`` (a dict, nested BSDFs included) with each reference to a texture of ``textures`` (id ->
    loaded texture) replaced by the texture."""
    out = {}
    for k, v in bsdf.items():
        if isinstance(v, dict) and v.get("type") == "ref" and v.get("id") in textures:
            out[k] = textures[v["id"]]
        elif isinstance(v, dict):
            out[k] = with_textures(v, textures)
        else:
            out[k] = v
    return out


__all__ = ["ALBEDO", "ALBEDO_REF", "NORMALS", "SPECULAR", "region_bsdf", "with_textures"]
