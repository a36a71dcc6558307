"""Image files: reading and writing OpenEXR, PNG, TIFF and netpbm, and the
largest image mifaces handles.

Images are numpy arrays of shape (H, W) or (H, W, C), float32 linear values
for EXR and display-referred [0, 1] values (sRGB-encoded here) for PNG.
Integer files are read at their true bit depth (:func:`read_codes`); turning
them into linear photographs (transfer curve, exposure, saturation) is
:func:`mifaces.capture.read_image`'s job.
"""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np
import OpenEXR
import png
import skimage.io
import tifffile
from PIL import Image

from .atomic import atomic_path, atomic_write

#: Largest image side and pixel count mifaces reads, renders or simulates
#: (8192² pixels: 0.8 GiB as float32 RGB); checked before any allocation.
MAX_IMAGE_SIDE = 16384
MAX_IMAGE_PIXELS = 8192 * 8192
#: Suffixes of the netpbm formats :func:`read_codes` reads itself (binary P5/P6).
NETPBM_SUFFIXES = (".pgm", ".ppm", ".pnm")
#: One netpbm header field, after whitespace and '#' comments (to the end of the line).
_NETPBM_FIELD = re.compile(rb"\s*(?:#[^\n]*\n\s*)*(\S+)")


def check_image_size(width, height, what: str = "image") -> tuple[int, int]:
    """``(width, height)`` as ints, or a ``ValueError`` saying the limit
    (:data:`MAX_IMAGE_SIDE`, :data:`MAX_IMAGE_PIXELS`): for a size read from a
    file's header or asked for by a user, before anything is allocated."""
    if isinstance(width, bool) or isinstance(height, bool):
        raise ValueError(f"{what}: width and height must be numbers, got {width!r} x {height!r}")
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise ValueError(f"{what}: size must be positive, got {width}x{height}")
    if max(width, height) > MAX_IMAGE_SIDE or width * height > MAX_IMAGE_PIXELS:
        raise ValueError(f"{what}: {width}x{height} pixels is larger than mifaces handles (at most "
                         f"{MAX_IMAGE_SIDE} pixels a side and {MAX_IMAGE_PIXELS} pixels, e.g. 8192x8192)")
    return width, height


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an OpenEXR file as a float32 array (H, W) or (H, W, C), channels
    in the order Y, or R, G, B(, A). The size in the header is checked
    (:func:`check_image_size`) before the pixels are read."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EXR image not found: {path}")
    with OpenEXR.File(str(path), header_only=True) as f:  # the size, before any pixel is allocated
        (x0, y0), (x1, y1) = (np.asarray(corner, np.int64) for corner in f.header()["dataWindow"])
    check_image_size(x1 - x0 + 1, y1 - y0 + 1, path.name)
    with OpenEXR.File(str(path), separate_channels=True) as f:
        channels = f.channels()
        order = [c for c in ("R", "G", "B", "A") if c in channels] or sorted(channels)
        planes = [np.asarray(channels[c].pixels, dtype=np.float32) for c in order]
    return planes[0] if len(planes) == 1 else np.stack(planes, axis=-1)


def _rescale(codes: np.ndarray, top: int) -> np.ndarray:
    """Codes in [0, top] to the full range of uint8 (top < 256) or uint16, exact for top 255 and 65535."""
    dtype = np.uint8 if top < 256 else np.uint16
    full = np.iinfo(dtype).max
    if top == full:
        return codes.astype(dtype)
    return np.round(codes.astype(np.float64) * (full / top)).astype(dtype)


def _read_png(path: Path) -> np.ndarray:
    """A PNG's codes at their depth: pypng for 16-bit files (Pillow reads 16-bit RGB as 8 bit), Pillow otherwise."""
    reader = png.Reader(filename=str(path))
    reader.preamble()
    if reader.bitdepth <= 8:
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
        data = tifffile.imread(path)
    elif suffix in NETPBM_SUFFIXES:
        data = _read_netpbm(path)
    else:
        data = skimage.io.imread(path)
    if data.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path.name}: integer images must be 8 or 16 bit, got {data.dtype}")
    return data


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------
def _as_hwc(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3:
        raise ValueError(f"image must have shape (H, W) or (H, W, C), got {image.shape}")
    return image


def write_exr(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write a linear float image as OpenEXR (float32 channels Y, RGB or RGBA)."""
    image = _as_hwc(image)
    names = {1: "Y", 3: "RGB", 4: "RGBA"}.get(image.shape[2])
    if names is None:
        raise ValueError(f"EXR images need 1, 3 or 4 channels, got {image.shape[2]}")
    channels = {n: np.ascontiguousarray(image[:, :, i]) for i, n in enumerate(names)}
    with atomic_path(path) as tmp:
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                     channels).write(tmp)


def encode_png(image: np.ndarray, srgb: bool = True) -> bytes:
    """An image with values in [0, 1] ((H, W), (H, W, 3) or (H, W, 4)) as the
    bytes of an 8-bit PNG, colour channels sRGB-encoded unless ``srgb`` is
    False (then written as they are); an alpha channel is always linear."""
    import colour  # colour-science takes most of a second to import: only where a PNG is encoded

    image = _as_hwc(image)
    if image.shape[2] not in (1, 3, 4):
        raise ValueError(f"PNG images need 1, 3 or 4 channels, got {image.shape[2]}")
    image = np.clip(np.nan_to_num(image), 0.0, 1.0)
    if srgb:
        colours = min(image.shape[2], 3)
        image = np.concatenate([colour.cctf_encoding(image[:, :, :colours], function="sRGB"),
                                image[:, :, colours:]], axis=2)
    data = np.round(image * 255.0).astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(data[:, :, 0] if data.shape[2] == 1 else data).save(buffer, format="PNG")
    return buffer.getvalue()


def write_png(path: str | os.PathLike, image: np.ndarray, srgb: bool = True) -> None:
    """Write an image with values in [0, 1] as 8-bit PNG, atomically (:func:`encode_png`)."""
    data = encode_png(image, srgb)
    with atomic_write(path) as f:
        f.write(data)


def save_image(image: np.ndarray, stem: str | os.PathLike) -> dict[str, Path]:
    """Write ``image`` as ``<stem>.exr`` (linear) and ``<stem>.png`` (sRGB,
    clipped at 1), atomically. Returns the two paths."""
    stem = Path(stem)
    paths = {"exr": stem.with_suffix(".exr"), "png": stem.with_suffix(".png")}
    write_exr(paths["exr"], image)
    write_png(paths["png"], image)
    return paths
