"""Writing a simulated capture: the photographs and the manifest a real capture
would have (:mod:`mifaces.capture`, ``docs/capture.md``), and the ground truth
beside them (:mod:`mifaces.capture.ground_truth`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..capture import FORMAT, MANIFEST, VERSION, GroundTruth, TrueLight, TrueMeasurement
from ..io.atomic import write_json
from ..io.image_files import write_exr, write_png
from ..model.landmarks import FEATURE_POINTS
from .photograph import FULL_WELL, READ_NOISE, Photographs, SpherePhotographs
from .environment_light import EnvironmentLight
from .scene import LAMP_RADIUS, LIGHT_DISTANCE, STEEL_SPHERE_RADIUS, Studio, white_value
from .subject import HeadPose, Subject

#: Folder of the photographs inside the capture.
IMAGES = "images"
#: The metric distances on the face the manifest gives (paper sec. 4.2).
DISTANCE_PAIRS = [("right_eye_outer", "left_eye_outer"), ("right_eye_inner", "left_eye_inner"),
                  ("mouth_right", "mouth_left")]


def light_name(light: int) -> str:
    """The manifest's name of light condition ``light``."""
    return f"L{light:02d}"


def light_names(studio: Studio) -> list[str]:
    """The manifest's names of the studio's light conditions: its environment's, or the point light's."""
    if studio.environment is not None:
        return [studio.environment.name]
    return [light_name(light) for light in range(len(studio.per_light))]


def camera_id(view: int) -> str:
    """The manifest id of camera ``view`` of a simulated rig."""
    return f"c{view}"


def view_name(name: str, view: int) -> str:
    """The name of measurement ``name``'s photograph by camera ``view`` of a rig: the first camera's
    keeps ``name`` (a one-camera capture's names), the others' add ``_c<view>``."""
    return name if view == 0 else f"{name}_{camera_id(view)}"


def pose_name(studio: Studio, light: int, pose: int) -> str:
    """The manifest's name of pose ``pose`` of condition ``light``: each head turn of an
    environment-lit capture its own."""
    return f"P{pose:02d}" if studio.environment is not None else f"P{light:02d}{pose}"


def write_environment(out: Path, light: EnvironmentLight) -> dict:
    """Write the environment map the photographs were rendered with (linear EXR, float32: exactly
    that map); its manifest entry, a given environment light."""
    write_exr(out / light.path, light.map)
    return light.manifest_entry()


def write_sphere_photographs(out: Path, studio: Studio, light: int, pictures: SpherePhotographs) -> dict:
    """Write the steel-sphere pictures of condition ``light`` (linear EXR); its manifest entry."""
    name = light_name(light)
    highlight, outline = f"{IMAGES}/{name}_spheres_point.exr", f"{IMAGES}/{name}_spheres_diffuse.exr"
    write_exr(out / highlight, pictures.highlight)
    write_exr(out / outline, pictures.outline)
    return {"name": name, "intensity": studio.intensity.tolist(),
            "spheres": {"radius_mm": STEEL_SPHERE_RADIUS,
                        "highlight": {"path": highlight, "exposure": pictures.highlight_exposure, "saturation": 1.0},
                        "outline": {"path": outline, "exposure": pictures.outline_exposure, "saturation": 1.0}}}


def write_photographs(out: Path, name: str, light: str, pose: str, photographs: Photographs) -> dict:
    """Write the pictures of measurement ``name`` under light ``light`` in pose ``pose`` (their
    manifest names): the point-light (or environment-lit) photograph as linear EXR, the
    companions as 8-bit sRGB PNG; its manifest entry (without feature points)."""
    point = f"{IMAGES}/{name}_point.exr"
    write_exr(out / point, photographs.point)
    entry = {"name": name, "light": light, "pose": pose,
             "image": {"path": point, "exposure": photographs.exposure, "saturation": 1.0}}
    if photographs.diffuse is not None:
        diffuse = f"{IMAGES}/{name}_diffuse.png"
        write_png(out / diffuse, photographs.diffuse)
        entry["diffuse"] = {"path": diffuse, "transfer": "srgb", "exposure": photographs.diffuse_exposure}
    if photographs.exposures:
        series = []
        for k, (picture, exposure) in enumerate(photographs.exposures):
            path = f"{IMAGES}/{name}_exposure{k}.png"
            write_png(out / path, picture)
            series.append({"path": path, "transfer": "srgb", "exposure": exposure})
        entry["exposures"] = series
    return entry


