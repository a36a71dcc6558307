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

from typing import Iterable, Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

from . import cosine_lobe
from .cooktorrance import from_cook_torrance_lobe
from .model import EXPONENT_GRID, MAX_LOBES, BRDFModel, Parameter, ParameterError, dot, mean, power

#: Largest lobe albedo estimate used to weight sampling (keeps weights finite).
_MAX_WEIGHT = 1e4
#: Prefixes of the parameters of lobes j >= 2 (``cxy_2``, ...).
_PREFIXES = ("cxy_", "cz_", "exponent_")


def lobe_names(lobe: int) -> tuple[str, str, str]:
    """Parameter names (cxy, cz, exponent) of lobe number ``lobe`` (1-based)."""
    suffix = "" if lobe == 1 else f"_{lobe}"
    return f"cxy{suffix}", f"cz{suffix}", f"exponent{suffix}"


def lobes_named(keys: Iterable[str]) -> list[int]:
    """Lobe numbers among parameter names ``keys``: 1, plus every j of a
    ``cxy_j``, ``cz_j`` or ``exponent_j``."""
    lobes = {1}
    for key in keys:
        for prefix in _PREFIXES:
            if key.startswith(prefix) and key[len(prefix):].isdigit():
                lobes.add(int(key[len(prefix):]))
    return sorted(lobes)


def energy_bound(exponent, log, exp):
    """c_max = ((n + 2) / 2π)^{1/n}: the largest coefficient magnitude whose
    lobe keeps an albedo estimate |s|^n 2π/(n + 2) of at most 1 (``log`` and
    ``exp`` numpy's or Dr.Jit's)."""
    return exp(log((exponent + 2.0) / (2.0 * np.pi)) / exponent)


