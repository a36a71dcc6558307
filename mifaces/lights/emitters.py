"""The lights of a rendered face as Mitsuba emitters: a capture's
:class:`~mifaces.capture.Light` (a point light, a directional light or an
environment map), or an environment given as a map or an emitter; and a
light's record in a report. World frame, mm; maps placed in the camera's
frame (:mod:`mifaces.lights.environment`)."""

from __future__ import annotations

import numpy as np

from ..brdf.model import check_numbers, rgb
from .environment import Environment


def light_emitters(light, camera, environment: Environment | None = None) -> dict:
    """The emitters of a face scene (its ``light`` and ``environment`` entries).

    ``light``: a :class:`~mifaces.capture.Light` -- a point light (``position``, world, mm;
    ``intensity``, radiant intensity), a directional one (``direction``, world frame, towards the
    light; ``intensity``, irradiance in pixel units: a white Lambertian surface facing it shows
    intensity/π) or an environment map (``envmap``); a light that is not a capture's is a ``Light``
    made for it, e.g. ``Light("held-out", position, intensity)``. ``environment``: an
    :class:`~mifaces.lights.environment.Environment` (a map and its scale, or an emitter such as
    :func:`mifaces.lights.environment.sky_emitter`'s), instead of or besides a point or directional
    light. Maps are placed in ``camera``'s frame (:func:`mifaces.lights.environment.environment_emitter`).
    """
    if light is not None and light.environment:
        if light.envmap is None:
            raise ValueError(f"light {light.name!r} is an unknown environment map: estimate it first")
        if environment is not None:
            raise ValueError(f"light {light.name!r} is an environment map: give no other")
        light, environment = None, Environment(np.asarray(light.envmap, np.float32))
    if light is None and environment is None:
        raise ValueError("a face scene needs a light: a point light position, a light direction or an "
                         "environment map")
    emitters = {}
    if light is not None:
        emitters["light"] = _light_emitter(light)
    if environment is not None:
        emitters["environment"] = environment.emitter(camera)
    return emitters


def light_record(light) -> dict:
    """A point or directional ``light`` for a report (JSON-ready): ``light_position`` or
    ``light_direction`` (world frame), and ``intensity``."""
    key, value = ("light_direction", light.direction) if light.directional else ("light_position", light.position)
    return {key: np.asarray(value).tolist(), "intensity": np.asarray(light.intensity).tolist()}


def _light_emitter(light) -> dict:
    """The Mitsuba ``point`` or ``directional`` emitter dict of a point or directional ``light``."""
    for name, value, minimum in (("light position", light.position, None),
                                 ("light direction", light.direction, None), ("light intensity", light.intensity, 0.0)):
        if value is not None:
            check_numbers(name, value, 3, minimum, scalar_ok=True)
    if light.position is not None and light.direction is not None:
        raise ValueError("give a point light position or a light direction, not both")
    if light.intensity is None:
        raise ValueError("a directional light needs its irradiance (intensity)" if light.directional
                         else "a point light needs its intensity")
    if light.directional:
        towards = np.asarray(light.direction, np.float64)
        norm = float(np.linalg.norm(towards)) if towards.shape == (3,) else 0.0
        if not np.isfinite(norm) or norm == 0:
            raise ValueError(f"light direction must be a finite, non-zero 3-vector, got {light.direction!r}")
        # Mitsuba's directional emitter takes the direction light travels in
        return {"type": "directional", "direction": [float(-x / norm) for x in towards],
                "irradiance": rgb(light.intensity)}
    if light.position is None:
        raise ValueError(f"light {light.name!r} has no position (load the capture with calibrate=True)")
    return {"type": "point", "position": [float(x) for x in light.position], "intensity": rgb(light.intensity)}


__all__ = ["light_emitters", "light_record"]
