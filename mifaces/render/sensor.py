"""The camera as a Mitsuba sensor, the limits of a render, and rendering in passes with progress."""

from __future__ import annotations

import math

import mitsuba as mi
import numpy as np

from ..capture.camera import PIXEL_BLUR_STD
from ..io.image_files import check_image_size
from ..runtime.progress import progress


#: Largest number of samples one render pass traces (Mitsuba's wavefront:
#: width x height x spp must stay below 2^32).
MAX_RENDER_SAMPLES = 2 ** 32 - 1


def check_render_size(width: int, height: int, spp: int, what: str = "render") -> None:
    """A ``ValueError`` unless an image of ``width`` x ``height`` at ``spp``
    samples per pixel fits the image limits and one Mitsuba pass
    (:data:`MAX_RENDER_SAMPLES`)."""
    check_image_size(width, height, what)
    if isinstance(spp, bool) or int(spp) < 1:
        raise ValueError(f"{what}: samples per pixel must be a positive integer, got {spp!r}")
    if width * height * int(spp) > MAX_RENDER_SAMPLES:
        raise ValueError(f"{what}: {width}x{height} pixels at {spp} spp are {width * height * int(spp)} samples, "
                         f"more than one render pass traces ({MAX_RENDER_SAMPLES}); lower the spp or the size")


def render_passes(scene, spp: int, passes: int = 8, desc: str = "rendering") -> np.ndarray:
    """Render ``scene`` with ``spp`` samples per pixel in ``passes`` passes of
    different seeds, averaged, showing progress. Returns a float32 (H, W, C)
    array of linear radiance."""
    passes = max(1, min(passes, spp))
    per_pass = [spp // passes + (1 if i < spp % passes else 0) for i in range(passes)]
    total = None
    for seed, n in enumerate(progress(per_pass, desc=desc, unit="pass", leave=False, detail=True)):
        image = np.array(mi.render(scene, spp=n, seed=seed), dtype=np.float64)
        total = image * n if total is None else total + image * n
    return (total / spp).astype(np.float32)


def mitsuba_sensor(camera, spp: int) -> dict:
    """A Mitsuba ``perspective`` sensor (dict) equal to a
    :class:`mifaces.capture.Camera` without distortion: same pose, field of
    view and principal point, an HDR film of the camera's size with a Gaussian
    pixel filter of 0.5 px (the optics' blur)."""
    if np.any(camera.distortion):
        raise ValueError("Mitsuba renders undistorted images only: the camera has lens distortion")
    fov = 2 * math.degrees(math.atan(camera.height / 2 / camera.fy))
    to_world = np.eye(4)
    # Mitsuba's camera looks along +z with +y up and +x to the left of the image
    to_world[:3, :3] = camera.rotation.T @ np.diag([-1.0, -1.0, 1.0])
    to_world[:3, 3] = camera.position
    return {"type": "perspective", "fov": fov, "fov_axis": "y",
            # Mitsuba shifts the image against its offsets (checked by tests/test_render.py)
            "principal_point_offset_x": (camera.width / 2 - camera.cx - 0.5) / camera.width,
            "principal_point_offset_y": (camera.height / 2 - camera.cy - 0.5) / camera.height,
            "near_clip": 10.0, "far_clip": 1e5, "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                     # the optics' blur: a Gaussian point spread function
                     "rfilter": {"type": "gaussian", "stddev": PIXEL_BLUR_STD}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp}}


__all__ = ["MAX_RENDER_SAMPLES", "check_render_size", "render_passes", "mitsuba_sensor"]
