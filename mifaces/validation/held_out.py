"""The conditions a fit never saw, under which the validation renders the
true and the fitted faces: a novel pose (:func:`novel_rotation`) and
held-out lights (:func:`held_out_lights`) chosen away from the lights the
simulator placed (:func:`true_lights`). :func:`held_out_lights` is the one
rule for a light the capture did not use: the report's novel light
(:func:`novel_light`) is the first it chooses from the capture's own lights (the validation
chooses from the lights the simulator placed, so the two differ where lights were estimated)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..capture.types import RELATIVE_IRRADIANCE
from ..capture import Light
from ..lights.light import lamp_towards
from ..io.image_files import read_exr

#: The novel pose: yaw about the camera's up axis, then pitch about its right
#: axis (degrees, through the true face's centroid; positive yaw turns the face
#: towards the image's left, positive pitch tips the top of the head towards the camera).
NOVEL_POSE = (35.0, 15.0)
#: Number of held-out point lights.
HELD_OUT_LIGHTS = 2
#: Candidate held-out light directions about the camera (azimuth, elevation in
#: degrees, :meth:`mifaces.capture.Camera.direction`), of which those farthest
#: from every capture light are taken.
#: They stay within 45° of the camera's axis sideways and between 15° below and 40° above it, lighting the front
#: of the face as a photographer would.
LIGHT_CANDIDATES = tuple((a, e) for a in (-45.0, -22.5, 0.0, 22.5, 45.0) for e in (-15.0, 5.0, 25.0, 40.0))


def novel_rotation(camera, pose=NOVEL_POSE) -> np.ndarray:
    """The world-frame rotation (3x3) of the novel pose: ``pose`` = (yaw,
    pitch) degrees about the camera's up and then its right axis (:attr:`~mifaces.capture.Camera.frame`)."""
    right, up, _ = camera.frame.T
    yaw = Rotation.from_rotvec(np.radians(pose[0]) * up)
    pitch = Rotation.from_rotvec(np.radians(pose[1]) * right)
    return (pitch * yaw).as_matrix()


def true_lights(capture, truth):
    """``capture`` with each light it estimated (or still does not know) replaced by the one the
    simulator placed (``truth``, its ground truth): its point light, or the environment map it
    rendered with. The held-out lights are chosen away from these, so that a run that estimated
    its lights is judged under the same held-out lights as one that was given them."""
    placed = {light.name: light for light in truth.lights}
    rendered = truth.description.get("map")  # an environment-lit capture's one map, inside the capture
    read_map = None if rendered is None else (lambda: read_exr(Path(capture.path) / rendered)[..., :3])
    return replace(capture, lights=tuple(light.as_simulated(placed.get(light.name), read_map)
                                         for light in capture.lights))


def held_out_lights(capture, centre: np.ndarray, count: int = HELD_OUT_LIGHTS,
                    names=None) -> list[tuple[Light, float]]:
    """``count`` lights none of the capture's photographs used (:class:`~mifaces.capture.Light`
    values named ``held_out_<k>``, or ``names``), each with its angle to the capture's lights: of
    :data:`LIGHT_CANDIDATES`, those whose smallest angle (seen from
    ``centre``) to every capture light and to each other is largest; point
    lights at the capture lights' mean distance with the first light's
    intensity (directional lights for a capture of directional lights, and for one lit by environment
    maps alone: irradiance :data:`~mifaces.capture.types.RELATIVE_IRRADIANCE`); away from where most
    of each environment map's light comes from, too; that angle (degrees) is the smallest to any of them."""
    used = np.array([light.main_direction(centre, capture.camera) for light in capture.lights], np.float64)
    candidates = np.array([capture.camera.direction(a, e) for a, e in LIGHT_CANDIDATES])
    chosen = []
    for _ in range(count):
        taken = np.concatenate([used, candidates[chosen]]) if chosen else used
        separation = np.degrees(np.arccos(np.clip(candidates @ taken.T, -1, 1))).min(axis=1)
        separation[chosen] = -1
        chosen.append(int(np.argmax(separation)))
    out = []
    for i, k in enumerate(chosen):
        angle = float(np.degrees(np.arccos(np.clip(used @ candidates[k], -1, 1))).min())
        name = names[i] if names is not None else f"held_out_{i + 1}"
        out.append((lamp_towards(capture.lights, name, candidates[k], centre, RELATIVE_IRRADIANCE), angle))
    return out


def novel_light(capture, centre: np.ndarray) -> Light:
    """The light none of the measurements used that :func:`mifaces.pipeline.measure.measure`
    renders each fit under beside its photograph: the first of :func:`held_out_lights`
    (of ``capture``'s lights, seen from ``centre``), named ``'novel'``."""
    light, _ = held_out_lights(capture, centre, 1, names=("novel",))[0]
    return light


__all__ = ["NOVEL_POSE", "HELD_OUT_LIGHTS", "LIGHT_CANDIDATES", "novel_rotation", "true_lights",
           "held_out_lights", "novel_light"]
