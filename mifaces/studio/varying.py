"""A spatially varying ground truth: per-texel specular scale and roughness maps.

Skin is not one material: sebum makes the T-zone (forehead and nose)
shinier and smoother than the drier cheeks (Weyrich et al. 2006 measured
per-region Torrance–Sparrow parameters over 149 faces: the forehead and
nose have a stronger, narrower specular lobe than the cheeks and chin).
:func:`varying_maps` makes, in the model's texture space and with the
albedo map's size, a map of the specular lobe's scale and one of its width
(Cook–Torrance ``roughness``, Ward ``alpha``): per region the published
value (:data:`mifaces.studio.truth.COOK_TORRANCE_REGIONS`), and on the skin
that value times a smooth T-zone and cheek modulation and a low-frequency
log-normal texture (:data:`MODULATION`).

The maps are rendered as bitmap textures on the plugin's parameters
(:func:`mifaces.render.region_bsdf`'s ``maps``); the ground truth keeps
them (``ground_truth/maps/<parameter>.exr``) and gives each region the
mean of its texels in ``brdf.json``.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np
import scipy.ndimage as ndi

from ..model.landmarks import FEATURE_POINTS
from ..model.regions import REGIONS, texel_regions_of_mesh
from ..model.texture_space import rasterize

#: Models that take maps: model -> (lobe-scale parameter, lobe-width parameter).
VARYING = {"cooktorrance": ("specular_reflectance", "roughness"), "ward": ("specular_reflectance", "alpha")}
#: Relative change of the lobe scale and width at full T-zone / cheek weight,
#: and the standard deviation (log units) and correlation length (mm) of the texture on top.
MODULATION = {"scale_tzone": 0.6, "scale_cheeks": -0.35, "width_tzone": -0.3, "width_cheeks": 0.25,
              "texture_log_sd": 0.06, "texture_mm": 6.0}
#: Width (mm) of the soft edges of the T-zone and of the cheeks' Gaussian.
EDGE_MM = 6.0
CHEEK_RADIUS_MM = 20.0


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(x / EDGE_MM))


def zone_weights(face_model, neutral: np.ndarray, raster) -> tuple[np.ndarray, np.ndarray]:
    """T-zone and cheek weights in [0, 1] per texel (size, size) of
    ``face_model``'s texture space (its rasterization ``raster`` by
    :func:`mifaces.model.texture_space.rasterize`), from the texels' positions on the
    ``neutral`` face (model frame: x across, y up, mm) relative to its
    eyebrows, eyes and nose tip. Texels no triangle covers take the
    nearest covered texel's weights."""
    size = raster.covered.shape[0]
    tri = face_model.triangles[raster.triangle[raster.covered]]
    points = np.einsum("nk,nkc->nc", raster.barycentric[raster.covered], neutral[tri].astype(np.float64))
    lm = face_model.landmark_positions(neutral)
    at = lambda name: np.asarray(lm[FEATURE_POINTS[name]], np.float64)  # noqa: E731
    brows = np.mean([at(n) for n in ("right_eyebrow_outer", "right_eyebrow_inner", "left_eyebrow_inner",
                                     "left_eyebrow_outer")], axis=0)
    eyes = np.mean([at(n) for n in ("right_eye_outer", "left_eye_outer")], axis=0)
    half_width = 0.5 * abs(at("left_eye_outer")[0] - at("right_eye_outer")[0])
    tip, bridge = at("nose_tip"), at("nose_bridge")
    x, y = points[:, 0] - bridge[0], points[:, 1]
    forehead = _sigmoid(y - brows[1] - 4.0) * _sigmoid(half_width - np.abs(x))
    nose = _sigmoid(12.0 - np.abs(x)) * _sigmoid(y - tip[1] + 6.0) * _sigmoid(brows[1] + 4.0 - y)
    tzone = np.maximum(forehead, nose)
    cheek_y = 0.5 * (eyes[1] + tip[1]) - 5.0
    cheeks = np.exp(-((np.abs(x) - 0.85 * half_width) ** 2 + (y - cheek_y) ** 2) / (2 * CHEEK_RADIUS_MM ** 2))
    out = []
    for values in (tzone, cheeks):
        image = np.zeros((size, size))
        image[raster.covered] = values
        out.append(image)
    _, (ri, ci) = ndi.distance_transform_edt(~raster.covered, return_indices=True)
    return out[0][ri, ci], out[1][ri, ci]


