"""A capture's light as a value: what it is (its fields, as ``capture.json`` gives them) and what its users
ask of it, so that they need not ask which kind it is.

A light is one of: a point light (``position``; from steel-sphere pictures where only those are given),
a directional light (``direction``), an environment map (``kind`` ``'environment'``, ``envmap``), or a
light nobody measured (``unknown``), which :mod:`mifaces.light_estimation` estimates as a directional
light or an environment map (``estimated``). Its users ask it:

- the incidence at surface points: :meth:`Light.towards`, :meth:`Light.direction_from`,
  :meth:`Light.first_seen_from`, :meth:`Light.main_direction`, and :meth:`Light.require_incidence`
  where it must be known;
- where a shape fit starts it: :meth:`Light.start_direction`, :attr:`Light.held_position`,
  :attr:`Light.direction_fitted`, :attr:`Light.fitted_on_face`;
- copies: :meth:`Light.calibrated`, :meth:`Light.moved_to`, :meth:`Light.with_intensity`,
  :meth:`Light.with_estimated_map`, :meth:`Light.as_simulated`; new lamps like them: :func:`lamp_towards`;
- the emitters for a scene: :attr:`Light.emitter_kind`, :meth:`Light.sphere_lamp`, :attr:`Light.radiance_map`,
  :attr:`Light.estimated_map`;
- what it is made of: :attr:`Light.pictures`, :attr:`Light.intensity_given`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .environment import dominant_direction


@dataclass(frozen=True, eq=False)
class Light:
    """One light condition.

    Attributes
    ----------
    name : str
    position : (3,) float64 or None
        World position in mm of a point light, as given or as calibrated from
        ``spheres``; None for a directional light.
    intensity : (3,) float64
        Per RGB channel: a point light's radiant intensity, in the units of
        the white target's calibration (pixel value x mm²); a directional
        light's irradiance at normal incidence (pixel value), 1 where its
        absolute value is unknown (``relative``).
    spheres : SpherePictures or None
        The steel-sphere pictures of :mod:`mifaces.capture.calibration`.
    calibration : object or None
        The :class:`mifaces.capture.calibration.LightCalibration` the position came from.
    direction : (3,) float64 or None
        A directional (distant) light: unit vector in the world frame from
        the subject towards the light. None for a point light.
    relative : bool
        The intensity is known only up to a factor common to all lights.
    unknown : bool
        Nobody measured this light: neither position nor direction is given, and
        :func:`mifaces.light_estimation.unknown.estimate_lights` estimates it with the face (the
        photographs sharing it share its estimate).
    kind : str
        What an unknown light is estimated as, one of :data:`mifaces.capture.types.LIGHT_KINDS`.
    guess : (3,) float64 or None
        An unknown directional light's stated guess of its direction (unit, world
        frame, towards the light), where to start; None: frontal (towards the camera).
    envmap_size : (int, int) or None
        An unknown environment light's map size (width, height) in texels.
    envmap : (H, 2H, 3) float32 or None
        An environment light's map (``kind`` ``'environment'``, given or estimated):
        latitude-longitude radiance in pixel value, in the camera-placed frame of
        :func:`mifaces.lights.environment.environment_emitter` (local +y the camera's up,
        +z towards the camera, the centre column behind the camera).
    estimated : bool
        The direction and intensity were estimated from the photographs (relative
        intensity), not given by the capture.
    """

    name: str
    position: np.ndarray | None
    intensity: np.ndarray
    spheres: object | None = None
    calibration: object | None = None
    direction: np.ndarray | None = None
    relative: bool = False
    unknown: bool = False
    kind: str = "directional"
    guess: np.ndarray | None = None
    envmap_size: tuple[int, int] | None = None
    estimated: bool = False
    envmap: np.ndarray | None = None

    @property
    def environment(self) -> bool:
        """Light from everywhere, an environment map (given, estimated, or to estimate)."""
        return self.kind == "environment"

    @property
    def directional(self) -> bool:
        """A distant light: the same direction and irradiance everywhere, no falloff."""
        return self.direction is not None

    def towards(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Unit directions (N, 3) from world ``points`` (N, 3) towards the light,
        and the distances (N,) to it (infinite for a directional light)."""
        points = np.atleast_2d(np.asarray(points, np.float64))
        if self.directional:
            d = np.broadcast_to(np.asarray(self.direction, np.float64), points.shape).copy()
            return d, np.full(len(points), np.inf)
        if self.unknown:
            raise ValueError(f"light {self.name!r} is unknown: estimate it first (mifaces.light_estimation.unknown.estimate_lights)")
        if self.environment:
            raise ValueError(f"light {self.name!r} is an environment map: it has no one direction "
                             "(mifaces.reflectance.environment.equivalent_lights)")
        if self.position is None:
            raise ValueError(f"light {self.name!r} has no position (load the capture with calibrate=True)")
        offset = np.asarray(self.position, np.float64) - points
        distance = np.linalg.norm(offset, axis=1)
        return offset / np.maximum(distance, 1e-30)[:, None], distance

    def direction_from(self, points) -> np.ndarray | None:
        """Unit directions (N, 3) from world ``points`` (N, 3) towards the light where it has one known
        direction there (a directional light; a point light with a position); None for an environment
        map, a light still to estimate and a point light not yet calibrated."""
        if self.environment or (not self.directional and self.position is None):
            return None
        return self.towards(points)[0]

    def first_seen_from(self, points) -> np.ndarray | None:
        """Unit directions (N, 3) from world ``points`` towards the light as a shape fit first sees it: a
        light to estimate's stated guess (as given), else :meth:`direction_from`; None for an environment
        map and a light without either (its estimate starts frontal)."""
        if self.unknown and not self.environment:
            return None if self.guess is None else np.broadcast_to(np.asarray(self.guess, np.float64),
                                                                   np.shape(np.atleast_2d(points)))
        return self.direction_from(points)

    def main_direction(self, centre, camera) -> np.ndarray:
        """The one direction (unit, world) most of the light reaches ``centre`` from: towards a point
        light, a directional light's direction, where most of an environment map's light comes from."""
        if self.environment:
            axis = np.asarray(dominant_direction(self.envmap, camera), np.float64)
        elif self.directional:
            axis = np.asarray(self.direction, np.float64)
        else:
            axis = np.asarray(self.position, np.float64) - np.asarray(centre, np.float64)
        return axis / np.linalg.norm(axis)

    def as_simulated(self, true: Light | None, rendered_map=None) -> Light:
        """The light as the simulator made it, to judge a run that estimated it under the lights of one
        that was given them: itself where given; for a light estimated or to estimate, ``true``'s position
        and intensity (the point light the simulator placed), or for an environment the map it rendered
        with (``rendered_map()``, read only then). ``ValueError`` where neither says."""
        if not (self.estimated or self.unknown):
            return self
        if true is not None:
            return replace(self, position=np.asarray(true.position, np.float64), direction=None,
                           intensity=np.asarray(true.intensity, np.float64), envmap=None,
                           unknown=False, estimated=False, relative=False)
        if self.environment and rendered_map is not None:
            return replace(self, envmap=rendered_map(), unknown=False, estimated=False, relative=False)
        raise ValueError(f"light {self.name!r} was estimated, and the ground truth does not say where the "
                         "simulator placed it")

    def require_incidence(self, where: str) -> None:
        """Raise ``ValueError`` (naming ``where``) unless the light's incidence on a face is known: a light
        to estimate must be estimated first, a point light needs its position."""
        if self.unknown:
            raise ValueError(f"{where}: light {self.name!r} is unknown: estimate it with the face first (mifaces "
                             "measure, or mifaces.light_estimation.unknown.estimate_lights on the shape fits)")
        if self.position is None and not self.directional and self.envmap is None:
            raise ValueError(f"{where}: light {self.name!r} has no position (load the capture with calibrate=True)")

    @property
    def direction_fitted(self) -> bool:
        """The shape fit fits this light's direction: a light to estimate, or an environment map (read
        there as the one directed light it is nearest to)."""
        return self.unknown or self.environment

    @property
    def fitted_on_face(self) -> bool:
        """A light to estimate as one direction, on each pose's fitted face
        (:func:`mifaces.shape.fit.fit_light`); an unknown environment is estimated from the samples."""
        return self.unknown and not self.environment

    def start_direction(self, camera) -> np.ndarray | None:
        """The world direction (unit) a shape fit starts this light's angles from: for a light whose direction
        is fitted, its stated guess, else where most of a given map's light comes from, else None
        (frontal); a directional light's direction; None for a point light (its position is held:
        :attr:`held_position`)."""
        if self.direction_fitted:
            if self.guess is not None:
                return np.asarray(self.guess, np.float64)
            return None if self.envmap is None else dominant_direction(self.envmap, camera)
        return None if self.direction is None else np.asarray(self.direction, np.float64)

    @property
    def held_position(self) -> np.ndarray | None:
        """The position a shape fit holds the light at: a point light's; None for every other light."""
        if self.direction_fitted or self.directional:
            return None
        return self.position

    @property
    def intensity_given(self) -> bool:
        """The capture gives this lamp's intensity: a point or directional light, neither to estimate nor
        estimated."""
        return not self.unknown and not self.estimated and not self.environment

    @property
    def radiance_map(self) -> np.ndarray | None:
        """An environment light's map (given or estimated); None for every other light."""
        return self.envmap if self.environment else None

    @property
    def estimated_map(self) -> np.ndarray | None:
        """An estimated environment light's map (which a refinement may refine); None for every other light."""
        return self.envmap if self.environment and self.estimated else None

    @property
    def emitter_kind(self) -> str:
        """The emitter a scene gives the light: ``'environment'``, ``'directional'`` or ``'point'``."""
        return "environment" if self.environment else "directional" if self.directional else "point"

    def sphere_lamp(self, radius: float | None) -> dict | None:
        """A point light as a Mitsuba sphere lamp of ``radius`` (mm) and the same intensity (I = L π r²),
        whose soft shadows a refinement differentiates; None for every other light, or no radius."""
        if self.environment or self.directional or self.position is None or not radius:
            return None
        radiance = np.asarray(self.intensity, np.float64) / (np.pi * radius ** 2)
        return {"type": "sphere", "center": [float(x) for x in self.position], "radius": float(radius),
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": radiance.tolist()}}}

    @property
    def pictures(self) -> tuple:
        """The pictures the light is calibrated from (its steel spheres' highlight and outline), if any."""
        return () if self.spheres is None else (self.spheres.highlight, self.spheres.outline)

    def calibrated(self, calibrate) -> Light:
        """The light at the position ``calibrate(spheres)`` gives (a ``LightCalibration``), where it has
        sphere pictures and no position; itself otherwise. ``calibrate``'s errors pass through."""
        if self.position is not None or self.spheres is None:
            return self
        calibration = calibrate(self.spheres)
        return replace(self, position=calibration.position, calibration=calibration)

    def moved_to(self, position) -> Light:
        """The light at world ``position`` (mm)."""
        return replace(self, position=np.asarray(position, np.float64))

    def with_intensity(self, intensity) -> Light:
        """The light with ``intensity`` (RGB); an environment map keeps its own radiance."""
        return self if self.environment else replace(self, intensity=intensity)

    def with_estimated_map(self, envmap) -> Light:
        """An estimated environment light with ``envmap`` in place of its estimate (None: unchanged);
        every other light unchanged."""
        if envmap is None or not (self.environment and self.estimated):
            return self
        return replace(self, envmap=np.asarray(envmap, np.float32))


def lamp_towards(lights, name: str, direction, centre, irradiance: float) -> Light:
    """A new lamp of the kind ``lights``' lamps are, in ``direction`` (unit, world) from ``centre``: a point
    light at their mean distance with the first one's intensity; a directional light where they are
    directional, and for lights that are environment maps alone (irradiance ``irradiance``)."""
    lamps = [light for light in lights if not light.environment]
    direction = np.asarray(direction, np.float64)
    if not lamps:
        return Light(name, None, np.full(3, irradiance), direction=direction)
    intensity = np.asarray(lamps[0].intensity, np.float64)
    if lamps[0].directional:
        return Light(name, None, intensity, direction=direction)
    distance = float(np.mean([np.linalg.norm(lamp.position - centre) for lamp in lamps]))
    return Light(name, centre + distance * direction, intensity)


def unknown_lights(lights) -> tuple[Light, ...]:
    """The lights nobody measured, to estimate with the face (:attr:`Light.unknown`)."""
    return tuple(light for light in lights if light.unknown)


def estimated_lights(lights) -> tuple[Light, ...]:
    """The lights estimated from the photographs (:attr:`Light.estimated`)."""
    return tuple(light for light in lights if light.estimated)


def any_relative(lights) -> bool:
    """Whether any light's intensity is known only up to a factor common to all lights."""
    return any(light.relative for light in lights)


__all__ = ["Light", "any_relative", "estimated_lights", "lamp_towards", "unknown_lights"]