def write_manifest(out: Path, studio: Studio, face_model, neutral: np.ndarray, lights: list[dict],
                   measurements: list[dict]) -> None:
    """Write ``capture.json``: the camera (or a rig's cameras), the white target (none for an environment-lit capture:
    its map is in pixel value), three metric distances on the ``neutral`` face, and the light and
    measurement entries."""
    landmarks = face_model.ibug_landmarks
    distances = [{"from": a, "to": b, "mm": round(float(np.linalg.norm(
        neutral[landmarks[FEATURE_POINTS[a]]] - neutral[landmarks[FEATURE_POINTS[b]]])), 3)}
        for a, b in DISTANCE_PAIRS]
    manifest = {"format": FORMAT, "version": VERSION}
    if studio.rig:
        manifest["cameras"] = [{"id": camera_id(view), **camera.to_json()} for view, camera in enumerate(studio.rig)]
    else:
        manifest["camera"] = studio.camera.to_json()
    if studio.environment is None:
        manifest["white_target"] = {"value": white_value(studio).tolist(), "reflectance": 1.0,
                                    "distance_mm": LIGHT_DISTANCE, "intensity": studio.intensity.tolist(),
                                    "cos_incidence": 1.0}
    manifest.update({"distances": distances, "lights": lights, "measurements": measurements,
                     "metadata": {"source": "mifaces simulate", "units": "mm"}})
    write_json(out / MANIFEST, manifest)


def true_measurement(name: str, light: str, pose: HeadPose, feature_points: dict, face_model) -> TrueMeasurement:
    """The ground truth of measurement ``name`` under light ``light`` (its manifest name): the
    subject's pose and shape, and the exact ``feature_points``."""
    expression = {} if pose.expression is None else dict(zip(face_model.expression_names,
                                                             map(float, pose.expression)))
    return TrueMeasurement(name, light, pose.vertices.astype(np.float32), pose.rotation,
                           pose.translation, np.array(pose.yaw_pitch_roll), expression,
                           {k: np.asarray(v) for k, v in feature_points.items()})


def ground_truth(face_model, subject: Subject, studio: Studio, measurements: list[TrueMeasurement], brdf: dict,
                 seed: int, spp: int, maps: dict | None = None, description: dict | None = None) -> GroundTruth:
    """What the simulation knew, as :func:`mifaces.capture.write_ground_truth` writes it (``maps``:
    a spatially varying truth's parameter maps; ``description``: what the truth was). The true
    lights are the point lights: an environment-lit capture has none (``description`` names its
    environment, the capture holds its map)."""
    lights = tuple(TrueLight(light_name(i), position, studio.intensity, LAMP_RADIUS, studio.sphere_centers)
                   for i, position in enumerate(studio.light_positions))  # none under an environment
    return GroundTruth(
        model=face_model.name, seed=seed, spp=spp, resolution=(studio.camera.width, studio.camera.height),
        coefficients=subject.coefficients, head_center=subject.head, camera=studio.camera, lights=lights,
        sphere_radius=STEEL_SPHERE_RADIUS, neutral=subject.neutral, measurements=tuple(measurements), brdf=brdf,
        albedo=subject.albedo, integrator=studio.integrator, noise={"full_well": FULL_WELL, "read_noise": READ_NOISE},
        maps=dict(maps or {}), description=dict(description or {}))
