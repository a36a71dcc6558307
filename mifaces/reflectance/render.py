"""Rendering a fitted BRDF (paper sec. 6): on the face it was fitted to or
on another face of the same model (BRDF transfer: all faces of a model share
its texture parameterization, so the albedo map and the regions move with
the BRDF), in a novel pose, under a novel point light or an environment map,
with Mitsuba's path tracer as the simulator renders photographs
(:class:`mifaces.render.FaceScene`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..brdf.model import check_numbers
from ..capture import Light, load_capture
from ..shape.io import load_geometry
from ..io.image_files import save_image
from ..lights.environment import Environment
from ..lights.relighting import Relighting
from ..model import MorphableModel
from ..model.geometry import rotation_about, turned
from ..io.paths import check_writable
from ..options.fields import check, option
from ..render import FaceScene
from .io import load_estimate
from .result import BRDFEstimate, fitted_light


def render_estimate(estimate: BRDFEstimate, face_model: MorphableModel, vertices: np.ndarray, camera,
                    light: Light | None = None, *, environment: Environment | None = None, spp: int = 64,
                    seed: int = 0) -> np.ndarray:
    """Render the fitted face (linear RGB, (H, W, 3)) on geometry ``vertices``
    (world frame) seen by ``camera``, under a :class:`~mifaces.capture.Light` (point,
    directional or environment map) and/or an :class:`~mifaces.lights.environment.Environment`
    (:func:`mifaces.lights.emitters.light_emitters`): for novel poses, novel lights and comparisons with
    held-out photographs. To render one face several times, build its
    :class:`~mifaces.render.FaceScene` once and call its ``render``."""
    return FaceScene(face_model, vertices).render(estimate.to_json(), estimate.albedo.albedo, camera, light,
                                                  environment=environment, spp=spp, seed=seed,
                                                  normals=estimate.normal_texture(),
                                                  specular=estimate.specular_texture())


@dataclass(frozen=True, eq=False)
class RenderOptions:
    """How :func:`render_fitted` renders a fitted BRDF (``mifaces render``): which face, in which
    pose, under which light, with how many samples. Validated on construction (a ``ValueError``
    naming the field).

    Attributes
    ----------
    measurement : str or None
        The measurement whose face geometry (and light) to use (None: the first with a geometry).
    geometry : str
        ``'ground-truth'`` (a simulated capture's) or a ``fit-shape`` folder
        (:func:`mifaces.shape.io.load_geometry`).
    face_model : str, MorphableModel or None
        The face model of the geometry (None: the one it names).
    yaw : float
        Turn the face by this many degrees about the camera's up direction (right-handed, about the
        face's centroid: :func:`~mifaces.model.geometry.turned`, :attr:`~mifaces.capture.Camera.up`).
    lighting : Relighting
        The light, where not the measurement's (:class:`mifaces.lights.relighting.Relighting`).
    spp : int
        Samples per pixel.
    """

    measurement: str | None = option(None, help="Measurement whose face geometry to use (default: the first).")
    geometry: str = option("ground-truth", help="'ground-truth' or the folder mifaces fit-shape wrote.")
    face_model: object = None
    yaw: float = option(0.0, help="Turn the face by this many degrees (a novel pose).")
    lighting: Relighting = option(factory=Relighting, nested=Relighting, help="The light of the render.")
    spp: int = option(64, bounds=(1, None), help="Samples per pixel.")

    def __post_init__(self):
        object.__setattr__(self, "yaw", check_numbers("yaw", self.yaw))
        check(self)


def render_fitted(brdf_dir, capture, out, options: RenderOptions | None = None) -> dict[str, Path]:
    """Render a fitted BRDF (a ``fit-brdf`` output folder) on a face of a capture,
    in a novel pose and light, and write ``out``.exr / .png.

    The BRDF may come from another face than the geometry: both share the
    model's texture parameterization, so the albedo map and the regions move
    with it (paper sec. 6). ``options`` (:class:`RenderOptions`; default: the first
    measurement's face and light, 64 samples per pixel) say which face, posed how, under which
    light: the measurement's unless its ``lighting`` gives another (a point or directional light,
    an intensity, an environment map or a sun and sky: :meth:`Relighting.lights
    <mifaces.lights.relighting.Relighting.lights>`). Rendered in the
    capture's camera and units, the image compares pixel for pixel with a
    photograph taken under that light.

    Parameters
    ----------
    brdf_dir : path
        The fitted BRDF's folder (``brdf.json``, ``albedo.exr``, ...).
    capture : path or Capture
    out : path
        The image's path without suffix.
    options : RenderOptions, optional

    Returns
    -------
    dict
        ``{'exr': path, 'png': path}``.
    """
    options = RenderOptions() if options is None else options
    check_writable(Path(out).parent)
    capture = load_capture(capture)
    data = load_estimate(brdf_dir)
    if data["albedo"] is None:
        raise FileNotFoundError(f"{brdf_dir}: no albedo map beside brdf.json")
    face, shapes = load_geometry(capture, options.geometry, options.face_model)
    name = options.measurement or next(m.name for m in capture.measurements if m.name in shapes)
    if name not in shapes:
        raise ValueError(f"no geometry for measurement {name!r}; have {sorted(shapes)}")
    albedo = data["albedo"]
    if albedo.ndim != 3 or albedo.shape[0] != albedo.shape[1]:
        raise ValueError(f"{brdf_dir}: the albedo map must be a square RGB image, got shape {albedo.shape}")
    vertices = np.asarray(shapes[name], np.float64)
    if options.yaw:
        vertices = turned(vertices, rotation_about(capture.camera.up, options.yaw), vertices.mean(axis=0))
    lamp = fitted_light(capture.light(next(m.light for m in capture.measurements if m.name == name)),
                        data.get("refinement"))  # a map the refinement refined, as scene.xml has it
    light, environment = options.lighting.lights(lamp, capture.camera)
    image = FaceScene(face, vertices).render(data, albedo, capture.camera, light, environment=environment,
                                             spp=options.spp, normals=data.get("normals"),
                                             specular=data.get("specular"))
    return save_image(image, out)


__all__ = ["render_estimate", "RenderOptions", "render_fitted"]