class Lafortune(BRDFModel):
    """Lafortune with the lobes numbered in ``lobes`` (1-based), default one. Its lobes have no
    microfacet parameters: it is exported as the nearest GGX lobe (:meth:`BRDFModel.gltf_lobe`)."""

    name = "lafortune"
    title = "Lafortune"
    SEVERAL_LOBES = True
    EXAMPLE_OPTIONS = {"lobes": 2}
    WIDTH_GRID = ("exponent", EXPONENT_GRID)
    SHARP_END = "upper"

    def __init__(self, lobes: int | Sequence[int] = 1):
        super().__init__()
        self.lobes = tuple(range(1, lobes + 1)) if isinstance(lobes, int) else tuple(lobes)
        if not self.lobes or min(self.lobes) < 1:
            raise ValueError(f"lafortune: lobes must be a count >= 1 or 1-based lobe numbers, got {lobes!r}")
        if max(self.lobes) > MAX_LOBES:
            raise ParameterError(f"lafortune: at most {MAX_LOBES} lobes (numbered 1 to {MAX_LOBES}), got lobe "
                                 f"{max(self.lobes)}")
        self.options = {"lobes": self.lobes}

    @classmethod
    def from_properties(cls, keys, get):
        """The lobes a scene names: 1, plus every j with ``cxy_j``, ``cz_j`` or ``exponent_j``."""
        return cls(lobes=lobes_named(keys))

    def validate_document(self, document):
        """As :meth:`BRDFModel.validate_document`; a document whose options
        give no ``lobes`` has the lobes its regions name (``cxy_2``, ...), and
        the checked options say so where they are more than one."""
        options = document.get("options", {})
        regions = document.get("regions")
        if "lobes" in options:
            return super().validate_document(document)
        keys = [key for params in (regions if isinstance(regions, dict) else {}).values()
                if isinstance(params, dict) for key in params]
        lobes = max(lobes_named(keys))
        if lobes == 1:
            return super().validate_document(document)
        return Lafortune(lobes=lobes).validate_document(dict(document, options=dict(options, lobes=lobes)))

    def specular_parameters(self):
        # The fit starts lobe 1 as a weak forward-scattering lobe, the others weaker and wider.
        out = []
        for j in self.lobes:
            cxy, cz, n = lobe_names(j)
            c = 0.75 if j == 1 else 0.5
            out += [
                Parameter(cxy, "rgb", -1.0, -10.0, 10.0, f"C_xy of lobe {j}", start=-c),
                Parameter(cz, "rgb", 1.0, -10.0, 10.0, f"C_z of lobe {j}", start=c),
                Parameter(n, "float", 20.0, 1.0, 1e5, f"exponent n of lobe {j}", start=10.0 if j == 1 else 3.0),
            ]
        return tuple(out)

    # -- fitting -----------------------------------------------------------
    def unit_lobe(self):
        """Lobe 1 as (-x·x - y·y + z·z)^n, whose scale c^n is b; the other lobes zero."""
        unit = {"cxy": -1.0, "cz": 1.0}
        for j in self.lobes:
            if j != 1:
                cxy, cz, _ = lobe_names(j)
                unit.update({cxy: 0.0, cz: 0.0})
        return unit

    def scaled_lobe(self, scales, width):
        """C_z = -C_xy = b^{1/n} of the channels' mean scale b; lobes j >= 2 keep their start."""
        c = max(float(np.mean(scales)), 1e-6) ** (1.0 / width)
        return {"cxy": [-c] * 3, "cz": [c] * 3}

    def energy_coupled(self):
        """Every lobe's C_xy and C_z, bounded by :meth:`coefficient_bound` of its exponent."""
        out = {}
        for j in self.lobes:
            cxy, cz, n = lobe_names(j)
            out[cxy] = out[cz] = n
        return out

    def coefficient_bound(self, exponent, log, exp):
        return energy_bound(exponent, log, exp)

    def lobe_scales(self):
        return {j: lobe_names(j)[:2] for j in self.lobes}

    def only_lobes(self, lobes):
        return Lafortune(lobes=lobes)

    def from_cook_torrance(self, region):
        return from_cook_torrance_lobe(self, region)

    def from_lobe(self, albedo, roughness):
        """One forward-scattering lobe, C_z = -C_xy = c, as wide as the
        Beckmann lobe (:func:`~mifaces.brdf.cosine_lobe.exponent_of_slope`),
        with c^n = a (n + 2)/2π for albedo a, so that the lobe's albedo at
        normal incidence, c^n 2π/(n + 2), is a: the normalised Phong lobe
        a (n + 2)/2π cos^n α written as a Lafortune lobe."""
        n = cosine_lobe.exponent_of_slope(roughness)
        c = [float((a * (n + 2) / (2 * np.pi)) ** (1.0 / n)) for a in albedo]
        return {"cxy": [-x for x in c], "cz": c, "exponent": n}

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

    def _axis_and_log_weight(self, j, wi, params):
        """Lobe j's axis s_j/|s_j|, exponent and log albedo estimate n log|s_j| + log(2π/(n + 2)),
        capped at log :data:`_MAX_WEIGHT`."""
        cxy, cz, n = self._lobe(j, params)
        s = mi.Vector3f(mean(cxy) * wi.x, mean(cxy) * wi.y, mean(cz) * wi.z)
        length = dr.sqrt(dr.maximum(dot(s, s), 1e-24))  # no infinite gradient at s = 0
        axis = dr.select(length > 1e-12, s / dr.maximum(length, 1e-12), mi.Vector3f(0, 0, 1))
        log_weight = n * dr.log(dr.maximum(length, 1e-30)) + dr.log(dr.two_pi / (n + 2.0))
        return axis, n, dr.minimum(log_weight, dr.log(_MAX_WEIGHT))

    def _lobes_and_shares(self, wi, params):
        """Each lobe's (axis, exponent, share of the sampling): the albedo estimates
        normalised in log space, relative to the largest, so that lobes whose
        estimates underflow float32 (n = 1e5 at grazing incidence) keep finite
        shares and gradients."""
        lobes = [self._axis_and_log_weight(j, wi, params) for j in self.lobes]
        if len(lobes) == 1:
            return [(lobes[0][0], lobes[0][1], 1.0)]
        largest = lobes[0][2]
        for _, _, lw in lobes[1:]:
            largest = dr.maximum(largest, lw)
        largest = dr.detach(largest)  # cancels in the ratio; no gradient through the max
        weights = [dr.exp(lw - largest) for _, _, lw in lobes]  # the largest is 1: the total is >= 1
        total = sum(weights)
        return [(axis, n, w / total) for (axis, n, _), w in zip(lobes, weights)]

    def specular_weight(self, wi, params):
        return sum(dr.exp(self._axis_and_log_weight(j, wi, params)[2]) for j in self.lobes)

    def sample_specular(self, wi, sample1, sample2, params):
        lobes = self._lobes_and_shares(wi, params)
        if len(lobes) == 1:
            axis, n, _ = lobes[0]
            return cosine_lobe.sample(axis, n, sample2)
        # Lobe j is chosen where cumulative share up to j-1 <= u < up to j:
        # going backwards, the last assignment is the first lobe whose
        # cumulative share exceeds u.
        cumulative, bounds = 0.0, []
        for _, _, share in lobes[:-1]:
            cumulative = cumulative + share
            bounds.append(cumulative)
        wo = cosine_lobe.sample(lobes[-1][0], lobes[-1][1], sample2)
        for (axis, n, _), bound in reversed(list(zip(lobes[:-1], bounds))):
            wo = dr.select(sample1 < bound, cosine_lobe.sample(axis, n, sample2), wo)
        return wo

    def pdf_specular(self, wi, wo, params):
        return sum(share * cosine_lobe.pdf(axis, n, wo) for axis, n, share in self._lobes_and_shares(wi, params))
