"""The simulator's ground-truth BRDFs: published skin measurements per region
(Cook–Torrance), the other models derived from them, and overrides in the
``brdf.json`` layout.

The ground truth is Cook–Torrance with the defaults of its options, per
region the lobe scale and Beckmann roughness of :data:`COOK_TORRANCE_REGIONS`
and the region's index of refraction
(:data:`mifaces.brdf.materials.REFRACTIVE_INDEX`). Every other model is
derived from the same lobe by its
:meth:`~mifaces.brdf.model.BRDFModel.from_lobe`: the Cook–Torrance lobe's
directional albedo at normal incidence and its roughness. Mitsuba's
built-ins (``roughplastic``, ``principled``: ground truths outside the
fitted families) take the same values by
:meth:`mifaces.brdf.builtin.BuiltinBSDF.from_cook_torrance`. Each BSDF
answers for itself (:func:`mifaces.brdf.bsdf`): its
``from_cook_torrance``, ``merge_overrides``, ``check_complete`` and
``validate_document``.
"""

from __future__ import annotations

from .. import brdf
from ..brdf.cooktorrance import CookTorrance
from ..brdf.materials import REFRACTIVE_INDEX
from ..model.regions import REGIONS

#: The model the published measurements are expressed in.
TRUTH_MODEL = CookTorrance.name
#: Cook–Torrance ground truth per region: lobe scale and roughness, with the
#: region's η from :data:`mifaces.brdf.materials.REFRACTIVE_INDEX`.
COOK_TORRANCE_REGIONS: dict[str, dict] = {
    name: {"specular_reflectance": [scale] * 3, "roughness": roughness, "eta": REFRACTIVE_INDEX[name]}
    for name, scale, roughness in [("skin", 1.0, 0.35), ("lips", 1.0, 0.25), ("eyes", 1.0, 0.05),
                                   ("eyebrows", 0.7, 0.45), ("nostrils", 0.5, 0.40), ("beard", 0.85, 0.40),
                                   ("hair", 0.7, 0.45)]
}


# --------------------------------------------------------------------------------------------
# Ground-truth BRDF
# --------------------------------------------------------------------------------------------
def default_brdf(model: str = TRUTH_MODEL) -> dict:
    """The ground-truth BRDF per region for plugin ``model``, in the
    ``brdf.json`` layout ``{"model", "options", "regions": {region: {param: value}}}``.

    Cook–Torrance is :data:`COOK_TORRANCE_REGIONS`; every other BSDF derives
    its parameters from it by its ``from_cook_torrance``
    (:meth:`mifaces.brdf.model.BRDFModel.from_cook_torrance`: the models as
    the module docstring explains, rounded to
    :data:`mifaces.brdf.cooktorrance.DIGITS` decimals; a built-in by
    :meth:`mifaces.brdf.builtin.BuiltinBSDF.from_cook_torrance`).
    """
    bsdf = brdf.bsdf(model)  # a ValueError names an unknown model
    return {"model": model, "options": bsdf.default_options(),
            "regions": {name: bsdf.from_cook_torrance(ct) for name, ct in COOK_TORRANCE_REGIONS.items()}}


def brdf_with_overrides(model: str, overrides: dict | None) -> dict:
    """:func:`default_brdf` with the regions and parameters of ``overrides``
    (the ``--brdf-params`` layout) replacing the defaults; validated against
    the plugin's parameter names (:func:`mifaces.brdf.validate_brdf`).
    A region's overrides are merged into its defaults by the BSDF's
    ``merge_overrides`` (principled's ``eta`` and ``specular`` exclude each
    other: giving one drops the other's default) and must leave it complete
    (``check_complete``: a model's every glossy parameter, Lafortune's
    ``cxy_2``, ...)."""

    if overrides is not None:
        if not isinstance(overrides, dict):
            raise ValueError("BRDF parameters must be a JSON object with 'model' and 'regions'")
        unknown = sorted(set(overrides) - {"model", "options", "regions"})
        if unknown:
            raise ValueError(f"unknown key(s) {unknown} in the BRDF parameters; the layout is "
                             "{\"model\": ..., \"options\": {...}, \"regions\": {region: {parameter: value}}}")
        model = overrides.get("model", model)
        if not isinstance(overrides.get("options", {}), dict):
            raise ValueError("'options' in the BRDF parameters must be an object of plugin options")
    truth = default_brdf(model)
    if overrides is None:
        return truth
    regions = overrides.get("regions", {})
    if not isinstance(regions, dict):
        raise ValueError("'regions' must map region names to parameter objects")
    vocabulary = [r for r in REGIONS if r != "background"]
    for region, params in regions.items():
        if region not in vocabulary:
            raise ValueError(f"unknown region {region!r} in the BRDF parameters; regions: {vocabulary}")
        if not isinstance(params, dict):
            raise ValueError(f"region {region!r}: parameters must be an object")
        if "diffuse_reflectance" in params:
            raise ValueError(f"region {region!r}: the diffuse reflectance is the albedo map, not a parameter")
    skin, defaults = truth["regions"]["skin"], brdf.bsdf(model, **truth["options"])
    merged = {region: defaults.merge_overrides(truth["regions"].get(region, skin), params)
              for region, params in regions.items()}
    # the BSDF's own validation: names, finiteness, ranges, options, lobes (Lafortune's cxy_2, ...)
    checked = brdf.validate_brdf({"model": model, "options": dict(truth["options"], **overrides.get("options", {})),
                                  "regions": {**merged, "skin": merged.get("skin", skin)}})
    bsdf = brdf.bsdf(model, **checked["options"])
    for region in regions:
        bsdf.check_complete(merged[region], f"region {region!r}")
        truth["regions"][region] = checked["regions"][region]
    truth["options"] = checked["options"]
    return truth
