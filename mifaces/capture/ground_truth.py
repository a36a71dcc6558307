"""The ground truth of a simulated capture: its ``ground_truth/`` folder.

The simulator (:func:`mifaces.studio.simulate`) writes beside the capture
what a real capture cannot know: the subject's shape per measurement, the
light positions, the BRDF and the albedo map. :func:`write_ground_truth`
and :func:`read_ground_truth` are the only writer and reader of that folder;
:func:`mifaces.capture.load_capture` never reads it.

Layout (lengths in mm, in the capture's world frame)::

    ground_truth/
        scene.json        the index: model, seed, camera, lights, per measurement
                          the pose, expression and exact feature points
        shapes/neutral.npy     the subject's neutral face (V, 3)
        shapes/<name>.npy      the face of measurement <name> in world space (V, 3) float32
        brdf.json         the BRDF per region, in the layout of :mod:`mifaces.studio.truth`
                          (of a spatially varying truth: each region's mean of the maps)
        albedo.exr        the albedo map (linear RGB, texture space of the model)
        maps/<parameter>.exr   a spatially varying truth's per-texel parameter maps
                          (one channel, texture space of the model, as the albedo map)

``scene.json``'s ``truth`` says what the truth was (``brdf``: the model or
built-in; ``varying``: parameter maps; ``detail``: geometry outside the
model's span, with its ``span_residual_mm``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write, write_json
from ..io.image_files import read_exr, write_exr
from .camera import Camera
from .types import GROUND_TRUTH, Capture

#: Files of the ground-truth folder.
SCENE = "scene.json"
BRDF = "brdf.json"
ALBEDO = "albedo.exr"
SHAPES = "shapes"
NEUTRAL = "neutral"
MAPS = "maps"


@dataclass(frozen=True, eq=False)
class TrueLight:
    """A light condition as the simulator placed it.

    Attributes
    ----------
    name : str
    position : (3,) float64
        The point light's world position, mm.
    intensity : (3,) float64
        Radiant intensity per RGB channel.
    lamp_radius : float
        Radius of the emitting sphere in the steel-sphere pictures, mm.
    sphere_centers : (S, 3) float64
        World centres of the steel spheres, mm.
    """

    name: str
    position: np.ndarray
    intensity: np.ndarray
    lamp_radius: float
    sphere_centers: np.ndarray


@dataclass(frozen=True, eq=False)
class TrueMeasurement:
    """The subject as it was in one measurement.

    Attributes
    ----------
    name, light : str
        The measurement and its light condition, as in the manifest.
    vertices : (V, 3) float32
        The face model's vertices in world space, mm.
    rotation : (3, 3) float64
        Head rotation about the head centre: ``x = R (x0 - c) + c + t``.
    translation : (3,) float64
        t of that relation, mm.
    yaw_pitch_roll : (3,) float64
        The angles of ``rotation``, degrees
        (:func:`mifaces.model.geometry.rotation_matrix`).
    expression : dict
        Expression name -> coefficient (empty for a model without expressions).
    feature_points : dict
        Feature point name -> exact pixel position (2,) of the visible landmarks
        (the manifest holds them with an annotator's noise).
    """

    name: str
    light: str
    vertices: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    yaw_pitch_roll: np.ndarray
    expression: dict[str, float]
    feature_points: dict[str, np.ndarray]


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """Everything the simulator knew about a capture (see the module docstring).

    Attributes
    ----------
    model : str
        The face model, as :func:`mifaces.load_model` takes it.
    seed, spp : int
        The simulation's seed and samples per pixel.
    resolution : (width, height)
    coefficients : dict
        The subject's model coefficients (``shape``, ``color``).
    head_center : (3,) float64
        Centre of the neutral face's bounding box, the centre of head rotations, mm.
    camera : Camera
    lights : tuple of TrueLight
    sphere_radius : float
        Radius of the steel spheres, mm.
    neutral : (V, 3)
        The neutral face in world space, mm.
    measurements : tuple of TrueMeasurement
    brdf : dict
        The ``brdf.json`` document ``{"model", "options", "regions"}``.
    albedo : (N, N, 3) float32
        The albedo map, linear RGB.
    integrator : dict
        The Mitsuba integrator the photographs were rendered with.
    noise : dict
        The sensor model: ``full_well`` (electrons at full scale) and ``read_noise``.
    path : Path or None
        The folder it was read from.
    maps : dict
        Parameter name -> (N, N) float32 per-texel map of a spatially varying
        truth (empty otherwise); ``brdf`` holds each region's mean.
    description : dict
        What the truth was: ``brdf`` (the model or built-in), ``varying``,
        ``detail`` (and its ``span_residual_mm``), as the simulator set them.
    """

    model: str
    seed: int
    spp: int
    resolution: tuple[int, int]
    coefficients: dict[str, np.ndarray]
    head_center: np.ndarray
    camera: Camera
    lights: tuple[TrueLight, ...]
    sphere_radius: float
    neutral: np.ndarray
    measurements: tuple[TrueMeasurement, ...]
    brdf: dict
    albedo: np.ndarray
    integrator: dict
    noise: dict[str, float]
    path: Path | None = None
    maps: dict[str, np.ndarray] = field(default_factory=dict)
    description: dict = field(default_factory=dict)

    @property
    def shapes(self) -> dict[str, np.ndarray]:
        """Measurement name -> (V, 3) world-space vertices, mm."""
        return {m.name: m.vertices for m in self.measurements}

    def light(self, name: str) -> TrueLight:
        """The light condition called ``name``."""
        for light in self.lights:
            if light.name == name:
                return light
        raise KeyError(f"no light {name!r} in the ground truth; lights: {[l.name for l in self.lights]}")


def ground_truth_folder(capture: Capture | str | os.PathLike) -> Path:
    """The ``ground_truth/`` folder of a capture (a :class:`Capture`, its folder or its manifest)."""
    root = Path(capture.path if isinstance(capture, Capture) else capture)
    return (root.parent if root.is_file() else root) / GROUND_TRUTH


def write_ground_truth(capture_dir: str | os.PathLike, truth: GroundTruth) -> Path:
    """Write ``truth`` into ``capture_dir/ground_truth/`` (each file atomically,
    ``scene.json`` last); returns the folder."""
    folder = Path(capture_dir) / GROUND_TRUTH
    _write_npy(folder / SHAPES / f"{NEUTRAL}.npy", truth.neutral)
    for m in truth.measurements:
        _write_npy(folder / SHAPES / f"{m.name}.npy", np.asarray(m.vertices, np.float32))
    write_exr(folder / ALBEDO, truth.albedo)
    for name, image in truth.maps.items():
        write_exr(folder / MAPS / f"{name}.exr", np.asarray(image, np.float32))
    write_json(folder / BRDF, truth.brdf)
    write_json(folder / SCENE, _scene_json(truth))
    return folder


def read_ground_truth(capture: Capture | str | os.PathLike) -> GroundTruth | None:
    """The ground truth of a simulated capture, or None for a capture without one.

    Parameters
    ----------
    capture : Capture or path
        The capture, its folder or its manifest.
    """
    folder = ground_truth_folder(capture)
    if not (folder / SCENE).is_file():
        return None
    scene = json.loads((folder / SCENE).read_text())
    head = np.asarray(scene["head_center_mm"], np.float64)
    lights = tuple(TrueLight(l["name"], np.asarray(l["position_mm"], np.float64),
                             np.asarray(l["intensity"], np.float64), float(l["lamp_radius_mm"]),
                             np.asarray(l["steel_sphere_centers_mm"], np.float64)) for l in scene["lights"])
    measurements = tuple(TrueMeasurement(
        m["name"], m["light"], np.load(folder / m["shape"]), np.asarray(m["rotation"], np.float64),
        np.asarray(m["translation_mm"], np.float64), np.asarray(m["yaw_pitch_roll_deg"], np.float64),
        {k: float(v) for k, v in m["expression"].items()},
        {k: np.asarray(v, np.float64) for k, v in m["feature_points"].items()}) for m in scene["measurements"])
    return GroundTruth(
        model=scene.get("model_source", scene.get("model", "builtin")), seed=scene["seed"], spp=scene["spp"],
        resolution=tuple(scene["resolution"]),
        coefficients={k: np.asarray(v, np.float64) for k, v in scene["coefficients"].items()},
        head_center=head, camera=Camera.from_json(scene["camera"]), lights=lights,
        sphere_radius=float(scene["steel_sphere_radius_mm"]), neutral=np.load(folder / SHAPES / f"{NEUTRAL}.npy"),
        measurements=measurements, brdf=json.loads((folder / scene.get("brdf", BRDF)).read_text()),
        albedo=read_exr(folder / scene.get("albedo", ALBEDO)), integrator=scene["integrator"],
        noise=scene["noise"], path=folder,
        maps={name: read_exr(folder / path) for name, path in scene.get("maps", {}).items()},
        description=scene.get("truth", {}))


def with_true_lights(capture: Capture) -> Capture:
    """``capture`` with each light at the position the simulator placed it (``ground_truth/``), in
    place of where its steel spheres located it: what a fit would see with a perfect calibration."""
    truth = read_ground_truth(capture)
    if truth is None:
        raise ValueError(f"capture {capture.path}: no ground truth, so no true light positions")
    positions = {light.name: light.position for light in truth.lights}
    unplaced = [light.name for light in capture.lights if light.name not in positions]
    if unplaced:
        raise ValueError(f"capture {capture.path}: the simulator placed no point light for light(s) {unplaced} "
                         "(an environment or directional light has no true position)")
    return replace(capture, lights=tuple(light.moved_to(positions[light.name]) for light in capture.lights))


def _scene_json(truth: GroundTruth) -> dict:
    """The ``scene.json`` document of ``truth``."""
    head = np.asarray(truth.head_center, np.float64).tolist()
    lights = [{"name": l.name, "position_mm": np.asarray(l.position).tolist(),
               "intensity": np.asarray(l.intensity).tolist(), "lamp_radius_mm": float(l.lamp_radius),
               "steel_sphere_centers_mm": np.asarray(l.sphere_centers).tolist()} for l in truth.lights]
    measurements = [{"name": m.name, "light": m.light, "shape": f"{SHAPES}/{m.name}.npy",
                     "rotation": np.asarray(m.rotation).tolist(), "translation_mm": np.asarray(m.translation).tolist(),
                     "rotation_center_mm": head, "yaw_pitch_roll_deg": np.asarray(m.yaw_pitch_roll).tolist(),
                     "expression": {k: float(v) for k, v in m.expression.items()},
                     "feature_points": {k: np.asarray(v).tolist() for k, v in m.feature_points.items()}}
                    for m in truth.measurements]
    return {"model": truth.model, "seed": int(truth.seed), "spp": int(truth.spp),
            "resolution": [int(r) for r in truth.resolution],
            "coefficients": {k: np.asarray(v).tolist() for k, v in truth.coefficients.items()},
            "head_center_mm": head, "camera": truth.camera.to_json(), "lights": lights,
            "steel_sphere_radius_mm": float(truth.sphere_radius), "measurements": measurements,
            "albedo": ALBEDO, "brdf": BRDF, "integrator": truth.integrator, "noise": truth.noise,
            "maps": {name: f"{MAPS}/{name}.exr" for name in truth.maps}, "truth": truth.description}


def _write_npy(path: Path, array: np.ndarray) -> None:
    with atomic_write(path) as f:
        np.save(f, array)
