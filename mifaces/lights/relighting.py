"""The light a fitted face is rendered under in a novel view (paper sec. 6): :class:`Relighting`, one
value from ``mifaces render``'s flags (or a script) to :func:`mifaces.reflectance.render_fitted`. It
says what changes from the light of the measurement whose face is rendered: another point or
directional light, another intensity, an environment map or Mitsuba's sun and sky; what it leaves
out is the measurement's. Angles are about the capture's camera (:meth:`mifaces.capture.Camera.direction`),
so the lights follow from it and the camera (:meth:`Relighting.lights`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..brdf.model import check_numbers
from ..options.fields import Conflict, check, option
from .environment import SKY_SUN_ANGLES, SKY_TURBIDITY, TURBIDITY, Environment, sky_emitter
from .light import Light

#: The fields that place the sky's sun, and the sky's other fields.
_SUN = ("sun_direction", "sun_angles", "sky_time")
_SKY = (*_SUN, "place", "turbidity")


@dataclass(frozen=True, eq=False)
class Relighting:
    """A novel light for a render of a measurement's face: what it gives replaces the measurement's
    light, what it leaves out is the measurement's.

    Validated on construction: options that contradict each other raise a
    :class:`~mifaces.options.fields.Conflict` (a ``ValueError``) naming them.

    Attributes
    ----------
    light_position : (3,) floats or None
        A point light at this world position (mm).
    light_direction : (3,) floats or None
        A directional light: world direction towards the light.
    light_angles : (azimuth, elevation) or None
        A directional light at these angles (degrees) about the camera's axis
        (:meth:`mifaces.capture.Camera.direction`).
    intensity : float, (3,) floats or None
        The light's intensity (a number: the same in R, G and B; irradiance for a directional light);
        None: the measurement light's.
    envmap : path, (H, W, 3) array, dict or None
        An environment map (equirectangular, linear RGB; placed as
        :func:`mifaces.lights.environment.environment_emitter` places it), or a Mitsuba emitter dict,
        instead of the measurement's light, or besides the point or directional light given.
    sky : bool
        Light by Mitsuba's sun and sky (:func:`mifaces.lights.environment.sky_emitter`) instead.
    sun_direction, sun_angles, sky_time, place, turbidity : optional
        The sky's sun as a world direction, as angles about the camera, or by a local ISO 8601 time
        (with ``place``: latitude, longitude, time zone); its haze (None:
        :data:`~mifaces.lights.environment.SKY_TURBIDITY`). Only with ``sky``.
    envmap_scale : float
        Scale of the environment map or the sky (the measurement's own map too).
    """

    light_position: tuple | None = option(None, flag="light", form=(float, float, float),
                                          help="Point light position x y z (world, mm; default: the measurement's "
                                               "light).")
    light_direction: tuple | None = option(None, form=(float, float, float),
                                           help="A directional light instead: x y z towards the light (world frame).")
    light_angles: tuple | None = option(None, form=(float, float),
                                        help="A directional light at azimuth and elevation (degrees) about the "
                                             "camera's axis: 0 0 from the camera, positive azimuth towards the "
                                             "image's left, positive elevation above (as the Yale database names its "
                                             "lights).")
    intensity: float | tuple | None = option(None, form=float,
                                             help="The light's intensity (irradiance for a directional light; "
                                                  "default: the measurement light's).")
    envmap: object = option(None, form="file",
                            help="Light by this equirectangular environment map (EXR) instead, placed in the camera's "
                                 "frame (its +y the camera's up, its centre column behind the camera).")
    sky: bool = option(False, form="flag",
                       help="Light by Mitsuba's sun and sky (sunsky) instead; the face looks south.")
    sun_direction: tuple | None = option(None, form=(float, float, float),
                                         help="With --sky: x y z from the face towards the sun (world frame).")
    sun_angles: tuple | None = option(None, form=(float, float),
                                      help="With --sky: the sun at azimuth and elevation (degrees) about the camera, "
                                           "as --light-angles "
                                           f"[default: {' '.join(f'{x:g}' for x in SKY_SUN_ANGLES)}].")
    sky_time: str | None = option(None, help="With --sky: the local date and time that places the sun, ISO 8601 "
                                             "(2024-06-21T08:30).")
    place: tuple | None = option(None, form=(float, float, float),
                                 help="With --sky-time: latitude (north), longitude (east) in degrees and the time "
                                      "zone in hours ahead of UTC [default: 0 0 0].")
    turbidity: float | None = option(None, bounds=TURBIDITY,
                                     help="With --sky: haze (2 arctic clear, 3 clear, 10 hazy) "
                                          f"[default: {SKY_TURBIDITY:g}].")
    envmap_scale: float = option(1.0, help="Scale of the environment map or the sky.")

    def __post_init__(self):
        check(self)
        check_numbers("environment map scale", self.envmap_scale, minimum=0.0)
        placed = [name for name in ("light_position", "light_direction", "light_angles")
                  if getattr(self, name) is not None]
        if len(placed) > 1:
            raise Conflict(Relighting, "give one of {}, {} and {}", "light_position", "light_direction",
                           "light_angles")
        given = [name for name in _SKY if getattr(self, name) is not None]
        if not self.sky and given:
            raise Conflict(Relighting, ", ".join(["{}"] * len(given)) + " need {}", *given, "sky")
        if self.sky and self.envmap is not None:
            raise Conflict(Relighting, "give {} or {}, not both", "sky", "envmap")
        if sum(getattr(self, name) is not None for name in _SUN) > 1:
            raise Conflict(Relighting, "give one of {}, {} and {}", *_SUN)
        if self.place is not None and self.sky_time is None:
            raise Conflict(Relighting, "{} needs {} (the sun's position follows from both)", "place", "sky_time")

    def environment(self, camera) -> Environment | None:
        """The environment it gives, placed by ``camera``: the sky, the map, or None."""
        if self.sky:
            sun = self.sun_direction if self.sun_angles is None else camera.direction(*self.sun_angles)
            turbidity = SKY_TURBIDITY if self.turbidity is None else self.turbidity
            return Environment(sky_emitter(camera, sun, self.sky_time, self.place, turbidity,
                                           scale=self.envmap_scale))  # the sky carries the scale
        return None if self.envmap is None else Environment(self.envmap, self.envmap_scale)

    def lights(self, lamp: Light, camera) -> tuple[Light | None, Environment | None]:
        """The light and the environment of a render of a face that ``lamp`` lit in a photograph
        ``camera`` took (the arguments ``light`` and ``environment`` of
        :meth:`mifaces.render.FaceScene.render`): the point or directional light given (with the
        environment given, if any), else the environment alone, else ``lamp`` (its map scaled by
        :attr:`envmap_scale`), with the intensity given."""
        direction = self.light_direction if self.light_angles is None else camera.direction(*self.light_angles)
        intensity = lamp.intensity if self.intensity is None else self.intensity
        if np.ndim(intensity) == 0:
            intensity = [intensity] * 3
        environment = self.environment(camera)
        if self.light_position is not None or direction is not None:
            return Light("novel", self.light_position, intensity, direction=direction), environment
        if environment is not None:
            return None, environment
        if lamp.radiance_map is not None:  # the measurement's own map, at the scale asked
            return None, Environment(np.asarray(lamp.radiance_map, np.float32), self.envmap_scale)
        return lamp.with_intensity(intensity), None


__all__ = ["Relighting"]
