"""A-priori regions of the face in the common parameterization (paper section 4.4, Figure 5).

A *region map* is a label image in texture space (``v = 0`` the top row):
each texel holds the label of one region from a single vocabulary, shared by
all models, so that "the lips" mean the same to every stage of mifaces.
Texels the face does not cover hold ``background``. Because the map lives in
the common parameterization, the same map applies to every face of a model
automatically.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import skimage.draw

from .texture_space import rasterize

#: The region vocabulary: name -> label value in a region map.
REGIONS: dict[str, int] = {
    "background": 0,
    "skin": 1,
    "lips": 2,
    "eyes": 3,
    "eyebrows": 4,
    "nostrils": 5,
    "beard": 6,
    "hair": 7,
}
#: label value -> name.
REGION_NAMES: tuple[str, ...] = tuple(sorted(REGIONS, key=REGIONS.get))
#: The region whose parameters a region without its own takes (one nothing was fitted to, or the
#: background's texels a render still shades).
FALLBACK_REGION = "skin"

#: iBUG 68-point indices (1-based) of the features used to outline regions.
IBUG_EYEBROWS = (tuple(range(18, 23)), tuple(range(23, 28)))
IBUG_EYES = (tuple(range(37, 43)), tuple(range(43, 49)))
IBUG_OUTER_LIPS = tuple(range(49, 61))
IBUG_NOSE_BASE = tuple(range(32, 37))
IBUG_NOSE_TIP = 31


def label(name: str) -> int:
    """The label value of region ``name``; raises with the vocabulary if unknown."""
    try:
        return REGIONS[name]
    except KeyError:
        raise ValueError(f"unknown region {name!r}; the vocabulary is {list(REGIONS)}") from None


def region_entry(table: Mapping, region: str):
    """``table[region]`` (a ``brdf.json``'s ``regions``, or any table by region name), or
    :data:`FALLBACK_REGION`'s where ``region`` has no entry."""
    return table[region] if region in table else table[FALLBACK_REGION]


def region_name(label: int) -> str:
    """The region a texel or triangle of ``label`` is shaded as: its name, :data:`FALLBACK_REGION` for
    the background or a label outside the vocabulary."""
    name = REGION_NAMES[label] if 0 <= label < len(REGION_NAMES) else FALLBACK_REGION
    return FALLBACK_REGION if name == "background" else name


def regions_present(region_map: np.ndarray) -> list[str]:
    """Names of the regions (other than background) that occur in ``region_map``."""
    used = np.unique(np.asarray(region_map))
    return [REGION_NAMES[i] for i in used if 0 < i < len(REGION_NAMES)]


def lookup(region_map: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Region label at texture coordinates ``uv`` (M, 2), nearest texel."""
    region_map = np.asarray(region_map)
    h, w = region_map.shape
    uv = np.asarray(uv, dtype=np.float64)
    col = np.clip((uv[:, 0] * w).astype(np.int64), 0, w - 1)
    row = np.clip((uv[:, 1] * h).astype(np.int64), 0, h - 1)
    return region_map[row, col]


def _fill_polygon(image: np.ndarray, value: int, uv_points: np.ndarray, where: np.ndarray) -> None:
    h, w = image.shape
    rows, cols = skimage.draw.polygon(uv_points[:, 1] * h - 0.5, uv_points[:, 0] * w - 0.5, shape=(h, w))
    keep = where[rows, cols]
    image[rows[keep], cols[keep]] = value


def region_map_from_landmarks(uv: np.ndarray, triangles: np.ndarray, landmarks: Mapping[int, int],
                              shape: tuple[int, int] = (512, 512)) -> np.ndarray:
    """Derive a region map from iBUG 68-point landmarks in texture space.

    Regions are polygons through the landmarks' texture coordinates: the eyes
    inside the eyelid contours (37-42, 43-48), the lips inside the outer lip
    contour (49-60), each eyebrow a band around its landmark line (18-22,
    23-27) a third of the brow-to-upper-lid distance thick, and each nostril
    an ellipse between the nose-base landmarks (32-36) set towards the nose
    tip (31). Everything else the mesh covers is ``skin``; texels it does not
    cover are ``background``. Regions whose landmarks the model lacks are left
    out.

    Parameters
    ----------
    uv : (N, 2) array
        Per-vertex texture coordinates.
    triangles : (T, 3) int array
    landmarks : mapping
        iBUG index (1-based) -> vertex index (0-based).
    shape : (int, int)
        ``(height, width)`` of the region map.

    Returns
    -------
    (H, W) uint8 array of labels from :data:`REGIONS`.
    """
    uv = np.asarray(uv, dtype=np.float64)
    covered = rasterize(uv, triangles, shape).covered
    image = np.where(covered, REGIONS["skin"], REGIONS["background"]).astype(np.uint8)
    lm = {int(k): uv[int(v)] for k, v in landmarks.items()}

    def have(ids):
        return all(i in lm for i in ids)

    def pts(ids):
        return np.array([lm[i] for i in ids])

    for brow, eye in zip(IBUG_EYEBROWS, IBUG_EYES):
        if have(brow) and have(eye[1:3]):
            line = pts(brow)
            gap = np.mean(pts(eye[1:3])[:, 1]) - np.mean(line[:, 1])
            half = np.abs(gap) / 6.0
            # Thicker at the inner end, tapering outwards (towards landmark 18 or 27).
            taper = np.linspace(0.6, 1.2, len(line)) if brow[0] == 18 else np.linspace(1.2, 0.6, len(line))
            offset = np.stack([np.zeros(len(line)), half * taper], axis=1)
            _fill_polygon(image, REGIONS["eyebrows"], np.concatenate([line - offset, (line + offset)[::-1]]),
                          covered)
    for eye in IBUG_EYES:
        if have(eye):
            _fill_polygon(image, REGIONS["eyes"], pts(eye), covered)
    if have(IBUG_OUTER_LIPS):
        _fill_polygon(image, REGIONS["lips"], pts(IBUG_OUTER_LIPS), covered)
    if have(IBUG_NOSE_BASE) and IBUG_NOSE_TIP in lm:
        base = pts(IBUG_NOSE_BASE)
        up = lm[IBUG_NOSE_TIP] - base[2]  # from subnasale towards the tip
        for a, b in ((0, 1), (4, 3)):  # alar base -> columella side
            centre = 0.5 * (base[a] + base[b]) + 0.2 * up
            ru = 0.55 * np.linalg.norm(base[a] - base[b])
            rv = 0.22 * np.linalg.norm(up)
            angle = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
            ellipse = centre + np.stack([ru * np.cos(angle), rv * np.sin(angle)], axis=1)
            _fill_polygon(image, REGIONS["nostrils"], ellipse, covered)
    return image


def texel_regions(region_map: np.ndarray, resolution: int) -> np.ndarray:
    """The region map resampled to an R × R texture (nearest label at each
    texel centre ((col + ½)/R, (row + ½)/R)), for labelling reflectance
    samples by their flat texel index row · R + col."""
    centres = (np.arange(resolution) + 0.5) / resolution
    u, v = np.meshgrid(centres, centres)
    return lookup(region_map, np.stack([u.ravel(), v.ravel()], axis=1)).reshape(resolution, resolution)


def triangle_regions(region_map: np.ndarray, uv: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Region label of each triangle: the region map at its uv centroid. The
    rendered face (the simulator, ``fit-brdf``'s scene) gives each triangle
    the material of its region."""
    return lookup(region_map, np.asarray(uv)[np.asarray(triangles)].mean(axis=1))


def texel_regions_of_mesh(region_map: np.ndarray, uv: np.ndarray, triangles: np.ndarray, resolution: int,
                          raster=None) -> np.ndarray:
    """Like :func:`texel_regions`, but each texel a triangle covers takes that
    triangle's label (:func:`triangle_regions`), so samples are grouped exactly
    as the rendered face assigns materials; uncovered texels keep the map's
    label. ``raster``: the mesh's :func:`rasterize` at that resolution, if at hand."""
    labels = texel_regions(region_map, resolution)
    raster = rasterize(uv, triangles, (resolution, resolution)) if raster is None else raster
    covered = raster.triangle >= 0
    labels[covered] = triangle_regions(region_map, uv, triangles)[raster.triangle[covered]]
    return labels
