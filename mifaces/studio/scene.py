"""The studio's geometry and its Mitsuba scenes (paper sec. 3).

A fixed, calibrated camera on the +z axis through the head; point lights on
a sphere of about :data:`LIGHT_DISTANCE` around the head, in front of the
face; four steel spheres in a plane facing the camera, around the head, to
locate each light from; a black room (no geometry but the subject and the
spheres: the walls return no light). Or, for a capture lit by an environment
(:mod:`mifaces.studio.environment_light`), that environment around the same
camera, no point lights and no spheres, and the head turned differently in
every photograph (:func:`head_turns`). Lengths in mm, world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..brdf.model import rgb
from ..capture import Camera, Light
from ..lights.emitters import light_emitters
from ..lights.environment import Environment
from ..render import mitsuba_sensor
from .environment_light import EnvironmentLight, environment_light

#: Studio geometry (mm). Camera distance to the head centre, field height there.
CAMERA_DISTANCE = 1200.0
FIELD_HEIGHT = 300.0
LIGHT_DISTANCE = 1500.0
#: Radius of the steel spheres and of the lamp's emitting sphere (mm). The lamp is a sphere in the
#: calibration pictures only (a point's mirror image has no area); its size makes the highlight a few
#: pixels wide, which locates it to a few hundredths of a pixel.
STEEL_SPHERE_RADIUS = 40.0
LAMP_RADIUS = 120.0
#: Steel-sphere centres relative to the head centre (mm, world frame).
SPHERE_OFFSETS = np.array([[-95.0, 95.0, 0.0], [95.0, 95.0, 0.0], [-95.0, -95.0, 0.0], [95.0, -95.0, 0.0]])
#: Exposures: the white target at the light distance reads this fraction of full scale.
WHITE_LEVEL = 0.5
#: Up to three poses per light: (yaw, pitch, roll) in degrees, before the subject's jitter.
POSES = [(0.0, 0.0, 0.0), (-25.0, 0.0, 0.0), (25.0, 0.0, 0.0)]
#: The head turns of an environment-lit capture spread over these yaw and pitch ranges (degrees).
TURN_YAW = (-35.0, 35.0)
TURN_PITCH = (-12.0, 12.0)
#: Yaw (degrees, about the head's vertical axis) of each camera of a simulated rig (``SimulationOptions(cameras=N)``
#: takes the first N): the studio camera in front, then others turned to either side.
RIG_YAWS = (0.0, -30.0, 30.0, -50.0, 50.0)
#: Mitsuba's path tracer: shadows and one-bounce-and-more interreflection.
INTEGRATOR = {"type": "path", "max_depth": 4, "hide_emitters": False}
#: The diffuse light of the companion and steel-sphere outline pictures: uniform white from all around.
DIFFUSE_LIGHT = {"diffuse_light": {"type": "constant", "radiance": rgb(1.0)}}


@dataclass(frozen=True, eq=False)
class Studio:
    """The studio set up around one subject.

    Attributes
    ----------
    camera : Camera
    head : (3,) float64
        The head centre, mm.
    light_positions : (L, 3) float64
        World positions of the point light in its L conditions, mm.
    intensity : (3,) float64
        Radiant intensity of the point light (the white target at
        :data:`LIGHT_DISTANCE` reads 1 per unit exposure).
    exposure : float
        Exposure of the point-light photographs.
    per_light : list of int
        Number of poses (measurements) per light condition.
    sphere_centers : (4, 3) float64
        Steel-sphere centres, mm.
    sensor : dict
        The Mitsuba sensor of ``camera``.
    integrator : dict
        The Mitsuba integrator of its pictures (:data:`INTEGRATOR`; the
        volumetric path tracer for a translucent subject).
    poses : list of (yaw, pitch, roll)
        The head turns (degrees, before the sitter's jitter) the pose indices
        of :attr:`schedule` refer to: :data:`POSES`, or :func:`head_turns`.
    environment : EnvironmentLight or None
        The environment lighting every photograph instead of the point light
        (then ``light_positions`` is empty, ``exposure`` 1 and ``per_light``
        one condition holding every measurement).
    rig : tuple of Camera
        Several calibrated cameras photographing each shot (:func:`rig_cameras`; the first is
        ``camera``), or empty: ``camera`` alone.
    """

    camera: Camera
    head: np.ndarray
    light_positions: np.ndarray
    intensity: np.ndarray
    exposure: float
    per_light: list[int]
    sphere_centers: np.ndarray
    sensor: dict
    integrator: dict = field(default_factory=lambda: dict(INTEGRATOR))
    poses: list[tuple[float, float, float]] = field(default_factory=lambda: list(POSES))
    environment: EnvironmentLight | None = None
    rig: tuple[Camera, ...] = ()

    @property
    def views(self) -> tuple[Camera, ...]:
        """The cameras that photograph the face: the rig's (the first is :attr:`camera`, whose frame
        the lights and the environment are placed in), or the one camera."""
        return self.rig or (self.camera,)

    @property
    def schedule(self) -> list[tuple[int, int]]:
        """(light index, pose index) of each measurement, in order."""
        return [(li, pi) for li, count in enumerate(self.per_light) for pi in range(count)]


def light_directions(count: int, rng: np.random.Generator, azimuth=(-70.0, 70.0), elevation=(-20.0, 50.0)
                     ) -> np.ndarray:
    """``count`` unit directions spread over the part of the sphere in front of the face
    (a Fibonacci lattice in azimuth and sin(elevation), jittered)."""
    golden = (math.sqrt(5) - 1) / 2
    out = []
    for i in range(count):
        u = ((i + 0.5) / count + rng.uniform(-0.15, 0.15) / count) % 1.0
        v = (i * golden + rng.uniform(-0.05, 0.05)) % 1.0
        az = np.radians(azimuth[0] + u * (azimuth[1] - azimuth[0]))
        s0, s1 = np.sin(np.radians(elevation[0])), np.sin(np.radians(elevation[1]))
        el = np.arcsin(s0 + v * (s1 - s0))
        out.append([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
    return np.array(out)


def head_turns(count: int, rng: np.random.Generator) -> list[tuple[float, float, float]]:
    """``count`` head turns (yaw, pitch, roll = 0; degrees) that see the face from varied sides:
    yaw stratified over :data:`TURN_YAW` (one jittered stratum each), pitch over
    :data:`TURN_PITCH` in golden-ratio order, so that neighbours in yaw differ in pitch."""
    golden = (math.sqrt(5) - 1) / 2
    turns = []
    for i in range(count):
        u = (i + 0.5 + rng.uniform(-0.3, 0.3)) / count
        v = ((i + 0.5) * golden + rng.uniform(-0.05, 0.05)) % 1.0
        turns.append((TURN_YAW[0] + u * (TURN_YAW[1] - TURN_YAW[0]),
                      TURN_PITCH[0] + v * (TURN_PITCH[1] - TURN_PITCH[0]), 0.0))
    return turns


def studio_camera(width: int, height: int, head: np.ndarray) -> Camera:
    """The fixed camera: on the +z axis through the head centre at
    :data:`CAMERA_DISTANCE`, looking at it, :data:`FIELD_HEIGHT` mm of field
    at the head, principal point at the image centre, no distortion."""
    fy = height * CAMERA_DISTANCE / FIELD_HEIGHT
    rotation = np.diag([1.0, -1.0, -1.0])  # OpenCV axes: x right, y down, z forward (world -z)
    position = head + np.array([0.0, 0.0, CAMERA_DISTANCE])
    return Camera(width, height, fy, fy, width / 2 - 0.5, height / 2 - 0.5, np.zeros(5), rotation,
                  -rotation @ position)


def rig_cameras(camera: Camera, head: np.ndarray, count: int) -> tuple[Camera, ...]:
    """``count`` cameras like ``camera``, turned about the vertical axis through ``head`` by the first
    ``count`` of :data:`RIG_YAWS` (the first is ``camera`` itself)."""
    if not 1 <= count <= len(RIG_YAWS):
        raise ValueError(f"cameras must be from 1 to {len(RIG_YAWS)}, got {count!r}")
    out = [camera]
    for yaw in np.radians(RIG_YAWS[1:count]):
        turn = np.array([[np.cos(yaw), 0.0, np.sin(yaw)], [0.0, 1.0, 0.0], [-np.sin(yaw), 0.0, np.cos(yaw)]])
        rotation = camera.rotation @ turn.T
        position = head + turn @ (camera.position - head)
        out.append(replace(camera, rotation=rotation, translation=-rotation @ position))
    return tuple(out)


def set_up_studio(width: int, height: int, head: np.ndarray, measurements: int, rng: np.random.Generator,
                  spp: int, environment: str | None = None) -> Studio:
    """The studio for ``measurements`` photographs of a head centred at ``head``:
    ceil(K / 3) light conditions with up to three poses each (the deficit from
    the last lights), the lights placed with ``rng``; or, with ``environment``
    (:data:`mifaces.studio.environment_light.ENVIRONMENTS`), one condition, that
    environment, with ``measurements`` head turns (:func:`head_turns`)."""
    camera = studio_camera(width, height, head)
    # the steel spheres: around where the head is, all in the field of view, in one plane facing the camera
    # so that for lights in front (azimuth within 70 degrees) none lies in another's shadow
    common = dict(camera=camera, head=head, intensity=np.full(3, np.pi * LIGHT_DISTANCE ** 2),
                  sphere_centers=head + SPHERE_OFFSETS, sensor=mitsuba_sensor(camera, spp))
    if environment is not None:  # no lamps: the map is in pixel value, the photographs' exposure 1
        return Studio(**common, light_positions=np.zeros((0, 3)), exposure=1.0, per_light=[measurements],
                      poses=head_turns(measurements, rng), environment=environment_light(environment, camera))
    n_lights = math.ceil(measurements / 3)
    per_light = [3] * n_lights
    for i in range(3 * n_lights - measurements):  # the deficit (at most 2) from the last lights
        per_light[-1 - i % n_lights] -= 1
    directions = light_directions(n_lights, rng)
    distances = LIGHT_DISTANCE * rng.uniform(0.9, 1.1, n_lights)
    return Studio(**common, light_positions=head + directions * distances[:, None], exposure=WHITE_LEVEL,
                  per_light=per_light)


def white_value(studio: Studio) -> np.ndarray:
    """What the white target reads per unit exposure: Lambertian, reflectance 1, frontal, at
    :data:`LIGHT_DISTANCE` (1 by the choice of :attr:`Studio.intensity`)."""
    return studio.intensity / (np.pi * LIGHT_DISTANCE ** 2)


# --------------------------------------------------------------------------------------------
# Mitsuba scenes
# --------------------------------------------------------------------------------------------
def scene(studio: Studio, meshes: dict, emitters: dict, spp: int) -> dict:
    """The scene dict of ``meshes`` (Mitsuba shapes) lit by ``emitters`` as the studio camera sees it
    with ``spp`` samples."""
    d = {"type": "scene", "integrator": studio.integrator,
         "sensor": dict(studio.sensor, sampler={"type": "independent", "sample_count": spp})}
    d.update(meshes)
    d.update(emitters)
    return d


def steel_spheres(studio: Studio) -> dict:
    """The four chrome spheres."""
    return {f"steel_{i}": {"type": "sphere", "center": c.tolist(), "radius": STEEL_SPHERE_RADIUS,
                           "bsdf": {"type": "conductor", "material": "Cr"}}
            for i, c in enumerate(studio.sphere_centers)}


def lamp(studio: Studio, light: int) -> dict:
    """The point light ``light`` as a sphere of :data:`LAMP_RADIUS` of the same intensity (the
    steel-sphere pictures: its mirror image has an area)."""
    radiance = studio.intensity / (np.pi * LAMP_RADIUS ** 2)
    return {"lamp": {"type": "sphere", "center": studio.light_positions[light].tolist(), "radius": LAMP_RADIUS,
                     "emitter": {"type": "area", "radiance": rgb(radiance)}}}


def face_light(studio: Studio, light: int) -> dict:
    """What lights the face photographs of condition ``light``: the studio's environment
    (its map in pixel value: the photographs' exposure is 1), or the point light."""
    if studio.environment is not None:
        return light_emitters(None, studio.camera, Environment(studio.environment.map))
    return point_light(studio, light)


def point_light(studio: Studio, light: int) -> dict:
    """The point light of condition ``light`` (:func:`mifaces.lights.emitters.light_emitters`)."""
    return light_emitters(Light(f"light_{light}", studio.light_positions[light], studio.intensity), studio.camera)
