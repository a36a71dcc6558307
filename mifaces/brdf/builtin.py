"""Mitsuba's built-in BSDFs as ground truths outside the fitted families.

The simulator's default ground truth is one of the four fitted models
(:data:`mifaces.brdf.MODELS`), so a fit can copy it exactly. These
built-ins are not in any fitted family:

``roughplastic``
    A rough dielectric coating (Beckmann microfacets, Fresnel at the
    coating's index) over a Lambertian base, with the base's light
    refracted in and out of the coating and internally reflected
    (Weidlich & Wilkie 2007, as Mitsuba implements it). Its diffuse part
    is therefore not ρ/π: it falls off at grazing angles, and its glossy
    part is a Torrance–Sparrow lobe with Smith shadowing.
``principled``
    Disney's principled BSDF (Burley 2012, 2015): a diffuse term with a
    grazing retro-reflection (Schlick weights), a GGX specular lobe, sheen
    and clearcoat.

A built-in ground truth keeps the ``brdf.json`` layout
``{"model", "options", "regions": {region: {parameter: value}}}`` with the
built-in's own parameter names (Mitsuba's XML names); the albedo map is
the diffuse reflectance (:attr:`BuiltinBSDF.albedo`: roughplastic's
``diffuse_reflectance``, principled's ``base_color``).

Mapping from the published Cook–Torrance skin values
----------------------------------------------------
:meth:`BuiltinBSDF.from_cook_torrance` turns a region's Cook–Torrance parameters
(lobe scale ρ_s, Beckmann RMS slope m, index η;
:data:`mifaces.studio.truth.COOK_TORRANCE_REGIONS`) into a built-in's:

* roughplastic: ``alpha`` = m (Mitsuba's Beckmann D(h) =
  exp(-tan²θh/α²)/(π α² cos⁴θh) is the Cook–Torrance D with α = m),
  ``int_ior`` = η, ``ext_ior`` = 1 (air), ``specular_reflectance`` = ρ_s;
  ``distribution`` = ``beckmann``, ``nonlinear`` = false.
* principled: ``roughness`` = √m (Mitsuba's GGX α is roughness², and GGX
  with α = m has the Beckmann lobe's core width), ``specular`` =
  ρ_s F0(η) / 0.08 with F0(η) = ((η - 1)/(η + 1))² (principled's normal
  Fresnel reflectance is 0.08 · specular: the lobe scale goes into F0),
  ``metallic`` = 0, ``spec_tint`` = 0, ``sheen`` = 0, ``clearcoat`` = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .parameter import Parameter, ParameterError, rgb


@dataclass(frozen=True)
class BuiltinBSDF:
    """One Mitsuba built-in BSDF usable as ground truth; it answers what a
    caller asks of a BSDF as :class:`~mifaces.brdf.model.BRDFModel` does
    (:func:`mifaces.brdf.bsdf` returns either): its options and parameters,
    the validation of a ``brdf.json`` document, a region's Mitsuba dict and
    its parameters for the published Cook–Torrance skin values.

    Attributes
    ----------
    name : str
        Mitsuba's plugin name.
    albedo : str
        The property the albedo map goes into.
    table : tuple of Parameter
        The numeric properties a ``brdf.json`` region may set, with their valid ranges.
    options : dict
        Option name -> allowed values (first = default).
    exclusive : tuple of (str, str)
        Pairs of parameters a region gives one of: Mitsuba derives one from the other.
    """

    name: str
    albedo: str
    table: tuple[Parameter, ...]
    options: dict
    exclusive: tuple[tuple[str, str], ...] = ()

    def parameters(self) -> tuple[Parameter, ...]:
        """The numeric properties a region may set (the albedo map aside)."""
        return self.table

    def parameter(self, name: str) -> Parameter:
        for p in self.table:
            if p.name == name:
                return p
        raise ParameterError(f"{self.name} has no parameter {name!r}; parameters: "
                             f"{[p.name for p in self.table]} (the albedo map is its {self.albedo})")

    def default_options(self) -> dict:
        return {k: v[0] for k, v in self.options.items()}

    def check_options(self, options: dict) -> dict:
        """``options`` if every one is known with an allowed value; a :class:`ParameterError` otherwise."""
        for key, value in options.items():
            if key not in self.options:
                raise ParameterError(f"{self.name}: unknown option {key!r}; options: {sorted(self.options) or 'none'}")
            if value not in self.options[key]:
                raise ParameterError(f"{self.name}: option {key} = {value!r}; allowed: {list(self.options[key])}")
        return options

    def from_cook_torrance(self, region: dict) -> dict:
        """This built-in's parameters for one region of Cook–Torrance
        parameters ``region`` (``specular_reflectance``, ``roughness``,
        ``eta``), by the mapping of the module docstring."""
        scale = float(np.mean(region["specular_reflectance"]))
        m, eta = float(region["roughness"]), float(region["eta"])
        if self.name == "roughplastic":
            return {"alpha": m, "int_ior": eta, "ext_ior": 1.0,
                    "specular_reflectance": [float(x) for x in np.broadcast_to(region["specular_reflectance"], 3)]}
        return {"roughness": round(float(np.sqrt(m)), 5),
                "specular": round(min(1.0, scale * fresnel_normal(eta) / 0.08), 5),
                "metallic": 0.0, "spec_tint": 0.0, "sheen": 0.0, "clearcoat": 0.0}

    def validate_document(self, document: dict) -> dict:
        """A ground truth of this built-in in the ``brdf.json`` layout,
        checked: known options with allowed values, every region an object
        of known parameter names with values in range (the albedo property
        is the albedo map, not a parameter), at most one of each
        :attr:`exclusive` pair. Returns the document with values as plain floats."""
        options = self.check_options(document.get("options", {}))
        regions = document.get("regions")
        if not isinstance(regions, dict) or not regions:
            raise ParameterError(f"{self.name}: 'regions' must map region names to parameter objects")
        checked = {}
        for region, params in regions.items():
            if not isinstance(params, dict):
                raise ParameterError(f"{self.name} region {region!r}: parameters must be an object")
            if self.albedo in params:
                raise ParameterError(f"{self.name} region {region!r}: {self.albedo} is the albedo map, "
                                     "not a parameter")
            checked[region] = {k: self.parameter(k).check(v, f"{self.name} region {region!r}")
                               for k, v in params.items()}
            for a, b in self.exclusive:
                if a in params and b in params:
                    raise ParameterError(f"{self.name} region {region!r}: give {a} or {b}, not both "
                                         "(Mitsuba derives one from the other)")
        return dict(document, options=dict(options), regions=checked)

    def merge_overrides(self, base: dict, params: dict) -> dict:
        """A region's parameters ``base`` with ``params`` replacing them; giving
        one of an :attr:`exclusive` pair drops the other's value from ``base``."""
        base = dict(base)
        for a, b in self.exclusive + tuple((b, a) for a, b in self.exclusive):
            if a in params and b not in params:
                base.pop(b, None)
        return dict(base, **params)

    def check_complete(self, params: dict, where: str) -> None:
        """Nothing to check: Mitsuba gives every parameter a region leaves out its default."""

    def region_plugin(self, params: dict, texture, options: dict | None = None) -> dict:
        """The Mitsuba dict of a region's ``params`` over albedo ``texture`` (None: Mitsuba's
        default), with the document's ``options``."""
        d = {"type": self.name, **(options or {})}
        if texture is not None:
            d[self.albedo] = texture
        kinds = {p.name: p.kind for p in self.table}
        for k, v in params.items():
            d[k] = rgb(v) if kinds[k] == "rgb" else float(v)
        return d


