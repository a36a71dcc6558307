"""Isotropic Lafortune BRDF: a diffuse term plus generalised cosine lobes.

    f(wi, wo) = ρ_d / π + Σ_j [C_xy,j (wi.x wo.x + wi.y wo.y) + C_z,j wi.z wo.z]^{n_j}

with the bracket clamped at 0. Source: Lafortune, Foo, Torrance & Greenberg,
"Non-linear approximation of reflectance functions", SIGGRAPH 1997 (eq. 4),
isotropic (C_x = C_y = C_xy). A forward-scattering (specular-like) lobe has
C_xy < 0 < C_z; a retro-reflective one C_xy > 0. The coefficients of a lobe
may be RGB (elementwise powers); the exponent is one number per lobe. The
lobes are not normalised: their albedo is whatever the coefficients make it.
Lobe j >= 2 has parameters ``cxy_j``, ``cz_j``, ``exponent_j``; lobe 1 has
no suffix. No cosine term included; local frame.

Sampling: lobe j is the cosine-power lobe |s_j|^{n_j} cos^{n_j} β around
s_j = (C_xy wi.x, C_xy wi.y, C_z wi.z) (channel means of the coefficients),
sampled as in :mod:`mifaces.brdf.cosine_lobe`; lobes are picked in
proportion to |s_j|^{n_j} 2π/(n_j + 2), an estimate of their albedo.
"""

from __future__ import annotations

from typing import Sequence

import drjit as dr
import mitsuba as mi

from . import cosine_lobe
from .model import BRDFModel, Parameter, dot, mean, power

#: Largest lobe albedo estimate used to weight sampling (keeps weights finite).
_MAX_WEIGHT = 1e4


def lobe_names(lobe: int) -> tuple[str, str, str]:
    """Parameter names (cxy, cz, exponent) of lobe number ``lobe`` (1-based)."""
    suffix = "" if lobe == 1 else f"_{lobe}"
    return f"cxy{suffix}", f"cz{suffix}", f"exponent{suffix}"


class Lafortune(BRDFModel):
    """Lafortune with the lobes numbered in ``lobes`` (1-based), default one."""

    name = "lafortune"

    def __init__(self, lobes: int | Sequence[int] = 1):
        super().__init__()
        self.lobes = tuple(range(1, lobes + 1)) if isinstance(lobes, int) else tuple(lobes)
        if not self.lobes or min(self.lobes) < 1:
            raise ValueError(f"lafortune: lobes must be a count >= 1 or 1-based lobe numbers, got {lobes!r}")
        self.options = {"lobes": self.lobes}

    def specular_parameters(self):
        out = []
        for j in self.lobes:
            cxy, cz, n = lobe_names(j)
            out += [
                Parameter(cxy, "rgb", -1.0, -10.0, 10.0, f"C_xy of lobe {j}"),
                Parameter(cz, "rgb", 1.0, -10.0, 10.0, f"C_z of lobe {j}"),
                Parameter(n, "float", 20.0, 1.0, 1e5, f"exponent n of lobe {j}"),
            ]
        return tuple(out)

    def _lobe(self, j, params):
        cxy, cz, n = lobe_names(j)
        return params[cxy], params[cz], params[n]

    def specular(self, wi, wo, params):
        xy = wi.x * wo.x + wi.y * wo.y
        zz = wi.z * wo.z
        value = mi.Color3f(0.0)
        for j in self.lobes:
            cxy, cz, n = self._lobe(j, params)
            # grey coefficients stay scalar: one power instead of three
            value += power(cxy * xy + cz * zz, n)
        return value

    def _axis_and_weight(self, j, wi, params):
        cxy, cz, n = self._lobe(j, params)
        s = mi.Vector3f(mean(cxy) * wi.x, mean(cxy) * wi.y, mean(cz) * wi.z)
        length = dr.sqrt(dot(s, s))
        axis = dr.select(length > 1e-12, s / dr.maximum(length, 1e-12), mi.Vector3f(0, 0, 1))
        log_weight = n * dr.log(dr.maximum(length, 1e-30)) + dr.log(dr.two_pi / (n + 2.0))
        weight = dr.exp(dr.minimum(log_weight, dr.log(_MAX_WEIGHT)))
        return axis, n, weight

    def specular_weight(self, wi, params):
        return sum(self._axis_and_weight(j, wi, params)[2] for j in self.lobes)

    def sample_specular(self, wi, sample1, sample2, params):
        lobes = [self._axis_and_weight(j, wi, params) for j in self.lobes]
        if len(lobes) == 1:
            axis, n, _ = lobes[0]
            return cosine_lobe.sample(axis, n, sample2)
        # Lobe j is chosen where cumulative weight up to j-1 <= u·total < up to j:
        # going backwards, the last assignment is the first lobe whose
        # cumulative weight exceeds the threshold.
        threshold = sample1 * sum(w for _, _, w in lobes)
        cumulative, bounds = 0.0, []
        for _, _, w in lobes[:-1]:
            cumulative = cumulative + w
            bounds.append(cumulative)
        wo = cosine_lobe.sample(lobes[-1][0], lobes[-1][1], sample2)
        for (axis, n, _), bound in reversed(list(zip(lobes[:-1], bounds))):
            wo = dr.select(threshold < bound, cosine_lobe.sample(axis, n, sample2), wo)
        return wo

    def pdf_specular(self, wi, wo, params):
        lobes = [self._axis_and_weight(j, wi, params) for j in self.lobes]
        if len(lobes) == 1:
            axis, n, _ = lobes[0]
            return cosine_lobe.pdf(axis, n, wo)
        total = dr.maximum(sum(w for _, _, w in lobes), 1e-30)
        return sum(w / total * cosine_lobe.pdf(axis, n, wo) for axis, n, w in lobes)
