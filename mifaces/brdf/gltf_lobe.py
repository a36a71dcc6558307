"""glTF 2.0's material model, the lobe every fitted BRDF is exported as.

glTF's model (glTF 2.0 specification, Appendix B, with
``KHR_materials_specular`` and ``KHR_materials_ior``), for a dielectric
(metallic 0), in a local frame with z the normal::

    f(ωi, ωo) = (1 − max_c F_c) · baseColor / π + F · D(h) · V(ωi, ωo)
    F = f90 · (r0 + (1 − r0)(1 − |ωo·h|)^5),   r0 = min(F0(η) · specularColor, 1),   f90 = specularFactor
    D = α² / (π ((h·n)² (α² − 1) + 1)²)                                 (GGX, α = roughness²)
    V = 0.5 / (n·ωo √((n·ωi)² (1 − α²) + α²) + n·ωi √((n·ωo)² (1 − α²) + α²))   (height-correlated Smith)

with F0(η) = ((η − 1)/(η + 1))². :func:`gltf_brdf` evaluates it. A region's
glTF lobe is described by :class:`GltfLobe`: the GGX α, the lobe's
reflectance at normal incidence ``f0`` (RGB, = f90 · r0) and at grazing
incidence ``f90``.

Each model maps its own parameters onto it
(:meth:`mifaces.brdf.model.BRDFModel.gltf_lobe`, its docstring the formula:
Phong, Cook–Torrance and Ward in closed form). A model without one (Lafortune,
whose lobes have no microfacet parameters) takes the default,
:func:`nearest_lobe`: the GGX lobe nearest by least squares of f cos θo over
the hemisphere grid (:func:`mifaces.brdf.hemisphere.hemisphere_pairs`), for
every α of :data:`ALPHA_GRID` the best non-negative scale per channel in
closed form, then the α with the least residual; f0 = the scale, f90 = its
largest channel.

The base colour is the albedo divided by 1 − max_c f0 (:meth:`GltfLobe.base_color`):
glTF takes the specular layer's share from the diffuse layer, mifaces' models
add the two, so the division keeps the diffuse reflectance at normal
incidence the fitted one (and everywhere, for lobes without Fresnel rise).
How close each mapping is: ``validation/export.py``, ``docs/export.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import mitsuba as mi
import numpy as np

from .builtin import fresnel_normal
from .hemisphere import hemisphere_pairs

#: Smallest and largest GGX α a glTF material is given (roughness = √α).
ALPHA_RANGE = (1e-3, 1.0)
#: The α :func:`nearest_lobe` fits over (log-spaced).
ALPHA_GRID = np.geomspace(0.02, 1.0, 64)
#: Directions per axis of the hemisphere grid of :func:`nearest_lobe`.
FIT_GRID = 12
#: Largest base colour written (glTF's baseColor is at most 1).
MAX_BASE_COLOR = 1.0


def _rgb(value) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, np.float64), 3).copy()


@dataclass(frozen=True)
class GltfLobe:
    """One region's glTF specular layer (module docstring).

    Attributes
    ----------
    alpha : float
        GGX α (glTF's roughness is √α).
    f0 : (3,) ndarray
        Reflectance of the layer at normal incidence, RGB (f90 · r0).
    f90 : float
        At grazing incidence (``specularFactor``).
    """

    alpha: float
    f0: np.ndarray
    f90: float

    @classmethod
    def clipped(cls, alpha: float, f0, f90: float) -> GltfLobe:
        """The lobe of GGX ``alpha``, ``f0`` (a number or RGB) and ``f90``, each kept where glTF
        can write it: α in :data:`ALPHA_RANGE`, f90 in [0, 1], f0 in [0, f90]."""
        f90 = float(np.clip(f90, 0.0, 1.0))
        return cls(float(np.clip(alpha, *ALPHA_RANGE)), np.clip(_rgb(f0), 0.0, f90), f90)

    @property
    def roughness(self) -> float:
        """glTF's perceptual roughness √α."""
        return float(np.sqrt(self.alpha))

    def specular_color(self, eta: float) -> np.ndarray:
        """``specularColorFactor`` (RGB, may exceed 1) for a material of index ``eta``: r0 / F0(η)."""
        r0 = self.f0 / self.f90 if self.f90 > 0 else np.zeros(3)
        return r0 / fresnel_normal(eta)

    def base_color(self, albedo: np.ndarray) -> np.ndarray:
        """The base colour that keeps diffuse reflectance ``albedo`` (..., 3) at normal incidence."""
        return np.clip(np.asarray(albedo) / (1.0 - float(np.max(self.f0))), 0.0, MAX_BASE_COLOR)


def gltf_brdf(wi: np.ndarray, wo: np.ndarray, base_color, lobe: GltfLobe) -> np.ndarray:
    """glTF's BRDF f(ωi, ωo) (module docstring), no cosine, for (N, 3) local
    directions, RGB base colour and a lobe; (N, 3) RGB. The material's index
    enters only through r0 = f0 / f90 (its specular colour absorbs it)."""
    wi, wo = np.asarray(wi, np.float64), np.asarray(wo, np.float64)
    h = wi + wo
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-30)
    ci, co, ch = wi[:, 2], wo[:, 2], h[:, 2]
    a2 = lobe.alpha ** 2
    d = a2 / (np.pi * np.square(ch * ch * (a2 - 1.0) + 1.0))
    v = 0.5 / np.maximum(co * np.sqrt(ci * ci * (1 - a2) + a2) + ci * np.sqrt(co * co * (1 - a2) + a2), 1e-30)
    r0 = lobe.f0 / lobe.f90 if lobe.f90 > 0 else np.zeros(3)
    schlick = (1.0 - np.abs(np.sum(wo * h, axis=1))) ** 5
    fresnel = lobe.f90 * (r0[None, :] + (1.0 - r0[None, :]) * schlick[:, None])
    f = (1.0 - fresnel.max(axis=1, keepdims=True)) * np.asarray(base_color, np.float64) / np.pi \
        + fresnel * (d * v)[:, None]
    return np.where(((ci > 0) & (co > 0))[:, None], f, 0.0)


