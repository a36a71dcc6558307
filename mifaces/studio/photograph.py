"""The studio's photographs: Mitsuba renders of :mod:`mifaces.studio.scene`
scenes through the camera's sensor model (shot and read noise, exposure,
clipping), and the feature points an annotator clicks on them.

Every random draw comes from the generator passed in, in a fixed order, and
every render takes the next of ``seeds`` as its Monte Carlo seed: a fixed
seed reproduces the photographs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import mitsuba as mi
import numpy as np

from ..capture import Camera
from ..model.landmarks import FEATURE_POINTS
from ..render.crop import CroppedScene, box_corners, dark_background
from .scene import DIFFUSE_LIGHT, LAMP_RADIUS, STEEL_SPHERE_RADIUS, Studio, face_light, lamp, scene, steel_spheres

#: Sensor model: electrons at full scale (shot noise) and read noise (full-scale units).
FULL_WELL = 20000.0
READ_NOISE = 0.002
#: Exposure series of the ``exposures`` companion, relative to the point-light photograph.
EXPOSURE_FACTORS = (0.25, 1.0, 4.0)
#: Exposure of the diffuse-light pictures (companions and steel-sphere outlines).
DIFFUSE_EXPOSURE = 0.8
#: The steel-sphere highlight picture is exposed so that its brightest highlight reads this.
HIGHLIGHT_LEVEL = 0.7


@dataclass(frozen=True, eq=False)
class SpherePhotographs:
    """The two steel-sphere pictures of one light condition, noisy, with their exposures."""

    highlight: np.ndarray
    highlight_exposure: float
    outline: np.ndarray
    outline_exposure: float


@dataclass(frozen=True, eq=False)
class Photographs:
    """The pictures of one measurement: the point-light (or environment-lit) photograph and its
    companions (``diffuse`` or None, ``exposures`` a list of (picture, exposure), maybe empty)."""

    point: np.ndarray
    exposure: float
    diffuse: np.ndarray | None
    diffuse_exposure: float
    exposures: list[tuple[np.ndarray, float]]


def camera_noise(values: np.ndarray, rng: np.random.Generator, full_well: float = FULL_WELL,
                 read_noise: float = READ_NOISE) -> np.ndarray:
    """Sensor noise on linear values in full-scale units, clipped to [0, 1].

    Photon (shot) noise with ``full_well`` electrons at full scale (Gaussian
    approximation, variance v / full_well) plus Gaussian read noise of
    standard deviation ``read_noise``.
    """
    v = np.clip(np.asarray(values, np.float64), 0.0, None)
    noisy = v + rng.standard_normal(v.shape) * np.sqrt(v / full_well + read_noise ** 2)
    return np.clip(noisy, 0.0, 1.0).astype(np.float32)


def render(scene_dict: dict, spp: int, seed: int, shown: tuple | None = None) -> np.ndarray:
    """Linear RGB radiance (H, W, 3) float32 of a scene dict, ``spp`` samples per pixel. With
    ``shown``, the camera of the scene's sensor and the point sets of the objects that can show
    (:class:`~mifaces.render.crop.CroppedScene`), only their windows are rendered: the rest is 0."""
    if shown is not None:
        return CroppedScene(scene_dict, *shown).render(spp, seed)
    return np.array(mi.render(mi.load_dict(scene_dict), spp=spp, seed=seed), dtype=np.float32)[..., :3]


def albedo_texture(albedo: np.ndarray):
    """The albedo map as a Mitsuba bitmap texture (raw linear values, bilinear, clamped)."""
    return mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(albedo), "raw": True,
                         "filter_type": "bilinear", "wrap_mode": "clamp"})


def photograph_spheres(studio: Studio, light: int, spp: int, seeds: Iterator[int],
                       rng: np.random.Generator) -> SpherePhotographs:
    """The steel spheres under the lamp of condition ``light`` and under the diffuse light."""
    spp_hl = max(4 * spp, 256)  # the lamp's reflection is a few pixels wide: sample it well
    # in the dark studio only the spheres and the lamp can show: only their windows are rendered
    shown = [box_corners(c, STEEL_SPHERE_RADIUS) for c in studio.sphere_centers]
    shown.append(box_corners(studio.light_positions[light], LAMP_RADIUS))
    hl = render(scene(studio, steel_spheres(studio), lamp(studio, light), spp_hl), spp_hl, next(seeds),
                (studio.camera, shown))
    t_hl = HIGHLIGHT_LEVEL / max(float(hl.max()), 1e-12)
    hl = camera_noise(hl * t_hl, rng)
    spp_ol = max(spp // 2, 4)
    ol = render(scene(studio, steel_spheres(studio), DIFFUSE_LIGHT, spp_ol), spp_ol, next(seeds))
    ol = camera_noise(ol * DIFFUSE_EXPOSURE, rng)
    return SpherePhotographs(hl, t_hl, ol, DIFFUSE_EXPOSURE)


def photograph_face(studio: Studio, meshes: dict, light: int, companion: str, spp: int, seeds: Iterator[int],
                    rng: np.random.Generator, shown: tuple | None = None) -> Photographs:
    """The face (Mitsuba meshes ``meshes``) under point light ``light`` (or the studio's environment,
    :func:`~mifaces.studio.scene.face_light`), and its companions: ``'diffuse'`` (a picture under
    the diffuse light, half the samples), ``'exposures'`` (the same render at
    :data:`EXPOSURE_FACTORS` times the exposure) or ``'both'``. With ``shown``, the camera of
    ``studio``'s sensor and the face's vertices (world, mm), a picture in which nothing else can show
    renders only the face's window (:mod:`mifaces.render.crop`)."""
    lit = scene(studio, meshes, face_light(studio, light), spp)
    crop = None if shown is None or not dark_background(lit) else (shown[0], [shown[1]])
    radiance = render(lit, spp, next(seeds), crop)
    point = camera_noise(radiance * studio.exposure, rng)
    diffuse, exposures = None, []
    if companion in ("diffuse", "both"):
        spp_d = max(spp // 2, 4)
        diffuse = render(scene(studio, meshes, DIFFUSE_LIGHT, spp_d), spp_d, next(seeds))
        diffuse = camera_noise(diffuse * DIFFUSE_EXPOSURE, rng)
    if companion in ("exposures", "both"):
        for factor in EXPOSURE_FACTORS:
            t_k = studio.exposure * factor
            exposures.append((camera_noise(radiance * t_k, rng), t_k))
    return Photographs(point, studio.exposure, diffuse, DIFFUSE_EXPOSURE, exposures)


def visible_feature_points(face_model) -> list[str]:
    """The feature points (:data:`mifaces.model.landmarks.FEATURE_POINTS`) the model has landmarks for."""
    return [n for n in FEATURE_POINTS if FEATURE_POINTS[n] in face_model.ibug_landmarks]


def annotate(meshes: dict, vertices: np.ndarray, face_model, names: list[str], camera: Camera,
             rng: np.random.Generator) -> tuple[dict[str, list], dict[str, list]]:
    """The feature points ``names`` as an annotator clicks them on a photograph of the face
    (Mitsuba ``meshes``, world-space ``vertices``): those whose landmark the camera sees,
    with 0.5 px noise per coordinate at 512 pixels width, rounded to 0.01 px.

    Returns
    -------
    points, exact : dict
        Name -> [x, y] clicked, and name -> [x, y] the exact projection.
    """
    targets = np.array([vertices[face_model.ibug_landmarks[FEATURE_POINTS[f]]] for f in names])
    offsets = targets - camera.position
    lengths = np.linalg.norm(offsets, axis=1)
    units = offsets / lengths[:, None]
    origin = [mi.Float(np.full(len(targets), c)) for c in camera.position]
    ray = mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(*[mi.Float(units[:, k]) for k in range(3)]))
    ray.maxt = mi.Float(lengths - 1.0)  # a landmark is visible when nothing is hit before it
    occluded = np.asarray(mi.load_dict({"type": "scene", **meshes}).ray_test(ray))
    points, exact = {}, {}
    for name, p, hidden in zip(names, targets, occluded):
        if hidden:
            continue
        xy = camera.project(p)
        exact[name] = xy.tolist()
        points[name] = (xy + rng.normal(0.0, 0.5 * camera.width / 512, 2)).round(2).tolist()
    return points, exact
