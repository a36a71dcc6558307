"""The fitted BRDFs mapped onto glTF 2.0's material model.

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
incidence ``f90``. Each fitted model maps onto it (:func:`gltf_lobe`):

* Cook–Torrance: α = m (Beckmann's RMS slope; GGX with α = m has the
  Beckmann lobe's core width, as :mod:`mifaces.brdf.builtin` maps it for
  ``principled``), f0 = ρ_s F0(η), f90 = ρ_s (the dielectric Fresnel term
  scaled by ρ_s, in Schlick's form).
* Phong: α = 1/√(2n), the inverse of
  :func:`mifaces.brdf.cosine_lobe.exponent_of_slope`; f0 = f90 = ρ_s (the
  Phong lobe reflects ρ_s at normal incidence and has no Fresnel rise).
* Ward: α = the Ward α (Ward's lobe is Beckmann's slope distribution),
  f0 = f90 = ρ_s.
* Lafortune: the lobes have no microfacet parameters; the nearest GGX lobe
  by least squares of f cos θo over the hemisphere grid of
  :func:`mifaces.validation.validator.hemisphere_grid` (:func:`fit_lafortune`):
  for every α of :data:`ALPHA_GRID` the best non-negative scale per channel
  in closed form, then the α with the least residual; f0 = the scale,
  f90 = its largest channel.

The base colour is the albedo divided by 1 − max_c f0 (:meth:`GltfLobe.base_color`):
glTF takes the specular layer's share from the diffuse layer, mifaces' models
add the two, so the division keeps the diffuse reflectance at normal
incidence the fitted one (and everywhere, for lobes without Fresnel rise).
How close each mapping is: ``validation/export.py``, ``docs/export.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..brdf import MODELS, model as brdf_model
from ..brdf.builtin import fresnel_normal
from ..brdf.materials import REFRACTIVE_INDEX, SKIN_REFRACTIVE_INDEX

#: Smallest and largest GGX α a glTF material is given (roughness = √α).
ALPHA_RANGE = (1e-3, 1.0)
#: The α the Lafortune lobes are fitted over (log-spaced).
ALPHA_GRID = np.geomspace(0.02, 1.0, 64)
#: Directions per axis of the hemisphere grid of the Lafortune fit.
FIT_GRID = 12
#: Largest base colour written (glTF's baseColor is at most 1).
MAX_BASE_COLOR = 1.0


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


def _rgb(value) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, np.float64), 3).copy()


def _lobe(alpha: float, f0, f90: float) -> GltfLobe:
    f90 = float(np.clip(f90, 0.0, 1.0))
    return GltfLobe(float(np.clip(alpha, *ALPHA_RANGE)), np.clip(_rgb(f0), 0.0, f90), f90)


def gltf_lobe(model: str, params: dict, region: str = "skin", options: dict | None = None) -> GltfLobe:
    """The glTF layer of one region's fitted parameters (module docstring).

    Parameters
    ----------
    model : str
        One of :data:`mifaces.brdf.NAMES`.
    params : dict
        The region's parameters (``brdf.json``'s ``regions[region]``).
    region : str
        The region (its index of refraction where the model has none).
    options : dict, optional
        The model's options (Lafortune's ``lobes``).
    """
    if model not in MODELS:
        raise ValueError(f"no glTF mapping for BRDF model {model!r}; known: {list(MODELS)}")
    if model == "lafortune":
        return fit_lafortune(params, options or {})
    rho = _rgb(params["specular_reflectance"])
    if model == "cooktorrance":
        eta = float(params.get("eta", REFRACTIVE_INDEX.get(region, SKIN_REFRACTIVE_INDEX)))
        return _lobe(params["roughness"], rho * fresnel_normal(eta), float(np.max(rho)))
    if model == "phong":
        return _lobe(1.0 / np.sqrt(2.0 * float(params["exponent"])), rho, float(np.max(rho)))
    return _lobe(params["alpha"], rho, float(np.max(rho)))  # ward


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


def hemisphere_pairs(grid: int = FIT_GRID) -> tuple[np.ndarray, np.ndarray]:
    """Every (ωi, ωo) pair of :func:`mifaces.validation.validator.hemisphere_grid` (cosine-weighted, stratified)."""
    from ..validation.validator import hemisphere_grid

    d = hemisphere_grid(grid)
    i, o = np.meshgrid(np.arange(len(d)), np.arange(len(d)), indexing="ij")
    return d[i.ravel()], d[o.ravel()]


def specular_lobe(model: str, params: dict, options: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """A fitted model's glossy part f_s(ωi, ωo) (no diffuse, no cosine), (N, 3), by its own
    Dr.Jit formula (:meth:`mifaces.brdf.model.BRDFModel.eval`)."""
    import mitsuba as mi

    def vec(a):
        return mi.Vector3f(*(np.ascontiguousarray(a[:, k], np.float32) for k in range(3)))

    instance = brdf_model(model, **options)
    values = {k: (mi.Color3f(*map(float, _rgb(v))) if np.ndim(v) else float(v)) for k, v in params.items()}
    f = instance.eval(vec(wi), vec(wo), values, diffuse=False)
    return np.stack([np.asarray(f[c], np.float64) for c in range(3)], axis=1)


def fit_lafortune(params: dict, options: dict, grid: int = FIT_GRID) -> GltfLobe:
    """The GGX lobe nearest (least squares of f cos θo over the hemisphere
    grid) to a region's Lafortune lobes; see the module docstring."""
    wi, wo = hemisphere_pairs(grid)
    target = specular_lobe("lafortune", params, options, wi, wo) * wo[:, 2:3]
    best = None
    unit = np.ones(3)
    for alpha in ALPHA_GRID:
        basis = gltf_brdf(wi, wo, np.zeros(3), GltfLobe(float(alpha), unit, 1.0))[:, 0] * wo[:, 2]
        scale = np.maximum(basis @ target / max(float(basis @ basis), 1e-30), 0.0)
        residual = float(np.sum((target - basis[:, None] * scale[None, :]) ** 2))
        if best is None or residual < best[0]:
            best = (residual, alpha, scale)
    _, alpha, scale = best
    return _lobe(alpha, scale, float(np.max(scale)))




