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
:func:`mifaces.brdf.builtin.from_cook_torrance`.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from .. import brdf
from ..brdf.builtin import BUILTINS, builtin, from_cook_torrance, validate_builtin
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
#: Decimals of the parameters derived from the lobe in ``brdf.json``: colours, numbers.
DIGITS = {"rgb": 5, "float": 4}


# --------------------------------------------------------------------------------------------
# Ground-truth BRDF
# --------------------------------------------------------------------------------------------
def _lobe_albedo(params: dict, samples: int = 256) -> np.ndarray:
    """Directional albedo at normal incidence of the Cook–Torrance specular lobe
    (RGB), by midpoint quadrature over the hemisphere with the array API."""

    model = brdf.model(TRUTH_MODEL)
    # quadrature in (cos θ, φ); the lobe at normal incidence is isotropic, φ is trivial
    mu = (np.arange(samples) + 0.5) / samples
    sin = np.sqrt(1 - mu * mu)
    wi = mi.Vector3f(0.0, 0.0, 1.0)
    wo = mi.Vector3f(mi.Float(sin), mi.Float(np.zeros(samples)), mi.Float(mu))
    p = {"diffuse_reflectance": mi.Color3f(0.0), "specular_reflectance": mi.Color3f(*params["specular_reflectance"]),
         "roughness": mi.Float(params["roughness"]), "eta": mi.Float(params["eta"])}
    f = model.eval(wi, wo, p, diffuse=False)
    f = np.array([np.asarray(f[i]) for i in range(3)])  # (3, samples)
    return 2 * np.pi * np.mean(f * mu, axis=1)


def default_brdf(model: str = TRUTH_MODEL) -> dict:
    """The ground-truth BRDF per region for plugin ``model``, in the
    ``brdf.json`` layout ``{"model", "options", "regions": {region: {param: value}}}``.

    Cook–Torrance is :data:`COOK_TORRANCE_REGIONS`; the other models are
    derived from it as the module docstring explains, their parameters
    rounded to :data:`DIGITS` decimals; a built-in (``roughplastic``,
    ``principled``) by :func:`mifaces.brdf.builtin.from_cook_torrance`.
    """
    if model in BUILTINS:
        return {"model": model, "options": builtin(model).default_options(),
                "regions": {name: from_cook_torrance(model, ct) for name, ct in COOK_TORRANCE_REGIONS.items()}}
    instance = brdf.model(model)  # a ValueError names an unknown model
    kinds = {p.name: p.kind for p in instance.specular_parameters()}
    regions = {}
    for name, ct in COOK_TORRANCE_REGIONS.items():
        if model == TRUTH_MODEL:
            regions[name] = {k: (list(v) if isinstance(v, list) else v) for k, v in ct.items()}
            continue
        albedo = [round(float(a), DIGITS["rgb"]) for a in _lobe_albedo(ct)]
        derived = instance.from_lobe(albedo, ct["roughness"])
        regions[name] = {k: ([round(x, DIGITS["rgb"]) for x in v] if kinds[k] == "rgb" else round(v, DIGITS["float"]))
                         for k, v in derived.items()}
    return {"model": model, "options": instance.default_options(), "regions": regions}


def brdf_with_overrides(model: str, overrides: dict | None) -> dict:
    """:func:`default_brdf` with the regions and parameters of ``overrides``
    (the ``--brdf-params`` layout) replacing the defaults; validated against
    the plugin's parameter names."""

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
    if model in BUILTINS:
        return _builtin_with_overrides(truth, regions, overrides.get("options", {}))
    # the models' own validation: names, finiteness, ranges, lobes (Lafortune's cxy_2, ...)
    merged = {region: dict(truth["regions"].get(region, truth["regions"]["skin"]), **params)
              for region, params in regions.items()}
    checked = brdf.validate_brdf({"model": model, "options": dict(truth["options"], **overrides.get("options", {})),
                                  "regions": {**merged, "skin": merged.get("skin", truth["regions"]["skin"])}})
    instance = brdf.model(model, **checked["options"])
    for region in regions:
        missing = [p.name for p in instance.specular_parameters() if p.name not in merged[region]]
        if missing:
            raise ValueError(f"region {region!r}: {model} with {len(instance.lobe_scales())} lobes needs "
                             f"{', '.join(missing)}")
        truth["regions"][region] = checked["regions"][region]
    truth["options"] = checked["options"]
    return truth


# --------------------------------------------------------------------------------------------
def _builtin_with_overrides(truth: dict, regions: dict, options: dict) -> dict:
    """The built-in ground truth ``truth`` with the region ``regions`` and
    ``options`` overrides, checked (:func:`mifaces.brdf.builtin.validate_builtin`).
    Principled's ``eta`` and ``specular`` exclude each other: giving one drops
    the other's default."""
    merged = {}
    for region, params in regions.items():
        base = dict(truth["regions"].get(region, truth["regions"]["skin"]))
        for a, b in (("eta", "specular"), ("specular", "eta")):
            if a in params and b not in params:
                base.pop(b, None)
        merged[region] = dict(base, **params)
    checked = validate_builtin({"model": truth["model"], "options": dict(truth["options"], **options),
                                "regions": merged or {"skin": truth["regions"]["skin"]}})
    truth["regions"].update(checked["regions"] if merged else {})
    truth["options"] = checked["options"]
    return truth
