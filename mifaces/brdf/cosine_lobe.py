"""Sampling a cosine-power lobe cos^n β around an axis (Phong, Lafortune).

The density is p(wo) = (n + 1)/(2π) · cos^n β for β, the angle between wo
and the unit ``axis``, below 90° (Lafortune & Willems 1994, sec. 3.3; Walter's
"Notes on the Ward BRDF" use the same inversion).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .model import dot, power


def sample(axis, exponent, sample2):
    """A direction with density (n+1)/(2π) cos^n β around ``axis``.

    cos β = u^(1/(n+1)), φ = 2π v.
    """
    cos_beta = dr.power(dr.maximum(sample2.x, 1e-30), 1.0 / (exponent + 1.0))
    sin_beta = dr.safe_sqrt(1.0 - cos_beta * cos_beta)
    sin_phi, cos_phi = dr.sincos(dr.two_pi * sample2.y)
    local = mi.Vector3f(sin_beta * cos_phi, sin_beta * sin_phi, cos_beta)
    return mi.Frame3f(axis).to_world(local)


def pdf(axis, exponent, wo):
    """Density of :func:`sample` at ``wo`` (per unit solid angle)."""
    return (exponent + 1.0) * dr.inv_two_pi * power(dot(axis, wo), exponent)


def exponent_of_slope(roughness: float) -> float:
    """The exponent n of a cosine lobe around the mirror direction as wide
    as a Beckmann lobe of RMS slope m = ``roughness``: n = 1/(2m²).

    Near its peak the Beckmann lobe is exp(-tan²θh/m²) ≈ exp(-θh²/m²); the
    angle to the mirror direction is α ≈ 2θh, and cos^n α ≈ exp(-nα²/2) =
    exp(-2nθh²), so the two agree for 2n = 1/m².
    """
    return 1.0 / (2.0 * roughness * roughness)
