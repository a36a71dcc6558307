"""Region parameters blended across region borders: no render shows a region's outline.

A fitted face has one set of glossy parameters per region (paper sec. 5).
Rendered as they are, two neighbouring regions whose fits differ meet in a
step of gloss along their common border: the outline of the region map,
which no face has. A fitted ``brdf.json`` therefore carries
``region_blend_mm`` (:data:`BLEND_MM`): in its renders each parameter that
differs between regions is a texture in the model's texture space in which
every texel holds its region's value, smoothed by a Gaussian whose 10–90 %
rise is that many millimetres on the face. Texels further than about
:data:`BLEND_MM` from a border keep their region's value; the fit and the
``regions`` of ``brdf.json`` are unchanged.

A document without ``region_blend_mm`` (a ground truth, whose regions do
meet in steps, or an older fit) renders with hard borders, as before.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import scipy.ndimage as ndi

from .. import brdf as brdf_models
from ..model.regions import region_entry
from ..model.texture_space import rasterize
from ..runtime.memo import ContentCache

#: The distance on the face (mm) over which a region's parameters turn into
#: its neighbour's, from 10 % to 90 % of the step: "a few millimetres".
BLEND_MM = 4.0
#: The 10–90 % rise of a Gaussian-blurred step in standard deviations (2 × 1.2816).
_RISE_SD = 2.5631
#: The document key that asks for blending (mm; 0 or absent: hard borders).
BLEND_KEY = "region_blend_mm"


def blend_width(brdf: Mapping) -> float:
    """The document's blend width (mm); 0 for hard borders. A ``ValueError`` for a
    negative or non-finite one."""
    width = float(brdf.get(BLEND_KEY, 0.0) or 0.0)
    if not np.isfinite(width) or width < 0:
        raise ValueError(f"{BLEND_KEY} must be a finite number of millimetres >= 0, got {brdf.get(BLEND_KEY)!r}")
    return width


def hard_borders(brdf: Mapping) -> dict:
    """``brdf`` without its blend width: rendered with each region's own values up to its
    border (the refinement, which moves each region's values, renders so)."""
    return {k: v for k, v in brdf.items() if k != BLEND_KEY}


def blended_parameters(brdf: Mapping, regions, *, exclude=()) -> list[str]:
    """The glossy parameters of ``brdf`` (the ``brdf.json`` layout) that differ
    between the ``regions`` a face shows (names; a region without an entry takes
    :func:`~mifaces.model.regions.region_entry`'s fallback), in the model's order: the ones a render takes as blended
    textures. Empty when the document does not ask for blending; ``exclude``:
    parameters that already have a map of their own (a per-texel specular map)."""
    if blend_width(brdf) == 0:
        return []
    model = brdf_models.bsdf(brdf["model"], **brdf.get("options", {}))
    table = brdf["regions"]
    values = [region_entry(table, r) for r in sorted(set(regions))]
    out = []
    for p in model.specular_parameters():
        if p.name in exclude:
            continue
        distinct = {tuple(np.atleast_1d(np.asarray(v[p.name], np.float64)).tolist()) for v in values}
        if len(distinct) > 1:
            out.append(p.name)
    return out


def region_maps(brdf: Mapping, meshes: Mapping, size: int, *, exclude=()) -> dict[str, np.ndarray]:
    """Each of :func:`blended_parameters` as a (size, size, 3) float32 texture
    (RGB parameters in colour, scalars repeated in every channel) in the
    texture space of the face's region ``meshes``
    (:class:`~mifaces.render.meshes.RegionMesh` values, as
    :class:`~mifaces.render.FaceScene` holds them): each texel its region's
    value, as the meshes assign materials, then smoothed over
    ``brdf["region_blend_mm"]`` on this face (its millimetres per texel from
    the meshes' areas). Texels no triangle covers take the nearest covered
    texel's value first, so that the smoothing never mixes in a value no
    region has."""
    names = blended_parameters(brdf, [m.region for m in meshes.values()], exclude=exclude)
    if not names:
        return {}
    model = brdf_models.bsdf(brdf["model"], **brdf.get("options", {}))
    kinds = {p.name: p.kind for p in model.specular_parameters()}
    table = brdf["regions"]
    parts = list(meshes.values())
    weights = _blurred_parts(meshes, size, blend_width(brdf))
    out = {}
    for name in names:
        values = np.array([np.broadcast_to(np.asarray(region_entry(table, m.region)[name], np.float64), 3)
                           for m in parts])
        out[name] = (weights.reshape(len(parts), -1).T @ values.astype(np.float32)).reshape(size, size, 3)
        if kinds[name] != "rgb":
            out[name] = np.repeat(out[name][..., :1], 3, axis=2)
    return out


#: How many faces' blurred region masks :func:`region_maps` keeps (a face's masks at 512² are 7 MB; one per
#: pose of a capture, so that each round of the bounced light renders every pose without smoothing again).
MASK_CACHE_SIZE = 8
_MASKS = ContentCache(MASK_CACHE_SIZE)


def _blurred_parts(meshes: Mapping, size: int, width_mm: float) -> np.ndarray:
    """(P, size, size): for each of the ``meshes`` (in order), the texels it owns
    (:func:`texel_parts`) as a mask, smoothed over ``width_mm`` on this face. A region's values
    blended over the face are the sum of its values times its mask (the smoothing is linear);
    kept by the meshes' content, so that every render of one face smooths once."""
    parts = list(meshes.values())
    key = [size, width_mm] + [a for m in parts for a in (m.vertices, m.uv, m.triangles)]

    def masks():
        part = texel_parts(meshes, size)
        sigma = width_mm / _RISE_SD / _mm_per_texel(parts, size)
        return np.stack([ndi.gaussian_filter((part == i).astype(np.float64), sigma=sigma, mode="nearest")
                         for i in range(len(parts))]).astype(np.float32)

    return _MASKS.get(key, masks)


def texel_parts(meshes: Mapping, size: int) -> np.ndarray:
    """(size, size) int: for each texel of the texture space, the index (in the order of
    ``meshes``) of the mesh whose triangle covers it; texels no triangle covers take the
    nearest covered texel's. Row 0 is v = 0, as :func:`~mifaces.model.texture_space.rasterize`
    lays it out."""
    parts = list(meshes.values())
    uv = np.concatenate([m.uv for m in parts]).astype(np.float64)
    offsets = np.cumsum([0] + [len(m.uv) for m in parts])[:-1]
    triangles = np.concatenate([m.triangles + o for m, o in zip(parts, offsets)])
    owner = np.concatenate([np.full(len(m.triangles), i) for i, m in enumerate(parts)])
    raster = rasterize(uv, triangles, (size, size))
    covered = raster.triangle >= 0
    if not covered.any():
        raise ValueError("the face's meshes cover no texel of its texture space")
    part = np.zeros((size, size), np.int64)
    part[covered] = owner[raster.triangle[covered]]
    _, (ri, ci) = ndi.distance_transform_edt(~covered, return_indices=True)
    return part[ri, ci]


def _mm_per_texel(parts, size: int) -> float:
    """The length on the face (mm) of one texel's side where most texels are: the median,
    over the texels, of their triangle's square root of its area over its area in
    texture space (a mean would count the sparse texels of the neck and the back of
    the head as much as the face's dense ones)."""
    scale, weight = [], []
    for m in parts:
        points, uv, tri = np.asarray(m.vertices, np.float64), np.asarray(m.uv, np.float64), m.triangles
        a, b, c = (points[tri[:, k]] for k in range(3))
        surface = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=-1)
        a, b, c = (uv[tri[:, k]] for k in range(3))
        u, v = b - a, c - a
        texture = 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        ok = texture > 0
        scale.append(np.sqrt(surface[ok] / texture[ok]))
        weight.append(texture[ok])
    scale, weight = np.concatenate(scale), np.concatenate(weight)
    order = np.argsort(scale)
    cumulative = np.cumsum(weight[order])
    return float(scale[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])]) / size


__all__ = ["BLEND_MM", "BLEND_KEY", "blend_width", "hard_borders", "blended_parameters", "region_maps", "texel_parts"]
