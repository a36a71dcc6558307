"""A photograph set against the differentiable render of the fitted face, shared by the
refinements of the reflectance (:mod:`mifaces.refine.reflectance`) and of the shape
(:mod:`mifaces.refine.shape`): the scene of its measurement cropped to the face
(:func:`photograph_view`, of the face's :class:`Appearance` rendered as :class:`RenderSettings`
say), its pixels M_k, and the robust image loss E_k over them (:func:`image_loss`,
:func:`mask_weight`)."""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy.ndimage import binary_erosion

from ..options.fields import check, option
from ..render.face_pixels import face_pixels
from ..render import FaceScene, mitsuba_sensor

#: Key of a capture's ``metadata`` that gives the lamp's radius (mm).
LAMP_RADIUS_KEY = "lamp_radius_mm"


def image_loss(image, target, weight, epsilon: float):
    """The robust image loss of one photograph (the module docstring's E_k).

    Parameters
    ----------
    image, target : mi.TensorXf (H, W, 3)
        Render and photograph, both divided by the photograph's mean μ_k over
        the mask (the residual is relative).
    weight : mi.TensorXf (H, W, 3)
        1/|M_k| on the masked pixels, 0 elsewhere.
    epsilon : float
        ε of ψ_ε(r) = sqrt(r² + ε²) - ε.

    Returns
    -------
    mi.Float
        Σ weight · ψ_ε(image - target), differentiable in ``image``.
    """
    r = image - target
    return dr.sum(weight * (dr.sqrt(r * r + epsilon * epsilon) - epsilon), axis=None).array


