"""High dynamic range: exposure series to linear radiance, and the white target's scale.

The paper takes, at each pose, either a diffuse-light picture or "a set of
pictures with varying exposure" (Fuchs et al. 2005, sec. 3), merged into one
image of extended dynamic range. With the camera's transfer curve inverted
(8-bit sRGB decoded with colour-science), a pixel of exposure t_k reads
v_k = t_k L + noise, clipped at full scale. The merge is the weighted mean of
the per-exposure estimates v_k / t_k (Debevec & Malik, "Recovering high
dynamic range radiance maps from photographs", SIGGRAPH 1997, eq. 6, with the
response already linearised):

    L = Σ_k w_k v_k / t_k / Σ_k w_k,   w_k = t_k · h(v_k)

t_k is the inverse-variance weight of v_k / t_k under photon noise (variance
of v_k proportional to t_k L); h is 1 inside the usable range and falls
linearly to 0 over the last ``ramp`` below the saturation level; pixels
flagged saturated, at or above ``saturation``, or below ``dark`` get weight 0.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Sequence

import numpy as np


def decode_srgb(codes: np.ndarray) -> np.ndarray:
    """8- or 16-bit sRGB codes (or floats in [0, 1]) to linear values in [0, 1].

    Uses colour-science's ``cctf_decoding`` (IEC 61966-2-1:1999); integer
    codes go through a table of its values for every code.
    """
    codes = np.asarray(codes)
    if codes.dtype in (np.uint8, np.uint16):
        return _srgb_table(codes.dtype.str)[codes]
    if np.issubdtype(codes.dtype, np.integer):
        raise ValueError(f"sRGB codes must be 8 or 16 bit (uint8, uint16) or floats, got {codes.dtype}")
    return _decode_srgb(codes)


def _decode_srgb(values) -> np.ndarray:
    import colour  # colour-science takes most of a second to import: only where sRGB is decoded

    return np.asarray(colour.cctf_decoding(np.clip(np.asarray(values, np.float64), 0.0, 1.0), function="sRGB"),
                      np.float32)


@functools.lru_cache(maxsize=None)
def _srgb_table(dtype: str) -> np.ndarray:
    top = np.iinfo(np.dtype(dtype)).max
    table = _decode_srgb(np.arange(top + 1) / top)
    table.flags.writeable = False
    return table


@dataclass(frozen=True, eq=False)
class HDRImage:
    """A merged exposure series.

    Attributes
    ----------
    radiance : (H, W, 3) float32
        Linear radiance per unit exposure.
    valid : (H, W) bool
        Pixels where at least one exposure was usable in every channel.
    weight : (H, W, 3) float32
        Sum of the weights (a relative confidence).
    """

    radiance: np.ndarray
    valid: np.ndarray
    weight: np.ndarray


def merge_exposures(values: Sequence[np.ndarray], exposures: Sequence[float], saturated=None,
                    dark: float = 2.0 / 255.0, saturation: float = 0.98, ramp: float = 0.1) -> HDRImage:
    """Merge linear pictures of one scene taken with different exposures.

    Parameters
    ----------
    values : sequence of (H, W, 3) arrays
        Linear pixel values in [0, 1] (full scale 1), **not** divided by the exposure.
    exposures : sequence of float
        Relative exposure t_k of each picture (time x gain).
    saturated : sequence of (H, W) bool arrays, optional
        Pixels known to be clipped (e.g. at the largest code of an 8-bit file).
    dark, saturation : float
        Values below ``dark`` or at/above ``saturation`` are not used.
    ramp : float
        Width of the linear fall-off of the weight below ``saturation``.

    Returns
    -------
    HDRImage
        Pixels no exposure could measure take the value of the shortest
        exposure if they are saturated everywhere, of the longest if they
        are dark everywhere, and are marked invalid.
    """
    if len(values) != len(exposures) or len(values) == 0:
        raise ValueError(f"values and exposures must be non-empty and of equal length, "
                         f"got {len(values)} and {len(exposures)}")
    t = np.asarray(exposures, np.float64)
    if np.any(~(t > 0)):
        raise ValueError(f"exposures must be positive, got {list(exposures)}")
    stack = np.stack([np.asarray(v, np.float64) for v in values])
    if stack.ndim == 3:
        stack = stack[..., None]
    shape = stack.shape[1:]
    if saturated is None:
        clipped = np.zeros(stack.shape[:3], bool)
    else:
        clipped = np.stack([np.asarray(s, bool) for s in saturated])
        if clipped.shape != stack.shape[:3]:
            raise ValueError(f"saturated masks must have shape {stack.shape[1:3]}, got {clipped.shape[1:]}")
    hat = np.clip((saturation - stack) / ramp, 0.0, 1.0)
    usable = (stack >= dark) & (stack < saturation) & ~clipped[..., None]
    w = t[:, None, None, None] * hat * usable
    estimates = stack / t[:, None, None, None]
    total = w.sum(axis=0)
    radiance = np.where(total > 0, (w * estimates).sum(axis=0) / np.where(total > 0, total, 1.0), np.nan)
    shortest, longest = np.argmin(t), np.argmax(t)
    too_bright = np.isnan(radiance) & (stack[shortest] >= dark)
    radiance = np.where(too_bright, estimates[shortest], radiance)
    radiance = np.where(np.isnan(radiance), estimates[longest], radiance)
    valid = np.all(total > 0, axis=-1)
    return HDRImage(radiance.astype(np.float32).reshape(shape), valid, total.astype(np.float32).reshape(shape))


def merge_series(images) -> HDRImage:
    """Merge the :class:`mifaces.capture.Image` pictures of an exposure series
    (``Measurement.exposures``): their pixels are per unit exposure already,
    their ``saturated`` masks say which were clipped."""
    images = list(images)
    if len(images) < 2:
        raise ValueError(f"an exposure series needs at least two pictures, got {len(images)}")
    values = [im.pixels.astype(np.float64) * im.exposure for im in images]
    return merge_exposures(values, [im.exposure for im in images], [im.saturated for im in images])


def scale_to_white(image: np.ndarray, white_value, reflectance: float = 1.0) -> np.ndarray:
    """Scale a linear image so the white target reads its reflectance.

    ``white_value`` is the target's linear RGB value in the same units as
    ``image`` (a picture of it under the same light and exposure). Each
    channel is divided by it and multiplied by ``reflectance`` (1 for an
    ideal white), which also white-balances the image.
    """
    white = np.asarray(white_value, np.float64)
    if np.any(~(white > 0)):
        raise ValueError(f"white_value must be positive, got {white_value!r}")
    return (np.asarray(image, np.float64) * (reflectance / white)).astype(np.float32)
