"""Cook-Torrance microfacet BRDF with the Beckmann distribution.

    f(wi, wo) = ρ_d / π + ρ_s · D(h) F(wi·h) G(wi, wo) / (4 cos θi cos θo)

Source: Cook & Torrance, "A reflectance model for computer graphics", ACM
TOG 1(1), 1982 (eqs. 2-5), in the form of Walter et al., "Microfacet models
for refraction through rough surfaces", EGSR 2007 (eq. 20): 4 cos θi cos θo
in the denominator where Cook & Torrance have π cos θi cos θo, their D
lacking the 1/π that normalises Beckmann's. ``specular_reflectance`` ρ_s scales the lobe;
D is Beckmann with RMS slope m = ``roughness``; F is the unpolarised
dielectric Fresnel term with relative index ``eta`` (default 1.4, skin:
Tuchin's tissue optics; a fit holds it at the published value of each face
region, :data:`mifaces.brdf.materials.REFRACTIVE_INDEX`),
Schlick's approximation, or 1; G is the V-cavity term of the original paper
or the separable Smith term of Walter et al. 2007. With F = 1, Smith G and
ρ_s = 1 this is Mitsuba's ``roughconductor`` (Beckmann) with a perfect
mirror material. No cosine term included; local frame.
"""

from __future__ import annotations

from typing import Mapping

import drjit as dr
import mitsuba as mi
import numpy as np

from . import microfacet
from .builtin import fresnel_normal
from .gltf_lobe import GltfLobe
from .materials import REFRACTIVE_INDEX, SKIN_REFRACTIVE_INDEX
from .model import SLOPE_GRID, BRDFModel, COS_EPSILON, Parameter, dot, mean

#: The index of refraction of the Fresnel term; a fit starts it at skin's.
ETA = Parameter("eta", "float", 1.4, 1.0, 3.0, "relative index of refraction of the Fresnel term",
                start=SKIN_REFRACTIVE_INDEX)
#: Decimals of the parameters derived from a Cook–Torrance lobe in ``brdf.json``: colours, numbers.
DIGITS = {"rgb": 5, "float": 4}


class CookTorrance(BRDFModel):
    """Cook-Torrance; options ``fresnel`` (dielectric | schlick | none) and
    ``geometry`` (vcavity | smith)."""

    name = "cooktorrance"
    title = "Cook-Torrance"
    OPTIONS = {"fresnel": ("dielectric", "schlick", "none"), "geometry": ("vcavity", "smith")}
    WIDTH_GRID = ("roughness", SLOPE_GRID)

    def specular_parameters(self):
        return (
            Parameter("specular_reflectance", "rgb", 1.0, 0.0, 10.0, "scale ρ_s of the microfacet lobe"),
            Parameter("roughness", "float", 0.3, 1e-3, 1.0, "Beckmann RMS slope m"),
            ETA,
        )

    def fixed_defaults(self):
        """η, at skin's: it trades off against the lobe scale, and skin's is known."""
        return {ETA.name: SKIN_REFRACTIVE_INDEX}

    def fixed_in_region(self, region):
        """η at the region's published value, where there is one."""
        return {ETA.name: REFRACTIVE_INDEX[region]} if region in REFRACTIVE_INDEX else {}

    def from_cook_torrance(self, region):
        """The region's values themselves."""
        return {k: (list(v) if isinstance(v, list) else v) for k, v in region.items()}

    def gltf_lobe(self, params):
        """α = m (Beckmann's RMS slope; GGX with α = m has the Beckmann lobe's core width, as
        :mod:`mifaces.brdf.builtin` maps it for ``principled``), f0 = ρ_s F0(η), f90 = ρ_s
        (the dielectric Fresnel term scaled by ρ_s, in Schlick's form)."""
        rho = np.broadcast_to(np.asarray(params["specular_reflectance"], np.float64), 3)
        eta = float(params.get(ETA.name, ETA.default))
        return GltfLobe.clipped(params["roughness"], rho * fresnel_normal(eta), float(np.max(rho)))

    def fresnel_term(self, cos_theta, eta):
        """F at incidence cosine ``cos_theta`` for this model's ``fresnel`` option."""
        if self.fresnel == "dielectric":
            return microfacet.fresnel_dielectric(cos_theta, eta)
        if self.fresnel == "schlick":
            return microfacet.fresnel_schlick(cos_theta, eta)
        return 1.0

    def specular(self, wi, wo, params):
        m = params["roughness"]
        h = microfacet.half_vector(wi, wo)
        d = microfacet.beckmann_d(h, m)
        if self.geometry == "vcavity":
            g = microfacet.vcavity_g(wi, wo, h)
        else:
            g = microfacet.smith_g(wi, wo, h, m)
        f = self.fresnel_term(dot(wi, h), params.get(ETA.name, ETA.default))
        cos_i = dr.maximum(wi.z, COS_EPSILON)
        cos_o = dr.maximum(wo.z, COS_EPSILON)
        return mi.Color3f(params["specular_reflectance"]) * (d * f * g / (4.0 * cos_i * cos_o))

    def specular_weight(self, wi, params):
        f = self.fresnel_term(wi.z, params.get(ETA.name, ETA.default))
        return mean(mi.Color3f(params["specular_reflectance"])) * f

    def sample_specular(self, wi, sample1, sample2, params):
        return microfacet.sample_beckmann(wi, sample2, params["roughness"])

    def pdf_specular(self, wi, wo, params):
        h = microfacet.half_vector(wi, wo)
        return microfacet.reflected_pdf(microfacet.beckmann_pdf_h(h, params["roughness"]), wo, h)


def lobe_albedo(params: Mapping, samples: int = 256) -> np.ndarray:
    """Directional albedo at normal incidence of the Cook–Torrance specular lobe
    with ``params`` (RGB), by midpoint quadrature over the hemisphere with the array API."""
    model = CookTorrance()
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


def from_cook_torrance_lobe(model: BRDFModel, region: Mapping) -> dict:
    """Glossy parameters of ``model`` for one region of Cook–Torrance
    parameters: its :meth:`~mifaces.brdf.model.BRDFModel.from_lobe` of the
    Cook–Torrance lobe's directional albedo at normal incidence
    (:func:`lobe_albedo`) and roughness, rounded to :data:`DIGITS` decimals."""
    kinds = {p.name: p.kind for p in model.specular_parameters()}
    albedo = [round(float(a), DIGITS["rgb"]) for a in lobe_albedo(region)]
    derived = model.from_lobe(albedo, region["roughness"])
    return {k: ([round(x, DIGITS["rgb"]) for x in v] if kinds[k] == "rgb" else round(v, DIGITS["float"]))
            for k, v in derived.items()}


__all__ = ["CookTorrance", "ETA", "DIGITS", "lobe_albedo", "from_cook_torrance_lobe"]