def texel_regions(face_model, size: int, raster=None) -> np.ndarray:
    """Region label per texel (size, size), as the rendered face assigns materials
    (:func:`mifaces.model.regions.texel_regions_of_mesh`; ``raster`` the mesh's rasterization
    if at hand), background counted as skin."""
    labels = texel_regions_of_mesh(face_model.region_map, face_model.uv, face_model.triangles, size,
                                   raster).astype(np.int32)
    return np.where(labels == REGIONS["background"], REGIONS["skin"], labels)


def varying_maps(face_model, neutral: np.ndarray, truth: dict, rng: np.random.Generator, size: int
                 ) -> dict[str, np.ndarray]:
    """Lobe-scale and lobe-width maps (size, size) float32 of the
    ``truth`` (``brdf.json`` layout, model in :data:`VARYING`): per region
    its value, on the skin modulated as the module docstring says."""
    if truth["model"] not in VARYING:
        raise ValueError(f"a spatially varying ground truth takes a model with a lobe scale and width map: "
                         f"{sorted(VARYING)}; got {truth['model']!r}")
    scale_name, width_name = VARYING[truth["model"]]
    raster = rasterize(face_model.uv, face_model.triangles, (size, size))
    labels = texel_regions(face_model, size, raster)
    tzone, cheeks = zone_weights(face_model, neutral, raster)
    mm_per_texel = (neutral.max(axis=0)[0] - neutral.min(axis=0)[0]) / size  # roughly: the face spans the map
    texture = [ndi.gaussian_filter(rng.standard_normal((size, size)), MODULATION["texture_mm"] / mm_per_texel)
               for _ in range(2)]
    texture = [MODULATION["texture_log_sd"] * t / max(t.std(), 1e-12) for t in texture]
    skin = labels == REGIONS["skin"]
    maps = {}
    for name, key, noise in ((scale_name, "scale", texture[0]), (width_name, "width", texture[1])):
        base = np.zeros((size, size))
        for region, label in REGIONS.items():
            if region in truth["regions"]:
                base[labels == label] = float(np.mean(truth["regions"][region][name]))
        factor = (1.0 + MODULATION[f"{key}_tzone"] * tzone + MODULATION[f"{key}_cheeks"] * cheeks) * np.exp(noise)
        maps[name] = np.where(skin, base * factor, base).astype(np.float32)
    return maps


def region_means(face_model, maps: dict[str, np.ndarray], truth: dict, digits: dict) -> dict:
    """``truth`` with each region's map parameters replaced by the mean of
    the maps over the region's texels (rounded to ``digits``): the region
    values a per-region fit is compared with."""
    out = {**truth, "regions": {k: dict(v) for k, v in truth["regions"].items()}}
    labels = texel_regions(face_model, next(iter(maps.values())).shape[0]) if maps else None
    for name, image in maps.items():
        for region, params in out["regions"].items():
            texels = labels == REGIONS[region]
            if not texels.any() or name not in params:
                continue
            mean = float(image[texels].mean())
            params[name] = [round(mean, digits["rgb"])] * 3 if isinstance(params[name], list) \
                else round(mean, digits["float"])
    return out


def map_textures(maps: dict[str, np.ndarray]) -> dict:
    """The maps as Mitsuba bitmap textures (raw values, bilinear, clamped), as the albedo map's."""
    return {name: mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(image[..., None])),
                                "raw": True, "filter_type": "bilinear", "wrap_mode": "clamp"})
            for name, image in maps.items()}
