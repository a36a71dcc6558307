"""Rendering a fitted BRDF (paper sec. 6): on the face it was fitted to or
on another face of the same model (BRDF transfer: all faces of a model share
its texture parameterization, so the albedo map and the regions move with
the BRDF), in a novel pose, under a novel point light or an environment map,
with Mitsuba's path tracer as the simulator renders photographs
(:class:`mifaces.render.FaceScene`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..brdf.model import check_numbers
from ..capture import Light, load_capture
from ..shape.io import load_geometry
from ..io.image_files import save_image
from ..model import MorphableModel
from ..model.geometry import rotation_about, turned
from ..io.paths import check_writable
from ..render import FaceScene
from .io import load_estimate
from .result import BRDFEstimate, fitted_light


def render_estimate(estimate: BRDFEstimate, face_model: MorphableModel, vertices: np.ndarray, camera,
                    light: Light | None = None, *, envmap=None, envmap_scale: float = 1.0, spp: int = 64,
                    seed: int = 0) -> np.ndarray:
    """Render the fitted face (linear RGB, (H, W, 3)) on geometry ``vertices``
    (world frame) seen by ``camera``, under a :class:`~mifaces.capture.Light` (point,
    directional or environment map) and/or an environment ``envmap``
    (:func:`mifaces.lights.emitters.light_emitters`): for novel poses, novel lights and comparisons with
    held-out photographs. To render one face several times, build its
    :class:`~mifaces.render.FaceScene` once and call its ``render``."""
    return FaceScene(face_model, vertices).render(estimate.to_json(), estimate.albedo.albedo, camera, light,
                                                  envmap=envmap, envmap_scale=envmap_scale, spp=spp, seed=seed,
                                                  normals=estimate.normal_texture(),
                                                  specular=estimate.specular_texture())


def render_fitted(brdf_dir, capture, out, measurement: str | None = None, geometry="ground-truth",
                  face_model=None, yaw: float = 0.0, light_position=None, envmap=None, envmap_scale: float = 1.0,
                  spp: int = 64, light_direction=None, intensity=None) -> dict[str, Path]:
    """Render a fitted BRDF (a ``fit-brdf`` output folder) on a face of a capture,
    in a novel pose and light, and write ``out``.exr / .png.

    The BRDF may come from another face than the geometry: both share the
    model's texture parameterization, so the albedo map and the regions move
    with it (paper sec. 6). ``yaw`` turns the face about the camera's up
    direction (degrees, right-handed, about the face's centroid:
    :func:`~mifaces.model.geometry.turned`, :attr:`~mifaces.capture.Camera.up`); the light is
    the measurement's light unless ``light_position`` (a point light, world,
    mm), ``light_direction`` (a directional light, world frame, towards the
    light; :meth:`mifaces.capture.Camera.direction` turns an azimuth and
    elevation into one) or an ``envmap`` is given (an equirectangular map,
    or an emitter dict such as :func:`mifaces.lights.environment.sky_emitter`'s); its intensity is the
    measurement light's unless ``intensity`` is given (the :class:`~mifaces.capture.Light` rendered:
    the measurement's, or one made of these). Rendered in the
    capture's camera and units, the image compares pixel for pixel with a
    photograph taken under that light.
    """
    yaw = check_numbers("yaw", yaw)
    check_writable(Path(out).parent)
    capture = load_capture(capture)
    data = load_estimate(brdf_dir)
    if data["albedo"] is None:
        raise FileNotFoundError(f"{brdf_dir}: no albedo map beside brdf.json")
    face, shapes = load_geometry(capture, geometry, face_model)
    name = measurement or next(m.name for m in capture.measurements if m.name in shapes)
    if name not in shapes:
        raise ValueError(f"no geometry for measurement {name!r}; have {sorted(shapes)}")
    albedo = data["albedo"]
    if albedo.ndim != 3 or albedo.shape[0] != albedo.shape[1]:
        raise ValueError(f"{brdf_dir}: the albedo map must be a square RGB image, got shape {albedo.shape}")
    vertices = np.asarray(shapes[name], np.float64)
    if yaw:
        vertices = turned(vertices, rotation_about(capture.camera.up, yaw), vertices.mean(axis=0))
    lamp = fitted_light(capture.light(next(m.light for m in capture.measurements if m.name == name)),
                        data.get("refinement"))  # a map the refinement refined, as scene.xml has it
    intensity = lamp.intensity if intensity is None else intensity
    if light_position is None and light_direction is None and envmap is None:  # the measurement's light
        light = lamp.with_intensity(intensity)
    elif light_position is None and light_direction is None:
        light = None  # the environment alone
    else:
        light = Light("novel", light_position, intensity, direction=light_direction)
    image = FaceScene(face, vertices).render(data, albedo, capture.camera, light, envmap=envmap,
                                             envmap_scale=envmap_scale, spp=spp, normals=data.get("normals"),
                                             specular=data.get("specular"))
    return save_image(image, out)


__all__ = ["render_estimate", "render_fitted"]
