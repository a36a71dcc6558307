"""How close a region's glTF material is to its fitted BRDF.

Each model maps its parameters onto glTF's lobe itself
(:meth:`mifaces.brdf.model.BRDFModel.gltf_lobe`; glTF's model and the lobe:
:mod:`mifaces.brdf.gltf_lobe`). :func:`mapping_rmse` measures what the
mapping loses; ``validation/export.py`` reports it per model and region,
``docs/export.md`` summarises it.
"""

from __future__ import annotations

import numpy as np

from ..brdf import model as brdf_model
from ..brdf.gltf_lobe import FIT_GRID, gltf_brdf
from ..brdf.hemisphere import hemisphere_pairs
from ..brdf.parameter import rgb
from ..model.regions import region_entry
from ..render import region_bsdf
from ..validation.brdf_error import eval_bsdf


def mapping_rmse(document: dict, region: str, albedo, grid: int = FIT_GRID) -> dict:
    """How far a region's glTF material is from its fitted BRDF: the relative
    RMSE of f cos θo over the hemisphere grid (every (ωi, ωo) pair of
    :func:`~mifaces.brdf.hemisphere.hemisphere_pairs`, RGB), ``sqrt(Σ (F_glTF − F_fit)² / Σ F_fit²)``,
    the fitted BRDF (a ``brdf.json`` document) evaluated by its Mitsuba plugin
    (:func:`mifaces.validation.brdf_error.eval_bsdf`), glTF's by
    :func:`~mifaces.brdf.gltf_lobe.gltf_brdf`; ``rmse`` for the whole BRDF (diffuse
    ``albedo``, RGB, plus lobe) and ``rmse_specular`` for the lobes alone (against the fitted
    lobes' RMS).
    """
    wi, wo = hemisphere_pairs(grid)
    params = region_entry(document["regions"], region)
    brdf = brdf_model(document["model"], **document.get("options", {}))
    lobe = brdf.gltf_lobe(brdf.region_values(params, region))
    albedo = np.broadcast_to(np.asarray(albedo, np.float64), 3).copy()
    uv = np.zeros((len(wi), 2))
    fit = eval_bsdf(region_bsdf(document, region, rgb(albedo)), uv, wi, wo)
    fit_lobe = eval_bsdf(region_bsdf(document, region, rgb(np.zeros(3))), uv, wi, wo)
    gltf = gltf_brdf(wi, wo, lobe.base_color(albedo), lobe) * wo[:, 2:3]
    gltf_lobe_only = gltf_brdf(wi, wo, np.zeros(3), lobe) * wo[:, 2:3]

    def relative(a, b):
        return float(np.sqrt(np.sum((a - b) ** 2) / max(float(np.sum(b ** 2)), 1e-30)))

    return {"rmse": relative(gltf, fit), "rmse_specular": relative(gltf_lobe_only, fit_lobe),
            "alpha": lobe.alpha, "roughness": lobe.roughness, "f0": lobe.f0.tolist(), "f90": lobe.f90}


__all__ = ["FIT_GRID", "mapping_rmse"]
