"""The environment that lights every photograph of an environment-lit simulated
capture (``SimulationOptions(environment=...)``), instead of the point lights.

The capture states it as one given environment light (``docs/capture.md``): a
latitude-longitude OpenEXR map in pixel value (radiance times the
photographs' exposure, so the photographs' exposure is 1) in the frame of
:func:`mifaces.lights.environment.environment_emitter` (local +y the camera's up,
+z towards the camera). The photographs are rendered with exactly that map:
the generated studio (:func:`mifaces.lights.environment.studio_environment`) as it
is, Mitsuba's sun and sky (:func:`mifaces.lights.environment.sky_emitter`, the sun
at :data:`mifaces.lights.environment.SKY_SUN_ANGLES` about the camera) baked into a
map first (:func:`mifaces.lights.environment.bake_environment`).

Exposure follows from the map, once per environment, not from a render: a
white Lambertian surface facing the map's brightest direction (the largest
irradiance E; it reads E / π, :func:`mifaces.lights.environment.irradiance`) reads
:data:`ENVIRONMENT_LEVEL` of full scale. The simulated subjects' skin
(brightest channel 0.3 to 0.73, pale to dark over seeds) then reads at most
about 0.65 (the 99th percentile of the face: 0.25 to 0.65), with headroom
for highlights: only the eyes' sharp reflections of the sun or the key light
clip.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..lights.environment import SKY_SUN_ANGLES, bake_environment, peak_irradiance, sky_emitter, studio_environment

#: The environments a simulated capture can be lit by.
ENVIRONMENTS = ("studio", "sky")
#: Height of the map a capture states (pixels; the width is twice this): the sun's disc is half a texel.
ENVIRONMENT_HEIGHT = 256
#: Exposure: a white Lambertian surface facing the map's brightest direction reads this fraction of full scale.
ENVIRONMENT_LEVEL = 0.9
#: Folder of the environment map inside the capture.
LIGHTS = "lights"


@dataclass(frozen=True, eq=False)
class EnvironmentLight:
    """The environment of a capture.

    Attributes
    ----------
    name : str
        One of :data:`ENVIRONMENTS`; the capture's light name.
    map : (H, 2H, 3) float32
        Latitude-longitude radiance in pixel value, in the frame of
        :func:`mifaces.lights.environment.environment_emitter`: what the capture states
        and what the photographs are rendered with.
    description : dict
        What the environment was, for the ground truth's description: with ``exposure``, the
        factor from the environment's radiance (the studio map's, the sky's in
        W m⁻² sr⁻¹ nm⁻¹) to ``map``.
    """

    name: str
    map: np.ndarray
    description: dict

    @property
    def path(self) -> str:
        """The map's path inside the capture."""
        return f"{LIGHTS}/{self.name}.exr"

    def manifest_entry(self) -> dict:
        """The capture's light entry: a given environment light."""
        return {"name": self.name, "kind": "environment", "map": self.path}


def check_environment(environment) -> str | None:
    """``environment`` if it is None or one of :data:`ENVIRONMENTS`; a ValueError naming it otherwise."""
    if environment is not None and environment not in ENVIRONMENTS:
        raise ValueError(f"environment must be one of {list(ENVIRONMENTS)} or None, got {environment!r}")
    return environment


def environment_radiance(name: str, camera) -> tuple[np.ndarray, dict]:
    """The environment ``name`` (one of :data:`ENVIRONMENTS`) as a map of radiance
    (:data:`ENVIRONMENT_HEIGHT` rows) placed by ``camera``, and its description."""
    if check_environment(name) is None:
        raise ValueError(f"environment must be one of {list(ENVIRONMENTS)}, got None")
    if name == "studio":
        return studio_environment(ENVIRONMENT_HEIGHT), {"environment": "studio"}
    sky = sky_emitter(camera)  # the sun at SKY_SUN_ANGLES about the camera
    return bake_environment(sky, camera, ENVIRONMENT_HEIGHT), {
        "environment": "sky", "sun_angles_deg": list(SKY_SUN_ANGLES), "turbidity": sky["turbidity"],
        "ground_albedo": sky["albedo"]}


def environment_exposure(radiance: np.ndarray) -> float:
    """The exposure at which a white Lambertian surface facing the brightest direction of the map
    ``radiance`` (:func:`mifaces.lights.environment.peak_irradiance`; E its largest channel) reads
    :data:`ENVIRONMENT_LEVEL`: level π / E."""
    peak = float(peak_irradiance(radiance).max())
    if peak <= 0:
        raise ValueError("the environment map is black: it lights nothing")
    return ENVIRONMENT_LEVEL * np.pi / peak


def environment_light(name: str, camera) -> EnvironmentLight:
    """The environment ``name`` (:data:`ENVIRONMENTS`) about ``camera``, exposed
    (:func:`environment_exposure`)."""
    radiance, description = environment_radiance(name, camera)
    exposure = environment_exposure(radiance)
    light = EnvironmentLight(name, np.ascontiguousarray(radiance * np.float32(exposure), np.float32), description)
    description.update({"map": light.path, "exposure": round(exposure, 6),
                        "point_lights": "none: every photograph is lit by the environment"})
    return light
