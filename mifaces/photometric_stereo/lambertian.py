"""Lambertian photometric stereo: the baseline mifaces is judged against on real photographs.

Woodham, "Photometric method for determining surface orientation from
multiple images", Optical Engineering 19(1), 1980. A Lambertian pixel under
a directional light ``l`` of unit intensity reads ``I = rho max(0, n . l)``;
where the pixel is lit, ``I = b . l`` with ``b = rho n``, so K >= 3 lit
observations give ``b`` by least squares, the normal as ``b / |b|`` and the
albedo as ``|b|``.

Frames: the light directions and the normals share whatever frame the
caller uses (DiLiGenT: x right, y up, z towards the camera; mifaces'
camera frame: x right, y down, z forward); the directions point from the
surface towards the lights.
"""

from __future__ import annotations

import numpy as np

#: Observations below this fraction of the pixel's brightest are taken as shadowed.
SHADOW_FRACTION = 0.05
#: Pixels whose lit directions span less than this (smallest eigenvalue of sum l l^T) are left unsolved.
MIN_SPREAD = 1e-6


def _channels(images: np.ndarray) -> np.ndarray:
    """(K, H, W) or (K, H, W, C) to (K, H, W, C)."""
    images = np.asarray(images, np.float64)
    if images.ndim == 3:
        images = images[..., None]
    if images.ndim != 4:
        raise ValueError(f"images must have shape (K, H, W) or (K, H, W, C), got {images.shape}")
    return images


def observation_weights(intensity: np.ndarray, saturated: np.ndarray | None = None,
                        shadow: float = SHADOW_FRACTION) -> np.ndarray:
    """Weight 1 for the lit, unsaturated observations of each pixel, 0 for the others.

    Parameters
    ----------
    intensity : (K, P) array
        Each pixel's observations (grey: the mean over channels).
    saturated : (K, P) bool array, optional
        Observations at the sensor's largest code.
    shadow : float
        Observations below ``shadow`` times the pixel's brightest are shadowed.
    """
    weights = intensity > shadow * intensity.max(axis=0, keepdims=True)
    if saturated is not None:
        weights &= ~saturated
    return weights.astype(np.float64)


def fit(images, directions, mask, saturated=None, shadow: float = SHADOW_FRACTION):
    """Albedo and normal per pixel by least squares over the lit, unsaturated observations.

    Solves, for each pixel, the 3x3 normal equations
    ``(sum_k w_k l_k l_k^T) b = sum_k w_k I_k l_k`` on the grey value (the mean
    over channels), with ``w_k`` from :func:`observation_weights`; the normal is
    ``b / |b|``. The albedo of each channel is then the least-squares scale
    ``sum_k w_k I_kc s_k / sum_k w_k s_k^2`` with ``s_k = n . l_k``.

    Parameters
    ----------
    images : (K, H, W) or (K, H, W, C) array
        Linear pixel values, each divided by its light's intensity.
    directions : (K, 3) array
        Unit directions towards the lights.
    mask : (H, W) bool array
        The pixels to solve.
    saturated : (K, H, W) bool array, optional
        Saturated observations, left out.
    shadow : float
        Fraction of each pixel's brightest observation below which an observation is shadowed.

    Returns
    -------
    albedo : (H, W) or (H, W, C) float64
        Zero outside the mask and where fewer than three spread lit directions remain.
    normals : (H, W, 3) float64
        Unit normals in the frame of ``directions``; zero where the albedo is.
    """
    values = _channels(images)
    k, h, w, c = values.shape
    directions = np.asarray(directions, np.float64)
    if directions.shape != (k, 3):
        raise ValueError(f"directions must have shape ({k}, 3) for {k} images, got {directions.shape}")
    mask = np.asarray(mask, bool)
    if mask.shape != (h, w):
        raise ValueError(f"mask must have shape ({h}, {w}), got {mask.shape}")
    observed = values[:, mask]  # (K, P, C)
    grey = observed.mean(axis=2)
    flags = None if saturated is None else np.asarray(saturated, bool)[:, mask]
    weights = observation_weights(grey, flags, shadow)
    normal_matrix = np.einsum("kp,ki,kj->pij", weights, directions, directions)
    right = np.einsum("kp,kp,ki->pi", weights, grey, directions)
    solvable = np.linalg.eigvalsh(normal_matrix)[:, 0] > MIN_SPREAD
    b = np.zeros_like(right)
    b[solvable] = np.linalg.solve(normal_matrix[solvable], right[solvable][:, :, None])[:, :, 0]
    length = np.linalg.norm(b, axis=1)
    solvable &= length > 0
    n = np.zeros_like(b)
    n[solvable] = b[solvable] / length[solvable, None]
    shading = directions @ n.T  # (K, P)
    denominator = np.einsum("kp,kp->p", weights, shading ** 2)
    scale = np.where(solvable, 1.0 / np.where(solvable, denominator, 1.0), 0.0)
    rho = np.einsum("kp,kpc,kp->pc", weights, observed, shading) * scale[:, None]
    albedo = np.zeros((h, w, c))
    normals = np.zeros((h, w, 3))
    albedo[mask] = rho
    normals[mask] = n
    return (albedo[:, :, 0] if np.ndim(images) == 3 else albedo), normals


def predict(albedo, normals, direction) -> np.ndarray:
    """The Lambertian image ``albedo max(0, n . l)`` under one directional light of unit intensity.

    Parameters
    ----------
    albedo : (H, W) or (H, W, C) array
    normals : (H, W, 3) array
    direction : (3,) array
        Unit direction towards the light, in the frame of ``normals``.
    """
    albedo = np.asarray(albedo, np.float64)
    shading = np.maximum(np.asarray(normals, np.float64) @ np.asarray(direction, np.float64), 0.0)
    return albedo * (shading[..., None] if albedo.ndim == 3 else shading)


def angular_error(normals, reference, mask) -> np.ndarray:
    """Angle in degrees between two normal maps (H, W, 3) at the pixels of ``mask`` (NaN where one is zero)."""
    a = np.asarray(normals, np.float64)[mask]
    r = np.asarray(reference, np.float64)[mask]
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.sum(a * r, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(r, axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


__all__ = ["MIN_SPREAD", "SHADOW_FRACTION", "angular_error", "fit", "observation_weights", "predict"]
