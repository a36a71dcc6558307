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


def evaluate(name: str, wi, wo, params, **options):
    """f(wi, wo) of model ``name``, without the cosine term (RGB)."""
    return model(name, **options).eval(wi, wo, params)


__all__ = ["BRDFModel", "Parameter", "MODELS", "NAMES", "model", "evaluate",
           "Phong", "CookTorrance", "Ward", "Lafortune"]
