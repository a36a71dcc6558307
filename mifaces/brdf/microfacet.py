"""Microfacet building blocks: the Beckmann distribution, shadowing-masking
and Fresnel terms, as pure Dr.Jit functions.

Directions are unit vectors in the local frame (z = normal) pointing away
from the surface; ``h`` is the unit half vector (wi + wo)/|wi + wo|.
Inputs are guarded so that values *and gradients* stay finite at grazing
angles (cos θ -> 0) and for roughness down to 1e-3.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .model import COS_EPSILON, dot, exp_flushed, safe_divide

#: Smallest roughness the formulas accept; smaller values are clamped.
MIN_ROUGHNESS = 1e-4
#: Cosines of the half vector are clamped to this in D (tan²θ <= 1e8).
_MIN_COS_H = 1e-4


def half_vector(wi, wo):
    """Unit half vector of ``wi`` and ``wo``; (0, 0, 1) where they cancel."""
    h = wi + wo
    length = dr.sqrt(dot(h, h))
    return dr.select(length > 1e-12, h / dr.maximum(length, 1e-12), mi.Vector3f(0, 0, 1))


def beckmann_log_slope(h, alpha):
    """-tan²θh / α², the logarithm of the Gaussian slope term shared by
    Beckmann and Ward, for the unit half vector ``h``.

    tan²θh is computed as (h.x² + h.y²)/h.z², not from cos θh (1 - cos² loses
    all precision near the peak of a sharp lobe in float32), with h.z clamped
    to 1e-4. The models work with logarithms so that neither the value nor
    its gradient meets a denominator that under- or overflows in float32 (the
    derivative of 1/(π α² cos⁴θh) does, for α = 1e-3 and cos θh = 1e-4)."""
    alpha = dr.maximum(alpha, MIN_ROUGHNESS)
    c = dr.maximum(h.z, _MIN_COS_H)
    return -((h.x * h.x + h.y * h.y) / (c * c)) / (alpha * alpha)


def beckmann_d(h, alpha):
    """Beckmann normal distribution (Beckmann & Spizzichino 1963; Cook &
    Torrance 1982, eq. 3; Walter et al. 2007, eq. 25):

        D(h) = exp(-tan²θh / α²) / (π α² cos⁴θh),

    normalised so that ∫ D(h) cos θh dω_h = 1. ``alpha`` is the RMS slope m.
    0 for θh >= 90°.
    """
    alpha = dr.maximum(alpha, MIN_ROUGHNESS)
    c = dr.maximum(h.z, _MIN_COS_H)
    log_d = beckmann_log_slope(h, alpha) - dr.log(dr.pi * alpha * alpha) - 4.0 * dr.log(c)
    return dr.select(h.z > 0, exp_flushed(log_d), 0.0)


def beckmann_pdf_h(h, alpha):
    """Density of half vectors sampled from D(h) cos θh (per solid angle of h)."""
    return beckmann_d(h, alpha) * dr.maximum(h.z, 0.0)


def reflected_pdf(pdf_h, wo, h):
    """Density of wo = reflect(wi, h) given the density of h: pdf_h / (4 |wo·h|)
    (Walter et al. 2007, eq. 14)."""
    return safe_divide(pdf_h, 4.0 * dr.abs(dot(wo, h)))


def sample_beckmann(wi, sample2, alpha):
    """Sample a half vector h ~ D(h) cos θh and reflect ``wi`` about it.

    Uses Mitsuba's Beckmann sampler (all normals, not only visible ones).
    Returns the outgoing direction (possibly below the horizon).
    """
    distr = mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann,
                                      dr.maximum(alpha, MIN_ROUGHNESS), False)
    h, _ = distr.sample(wi, sample2)
    return mi.reflect(wi, h)


def smith_g1(v, h, alpha):
    """Smith masking for the Beckmann distribution, with the rational
    approximation of Walter et al. 2007 (eq. 27; < 0.35 % error), the one
    Mitsuba uses:

        a = 1 / (α tan θv),  G1 = (3.535 a + 2.181 a²) / (1 + 2.276 a + 2.577 a²)  for a < 1.6, else 1,

    and 0 where ``v`` sees the back of the microfacet.
    """
    alpha = dr.maximum(alpha, MIN_ROUGHNESS)
    cos_v = v.z
    sin_v = dr.sqrt(v.x * v.x + v.y * v.y)  # not sqrt(1 - cos²): precise near the normal
    a = safe_divide(cos_v, alpha * sin_v)
    a = dr.minimum(dr.maximum(a, 0.0), 1.6)
    g = (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
    g = dr.select(a >= 1.6, 1.0, g)
    return dr.select(dot(v, h) * cos_v > 0, g, 0.0)


def smith_g(wi, wo, h, alpha):
    """Separable Smith shadowing-masking G1(wi) G1(wo)."""
    return smith_g1(wi, h, alpha) * smith_g1(wo, h, alpha)


def vcavity_g(wi, wo, h):
    """V-cavity shadowing-masking of Cook & Torrance 1982 (eq. 5; after
    Torrance & Sparrow 1967):

        G = min(1, 2 (n·h)(n·wo) / (wo·h), 2 (n·h)(n·wi) / (wi·h)).
    """
    nh = h.z
    g_o = safe_divide(2.0 * nh * wo.z, dot(wo, h))
    g_i = safe_divide(2.0 * nh * wi.z, dot(wi, h))
    return dr.maximum(dr.minimum(dr.minimum(1.0, g_o), g_i), 0.0)


def fresnel_dielectric(cos_theta, eta):
    """Unpolarised Fresnel reflectance of a dielectric interface with relative
    index ``eta`` (Mitsuba's ``fresnel``), at incidence cosine ``cos_theta``."""
    f, _, _, _ = mi.fresnel(dr.maximum(cos_theta, COS_EPSILON), dr.maximum(eta, 1e-3))
    return f


def fresnel_schlick(cos_theta, eta):
    """Schlick's approximation (Schlick 1994, eq. 24):
    F = F0 + (1 - F0)(1 - cos θ)^5, F0 = ((η - 1)/(η + 1))²."""
    f0 = dr.square((eta - 1.0) / (eta + 1.0))
    m = 1.0 - dr.clip(cos_theta, 0.0, 1.0)
    m2 = m * m
    return f0 + (1.0 - f0) * (m2 * m2 * m)
