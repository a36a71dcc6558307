"""Environments that light a face for novel views: a studio generated in
code, and Mitsuba's ``sunsky`` daylight; both placed in the camera's frame.

Frames. A face scene is in its capture's world frame (mm); its camera says
where "up" and "towards the camera" are (:attr:`mifaces.capture.Camera.frame`): up is the
camera's −y axis (OpenCV: y points down in the image), "towards the camera"
its −z axis. Every environment is placed in that frame, so it lights a face
the same way whatever the capture's world frame is.

- An equirectangular map (Mitsuba's ``envmap``: u = atan2(x, −z) / 2π,
  v = acos(y) / π in its local frame, +y up) is turned so that its local +y
  is the camera's up and its local +z points towards the camera: the map's
  centre column (u = ½) lies behind the camera, its left and right edges
  behind the face.
- Mitsuba's ``sunsky`` (Hošek & Wilkie 2012, 2013: sky dome and sun) has its
  zenith along local +z. Given a time and place, Mitsuba puts the sun's
  south at local +x and east at local −y; the sky is turned so that south
  lies towards the camera (the face looks south) with east on the image's
  right, as it is for a camera looking north. A sun direction is given in
  the world frame instead. Its radiance is in physical units
  (W m⁻² sr⁻¹ nm⁻¹): a face in clear-sky daylight reads about 0.1–0.5 with
  scale 1, like the simulated photographs.
"""

from __future__ import annotations

import datetime as _dt
import os
from dataclasses import dataclass
from pathlib import Path

import mitsuba as mi
import numpy as np

from ..brdf.model import check_numbers
from ..model.geometry import camera_frame_direction

#: The studio's soft boxes about the camera: name, azimuth and elevation
#: (degrees, as :meth:`mifaces.capture.Camera.direction`: 0 0 from the camera,
#: positive azimuth towards the image's left), angular radius (degrees) and
#: radiance (linear, white).
STUDIO_PANELS = (("key", 40.0, 30.0, 22.0, 4.0), ("fill", -50.0, 10.0, 28.0, 0.8),
                 ("rim", -150.0, 40.0, 14.0, 2.0), ("top", 0.0, 80.0, 18.0, 0.8))
#: Radiance of the studio's walls: above and below the horizon (a dim room).
STUDIO_AMBIENT = (0.06, 0.02)
#: Default height of the generated studio map (pixels; the width is twice this).
STUDIO_HEIGHT = 128
#: Range of the sky's turbidity that Mitsuba's sun and sky model covers.
TURBIDITY = (1.0, 10.0)
#: The sky's turbidity unless one is given (clear).
SKY_TURBIDITY = 3.0
#: Default height of a baked map (:func:`bake_environment`; pixels, the width is twice this).
BAKE_HEIGHT = 256
#: Sub-samples per texel side of a bake; a texel whose sub-samples differ by more than
#: :data:`BAKE_CONTRAST` times their mean (the sun's disc, the horizon) is baked again with
#: :data:`BAKE_REFINED` per side, so that a sun smaller than a texel keeps its energy.
BAKE_SAMPLES = 8
BAKE_REFINED = 64
BAKE_CONTRAST = 0.5
#: Directions a bake evaluates at once (bounds its memory).
_BAKE_LANES = 1 << 20
#: Environments the validation renders: the studio and a sky with the sun
#: at these angles about the camera (azimuth, elevation; :meth:`Camera.direction`).
SKY_SUN_ANGLES = (-35.0, 40.0)
#: Luminance weights (Rec. 709) that rank texels and directions by brightness.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: Surface orientations :func:`peak_irradiance` searches (a grid of this height, twice as wide:
#: E(n) is smooth, a 5.6° grid finds its peak to 0.1 %).
PEAK_NORMALS_HEIGHT = 32


def _transform(columns: np.ndarray) -> mi.ScalarTransform4f:
    matrix = np.eye(4)
    matrix[:3, :3] = columns
    return mi.ScalarTransform4f(matrix.tolist())


