"""Rendering Mitsuba scenes in passes, with progress, to EXR and PNG."""

from __future__ import annotations

import os
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
from tqdm import tqdm

from .files import write_exr, write_png


def render_passes(scene, spp: int, passes: int = 8, desc: str = "rendering") -> np.ndarray:
    """Render ``scene`` with ``spp`` samples per pixel in ``passes`` passes of
    different seeds, averaged, showing progress. Returns a float32 (H, W, C)
    array of linear radiance."""
    passes = max(1, min(passes, spp))
    per_pass = [spp // passes + (1 if i < spp % passes else 0) for i in range(passes)]
    total = None
    for seed, n in enumerate(tqdm(per_pass, desc=desc, unit="pass", leave=False)):
        image = np.array(mi.render(scene, spp=n, seed=seed), dtype=np.float64)
        total = image * n if total is None else total + image * n
    return (total / spp).astype(np.float32)


def save_image(image: np.ndarray, stem: str | os.PathLike) -> dict[str, Path]:
    """Write ``image`` as ``<stem>.exr`` (linear) and ``<stem>.png`` (sRGB,
    clipped at 1), atomically. Returns the two paths."""
    stem = Path(stem)
    paths = {"exr": stem.with_suffix(".exr"), "png": stem.with_suffix(".png")}
    write_exr(paths["exr"], image)
    write_png(paths["png"], image)
    return paths
