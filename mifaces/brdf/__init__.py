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

from .builtin import BUILTIN_NAMES, BUILTINS, BuiltinBSDF
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


def bsdf(name: str, **options) -> BRDFModel | BuiltinBSDF:
    """The BSDF ``name``: one of the fitted models (:func:`model` with
    ``options``) or one of Mitsuba's built-ins usable as ground truth
    (:data:`~mifaces.brdf.builtin.BUILTINS`, its ``options`` checked). Both
    answer what the renderers, the simulator and the readers of
    ``brdf.json`` ask of a BSDF: ``validate_document``, ``region_plugin``,
    ``default_options``, ``parameters``, ``from_cook_torrance``,
    ``merge_overrides`` and ``check_complete``."""
    if name in BUILTINS:
        BUILTINS[name].check_options(options)
        return BUILTINS[name]
    return model(name, **options)


def validate_brdf(document) -> dict:
    """A BRDF in the ``brdf.json`` layout (``{"model", "options", "regions"}``)
    checked by its :func:`bsdf`'s ``validate_document``
    (:meth:`~mifaces.brdf.model.BRDFModel.validate_document`,
    :meth:`~mifaces.brdf.builtin.BuiltinBSDF.validate_document`): the one
    validation the renderers, the simulator and the readers of ``brdf.json``
    share. A ground truth may also be one of Mitsuba's built-ins
    (:data:`mifaces.brdf.builtin.BUILTINS`). Raises
    :class:`~mifaces.brdf.model.ParameterError` (or a ``ValueError`` for an
    unknown model or option)."""
    if not isinstance(document, dict) or not isinstance(document.get("model"), str):
        raise ParameterError(f"a BRDF must be an object with a 'model' name, got {document!r}"[:300])
    options = document.get("options", {})
    if not isinstance(options, dict):
        raise ParameterError(f"'options' of the BRDF must be an object of plugin options, got {options!r}"[:300])
    return bsdf(document["model"], **options).validate_document(document)


def evaluate(name: str, wi, wo, params, **options):
    """f(wi, wo) of model ``name``, without the cosine term (RGB)."""
    return model(name, **options).eval(wi, wo, params)


__all__ = ["BUILTINS", "BUILTIN_NAMES", "BuiltinBSDF", "BRDFModel", "Parameter", "ParameterError", "MAX_LOBES",
           "MODELS", "NAMES", "model", "bsdf", "evaluate", "validate_brdf",
           "Phong", "CookTorrance", "Ward", "Lafortune"]
