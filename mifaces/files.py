"""Writing outputs atomically, and reading/writing images.

Every file mifaces writes goes through :func:`atomic_path` or :func:`atomic_write`: the data lands in
a temporary file beside the target and is renamed over it only once complete,
so an interrupted run never leaves a half-written output and never destroys
one written earlier.

Images are numpy arrays of shape (H, W) or (H, W, C), float32 linear values
for EXR and display-referred [0, 1] values (sRGB-encoded here) for PNG.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary path beside ``path``; move it to ``path`` on success.

    For libraries that write to a file name. The parent folder is created if
    needed. On an exception the temporary file is removed and ``path`` is left
    as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 would outlive the rename
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb"):
    """Open a file for writing that appears at ``path`` only once complete.

    Yields
    ------
    file object
        Opened with ``mode`` (``'wb'`` or ``'w'``).
    """
    with atomic_path(path) as tmp, open(tmp, mode) as f:
        yield f
        f.flush()
        os.fsync(f.fileno())


def write_json(path: str | os.PathLike, data) -> None:
    """Write ``data`` as indented JSON, atomically."""
    with atomic_write(path, "w") as f:
        json.dump(data, f, indent=2, sort_keys=False)
        f.write("\n")


def _as_hwc(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3:
        raise ValueError(f"image must have shape (H, W) or (H, W, C), got {image.shape}")
    return image


def write_exr(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write a linear float image as OpenEXR (float32 channels Y, RGB or RGBA)."""
    import OpenEXR

    image = _as_hwc(image)
    names = {1: "Y", 3: "RGB", 4: "RGBA"}.get(image.shape[2])
    if names is None:
        raise ValueError(f"EXR images need 1, 3 or 4 channels, got {image.shape[2]}")
    channels = {n: np.ascontiguousarray(image[:, :, i]) for i, n in enumerate(names)}
    with atomic_path(path) as tmp:
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                     channels).write(tmp)


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an OpenEXR file as a float32 array (H, W) or (H, W, C), channels
    in the order Y, or R, G, B(, A)."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EXR image not found: {path}")
    with OpenEXR.File(str(path), separate_channels=True) as f:
        channels = f.channels()
        order = [c for c in ("R", "G", "B", "A") if c in channels] or sorted(channels)
        planes = [np.asarray(channels[c].pixels, dtype=np.float32) for c in order]
    return planes[0] if len(planes) == 1 else np.stack(planes, axis=-1)


def write_png(path: str | os.PathLike, image: np.ndarray, srgb: bool = True) -> None:
    """Write an image with values in [0, 1] as 8-bit PNG, sRGB-encoded unless
    ``srgb`` is False (then the values are written as they are)."""
    import colour
    import skimage.io

    image = _as_hwc(image)
    if image.shape[2] == 1:
        image = image[:, :, 0]
    image = np.clip(np.nan_to_num(image), 0.0, 1.0)
    if srgb:
        image = colour.cctf_encoding(image, function="sRGB")
    data = np.round(image * 255.0).astype(np.uint8)
    with atomic_path(path) as tmp:
        skimage.io.imsave(tmp, data, check_contrast=False)
