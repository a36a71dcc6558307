"""The simulated subject: a morphable-model face, its albedo map, and its
pose and expression in each measurement (lengths in mm, world frame)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.ndimage as ndi

from ..model.geometry import head_centre, rotation_matrix, turned
from ..model.texture_space import bake
from .skin import paint_skin


@dataclass(frozen=True, eq=False)
class Subject:
    """A face: model coefficients, the neutral shape and the albedo map.

    Attributes
    ----------
    coefficients : dict
        ``shape`` (and ``color`` for a model with texture) coefficients.
    neutral : (V, 3)
        The neutral face, mm.
    head : (3,) float64
        Centre of the neutral face's bounding box: the centre of head rotations.
    albedo : (N, N, 3) float32
        Linear RGB albedo map in the model's texture space.
    detail : (V, 3) float64, optional
        Offsets (mm, model frame) the model cannot express, added to the face
        in every pose and expression (:mod:`mifaces.studio.detail`);
        ``neutral`` includes them.
    """

    coefficients: dict[str, np.ndarray]
    neutral: np.ndarray
    head: np.ndarray
    albedo: np.ndarray
    detail: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class HeadPose:
    """The subject in one measurement: ``vertices = R (shape(expression) - head) + head + t``.

    ``yaw_pitch_roll`` in degrees (:func:`mifaces.model.geometry.rotation_matrix`),
    ``expression`` the expression coefficients (None for a model without
    expressions), ``vertices`` (V, 3) float64 in world space.
    """

    yaw_pitch_roll: tuple[float, float, float]
    rotation: np.ndarray
    translation: np.ndarray
    expression: np.ndarray | None
    vertices: np.ndarray


def make_subject(face_model, rng: np.random.Generator, albedo_resolution: int) -> Subject:
    """A typical (not an extreme) face of ``face_model``: random coefficients scaled by 0.7, and
    its albedo map with fine detail (:func:`albedo_map`)."""
    coefficients = face_model.random_coefficients(rng)
    coefficients["shape"] *= 0.7
    if "color" in coefficients:
        coefficients["color"] *= 0.7
    neutral = face_model.shape(coefficients["shape"])
    head = head_centre(neutral, face_model.ibug_landmarks)
    albedo = albedo_map(face_model, coefficients.get("color"), rng, albedo_resolution)
    return Subject(coefficients, neutral, head, albedo)


def with_detail(subject: Subject, detail: np.ndarray) -> Subject:
    """``subject`` with fine ``detail`` (V, 3) added to its face (the head centre stays)."""
    return replace(subject, neutral=(subject.neutral + detail).astype(np.float32), detail=np.asarray(detail, np.float64))


def head_pose(face_model, subject: Subject, turn: tuple[float, float, float],
              rng: np.random.Generator) -> HeadPose:
    """The subject turned by ``turn`` (yaw, pitch, roll in degrees: one of the studio's poses,
    :attr:`mifaces.studio.scene.Studio.poses`), as a sitter holds it: jittered by up to 3° yaw,
    4° pitch, 2° roll, moved by 3 mm (standard deviation) and with a small random expression."""
    yaw, pitch, roll = turn
    yaw += rng.uniform(-3, 3)
    pitch += rng.uniform(-4, 4)
    roll += rng.uniform(-2, 2)
    rotation = rotation_matrix(yaw, pitch, roll)
    translation = rng.normal(0.0, 3.0, 3)
    expression = None
    if face_model.has_expressions:
        expression = np.abs(rng.normal(0.0, 0.12, face_model.expression_dim))
    local = face_model.shape(subject.coefficients["shape"], expression).astype(np.float64)
    if subject.detail is not None:
        local = local + subject.detail
    vertices = turned(local, rotation, subject.head) + translation
    return HeadPose((yaw, pitch, roll), rotation, translation, expression, vertices)


def albedo_map(model, color, rng: np.random.Generator, size: int = 1024, detail: float = 0.12) -> np.ndarray:
    """Per-texel albedo (size, size, 3), linear RGB, in the model's texture space.

    The model's per-vertex albedo for colour coefficients ``color``,
    interpolated over the triangles (for a model without colour model, a
    painted skin: :func:`mifaces.studio.skin.paint_skin`), times fine multiplicative detail:
    log-normal noise at pore/freckle scales (1-2 texels and ~6 texels;
    ``detail`` is its standard deviation in log units), and a few darker
    spots. Texels no triangle covers take the nearest covered texel.
    """
    if model.has_texture:
        image = bake(model.uv, model.triangles, model.texture(color), size)
    else:
        image = paint_skin(model, rng, size).astype(np.float64)
    fine = ndi.gaussian_filter(rng.standard_normal((size, size)), 0.8)
    medium = ndi.gaussian_filter(rng.standard_normal((size, size)), 3.0)
    fine /= fine.std()
    medium /= medium.std()
    spots = ndi.gaussian_filter((rng.random((size, size)) < 2e-4).astype(float), 2.0)
    spots /= max(spots.max(), 1e-12)
    log = detail * (0.6 * fine + 0.8 * medium) - 0.5 * spots
    tint = np.array([0.8, 1.0, 1.15])  # spots are melanin: darker in blue than red
    image = image * np.exp(log[..., None] * tint)
    return np.clip(image, 0.0, 0.95).astype(np.float32)