def mapping_rmse(document: dict, region: str, albedo, grid: int = FIT_GRID) -> dict:
    """How far a region's glTF material is from its fitted BRDF: the relative
    RMSE of f cos θo over the hemisphere grid (every (ωi, ωo) pair of
    :func:`hemisphere_pairs`, RGB), ``sqrt(Σ (F_glTF − F_fit)² / Σ F_fit²)``,
    the fitted BRDF evaluated by its Mitsuba plugin
    (:func:`mifaces.validation.validator.eval_bsdf`), glTF's by :func:`gltf_brdf`;
    ``rmse`` for the whole BRDF (diffuse ``albedo``, RGB, plus lobe) and
    ``rmse_specular`` for the lobes alone (against the fitted lobes' RMS).
    """
    from ..brdf.model import rgb
    from ..render import region_bsdf
    from ..validation.validator import eval_bsdf

    wi, wo = hemisphere_pairs(grid)
    params = document["regions"].get(region, document["regions"]["skin"])
    lobe = gltf_lobe(document["model"], params, region, document.get("options", {}))
    albedo = _rgb(albedo)
    uv = np.zeros((len(wi), 2))
    fit = eval_bsdf(region_bsdf(document, region, rgb(albedo)), uv, wi, wo)
    fit_lobe = eval_bsdf(region_bsdf(document, region, rgb(np.zeros(3))), uv, wi, wo)
    gltf = gltf_brdf(wi, wo, lobe.base_color(albedo), lobe) * wo[:, 2:3]
    gltf_lobe_only = gltf_brdf(wi, wo, np.zeros(3), lobe) * wo[:, 2:3]

    def relative(a, b):
        return float(np.sqrt(np.sum((a - b) ** 2) / max(float(np.sum(b ** 2)), 1e-30)))

    return {"rmse": relative(gltf, fit), "rmse_specular": relative(gltf_lobe_only, fit_lobe),
            "alpha": lobe.alpha, "roughness": lobe.roughness, "f0": lobe.f0.tolist(), "f90": lobe.f90}


__all__ = ["ALPHA_RANGE", "ALPHA_GRID", "GltfLobe", "gltf_lobe", "gltf_brdf", "fit_lafortune", "specular_lobe", "mapping_rmse",
           "hemisphere_pairs"]
