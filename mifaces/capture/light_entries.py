"""The light conditions of a capture manifest (:func:`read_lights`): point lights (a
position, or the steel-sphere pictures to calibrate it from), directional lights,
given environment maps, and unknown lights to estimate."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.image_files import read_exr
from ..io.paths import resolve_inside
from .camera import Camera
from .measurement_entries import read_image_entry
from .problems import Problems
from .types import (ENVMAP_HEIGHTS, ENVMAP_SIZE, GIVEN_ENVMAP_HEIGHTS, LIGHT_KINDS, RELATIVE_IRRADIANCE, Light,
                    SpherePictures)


def read_lights(data: dict, root: Path, camera: Camera | None, problems: Problems) -> list[Light]:
    """The manifest's ``lights``, each read by its kind; the problems found go to ``problems``."""
    lights = []
    for i, e, where in problems.objects(data, "lights", " of light conditions"):
        name = problems.need(e, "name", where, str)
        where = f"lights[{i}] ({name})" if name else where
        relative = e.get("relative", False)
        if not isinstance(relative, bool):
            problems.append(f"{where}.relative: must be true or false, got {relative!r}")
        unknown = e.get("unknown", False)
        if not isinstance(unknown, bool):
            problems.append(f"{where}.unknown: must be true or false, got {unknown!r}")
        if unknown is True:
            light = _unknown_light(e, name, where, problems)
        elif e.get("kind") == "environment" or "map" in e:
            light = _environment_light(e, name, where, relative, root, problems)
        elif "direction" in e:
            light = _directional_light(e, name, where, relative, problems)
        else:
            light = _point_light(e, name, where, relative, root, camera, problems)
        if light is not None:
            lights.append(light)
    problems.unique("lights", [l.name for l in lights])
    return lights


def _directional_light(e: dict, name, where: str, relative, problems: Problems) -> Light | None:
    """A distant light: ``direction`` towards it (world frame), ``intensity`` optional (then
    :data:`~mifaces.capture.types.RELATIVE_IRRADIANCE`, relative)."""
    for key in ("position_mm", "spheres"):
        if key in e:
            problems.append(f"{where}: give 'direction' (a directional light) or '{key}' (a point light), not both")
    direction = problems.vector(e, "direction", where, 3)
    if direction is not None and np.linalg.norm(direction) < 1e-12:
        problems.append(f"{where}.direction: must be non-zero, got {e['direction']!r}")
        direction = None
    intensity = problems.vector(e, "intensity", where, 3, positive=True, scalar_ok=True, required=False)
    if "intensity" not in e:
        intensity, relative = np.full(3, RELATIVE_IRRADIANCE), True
    if name is None or direction is None or intensity is None:
        return None
    return Light(name, None, intensity, direction=direction / np.linalg.norm(direction), relative=relative is True)


#: Keys that give a light: none of them may come with ``"unknown": true``.
_GIVEN = ("direction", "position_mm", "spheres", "intensity", "map")


def _environment_light(e: dict, name, where: str, relative, root: Path, problems: Problems) -> Light | None:
    """A given environment map: ``map``, a latitude-longitude OpenEXR file (width twice the height,
    linear RGB radiance in pixel value, times the optional ``scale``) in the frame of
    :func:`mifaces.lights.environment.environment_emitter`."""
    n = len(problems)
    if e.get("kind", "environment") != "environment":
        problems.append(f"{where}: light {name!r} has a 'map' but kind {e['kind']!r}: a map is an environment light")
    for key in ("direction", "position_mm", "spheres", "intensity", "size", "guess"):
        if key in e:
            problems.append(f"{where}: light {name!r} is an environment map: it takes no '{key}'")
    rel = problems.need(e, "map", where, str)
    scale = problems.number(e, "scale", where, positive=True, default=1.0, required=False)
    if rel is None or len(problems) > n:
        return None
    try:
        path = resolve_inside(root, rel, problems.allow_outside)
    except (ValueError, OSError) as err:
        problems.append(f"{where}.map: {err}")
        return None
    if path.suffix.lower() != ".exr" or not path.is_file():
        problems.append(f"{where}.map: light {name!r}: {rel!r} is not an OpenEXR file in the capture")
        return None
    try:
        envmap = read_exr(path)
    except Exception as err:  # noqa: BLE001 - any reader failure is a problem of this capture
        problems.append(f"{where}.map: cannot read {rel}: {err}")
        return None
    if envmap.ndim != 3 or envmap.shape[2] < 3:
        problems.append(f"{where}.map: light {name!r}: {rel} must be an RGB image, got shape {envmap.shape}")
        return None
    envmap = envmap[..., :3]
    if _envmap_size([int(envmap.shape[1]), int(envmap.shape[0])], name, f"{where}.map", problems,
                    GIVEN_ENVMAP_HEIGHTS) is None:
        return None
    if not np.all(np.isfinite(envmap)) or envmap.min() < 0:
        problems.append(f"{where}.map: light {name!r}: {rel} has NaN, infinite or negative radiance")
        return None
    return Light(name, None, np.ones(3), relative=relative is True, kind="environment",
                 envmap=np.ascontiguousarray(envmap * np.float32(scale), np.float32))


