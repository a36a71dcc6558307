"""Reading photographs: integer or float files to linear RGB per unit exposure.

The files themselves are read by :mod:`mifaces.io.image_files`; here their codes become linear
values (transfer curve, exposure) and their saturated pixels are marked.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..io.image_files import read_codes, read_exr
from .hdr import decode_srgb
from .types import TRANSFERS, Image


def decode(data: np.ndarray, transfer: str = "linear", gamma: float = 2.2) -> np.ndarray:
    """Integer or float pixel data to linear float values in [0, 1] (floats unchanged by ``'linear'``).

    Parameters
    ----------
    data : array
        ``uint8``/``uint16`` codes (divided by the largest code) or floats.
    transfer : {'linear', 'srgb', 'gamma'}
        The encoding curve: ``'srgb'`` is IEC 61966-2-1, inverted with
        colour-science's ``cctf_decoding``; ``'gamma'`` is ``v ** gamma``.
    """
    if transfer == "srgb":
        return decode_srgb(data)
    if np.issubdtype(data.dtype, np.integer):
        values = data.astype(np.float64) / np.iinfo(data.dtype).max
    else:
        values = data.astype(np.float64)
    if transfer == "linear":
        out = values
    elif transfer == "gamma":
        out = np.clip(values, 0.0, None) ** gamma
    else:
        raise ValueError(f"transfer must be one of {TRANSFERS}, got {transfer!r}")
    return np.asarray(out, np.float32)


def read_image(path: str | os.PathLike, transfer: str = "linear", gamma: float = 2.2, exposure: float = 1.0,
               saturation: float | None = None) -> Image:
    """Read a photograph as an :class:`Image` (linear RGB per unit exposure).

    EXR files must be linear. Integer images (PNG, TIFF, PGM/PPM, JPEG; 8 or
    16 bit, read at their true depth by :func:`mifaces.io.image_files.read_codes`)
    are decoded with ``transfer``; their saturated pixels are those at the
    largest code. ``saturation`` (linear value, before dividing by the
    exposure) marks saturated pixels of float images. A greyscale file (one
    channel) gives ``channels=1``, its value repeated in the three channels of
    ``pixels``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"image not found: {path}")
    if path.suffix.lower() == ".exr":
        if transfer != "linear":
            raise ValueError(f"{path.name}: EXR images are linear, not {transfer!r}")
        data = read_exr(path)
        top = None
    else:
        data = read_codes(path)
        top = np.iinfo(data.dtype).max
    if data.ndim == 2:
        data = data[:, :, None]
    if data.ndim != 3 or data.shape[2] not in (1, 3, 4):
        raise ValueError(f"{path.name}: expected 1, 3 or 4 channels, got shape {data.shape}")
    channels = 1 if data.shape[2] == 1 else 3
    data = data[:, :, :3] if data.shape[2] >= 3 else np.repeat(data, 3, axis=2)
    if top is not None:
        saturated = np.any(data >= top, axis=2)
    elif saturation is not None:
        saturated = np.any(data >= saturation, axis=2)
    else:
        saturated = np.zeros(data.shape[:2], bool)
    pixels = decode(data, transfer, gamma) / np.float32(exposure)
    return Image(pixels=pixels, saturated=saturated, exposure=float(exposure), path=path, channels=channels)

