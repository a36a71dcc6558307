"""Reflectance samples: radiance turned into reflectance, with confidence
(paper sec. 4.3 and 5.1).

A reflectance sample (eq. 5) is ((l̂, v̂), r, σ): unit light and view
directions in the local shading frame, the reflectance r (RGB) and the
confidence scale σ (the fit weights a sample by 1/σ²).

**Eq. 4, the reading implemented.** The paper prints
r = R / (|l̂·n| ‖l‖²), dividing by the squared light distance. A point light
of intensity I at distance d gives the irradiance E = I cos θl / d², and the
BRDF is f = R / E, so the physical relation multiplies by d²:

    r = s · R · d² / (I · cos θl),

which is what :func:`reflectance` computes. The scale s makes a white
Lambertian target (f = 1/π) have r = 1, as the paper requires: s = π when
R and I are in consistent physical units, or the value the capture's white
target calibration gives. So r = π f for every model, and the fitters
compare r with π f(l̂, v̂).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

#: Samples seen or lit at cos θ below this are dropped (θ > 80°).
MIN_COSINE = np.cos(np.radians(80.0))
#: Eq. 10's d_max at the paper's texture resolution of 1000².
D_MAX_AT_1000 = 10.0


def reflectance(radiance, light_distance, intensity, cos_light, scale: float = np.pi):
    """r = scale · R · d² / (I cos θl), the physical reading of eq. 4.

    Parameters
    ----------
    radiance : array (..., 3)
        Observed radiance R.
    light_distance : array (...)
        Distance d from the surface point to the light.
    intensity : array (3,) or (..., 3)
        Radiant intensity I of the point light.
    cos_light : array (...)
        cos θl = l̂ · n (> 0 where used; other samples are invalid).
    scale : float
        π for physical units (a white Lambertian target gives 1).

    Returns
    -------
    ndarray (..., 3)
        Reflectance; NaN where cos θl <= 0.
    """
    radiance = np.asarray(radiance, np.float64)
    d2 = np.square(np.asarray(light_distance, np.float64))[..., None]
    cos_light = np.asarray(cos_light, np.float64)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = scale * radiance * d2 / (np.asarray(intensity, np.float64) * cos_light)
    return np.where(cos_light > 0, r, np.nan)


def confidence(light_z, view_z):
    """σ = 1 / (l_z² v_z), eq. 9 (l_z = cos θl, v_z = cos θv, both > 0)."""
    light_z, view_z = np.asarray(light_z, np.float64), np.asarray(view_z, np.float64)
    return 1.0 / (np.square(light_z) * view_z)


def d_max(resolution: int) -> float:
    """Eq. 10's d_max in texels at texture resolution ``resolution``: the
    paper's 10 texels at 1000², scaled with the resolution."""
    return D_MAX_AT_1000 * resolution / 1000.0


def distance_to_missing(valid: np.ndarray) -> np.ndarray:
    """Euclidean distance in texels from each valid texel to the nearest
    texel without a sample (0 on invalid texels). Texels outside the image
    count as missing."""
    valid = np.asarray(valid, bool)
    padded = np.pad(valid, 1, constant_values=False)
    return scipy.ndimage.distance_transform_edt(padded)[1:-1, 1:-1]


def confidence_with_distance(light_z, view_z, distance, dmax):
    """σ = d_max / (min(d, d_max) · l_z² · v_z), eq. 10."""
    distance = np.asarray(distance, np.float64)
    with np.errstate(divide="ignore"):
        return dmax / (np.minimum(distance, dmax) * np.square(light_z) * np.asarray(view_z, np.float64))


def unsaturated(pixels, saturation: float = 1.0, margin: float = 0.98):
    """Pixels whose every channel stays below ``margin · saturation``: a
    clipped channel no longer measures the radiance, so its sample is
    dropped rather than fitted. ``pixels`` is (..., 3) in the camera's
    linear units, ``saturation`` the level at which the sensor clips."""
    return np.all(np.asarray(pixels) < margin * saturation, axis=-1)


def valid_samples(light_z, view_z, lit, visible, erosion: int = 1, min_cosine: float = MIN_COSINE):
    """Texels that give a usable sample (sec. 4.3).

    A texel is kept where it is visible from the camera, not in cast shadow,
    and neither seen nor lit at a grazing angle (cos θ >= ``min_cosine``);
    the mask is then eroded by ``erosion`` texels so that samples along
    shadow borders and occluding contours are dropped too.

    Parameters
    ----------
    light_z, view_z : ndarray (R, R)
        cos θl and cos θv per texel.
    lit, visible : ndarray (R, R) of bool
        Not in cast shadow; seen by the camera.
    """
    import skimage.morphology

    light_z, view_z = np.asarray(light_z), np.asarray(view_z)
    with np.errstate(invalid="ignore"):
        mask = np.asarray(lit, bool) & np.asarray(visible, bool) & (light_z >= min_cosine) & (view_z >= min_cosine)
    if erosion > 0:
        mask = skimage.morphology.erosion(mask, skimage.morphology.disk(erosion))
    return mask