def _box_mean(a: np.ndarray, k: int) -> np.ndarray:
    """``a`` (H, W, ...) averaged over k × k blocks (H, W cut to multiples of k)."""
    h, w = a.shape[0] // k * k, a.shape[1] // k * k
    a = a[:h, :w]
    return a.reshape(h // k, k, w // k, k, *a.shape[2:]).mean(axis=(1, 3))


def _light(capture, measurement, lamp_radius: float | None) -> tuple:
    """The measurement's :class:`~mifaces.capture.Light`, and the sphere lamp that replaces its point
    light (or None)."""
    light = capture.light(measurement.light)
    return light, light.sphere_lamp(lamp_radius)


@dataclass(frozen=True, eq=False)
class Appearance:
    """The fitted face's reflectance, as :meth:`FaceScene.scene` renders it.

    Attributes
    ----------
    brdf : dict
        The ``brdf.json`` layout (:meth:`~mifaces.reflectance.result.BRDFEstimate.to_json`).
    albedo : (R, R, 3) array
        The albedo map.
    normals, specular : (R', R', 3) arrays or None
        The per-texel normal map (tangent space, encoded) and specular map, where fitted.
    """

    brdf: dict
    albedo: np.ndarray
    normals: np.ndarray | None = None
    specular: np.ndarray | None = None

    def __post_init__(self):
        if not isinstance(self.brdf, dict):
            raise ValueError(f"Appearance.brdf must be the brdf.json layout (a dict), got {type(self.brdf).__name__}")
        if np.ndim(self.albedo) != 3 or np.shape(self.albedo)[2] != 3:
            raise ValueError(f"Appearance.albedo must be an (R, R, 3) map, got shape {np.shape(self.albedo)}")

    @classmethod
    def of(cls, estimate) -> Appearance:
        """A :class:`~mifaces.reflectance.result.BRDFEstimate`'s: its BRDF, albedo map and, where it
        has them, its normal and specular maps."""
        return cls(estimate.to_json(), estimate.albedo.albedo, estimate.normal_texture(), estimate.specular_texture())


@dataclass(frozen=True)
class RenderSettings:
    """How :func:`photograph_view` renders a photograph's view.

    Attributes
    ----------
    downsample : int
        Render at 1/``downsample`` of the camera's resolution, against the photograph averaged over
        ``downsample``² blocks.
    spp : int
        Samples per pixel.
    integrator : dict
        The Mitsuba integrator (``prb``, ``direct_projective``, ...), as ``mi.load_dict`` takes it.
    sample_border : bool
        The film's ``sample_border``: samples beyond the crop, for a projective integrator's
        gradients of geometry crossing the film's edge.
    """

    downsample: int = option(bounds=(1, None))
    spp: int = option(bounds=(1, None))
    integrator: dict
    sample_border: bool = False

    def __post_init__(self):
        check(self)
        if not isinstance(self.integrator, dict) or "type" not in self.integrator:
            raise ValueError(f"RenderSettings.integrator must be a Mitsuba integrator's dict (with a 'type'), got "
                             f"{self.integrator!r}")


@dataclass(eq=False)
class PhotographView:
    """One measurement's photograph and its differentiable render, at the
    render resolution, cropped to the face.

    Attributes
    ----------
    scene : mi.Scene
        The face (:meth:`FaceScene.scene`) under the measurement's light, with
        the given integrator and a film cropped to ``mask``'s bounding box.
    params : mi.SceneParameters
    target : mi.TensorXf (H, W, 3)
        The photograph in the renderer's units divided by its mean over the mask (μ_k).
    mask : (H, W) bool
        Pixels whose every photograph pixel the face covers (eroded by one
        pixel at silhouettes), none saturated.
    labels : (H, W) int
        Region label at each pixel (:func:`mifaces.render.face_pixels.face_pixels` of the pixel centres,
        sampled at the render resolution).
    scale : float
        1/μ_k: multiplies a render to compare it with ``target``.
    light_kind : str
        ``'point'``, ``'directional'``, ``'sphere'`` or ``'environment'``.
    """

    scene: mi.Scene
    params: mi.SceneParameters
    target: mi.TensorXf
    mask: np.ndarray
    labels: np.ndarray
    scale: float
    light_kind: str


def mask_weight(mask: np.ndarray) -> mi.TensorXf:
    """The weight of :func:`image_loss`: 1/|M_k| on the (H, W) ``mask``'s pixels (each channel a third), 0 elsewhere."""
    weight = np.repeat(mask[..., None], 3, axis=2) / (3.0 * max(int(mask.sum()), 1))
    return mi.TensorXf(np.ascontiguousarray(weight, np.float32))


def photograph_view(capture, m, face: FaceScene, appearance: Appearance, region_map: np.ndarray, scale: np.ndarray,
                    lamp_radius: float | None, rendering: RenderSettings) -> PhotographView:
    """The render of measurement ``m`` of ``capture`` set against its photograph.

    Parameters
    ----------
    capture : Capture
    m : Measurement
    face : FaceScene
        The face's meshes in ``m``'s pose (world frame, mm).
    appearance : Appearance
        The BRDF, albedo map and optional normal and specular maps (:meth:`FaceScene.scene`).
    region_map : (R', R') uint8
        Region labels in texture space (the pixels' labels).
    scale : (3,) array
        Photograph value -> renderer units (s_white/π, eq. 4).
    lamp_radius : float or None
        Radius (mm) of a spherical lamp in place of a point light.
    rendering : RenderSettings
        The render's resolution (``downsample``), samples per pixel, integrator and film border.

    Returns
    -------
    PhotographView
    """
    k = rendering.downsample
    camera = capture.camera_of(m)
    light, lamp = _light(capture, m, lamp_radius)
    kind = "sphere" if lamp is not None else light.emitter_kind
    description = face.scene(appearance.brdf, appearance.albedo, camera, light, normals=appearance.normals,
                             specular=appearance.specular)
    labels = face_pixels(face, camera, spp=None, region_map=region_map)
    covered = binary_erosion(labels > 0, iterations=1) & ~m.image.saturated
    # the render's pixels: those whose every photograph pixel is covered
    low_mask = _box_mean(covered.astype(np.float64), k) > 0.999
    if not low_mask.any():
        raise ValueError(f"measurement {m.name!r}: the face covers no unsaturated pixel")
    rows, cols = np.nonzero(low_mask)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    target = _box_mean(m.image.pixels * scale, k)[r0:r1, c0:c1]
    mask = low_mask[r0:r1, c0:c1]
    mean = float(target[mask].mean())
    sensor = mitsuba_sensor(camera, rendering.spp)
    sensor["film"] = dict(sensor["film"], width=camera.width // k, height=camera.height // k,
                          crop_offset_x=int(c0), crop_offset_y=int(r0), crop_width=int(c1 - c0),
                          crop_height=int(r1 - r0), rfilter={"type": "gaussian", "stddev": 0.5 / k}
                          if k == 1 else {"type": "box"}, sample_border=bool(rendering.sample_border))
    description["sensor"] = sensor
    description["integrator"] = rendering.integrator
    if lamp is not None:
        description["light"] = lamp
    scene = mi.load_dict(description)
    low_labels = labels[: labels.shape[0] // k * k, : labels.shape[1] // k * k][::k, ::k][r0:r1, c0:c1]
    return PhotographView(scene, mi.traverse(scene), mi.TensorXf(np.ascontiguousarray(target / mean, np.float32)),
                          mask, low_labels, 1.0 / mean, kind)


__all__ = ["LAMP_RADIUS_KEY", "Appearance", "PhotographView", "RenderSettings", "image_loss", "mask_weight",
           "photograph_view"]
