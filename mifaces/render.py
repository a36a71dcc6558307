"""Rendering with Mitsuba: the capture's camera as a sensor, a face with its
fitted (or ground-truth) BRDF per region, lit by a point light or an
environment map; rendering in passes with progress; writing EXR and PNG."""

from __future__ import annotations

import math
import os
from pathlib import Path

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
            "principal_point_offset_x": (camera.cx + 0.5 - camera.width / 2) / camera.width,
            "principal_point_offset_y": (camera.cy + 0.5 - camera.height / 2) / camera.height,
            "near_clip": 10.0, "far_clip": 1e5, "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                     # the optics' blur: a Gaussian point spread function of 0.5 px
                     "rfilter": {"type": "gaussian", "stddev": 0.5}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp}}


def rgb(value) -> dict:
    """A Mitsuba ``rgb`` spectrum dict from a number or an RGB triple."""
    v = np.broadcast_to(np.asarray(value, np.float64), 3)
    return {"type": "rgb", "value": [float(x) for x in v]}


def _bsdf(truth: dict, region: str, texture) -> dict:
    """The plugin dict of one region: its parameters over the albedo texture."""
    from . import brdf

    model = truth["model"]
    options = dict(truth["options"])
    instance = brdf.model(model, **options)
    params = truth["regions"].get(region, truth["regions"]["skin"])
    d = {"type": model} if texture is None else {"type": model, "diffuse_reflectance": texture}
    for k, v in options.items():
        if k != "lobes":
            d[k] = v
    kinds = {p.name: p.kind for p in instance.specular_parameters()}
    for k, v in params.items():
        d[k] = rgb(v) if kinds.get(k) == "rgb" else float(v)
    return d


def face_shapes(model, vertices: np.ndarray, truth: dict, texture=None, normals: np.ndarray | None = None) -> dict:
    """One Mitsuba mesh per region (triangles labelled by the region map at their uv centroid),
    each with its region's BSDF from ``truth`` (the ``brdf.json`` layout) over the albedo
    ``texture`` (the plugin's default diffuse if None); shading normals from the whole face
    (``normals``, default the model's vertex normals of ``vertices``) so seams stay invisible.
    Keys are ``face_<region>_<label>``."""
    from .model.mesh import mitsuba_mesh
    from .model.regions import REGIONS, triangle_regions

    vertices = np.asarray(vertices, np.float32)
    normals = model.vertex_normals(vertices) if normals is None else normals
    names = {label: name for name, label in REGIONS.items()}
    labels = triangle_regions(model.region_map, model.uv, model.triangles)
    shapes = {}
    for label in np.unique(labels):
        name = names.get(int(label), "skin")
        name = "skin" if name == "background" else name
        tri = model.triangles[labels == label]
        used, inverse = np.unique(tri, return_inverse=True)
        shapes[f"face_{name}_{int(label)}"] = mitsuba_mesh(
            vertices[used], inverse.reshape(-1, 3), model.uv[used], normals=normals[used],
            bsdf=_bsdf(truth, name, texture), name=f"face_{name}")
    return shapes


def face_scene(brdf: dict, albedo: np.ndarray, face_model, vertices: np.ndarray, camera, light_position=None,
               intensity=None, envmap=None, envmap_scale: float = 1.0, spp: int = 64, max_depth: int = 4) -> dict:
    """The Mitsuba scene (a dict for ``mi.load_dict``) of a face with a
    per-region BRDF over an albedo map, as ``camera`` sees it.

    Parameters
    ----------
    brdf : dict
        The ``brdf.json`` layout: ``model``, ``options``, ``regions``.
    albedo : (R, R, 3) array
        Diffuse albedo in the model's texture space (row 0 at v = 0).
    face_model : MorphableModel
    vertices : (V, 3) array
        The face in world coordinates (mm).
    camera : mifaces.capture.Camera
    light_position, intensity : (3,) arrays, optional
        A point light (world, mm) and its radiant intensity.
    envmap : path or (H, W, 3) array, optional
        An equirectangular environment map (linear RGB) instead of, or
        besides, the point light, scaled by ``envmap_scale``. A scene holds
        only the emitters it is given.
    spp, max_depth : int
        Samples per pixel and the path tracer's depth (shadows and
        interreflection).
    """
    import mitsuba as mi

    if light_position is None and envmap is None:
        raise ValueError("render_face needs a light: a point light position or an environment map")
    texture = mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(albedo, np.float32)),
                            "raw": True, "filter_type": "bilinear", "wrap_mode": "clamp"})
    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": int(max_depth)},
             "sensor": mitsuba_sensor(camera, spp), **face_shapes(face_model, vertices, brdf, texture)}
    if light_position is not None:
        if intensity is None:
            raise ValueError("a point light needs its intensity")
        scene["light"] = {"type": "point", "position": [float(x) for x in light_position], "intensity": rgb(intensity)}
    if envmap is not None:
        environment = {"type": "envmap", "scale": float(envmap_scale)}
        if isinstance(envmap, (str, os.PathLike)):
            if not Path(envmap).is_file():
                raise FileNotFoundError(f"environment map not found: {envmap}")
            environment["filename"] = str(envmap)
        else:
            environment["bitmap"] = mi.Bitmap(np.ascontiguousarray(envmap, np.float32))
        scene["environment"] = environment
    return scene


def render_face(brdf: dict, albedo: np.ndarray, face_model, vertices: np.ndarray, camera, light_position=None,
                intensity=None, envmap=None, envmap_scale: float = 1.0, spp: int = 64, seed: int = 0,
                max_depth: int = 4) -> np.ndarray:
    """Render :func:`face_scene`: (H, W, 3) float32 linear radiance."""
    scene = face_scene(brdf, albedo, face_model, vertices, camera, light_position, intensity, envmap, envmap_scale,
                       spp, max_depth)
    return np.array(mi.render(mi.load_dict(scene), spp=spp, seed=seed), dtype=np.float32)[..., :3]
