"""Reading photographs: integer or float files to linear RGB per unit exposure."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..files import read_exr
from .hdr import decode_srgb
from .types import TRANSFERS, Image

#: Suffixes of the netpbm formats :func:`read_codes` reads itself (binary P5/P6).
NETPBM_SUFFIXES = (".pgm", ".ppm", ".pnm")
#: One netpbm header field, after whitespace and '#' comments (to the end of the line).
_NETPBM_FIELD = re.compile(rb"\s*(?:#[^\n]*\n\s*)*(\S+)")


def _rescale(codes: np.ndarray, top: int) -> np.ndarray:
    """Codes in [0, top] to the full range of uint8 (top < 256) or uint16, exact for top 255 and 65535."""
    dtype = np.uint8 if top < 256 else np.uint16
    full = np.iinfo(dtype).max
    if top == full:
        return codes.astype(dtype)
    return np.round(codes.astype(np.float64) * (full / top)).astype(dtype)


def _read_png(path: Path) -> np.ndarray:
    """A PNG's codes at their depth: pypng for 16-bit files (Pillow reads 16-bit RGB as 8 bit), Pillow otherwise."""
    import png

    reader = png.Reader(filename=str(path))
    reader.preamble()
    if reader.bitdepth <= 8:
        import skimage.io

        return skimage.io.imread(path)
    width, height, rows, info = reader.asDirect()  # palettes expanded; sBIT honoured (depth in info)
    codes = np.vstack([np.asarray(row, np.uint32) for row in rows]).reshape(height, width, info["planes"])
    return _rescale(codes, 2 ** info["bitdepth"] - 1)


def _read_netpbm(path: Path) -> np.ndarray:
    """A binary PGM (P5) or PPM (P6) file's codes (netpbm: 16-bit samples are big-endian).

    Pillow reads 16-bit PPM as 8 bit, and the format is a short header
    followed by the raw samples, so it is read here.
    """
    raw = path.read_bytes()
    fields, pos = [], 0
    while len(fields) < 4:  # magic, width, height, maxval
        match = _NETPBM_FIELD.match(raw, pos)
        if match is None:
            raise ValueError(f"{path.name}: truncated netpbm header")
        fields.append(match.group(1))
        pos = match.end()
    magic, (width, height, top) = fields[0], (int(f) for f in fields[1:])
    if magic not in (b"P5", b"P6"):
        raise ValueError(f"{path.name}: only binary netpbm (P5, P6) is read, got {magic.decode(errors='replace')}")
    planes = 1 if magic == b"P5" else 3
    dtype = np.dtype(">u2" if top > 255 else "u1")
    data = np.frombuffer(raw, dtype, width * height * planes, offset=pos + 1)  # one whitespace byte ends the header
    data = data.reshape(height, width, planes)
    return _rescale(data[:, :, 0] if planes == 1 else data, top)


def read_codes(path: str | os.PathLike) -> np.ndarray:
    """An integer image's codes at their true bit depth, ``uint8`` or ``uint16``, (H, W) or (H, W, C).

    16-bit PNG is read with pypng, TIFF with tifffile, binary PGM/PPM here
    (depths other than 8 and 16 bits rescaled to the full range of the
    next); other formats (8-bit PNG, JPEG) with Pillow through scikit-image.

    Raises
    ------
    ValueError
        For pixel data that is not 8 or 16 bit unsigned integers.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".png":
        data = _read_png(path)
    elif suffix in (".tif", ".tiff"):
        import tifffile

        data = tifffile.imread(path)
    elif suffix in NETPBM_SUFFIXES:
        data = _read_netpbm(path)
    else:
        import skimage.io

        data = skimage.io.imread(path)
    if data.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path.name}: integer images must be 8 or 16 bit, got {data.dtype}")
    return data

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
    16 bit, read at their true depth by :func:`read_codes`) are decoded with
    ``transfer``; their saturated pixels are those at the largest code. ``saturation`` (linear value, before dividing by the
    exposure) marks saturated pixels of float images. A greyscale file (one channel) gives
    ``channels=1``, its value repeated in the three channels of ``pixels``.
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

