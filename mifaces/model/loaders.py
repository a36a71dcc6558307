"""Reading morphable models that users bring, converted at the edge to :class:`MorphableModel`.

Every reader checks the file's layout first and raises :class:`ModelFormatError`
naming the file, the missing key or the array whose shape is wrong.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


class ModelFormatError(ValueError):
    """A model file that does not have the layout its format requires."""


def require(data, key: str, path: Path, what: str):
    """``data[key]``, or a :class:`ModelFormatError` naming the missing key."""
    try:
        return data[key]
    except (KeyError, ValueError):
        raise ModelFormatError(f"{path}: missing key {key!r} ({what})") from None


def check_shape(array, shape: tuple, key: str, path: Path) -> np.ndarray:
    """``array`` as numpy, or a :class:`ModelFormatError` naming ``key`` and both shapes.

    ``None`` in ``shape`` matches any length.
    """
    a = np.asarray(array)
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ModelFormatError(f"{path}: {key!r} has shape {a.shape}, expected {want}")
    return a


def existing(path: str | os.PathLike) -> Path:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"model file not found: {path}")
    return path


def read_ibug_mapping(path: str | os.PathLike) -> dict[int, int]:
    """Read an eos landmark mapping file (``ibug_to_sfm.txt``: TOML, ``[landmark_mappings]``
    with lines ``ibug = vertex``). Returns iBUG index (1-based) -> vertex index."""
    path = existing(path)
    mapping, section = {}, None
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith("["):
            section = line.strip("[]").strip()
            continue
        if section == "landmark_mappings":
            key, _, value = line.partition("=")
            try:
                mapping[int(key.strip().strip('"'))] = int(value.strip().strip('"'))
            except ValueError:
                raise ModelFormatError(f"{path}:{number}: expected 'ibug = vertex', got {line!r}") from None
    if not mapping:
        raise ModelFormatError(f"{path}: no [landmark_mappings] entries")
    return mapping