def _p(name: str, kind: str, default: float, lower: float, upper: float, doc: str) -> Parameter:
    return Parameter(name, kind, default, lower, upper, doc)


_UNIT = ("metallic", "specular", "spec_tint", "anisotropic", "sheen", "sheen_tint", "clearcoat", "clearcoat_gloss",
         "spec_trans")
#: Built-in name -> its description, in the order the CLI lists them.
BUILTINS: dict[str, BuiltinBSDF] = {
    "roughplastic": BuiltinBSDF("roughplastic", "diffuse_reflectance", (
        _p("alpha", "float", 0.1, 1e-3, 1.0, "Beckmann (or GGX) roughness α of the coating"),
        _p("int_ior", "float", 1.49, 1.0, 3.0, "index of refraction of the coating"),
        _p("ext_ior", "float", 1.0, 1.0, 3.0, "index of refraction outside (air)"),
        _p("specular_reflectance", "rgb", 1.0, 0.0, 10.0, "scale of the specular lobe"),
    ), {"distribution": ("beckmann", "ggx"), "nonlinear": (False, True)}),
    "principled": BuiltinBSDF("principled", "base_color", (
        _p("roughness", "float", 0.5, 0.0, 1.0, "GGX roughness (α = roughness²)"),
        _p("eta", "float", 1.5, 1.0, 3.0, "index of refraction (instead of specular)"),
        *(_p(n, "float", 0.0, 0.0, 1.0, f"principled {n}") for n in _UNIT),
    ), {}, exclusive=(("eta", "specular"),)),
}
#: The built-in names.
BUILTIN_NAMES = tuple(BUILTINS)


def fresnel_normal(eta: float) -> float:
    """Fresnel reflectance of a dielectric of index ``eta`` at normal incidence, ((η - 1)/(η + 1))²."""
    return ((eta - 1.0) / (eta + 1.0)) ** 2


__all__ = ["BuiltinBSDF", "BUILTINS", "BUILTIN_NAMES", "fresnel_normal"]