def _unknown_light(e: dict, name, where: str, problems: Problems) -> Light | None:
    """A light nobody measured: its ``kind`` (:data:`LIGHT_KINDS`, default directional), for a
    directional one an optional ``guess`` (``{"direction": [x, y, z]}``), for an environment map an
    optional ``size`` ([width, height], width twice the height, height in :data:`ENVMAP_HEIGHTS`).
    Its intensity is relative (:data:`RELATIVE_IRRADIANCE` until estimated)."""
    n = len(problems)
    for key in _GIVEN:
        if key in e:
            problems.append(f"{where}: light {name!r} is both unknown and given ('{key}'): "
                            "drop 'unknown' or drop the measured values (a stated guess goes in 'guess')")
    kind = e.get("kind", LIGHT_KINDS[0])
    if kind not in LIGHT_KINDS:
        problems.append(f"{where}.kind: light {name!r} has unknown kind {kind!r}; kinds: {list(LIGHT_KINDS)}")
    guess = size = None
    if "guess" in e:
        if kind != "directional":
            problems.append(f"{where}.guess: light {name!r} of kind {kind!r} takes no guess (only a directional one)")
        elif not isinstance(e["guess"], dict) or set(e["guess"]) != {"direction"}:
            problems.append(f"{where}.guess: light {name!r}: must be {{\"direction\": [x, y, z]}}, "
                            f"got {e['guess']!r}"[:300])
        else:
            guess = problems.vector(e["guess"], "direction", f"{where}.guess", 3)
            if guess is not None and np.linalg.norm(guess) < 1e-12:
                problems.append(f"{where}.guess.direction: light {name!r}: must be non-zero, got {guess.tolist()}")
                guess = None
            elif guess is not None:
                guess = guess / np.linalg.norm(guess)
    if "size" in e and kind != "environment":
        problems.append(f"{where}.size: light {name!r} of kind {kind!r} has no map size (only an environment one)")
    elif kind == "environment":
        size = _envmap_size(e.get("size", list(ENVMAP_SIZE)), name, f"{where}.size", problems)
    if name is None or len(problems) > n:
        return None
    return Light(name, None, np.full(3, RELATIVE_IRRADIANCE), relative=True, unknown=True, kind=kind, guess=guess,
                 envmap_size=size)


def _envmap_size(value, name, where: str, problems: Problems, heights=ENVMAP_HEIGHTS) -> tuple[int, int] | None:
    """An environment map's (width, height): two integers, width = 2 x height (latitude-longitude),
    height in ``heights`` (low, high): :data:`ENVMAP_HEIGHTS` for a map to estimate,
    :data:`GIVEN_ENVMAP_HEIGHTS` for a given one."""
    low, high = heights
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
        problems.append(f"{where}: light {name!r}: invalid envmap size {value!r}: "
                        "must be [width, height] in texels"[:300])
        return None
    width, height = value
    if width != 2 * height or not low <= height <= high:
        problems.append(f"{where}: light {name!r}: invalid envmap size {width}x{height}: the width must be twice the "
                        f"height (a latitude-longitude map) and the height between {low} and {high}")
        return None
    return width, height


def _point_light(e: dict, name, where: str, relative, root: Path, camera: Camera | None,
                 problems: Problems) -> Light | None:
    """A point light: ``intensity`` and ``position_mm`` or the steel-sphere pictures to calibrate it from."""
    intensity = problems.vector(e, "intensity", where, 3, positive=True, scalar_ok=True)
    position = problems.vector(e, "position_mm", where, 3, required=False)
    spheres = None
    if "spheres" in e:
        s = e["spheres"]
        sw = f"{where}.spheres"
        radius = problems.number(s, "radius_mm", sw, positive=True)
        hl = read_image_entry(s.get("highlight") if isinstance(s, dict) else None, f"{sw}.highlight", root, camera,
                              problems)
        ol = read_image_entry(s.get("outline") if isinstance(s, dict) else None, f"{sw}.outline", root, camera,
                              problems)
        if radius is not None and hl is not None and ol is not None:
            spheres = SpherePictures(radius, hl, ol)
    elif position is None and "position_mm" not in e:
        problems.append(f"{where}: needs 'position_mm' or 'spheres' (the steel-sphere pictures), "
                        "or 'direction' for a directional light")
    if name is None or intensity is None:
        return None
    return Light(name, position, intensity, spheres, relative=relative is True)
