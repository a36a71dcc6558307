"""Samples whose pixels mix two regions' light.

A texel along the border between two regions of different reflectance (dark
eyebrows on skin) is read from pixels that show both: the bilinear read takes
the neighbouring pixels, and each pixel integrates its own footprint. Its
sample then carries the neighbour's light, and the fitted albedo map would
outline the region (a bright rim round the eyebrows). Such samples are
dropped (:func:`mifaces.reflectance.resampling.measurement_samples`), and their
texels take their region's local mean
(:data:`mifaces.reflectance.maps.diffuse.FILL_TEXELS`).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

#: A sample is dropped when a pixel this close (pixels, in x and in y) to its
#: projection also sees another region: the bilinear read and the pixel's own
#: footprint mix that region's light into it (:func:`region_mixed`).
MIX_REACH = 1


def region_mixed(xy: np.ndarray, label: np.ndarray, seen: np.ndarray, shape: tuple[int, int],
                 reach: int = MIX_REACH) -> np.ndarray:
    """(N,) bool: the texels whose reading of the photograph mixes in another
    region's light. ``xy`` (N, 2): the texels' projections (pixel centres at
    integers); ``label`` (N,): their regions; ``seen`` (N,): the texels the
    photograph shows (in front, unoccluded, inside it); ``shape``: (H, W).
    A texel is mixed when a pixel within ``reach`` of its nearest pixel (the
    bilinear read's taps and the camera's blur) shows a texel of another region.
    Where two regions' reflectance differs (dark eyebrows on skin) such
    samples carry the neighbour's light (the module docstring)."""
    height, width = shape
    pixel = np.rint(xy).astype(np.int64)
    inside = seen & (pixel[:, 0] >= 0) & (pixel[:, 0] < width) & (pixel[:, 1] >= 0) & (pixel[:, 1] < height)
    mixed = np.zeros(len(xy), bool)
    labels = np.unique(label[inside])
    if len(labels) < 2:
        return mixed
    window = np.ones((2 * reach + 1, 2 * reach + 1), bool)
    near = {}
    for k in labels:
        hit = np.zeros((height, width), bool)
        which = inside & (label == k)
        hit[pixel[which, 1], pixel[which, 0]] = True
        near[k] = scipy.ndimage.binary_dilation(hit, window)
    rows, cols = pixel[inside, 1], pixel[inside, 0]
    own = label[inside]
    other = np.zeros(len(rows), bool)
    for k in labels:
        other |= near[k][rows, cols] & (own != k)
    mixed[inside] = other
    return mixed


__all__ = ["MIX_REACH", "region_mixed"]
