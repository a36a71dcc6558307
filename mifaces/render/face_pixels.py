"""The pixels of a camera's image that a face covers: the one test, for the refinement's masks
and region labels (:func:`mifaces.refine.photograph.photograph_view`), the training error of
``mifaces measure`` (:mod:`mifaces.pipeline.measure`), and the validation's masks
(:mod:`mifaces.validation.validator`: :func:`front_of_face_pixels`, the front of the face only).

Two footprints of a pixel, for two uses:

* the ray through the pixel's centre (``spp=None``): the pixel is the face's where that ray hits
  one of its region meshes, and its region is the region map's label at the texture coordinate
  hit. A render at the camera's resolution and its photograph are compared on these pixels;
* the pixel's filtered samples (``spp`` an int): the pixel is the face's where any of the ``spp``
  samples per pixel that the sensor's reconstruction filter (:func:`mifaces.render.mitsuba_sensor`:
  a Gaussian of 0.5 px) spreads onto it hits the face, i.e. where a render of the face draws into
  the pixel, silhouette pixels the filter mixes in included (a depth render, :func:`depth_image`).
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from ..model.mesh import mitsuba_mesh
from . import FaceScene, mitsuba_sensor
from ..validation.shape_errors import front_of_face

#: Samples per pixel of the filtered footprint (:func:`face_pixels`).
FOOTPRINT_SPP = 4


def depth_image(camera, shapes: dict, spp: int = FOOTPRINT_SPP) -> np.ndarray:
    """The distance (mm) along ``camera``'s rays to the nearest of ``shapes`` (key -> Mitsuba
    mesh), filtered as :func:`mifaces.render.mitsuba_sensor` renders with ``spp`` samples per pixel;
    0 where no sample hits: (H, W) float32."""
    description = {"type": "scene", "integrator": {"type": "aov", "aovs": "depth:depth"},
                   "sensor": mitsuba_sensor(camera, spp), **shapes}
    return np.array(mi.render(mi.load_dict(description), spp=spp), np.float32)[..., 0]


def face_pixels(scene: FaceScene, camera, spp: int | None = FOOTPRINT_SPP, region_map: np.ndarray | None = None
                ) -> np.ndarray:
    """The pixels of ``camera``'s image that the face of ``scene`` covers.

    Parameters
    ----------
    scene : FaceScene
        The face's region meshes (world frame, mm).
    camera : mifaces.capture.Camera
    spp : int or None
        The pixel's footprint (the module docstring): ``spp`` samples per pixel through the sensor's
        reconstruction filter (a render's pixels), or, None, the ray through the pixel's centre.
    region_map : (R, R) array, optional
        Region labels in texture space, with ``spp=None`` only: each pixel's region label
        instead of a mask.

    Returns
    -------
    (H, W) bool, or (H, W) int with ``region_map``
        Whether the face covers the pixel; with ``region_map``, ``region_map`` at the texture
        coordinate its centre's ray hits (at least 1, the face's texels without a region), 0 where
        the ray misses the face.
    """
    if spp is not None:
        if region_map is not None:
            raise ValueError("region labels are those of the pixel centres' rays: give region_map with spp=None")
        return depth_image(camera, {key: part.mesh({"type": "diffuse"}) for key, part in scene.meshes.items()},
                           spp) > 0
    uv = texture_coordinates(scene, camera)
    hit = ~np.isnan(uv[..., 0])
    if region_map is None:
        return hit
    return np.where(hit, np.maximum(texture_lookup(region_map, uv), 1), 0)


def texture_coordinates(scene: FaceScene, camera) -> np.ndarray:
    """The texture coordinate (u, v) where the ray through each pixel's centre first meets the face of
    ``scene``: (H, W, 2) float32, NaN where it misses."""
    meshes = {key: part.mesh({"type": "diffuse"}) for key, part in scene.meshes.items()}
    ys, xs = np.mgrid[0:camera.height, 0:camera.width]
    directions = camera.pixel_rays(np.stack([xs, ys], -1).reshape(-1, 2)) @ camera.rotation  # to world: R^T d
    origin = [mi.Float(np.full(len(directions), c, np.float32)) for c in camera.position]
    ray = mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(np.ascontiguousarray(directions.T, np.float32)))
    si = mi.load_dict({"type": "scene", **meshes}).ray_intersect(ray)
    uv = np.asarray(si.uv, np.float32).T
    uv[~np.asarray(si.is_valid())] = np.nan
    return uv.reshape(camera.height, camera.width, 2)


def texture_lookup(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``texture`` (R, R, ...) (row 0 at v = 0) at the texel of each coordinate of ``uv`` (..., 2), nearest
    texel; coordinates that are NaN read texel (0, 0)."""
    r = texture.shape[0]
    uv = np.nan_to_num(uv, nan=0.0)
    col = np.clip((uv[..., 0] * r).astype(int), 0, r - 1)
    row = np.clip((uv[..., 1] * r).astype(int), 0, r - 1)
    return texture[row, col]


def front_of_face_pixels(face_model, vertices: np.ndarray, camera, spp: int = FOOTPRINT_SPP) -> np.ndarray:
    """Pixels of ``camera``'s image where the front of the face (:func:`mifaces.validation.shape_errors.front_of_face`
    on the model's mean shape: the vertices that look forward, from the chin up, outside the hair)
    is the surface seen: (H, W) bool. The back of the head, the ears, the neck and the scalp are left
    out: no photograph of a capture sees them well, so their albedo is not measured, and an error
    there says nothing about the reflectance. Pixels of the filtered footprint of
    :func:`face_pixels` (a depth render of the front against one of the whole face)."""
    front = front_of_face(face_model)
    triangles = np.asarray(face_model.triangles)
    on_face = triangles[np.all(front[triangles], axis=1)]

    def depth(tris):
        return depth_image(camera, {"face": mitsuba_mesh(np.asarray(vertices, np.float32), tris,
                                                         bsdf={"type": "diffuse"})}, spp)

    whole, face = depth(triangles), depth(on_face)
    return (face > 0) & (np.abs(face - whole) <= 1e-3 * np.maximum(whole, 1.0))


__all__ = ["FOOTPRINT_SPP", "depth_image", "face_pixels", "front_of_face_pixels", "texture_coordinates", "texture_lookup"]
