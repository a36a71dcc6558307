"""A skin albedo map for a face model without a colour model (the built-in ICT head).

The simulator needs a true albedo a person would take for skin. This paints
one in the model's texture space from where each texel sits on the mean face
(positions interpolated over the triangles) and the region map:

* skin: a tone drawn between light and dark (linear RGB), with low-frequency
  variation, redder cheeks, nose and ears (more blood near the surface), a
  darker, slightly bluish cast where the beard grows on a man;
* lips: redder and darker than the skin, with a soft edge;
* eyebrows and scalp: hair of one colour in fine strands;
* stubble: dark dots over the beard area on a man;
* eyes: sclera, an iris of a drawn colour with a dark limbal ring, a black
  pupil, placed in 3D around each eye's centre (the mean of its six iBUG
  eyelid points), so the same rule serves any model whose eyes are a region.

All lengths are in mm on the mean face; colours are linear RGB albedos.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi

from ..model.regions import REGIONS, texel_regions_of_mesh
from ..model.texture_space import bake, rasterize

#: Skin albedo at the light and the dark end of the drawn tone (linear RGB).
SKIN_LIGHT = np.array([0.62, 0.44, 0.35])
SKIN_DARK = np.array([0.20, 0.11, 0.07])
#: Lip colour relative to the skin's (multiplied per channel).
LIP_TINT = np.array([0.95, 0.55, 0.58])
#: Hair colours to draw from (linear RGB): black, dark brown, brown, dark blond.
HAIR = np.array([[0.02, 0.017, 0.015], [0.05, 0.03, 0.02], [0.10, 0.06, 0.035], [0.22, 0.15, 0.08]])
#: Iris colours to draw from: brown, hazel, green-grey, blue.
IRIS = np.array([[0.10, 0.05, 0.02], [0.18, 0.12, 0.05], [0.16, 0.18, 0.13], [0.12, 0.17, 0.25]])
SCLERA = np.array([0.70, 0.64, 0.58])
#: Radii on the eye (mm, in the face's plane): pupil, iris, limbal ring.
PUPIL_MM, IRIS_MM, LIMBUS_MM = 1.8, 5.6, 6.2


def _noise(rng, shape, sigma: float) -> np.ndarray:
    n = ndi.gaussian_filter(rng.standard_normal(shape), sigma)
    return n / max(float(n.std()), 1e-12)


def _soft(mask: np.ndarray, sigma: float) -> np.ndarray:
    return np.clip(ndi.gaussian_filter(mask.astype(np.float64), sigma), 0.0, 1.0)


def _bump(positions: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    return np.exp(-np.sum((positions - centre) ** 2, axis=-1) / (2 * radius ** 2))


def paint_skin(model, rng: np.random.Generator, size: int = 1024, male: bool | None = None) -> np.ndarray:
    """A skin albedo map (size, size, 3), linear RGB, for ``model``'s texture space.

    Parameters
    ----------
    model : MorphableModel
        Its mean shape, triangles, uv, region map and iBUG landmarks (eyes, cheeks, nose).
    rng : numpy.random.Generator
        Draws the tone, hair and iris colours, the sex (when ``male`` is None) and the noise.
    size : int
        Texels per side.
    male : bool, optional
        A man's face has stubble and a darker beard area.

    Returns
    -------
    (size, size, 3) float32 array
        Texels no triangle covers take the nearest covered texel's colour.
    """
    raster = rasterize(model.uv, model.triangles, (size, size))
    positions = bake(model.uv, model.triangles, model.shape_mean, size, raster)
    _, (ri, ci) = ndi.distance_transform_edt(~raster.covered, return_indices=True)
    labels = texel_regions_of_mesh(model.region_map, model.uv, model.triangles, size, raster)[ri, ci]
    lm = {i: np.asarray(p, np.float64) for i, p in model.landmark_positions().items()}
    male = bool(rng.random() < 0.5) if male is None else male
    shape = (size, size)
    scale = size / 1024.0

    tone = rng.uniform(0.0, 1.0) ** 1.4
    skin = (1 - tone) * SKIN_LIGHT + tone * SKIN_DARK
    image = np.broadcast_to(skin, shape + (3,)).copy()
    # Blood near the surface: cheeks, nose, ears, lips' surroundings redden; shown as less green and blue.
    red = np.zeros(shape)
    if all(i in lm for i in (2, 16, 31, 49, 55, 37, 46)):
        for eye, corner, jaw in ((37, 49, 2), (46, 55, 16)):
            red += 0.8 * _bump(positions, (lm[eye] + lm[corner] + lm[jaw]) / 3.0, 14.0)
        red += 0.6 * _bump(positions, lm[31], 9.0)
    red += 0.25 * _noise(rng, shape, 40 * scale)
    image *= np.exp(-0.18 * np.clip(red, -1, 2)[..., None] * np.array([0.0, 1.0, 0.8]))
    image *= np.exp(0.07 * _noise(rng, shape, 25 * scale))[..., None]

    hair = HAIR[rng.integers(len(HAIR))]
    strands = np.clip(1.0 + 0.35 * _noise(rng, shape, 0.7 * scale), 0.3, 2.0)[..., None]
    beard = _soft(labels == REGIONS["beard"], 6 * scale)
    if male:
        image *= (1 - 0.25 * beard[..., None] * np.array([1.0, 0.95, 0.85]))
        dots = (_noise(rng, shape, 0.8 * scale) > 1.3) * beard
        image = image * (1 - 0.7 * dots[..., None]) + 0.7 * dots[..., None] * hair * strands
    lips = _soft(labels == REGIONS["lips"], 3 * scale)[..., None]
    image = image * (1 - lips) + lips * image * LIP_TINT
    for region, cover in (("eyebrows", 0.85), ("hair", 0.97)):
        mask = _soft(labels == REGIONS[region], 2 * scale)[..., None] * cover
        image = image * (1 - mask) + mask * hair * strands

    eyes = labels == REGIONS["eyes"]
    if eyes.any() and all(i in lm for i in range(37, 49)):
        iris = IRIS[rng.integers(len(IRIS))] * np.exp(0.25 * _noise(rng, shape, 1.5 * scale))[..., None]
        colour = SCLERA * np.exp(0.05 * _noise(rng, shape, 4 * scale))[..., None]
        for ids in (range(37, 43), range(43, 49)):
            centre = np.mean([lm[i] for i in ids], axis=0)
            near = eyes & (np.sign(positions[..., 0] - 0.0) == np.sign(centre[0]))
            front = positions[..., 2] > centre[2] - 8.0
            r = np.linalg.norm(positions[..., :2] - centre[:2], axis=-1)
            ring = near & front & (r < LIMBUS_MM)
            colour[ring] = 0.4 * iris[ring]
            colour[ring & (r < IRIS_MM)] = iris[ring & (r < IRIS_MM)]
            colour[ring & (r < PUPIL_MM)] = 0.01
        image[eyes] = colour[eyes]
    return np.clip(image, 0.0, 0.95).astype(np.float32)
