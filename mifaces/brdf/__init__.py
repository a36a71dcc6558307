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

from .cooktorrance import CookTorrance
from .lafortune import Lafortune
from .model import BRDFModel, Parameter
from .phong import Phong
from .ward import Ward

#: XML / ``brdf.json`` model name -> model class.
MODELS = {cls.name: cls for cls in (Phong, CookTorrance, Ward, Lafortune)}


def model(name: str, **options) -> BRDFModel:
    """The BRDF model ``name`` (``phong``, ``cooktorrance``, ``ward``,
    ``lafortune``) with the given options (e.g. ``fresnel='schlick'``,
    ``normalization='ward1992'``, ``lobes=2``)."""
    try:
        cls = MODELS[name]
    except KeyError:
        raise ValueError(f"unknown BRDF model {name!r}; known: {sorted(MODELS)}") from None
    return cls(**options)


def evaluate(name: str, wi, wo, params, **options):
    """f(wi, wo) of model ``name``, without the cosine term (RGB)."""
    return model(name, **options).eval(wi, wo, params)


__all__ = ["BRDFModel", "Parameter", "MODELS", "model", "evaluate",
           "Phong", "CookTorrance", "Ward", "Lafortune"]
