"""Energy-normalised modified Phong BRDF.

    f(wi, wo) = ρ_d / π + ρ_s · (n + 2) / (2π) · cos^n α,
    cos α = max(0, r(wi) · wo),  r(wi) = (-wi.x, -wi.y, wi.z) the mirror direction.

Source: Lewis, "Making shaders more physically plausible", 1994, and
Lafortune & Willems, "Using the modified Phong reflectance model for
physically based rendering", 1994 (the (n+2)/(2π) normalisation). The glossy
lobe reflects exactly ρ_s at normal incidence and less elsewhere, so
ρ_d + ρ_s <= 1 conserves energy. No cosine term included; local frame.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from . import cosine_lobe
from .cooktorrance import from_cook_torrance_lobe
from .gltf_lobe import GltfLobe
from .model import EXPONENT_GRID, BRDFModel, Parameter, mean, power


class Phong(BRDFModel):
    """Modified Phong: parameters ``specular_reflectance`` (ρ_s, RGB) and
    ``exponent`` (n >= 0)."""

    name = "phong"
    title = "Modified Phong"
    WIDTH_GRID = ("exponent", EXPONENT_GRID)
    SHARP_END = "upper"

    def specular_parameters(self):
        return (
            Parameter("specular_reflectance", "rgb", 0.2, 0.0, 1.0, "albedo ρ_s of the lobe at normal incidence",
                      start=0.05),
            Parameter("exponent", "float", 30.0, 1.0, 1e5, "Phong exponent n", start=10.0),
        )

    def from_cook_torrance(self, region):
        return from_cook_torrance_lobe(self, region)

    def from_lobe(self, albedo, roughness):
        """ρ_s = the albedo (the lobe reflects exactly ρ_s at normal
        incidence), n from :func:`~mifaces.brdf.cosine_lobe.exponent_of_slope`."""
        return {"specular_reflectance": list(albedo), "exponent": cosine_lobe.exponent_of_slope(roughness)}

    def gltf_lobe(self, params):
        """α = 1/√(2n), the inverse of :func:`~mifaces.brdf.cosine_lobe.exponent_of_slope`;
        f0 = f90 = ρ_s (the lobe reflects ρ_s at normal incidence and has no Fresnel rise)."""
        rho = np.broadcast_to(np.asarray(params["specular_reflectance"], np.float64), 3)
        return GltfLobe.clipped(1.0 / np.sqrt(2.0 * float(params["exponent"])), rho, float(np.max(rho)))

    def specular(self, wi, wo, params):
        n = params["exponent"]
        cos_alpha = wi.z * wo.z - wi.x * wo.x - wi.y * wo.y  # r(wi)·wo
        lobe = (n + 2.0) * dr.inv_two_pi * power(cos_alpha, n)
        return mi.Color3f(params["specular_reflectance"]) * lobe

    def specular_weight(self, wi, params):
        return mean(mi.Color3f(params["specular_reflectance"]))

    def sample_specular(self, wi, sample1, sample2, params):
        return cosine_lobe.sample(mi.reflect(wi), params["exponent"], sample2)

    def pdf_specular(self, wi, wo, params):
        return cosine_lobe.pdf(mi.reflect(wi), params["exponent"], wo)
