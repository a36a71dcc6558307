"""Rendering only the part of the image where something can show.

A face or a steel sphere photographed in the black studio, lit by point lights, fills part of the
frame; every other pixel is exactly 0. Mitsuba still traces each of their samples and splats it
through the pixel filter, and on a 512² photograph of the face that is a third of the render's
time. :class:`CroppedScene` renders a scene dict through films cropped to the windows where its
objects project (:func:`crop_window`), and puts the windows back into an image of the camera's size.
Where anything else could show, an environment or a lamp's own radiance, the objects passed must
include it (the lamp), or the scene is rendered whole (:func:`dark_background`).

The window's size and offset are compiled into the render's kernel, so windows snap outward to a
grid of :data:`CROP_GRID` pixels: the photographs of a capture share a few kernels rather than
compiling one each. A cropped render has its own Monte Carlo noise (each sample stream follows the
window's pixels), equal in distribution to the whole render's, and the same mean.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

#: Crop windows snap outward to multiples of this many pixels (module docstring).
CROP_GRID = 32
#: Pixels added around an object's projection: the pixel filter's reach (a Gaussian of 0.5 px,
#: cut at 2 px) and more.
CROP_MARGIN = 4
#: Emitter plugins that the camera never sees: only the surfaces they light can show.
DELTA_EMITTERS = frozenset({"point", "directional", "spot"})
#: Scene entries that are not emitters (what the rest of a face scene holds).
_NOT_EMITTERS = frozenset({"scene", "integrator", "sensor", "bitmap"})


def crop_window(camera, points) -> tuple[int, int, int, int] | None:
    """The pixel window ``(x, y, width, height)`` of ``camera``'s image that holds the projection of
    world ``points`` ((N, 3), mm: an object's vertices, or corners of a box around it), with
    :data:`CROP_MARGIN`, snapped outward to :data:`CROP_GRID` and clipped to the image. None where
    that is the whole image, or the points straddle the camera's plane (render it whole);
    ``(0, 0, 0, 0)`` where the object cannot show (outside the image, or behind the camera)."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    # the sensor's own pinhole (:func:`~mifaces.render.sensor.mitsuba_sensor`: no lens distortion)
    local = (points - np.asarray(camera.position, np.float64)) @ np.asarray(camera.rotation, np.float64).T
    behind = local[:, 2] <= 0.0
    if np.all(behind):
        return 0, 0, 0, 0
    if np.any(behind):
        return None
    xy = np.stack([camera.fx * local[:, 0] / local[:, 2] + camera.cx,
                   camera.fy * local[:, 1] / local[:, 2] + camera.cy], axis=-1)
    low = np.floor((xy.min(axis=0) - CROP_MARGIN) / CROP_GRID) * CROP_GRID
    high = np.ceil((xy.max(axis=0) + CROP_MARGIN + 1) / CROP_GRID) * CROP_GRID
    size = np.array([camera.width, camera.height])
    low, high = np.clip(low, 0, size).astype(int), np.clip(high, 0, size).astype(int)
    if np.any(high <= low):
        return 0, 0, 0, 0
    if np.all(low == 0) and np.all(high == size):
        return None
    return int(low[0]), int(low[1]), int(high[0] - low[0]), int(high[1] - low[1])


def box_corners(center, radius: float) -> np.ndarray:
    """The 8 corners (8, 3) of the cube around a sphere: points whose projection holds the sphere's."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float64)
    return np.asarray(center, np.float64) + radius * signs


def dark_background(scene: dict) -> bool:
    """Whether nothing of scene dict ``scene`` but its shapes can show: every emitter is a point,
    directional or spot light (:data:`DELTA_EMITTERS`), and no shape emits."""
    for value in scene.values():
        if isinstance(value, dict):
            kind = value.get("type")
            if "emitter" in value or (kind not in DELTA_EMITTERS and kind not in _NOT_EMITTERS
                                      and _is_emitter_type(kind)):
                return False
        elif isinstance(value, mi.Emitter):
            if not mi.has_flag(value.flags(), mi.EmitterFlags.Delta):
                return False
        elif isinstance(value, mi.Shape) and value.is_emitter():
            return False
    return True


def _is_emitter_type(kind) -> bool:
    """Whether plugin ``kind`` is one of Mitsuba's emitters (environments, skies, area lights)."""
    return kind in {"constant", "envmap", "sunsky", "sky", "sun", "area", "directionalarea", "projector"}


def _merged(windows: list[tuple[int, int, int, int]]) -> list[tuple[int, int, int, int]]:
    """``windows`` with overlapping ones joined into their bounding window (a pixel is rendered once)."""
    boxes = [[x, y, x + w, y + h] for x, y, w, h in windows if w > 0 and h > 0]
    merged = True
    while merged:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                    boxes[i] = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])]
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return [(x0, y0, x1 - x0, y1 - y0) for x0, y0, x1, y1 in boxes]


def _cropped_sensor(sensor: dict, window) -> dict:
    x, y, w, h = window
    film = dict(sensor["film"], crop_offset_x=x, crop_offset_y=y, crop_width=w, crop_height=h)
    return dict(sensor, film=film)


class CroppedScene:
    """Scene dict ``scene`` loaded once, to render through the windows of ``objects`` (world point
    sets, one per object that can show: :func:`crop_window`) of its sensor, ``camera``'s; the whole
    image where ``objects`` is None (anything can show), a window is None (an object straddling the
    camera's plane) or the windows cover the image."""

    def __init__(self, scene: dict, camera, objects=None):
        self.scene, self.camera = mi.load_dict(scene), camera
        windows = [None] if objects is None else [crop_window(camera, points) for points in objects]
        self.windows = None if any(w is None for w in windows) else _merged(windows)
        if self.windows is not None and sum(w * h for _, _, w, h in self.windows) >= camera.width * camera.height:
            self.windows = None
        self.sensors = [] if self.windows is None else [mi.load_dict(_cropped_sensor(scene["sensor"], window))
                                                        for window in self.windows]

    def render(self, spp: int, seed: int = 0, integrator=None) -> np.ndarray:
        """(H, W, 3) float32 linear radiance at Monte Carlo ``seed``, 0 outside the windows;
        ``integrator`` (a loaded one) in place of the scene's."""
        if self.windows is None:
            return np.array(mi.render(self.scene, spp=spp, seed=seed, integrator=integrator), np.float32)[..., :3]
        image = np.zeros((self.camera.height, self.camera.width, 3), np.float32)
        for index, ((x, y, w, h), sensor) in enumerate(zip(self.windows, self.sensors)):
            # each window its own stream of random numbers: the windows' noise independent
            part = mi.render(self.scene, sensor=sensor, spp=spp, seed=(seed + (index << 20)) & 0xFFFFFFFF,
                             integrator=integrator)
            image[y:y + h, x:x + w] = np.array(part, np.float32)[..., :3]
        return image


__all__ = ["CROP_GRID", "CROP_MARGIN", "DELTA_EMITTERS", "crop_window", "box_corners", "dark_background",
           "CroppedScene"]
