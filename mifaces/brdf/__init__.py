"""Analytic BRDF models as pure Dr.Jit functions: one formula, two faces.

The same code is called by the Mitsuba plugins (:mod:`mifaces.plugins`) and
by the BRDF fitters on plain arrays of local-frame directions::

    import mifaces, mitsuba as mi
    from mifaces import brdf

    ct = brdf.model("cooktorrance", fresnel="dielectric", geometry="vcavity")
    f = ct.eval(wi, wo, {"diffuse_reflectance": mi.Color3f(0.4, 0.3, 0.25),
                         "specular_reflectance": 0.3, "roughness": 0.25, "eta": 1.4})

``f`` is the BRDF without the cosine term (see :mod:`mifaces.brdf.model` for
the conventions). Every operation is differentiable in Dr.Jit's forward and
reverse modes.
"""

from __future__ import annotations

from .builtin import BUILTIN_NAMES, BUILTINS, validate_builtin
from .cooktorrance import CookTorrance
from .lafortune import Lafortune
from .model import MAX_LOBES, BRDFModel, Parameter, ParameterError
from .phong import Phong
from .ward import Ward

#: XML / ``brdf.json`` model name -> model class, in the order the CLI, the
#: gallery, the pipeline and the reports list them.
MODELS = {cls.name: cls for cls in (Phong, CookTorrance, Ward, Lafortune)}
#: The model names, in that order.
NAMES = tuple(MODELS)


def model(name: str, **options) -> BRDFModel:
    """The BRDF model ``name`` (one of :data:`NAMES`) with the given options
    (e.g. ``fresnel='schlick'``, ``normalization='ward1992'``, ``lobes=2``).
    ``lobes=1`` is accepted by every model."""
    try:
        cls = MODELS[name]
    except KeyError:
        raise ValueError(f"unknown BRDF model {name!r}; known: {sorted(MODELS)}") from None
    if "lobes" in options and not cls.SEVERAL_LOBES:
        lobes = options.pop("lobes")
        if lobes != 1:
            several = " and ".join(n for n, c in MODELS.items() if c.SEVERAL_LOBES)
            raise ValueError(f"lobes={lobes}: only the {several} model has several lobes")
    return cls(**options)


def validate_brdf(document) -> dict:
    """A BRDF in the ``brdf.json`` layout (``{"model", "options", "regions"}``)
    with its regions checked by :meth:`~mifaces.brdf.model.BRDFModel.validate_regions`:
    the one validation the renderers, the simulator and the readers of
    ``brdf.json`` share. A ground truth may also be one of Mitsuba's
    built-ins (:data:`mifaces.brdf.builtin.BUILTINS`), checked by
    :func:`~mifaces.brdf.builtin.validate_builtin`. Raises
    :class:`~mifaces.brdf.model.ParameterError` (or a ``ValueError`` for an
    unknown model or option)."""
    if not isinstance(document, dict) or not isinstance(document.get("model"), str):
        raise ParameterError(f"a BRDF must be an object with a 'model' name, got {document!r}"[:300])
    options = document.get("options", {})
    if not isinstance(options, dict):
        raise ParameterError(f"'options' of the BRDF must be an object of plugin options, got {options!r}"[:300])
    if document["model"] in BUILTINS:
        return validate_builtin(document)
    regions = document.get("regions")
    if document["model"] in MODELS and MODELS[document["model"]].SEVERAL_LOBES and "lobes" not in options:
        # the lobes the regions name, as a scene's properties would (Lafortune's cxy_2, ...)
        keys = [key for params in (regions if isinstance(regions, dict) else {}).values()
                if isinstance(params, dict) for key in params]
        lobes = max(MODELS[document["model"]].from_properties(keys, options.get).lobe_scales())
        options = dict(options, lobes=lobes) if lobes > 1 else options
    instance = model(document["model"], **options)
    return dict(document, options=dict(options), regions=instance.validate_regions(regions))


def evaluate(name: str, wi, wo, params, **options):
    """f(wi, wo) of model ``name``, without the cosine term (RGB)."""
    return model(name, **options).eval(wi, wo, params)


__all__ = ["BUILTINS", "BUILTIN_NAMES", "BRDFModel", "Parameter", "ParameterError", "MAX_LOBES", "MODELS", "NAMES", "model", "evaluate",
           "validate_brdf",
           "Phong", "CookTorrance", "Ward", "Lafortune"]
