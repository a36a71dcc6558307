"""The BSDF gallery: the four plugins side by side on spheres."""

from __future__ import annotations

import os
import time
from pathlib import Path

import mitsuba as mi

from ..brdf import NAMES
from ..io.image_files import save_image
from ..render import render_passes
from ..render.scenes import scene_path

#: Plugins in the gallery, left to right.
ORDER = NAMES


def render_gallery(out_dir: str | os.PathLike = "out/gallery", spp: int = 128,
                   width: int = 1200, height: int = 340) -> dict:
    """Render ``scenes/gallery.xml`` (one sphere per plugin, left to right
    phong, cooktorrance, ward, lafortune) to ``gallery.exr`` and
    ``gallery.png`` in ``out_dir``.

    Returns
    -------
    dict
        ``exr`` and ``png`` paths, ``seconds`` of rendering, ``variant``.
    """
    scene = mi.load_file(str(scene_path("gallery")), spp=spp, width=width, height=height)
    start = time.perf_counter()
    image = render_passes(scene, spp, desc="gallery")
    seconds = time.perf_counter() - start
    paths = save_image(image, Path(out_dir) / "gallery")
    return {**paths, "seconds": seconds, "variant": mi.variant()}