def glossy_values(model, params: Mapping, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """A model's glossy part f_s(ωi, ωo) (no diffuse, no cosine), (N, 3), by its own
    Dr.Jit formula (:meth:`mifaces.brdf.model.BRDFModel.eval`), for (N, 3) local directions
    and one region's parameters (numbers, RGB as three)."""
    def vec(a):
        return mi.Vector3f(*(np.ascontiguousarray(a[:, k], np.float32) for k in range(3)))

    values = {k: (mi.Color3f(*map(float, _rgb(v))) if np.ndim(v) else float(v)) for k, v in params.items()}
    f = model.eval(vec(wi), vec(wo), values, diffuse=False)
    return np.stack([np.asarray(f[c], np.float64) for c in range(3)], axis=1)


def nearest_lobe(model, params: Mapping, grid: int = FIT_GRID) -> GltfLobe:
    """The GGX lobe nearest (least squares of f cos θo over the hemisphere
    grid) to the glossy part of ``model`` (a :class:`~mifaces.brdf.model.BRDFModel`)
    with one region's ``params``; see the module docstring."""
    wi, wo = hemisphere_pairs(grid)
    target = glossy_values(model, params, wi, wo) * wo[:, 2:3]
    best = None
    unit = np.ones(3)
    for alpha in ALPHA_GRID:
        basis = gltf_brdf(wi, wo, np.zeros(3), GltfLobe(float(alpha), unit, 1.0))[:, 0] * wo[:, 2]
        scale = np.maximum(basis @ target / max(float(basis @ basis), 1e-30), 0.0)
        residual = float(np.sum((target - basis[:, None] * scale[None, :]) ** 2))
        if best is None or residual < best[0]:
            best = (residual, alpha, scale)
    _, alpha, scale = best
    return GltfLobe.clipped(alpha, scale, float(np.max(scale)))


__all__ = ["ALPHA_RANGE", "ALPHA_GRID", "FIT_GRID", "MAX_BASE_COLOR", "GltfLobe", "gltf_brdf", "glossy_values",
           "nearest_lobe"]