def map_directions(u, v) -> np.ndarray:
    """Unit directions (..., 3) of equirectangular map coordinates ``u`` (columns) and ``v``
    (rows) in [0, 1], in the map's local frame (Mitsuba's ``envmap``: φ = 2π u, θ = π v,
    d = (sin θ sin φ, cos θ, −sin θ cos φ), +y up); ``u`` and ``v`` broadcast together
    (a row of ``u`` and a column of ``v`` give the map's grid)."""
    phi, theta = np.broadcast_arrays(2 * np.pi * np.asarray(u, np.float64), np.pi * np.asarray(v, np.float64))
    return np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], axis=-1)


def texel_directions(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (H*W, 3) in the map's frame of an H x W map's texels, row by row, as
    Mitsuba's ``envmap`` places them: texel (row j, column i) at u = (i + 1/2) / W,
    v = j / (H - 1) (it interpolates bilinearly, the first and last rows at the poles), and their
    solid angles (H*W,) (the rows' bands around them; they sum to 4π)."""
    d = map_directions(((np.arange(width) + 0.5) / width)[None, :], (np.arange(height) / (height - 1))[:, None])
    edges = np.clip((np.arange(height + 1) - 0.5) / (height - 1), 0, 1) * np.pi
    band = np.cos(edges[:-1]) - np.cos(edges[1:])
    solid = np.repeat(band[:, None] * 2 * np.pi / width, width, axis=1)
    return d.reshape(-1, 3), solid.ravel()


def to_world(directions: np.ndarray, camera) -> np.ndarray:
    """Directions (N, 3) in the map's frame turned into ``camera``'s world frame."""
    return np.asarray(directions, np.float64) @ camera.frame.T


def dominant_direction(envmap: np.ndarray, camera) -> np.ndarray:
    """The world unit direction of ``envmap``'s irradiance vector (placed by
    :func:`environment_emitter` for ``camera``): where most of its light comes from."""
    envmap = np.asarray(envmap, np.float64)
    d, solid = texel_directions(envmap.shape[1], envmap.shape[0])
    vector = to_world(((envmap.reshape(-1, 3) @ LUMINANCE) * solid) @ d, camera)
    return vector / max(float(np.linalg.norm(vector)), 1e-30)


def peak_irradiance(envmap: np.ndarray) -> np.ndarray:
    """The largest unoccluded irradiance (3,) ``envmap`` (H, W, 3) gives a surface
    (:func:`irradiance`): at the normal, of a grid :data:`PEAK_NORMALS_HEIGHT` high and twice as
    wide over the sphere, where its luminance is largest. The scale of a simulated capture's
    exposure and of an estimated map."""
    h = PEAK_NORMALS_HEIGHT
    normals = map_directions((np.arange(2 * h)[None] + 0.5) / (2 * h), (np.arange(h)[:, None] + 0.5) / h)
    e = irradiance(envmap, normals.reshape(-1, 3))
    return e[np.argmax(e @ LUMINANCE)]


def studio_environment(height: int = STUDIO_HEIGHT) -> np.ndarray:
    """A small photo studio as an equirectangular map (``height`` x 2 ``height``
    x 3, float32 linear radiance), generated here (no download): the
    :data:`STUDIO_PANELS` soft boxes (discs of smooth edges, a quarter of their
    radius wide) over dim walls (:data:`STUDIO_AMBIENT`, brighter above the
    horizon). Directions are those of the map's local frame (+y up, +z towards
    the camera once placed by :func:`environment_emitter`)."""
    height = int(check_numbers("studio map height", height, minimum=8))
    width = 2 * height
    d = map_directions((np.arange(width)[None] + 0.5) / width, (np.arange(height)[:, None] + 0.5) / height)
    above, below = STUDIO_AMBIENT
    smooth = np.clip(d[..., 1] * 4 + 0.5, 0, 1)  # a soft horizon
    image = (below + (above - below) * smooth)[..., None] * np.ones(3)
    for _, azimuth, elevation, radius, radiance in STUDIO_PANELS:
        centre = camera_frame_direction(azimuth, elevation) * [1, -1, -1]  # OpenCV axes to the map's
        angle = np.degrees(np.arccos(np.clip(d @ centre, -1, 1)))
        edge = 0.25 * radius
        weight = np.clip((radius + edge / 2 - angle) / edge, 0, 1)
        image += radiance * weight[..., None]
    return image.astype(np.float32)


def environment_emitter(envmap, camera, scale: float = 1.0) -> dict:
    """A Mitsuba ``envmap`` emitter dict of an equirectangular map (a path or
    an (H, W, 3) array, linear RGB) placed in ``camera``'s frame (see the
    module docstring), its radiance times ``scale``."""
    check_numbers("environment map scale", scale, minimum=0.0)
    emitter = {"type": "envmap", "scale": float(scale), "to_world": _transform(camera.frame)}
    if isinstance(envmap, np.ndarray):
        if envmap.ndim != 3 or envmap.shape[2] != 3 or not np.all(np.isfinite(envmap)) or envmap.min() < 0:
            raise ValueError(f"an environment map must be a finite, non-negative (H, W, 3) array, got shape "
                             f"{envmap.shape}")
        emitter["bitmap"] = mi.Bitmap(np.ascontiguousarray(envmap, np.float32))
    else:
        emitter["filename"] = str(envmap)
    return emitter


@dataclass(frozen=True, eq=False)
class Environment:
    """Light from every direction around a face: an equirectangular map times a scale, or an
    emitter that carries its own (:func:`sky_emitter`'s), placed in the camera's frame (module
    docstring). A face scene's environment (:meth:`mifaces.render.FaceScene.render`), beside or
    instead of a capture's :class:`~mifaces.lights.light.Light`.

    Validated on construction: a ``ValueError`` for a negative or non-finite scale or a scale on
    an emitter, a ``FileNotFoundError`` for a map file that is not there.

    Attributes
    ----------
    source : path, (H, W, 3) array or dict
        The map (a file, or linear RGB radiance; its local frame as :func:`environment_emitter`
        places it), or a Mitsuba emitter dict.
    scale : float
        Factor on the map's radiance; 1 for an emitter.
    """

    source: object
    scale: float = 1.0

    def __post_init__(self):
        check_numbers("environment map scale", self.scale, minimum=0.0)
        if isinstance(self.source, dict) and self.scale != 1.0:
            raise ValueError("an environment given as an emitter carries its own scale: leave the scale at 1")
        if isinstance(self.source, (str, os.PathLike)) and not Path(self.source).is_file():
            raise FileNotFoundError(f"environment map not found: {self.source}")

    def emitter(self, camera) -> dict:
        """The Mitsuba emitter dict lighting a scene ``camera`` sees (:func:`environment_emitter`)."""
        if isinstance(self.source, dict):
            return self.source
        path = isinstance(self.source, (str, os.PathLike))
        return environment_emitter(str(self.source) if path else np.asarray(self.source, np.float32), camera,
                                   self.scale)


def sky_emitter(camera, sun_direction=None, time: str | _dt.datetime | None = None, place=None,
                turbidity: float = SKY_TURBIDITY, ground_albedo: float = 0.3, scale: float = 1.0) -> dict:
    """Mitsuba's ``sunsky`` emitter dict (Hošek–Wilkie sun and sky) placed in
    ``camera``'s frame (module docstring).

    Parameters
    ----------
    camera : mifaces.capture.Camera
    sun_direction : (3,) array, optional
        World-frame direction from the face towards the sun; it must be above
        the camera's horizon. Default, without ``time``: the sun at
        :data:`SKY_SUN_ANGLES` about the camera (:meth:`Camera.direction`).
    time : str or datetime, optional
        Local time, ISO 8601 (``'2024-06-21T08:30'``), instead of a
        direction; with ``place``.
    place : (latitude, longitude, timezone), optional
        Degrees north, degrees east, hours ahead of UTC. Default (0, 0, 0).
    turbidity : float
        Haze, within :data:`TURBIDITY` (2: arctic clear, 3: clear, 10: hazy).
    ground_albedo : float
        Reflectance of the ground under the sky, in [0, 1].
    scale : float
        Factor on the sun's and the sky's radiance.
    """
    check_numbers("turbidity", turbidity)
    if not TURBIDITY[0] <= float(turbidity) <= TURBIDITY[1]:
        raise ValueError(f"turbidity must lie within {list(TURBIDITY)} (Mitsuba's sun and sky model), "
                         f"got {turbidity}")
    check_numbers("ground albedo", ground_albedo, minimum=0.0)
    if float(ground_albedo) > 1:
        raise ValueError(f"ground albedo must lie within [0, 1], got {ground_albedo}")
    check_numbers("sky scale", scale, minimum=0.0)
    frame = camera.frame
    right, up, towards = frame.T
    emitter = {"type": "sunsky", "turbidity": float(turbidity), "albedo": float(ground_albedo),
               "sun_scale": float(scale), "sky_scale": float(scale),
               # local x (south) towards the camera, local -y (east) to the image's right, local z up: a mirror
               "to_world": _transform(np.stack([towards, -right, up], axis=1))}
    if time is not None:
        if sun_direction is not None:
            raise ValueError("give the sun's direction or a time and place, not both")
        emitter.update(_time_and_place(time, place))
        return emitter
    if place is not None:
        raise ValueError("a place needs a time (the sun's position follows from both)")
    if sun_direction is None:
        sun_direction = camera.direction(*SKY_SUN_ANGLES)
    sun = check_numbers("sun direction", sun_direction, 3)
    norm = float(np.linalg.norm(sun))
    if norm == 0:
        raise ValueError("the sun direction must be a non-zero 3-vector")
    sun = np.asarray(sun, np.float64) / norm
    if sun @ up <= 0:
        raise ValueError(f"the sun must be above the horizon (the camera's up is {np.round(up, 3).tolist()}), "
                         f"got direction {np.round(sun, 3).tolist()}")
    emitter["sun_direction"] = [float(x) for x in sun]
    return emitter


def bake_environment(emitter: dict, camera, height: int = BAKE_HEIGHT, samples: int = BAKE_SAMPLES) -> np.ndarray:
    """An emitter (a Mitsuba emitter dict, e.g. :func:`sky_emitter`) as an equirectangular map
    that :func:`environment_emitter` places where the emitter was: (``height``, 2 ``height``, 3)
    float32 linear radiance in the map's local frame (+y the camera's up, +z towards the camera).

    Each texel holds the emitter's mean radiance over the texel's solid angle: the emitter is
    evaluated (``Emitter.eval``) at ``samples`` x ``samples`` directions per texel, stratified
    in (u, v) and weighted by sin θ (dω = sin θ dθ dφ); where those differ by more than
    :data:`BAKE_CONTRAST` times their mean (the edge of the sun's disc, the horizon) the texel
    is evaluated again at :data:`BAKE_REFINED` x :data:`BAKE_REFINED` directions. Radiance times
    solid angle, the energy, is kept also for a sun far smaller than a texel (the sun's 0.53°
    disc is half a texel at the default height). ``samples`` must be fine enough for the first
    pass to see the sun: 8 per side at the default height are 0.09° apart.

    Examples
    --------
    >>> from mifaces.studio.scene import studio_camera
    >>> camera = studio_camera(64, 64, np.zeros(3))
    >>> bake_environment(sky_emitter(camera), camera, height=16).shape
    (16, 32, 3)
    """
    height = int(check_numbers("baked map height", height, minimum=4))
    samples = int(check_numbers("samples per texel side", samples, minimum=1))
    source = mi.load_dict(emitter)
    width = 2 * height
    image = np.empty((height, width, 3), np.float32)
    rows = max(1, _BAKE_LANES // (width * samples ** 2))
    sharp = []
    for top in range(0, height, rows):
        bottom = min(height, top + rows)
        texels = np.stack(np.meshgrid(np.arange(top, bottom), np.arange(width), indexing="ij"), -1).reshape(-1, 2)
        mean, contrasted = _texel_radiance(source, camera, texels, height, samples)
        image[top:bottom] = mean.reshape(bottom - top, width, 3)
        sharp.append(texels[contrasted])
    sharp = np.concatenate(sharp)
    chunk = max(1, _BAKE_LANES // BAKE_REFINED ** 2)
    for start in range(0, len(sharp), chunk):
        texels = sharp[start:start + chunk]
        image[texels[:, 0], texels[:, 1]] = _texel_radiance(source, camera, texels, height, BAKE_REFINED)[0]
    return image


def _texel_radiance(source, camera, texels: np.ndarray, height: int, n: int):
    """The mean radiance (T, 3) of emitter ``source`` over the solid angle of map ``texels``
    (T, 2: row, column) as Mitsuba reads the map (:func:`texel_directions`: row j the band
    v in [(j - 1/2) / (H - 1), (j + 1/2) / (H - 1)], clipped at the poles) from n x n stratified
    directions, and whether their values differ by more than :data:`BAKE_CONTRAST` times their
    mean (T,)."""
    offsets = (np.arange(n) + 0.5) / n
    top = np.clip((texels[:, 0] - 0.5) / (height - 1), 0, 1)
    bottom = np.clip((texels[:, 0] + 0.5) / (height - 1), 0, 1)
    v = top[:, None, None] + (bottom - top)[:, None, None] * offsets[None, :, None]
    u = (texels[:, 1, None, None] + offsets[None, None, :]) / (2 * height)
    world = -to_world(map_directions(u, v).reshape(-1, 3), camera)  # Emitter.eval looks along -wi
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*(mi.Float(np.ascontiguousarray(world[:, k], np.float32)) for k in range(3)))
    radiance = np.asarray(source.eval(si), np.float64).T.reshape(len(texels), n * n, 3)  # Color3f: (3, N)
    weight = np.broadcast_to(np.sin(np.pi * v), (len(texels), n, n)).reshape(len(texels), n * n)
    mean = np.einsum("tkc,tk->tc", radiance, weight) / weight.sum(axis=1)[:, None]
    level = radiance.max(axis=2)
    contrasted = level.max(axis=1) - level.min(axis=1) > BAKE_CONTRAST * level.mean(axis=1)
    return mean.astype(np.float32), contrasted


def irradiance(envmap: np.ndarray, normals) -> np.ndarray:
    """Irradiance E(n) = ∫ L(ω) max(0, n·ω) dω (N, 3) of an equirectangular map ``envmap``
    (H, W, 3, linear radiance) on unoccluded surfaces facing unit ``normals`` (N, 3, the map's local
    frame), each texel in its direction and solid angle as Mitsuba reads it (:func:`texel_directions`).
    A white Lambertian surface facing n reflects radiance E(n) / π."""
    envmap = np.asarray(envmap, np.float64)
    directions, solid = texel_directions(envmap.shape[1], envmap.shape[0])
    power = envmap.reshape(-1, 3) * solid[:, None]
    normals = np.atleast_2d(np.asarray(normals, np.float64))
    step = max(1, _BAKE_LANES // len(directions))
    return np.concatenate([np.clip(normals[k:k + step] @ directions.T, 0, None) @ power
                           for k in range(0, len(normals), step)])


def _time_and_place(time, place) -> dict:
    """The ``sunsky`` properties of a local time and a place."""
    if isinstance(time, str):
        try:
            time = _dt.datetime.fromisoformat(time)
        except ValueError:
            raise ValueError(f"sky time {time!r} is not an ISO 8601 date and time such as 2024-06-21T08:30") from None
    if not isinstance(time, _dt.datetime):
        raise ValueError(f"sky time must be a datetime or an ISO 8601 string, got {time!r}")
    latitude, longitude, timezone = check_numbers("place (latitude, longitude, timezone)",
                                                  (0.0, 0.0, 0.0) if place is None else place, 3)
    if abs(latitude) > 90 or abs(longitude) > 180 or abs(timezone) > 14:
        raise ValueError(f"place must be latitude in [-90, 90], longitude in [-180, 180] degrees and a timezone "
                         f"within ±14 h, got {list(place)}")
    return {"latitude": float(latitude), "longitude": float(longitude), "timezone": float(timezone),
            "year": time.year, "month": time.month, "day": time.day, "hour": float(time.hour),
            "minute": float(time.minute), "second": float(time.second)}


__all__ = ["STUDIO_PANELS", "STUDIO_AMBIENT", "STUDIO_HEIGHT", "TURBIDITY", "SKY_TURBIDITY", "SKY_SUN_ANGLES",
           "BAKE_HEIGHT", "BAKE_SAMPLES", "BAKE_REFINED", "BAKE_CONTRAST", "Environment", "map_directions",
           "studio_environment", "environment_emitter", "sky_emitter", "bake_environment", "irradiance",
           "peak_irradiance"]
