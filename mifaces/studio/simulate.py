"""The photo studio, simulated: captures with ground truth (paper sec. 3).

:func:`simulate` renders a subject as the paper photographs one: a fixed,
calibrated camera; a point light moved between light conditions on a sphere
around the head; up to three poses per light with small expression changes
between measurements; per measurement a point-light photograph and a
companion under diffuse light (or an exposure series); per light the two
steel-sphere pictures the light is located from; camera noise and exposure.
Rendering is Mitsuba's path tracer (shadows and interreflection) in a black
room (no geometry but the subject: the walls return no light).

The face is a morphable model face (built-in by default) with a
ground-truth spatially varying BRDF: per region the specular parameters of
one of the plugins ``phong``, ``cooktorrance``, ``ward``, ``lafortune``,
over a per-texel albedo map with fine detail. The capture folder it writes
loads with :func:`mifaces.capture.load_capture` and holds only what a real
capture would; ``ground_truth/`` holds the rest.

Published skin parameters
-------------------------
:data:`COOK_TORRANCE_REGIONS` holds the Cook–Torrance parameters per region.
Skin: Beckmann roughness m = 0.35 and η = 1.38, from Weyrich et al.,
"Analysis of human faces using a measurement-based skin reflectance model",
SIGGRAPH 2006 (Torrance–Sparrow fits over 149 faces: η = 1.38, roughness of
facial skin regions around 0.3–0.45; we use representative rounded values),
with ρ_s = 1: the lobe is then exactly the Fresnel reflection of the skin's
surface. Lips are smoother (m = 0.25). Eyes: the cornea's index η = 1.376
(Le Grand's schematic eye; Atchison & Smith, "Optics of the Human Eye",
2000) and a nearly smooth tear film (m = 0.05). Eyebrows and hair: keratin,
η = 1.55 (Marschner et al., "Light scattering from human hair fibers",
SIGGRAPH 2003), rough and weaker (hair is not a surface; this is a crude
stand-in). Nostrils and beard: skin, weaker (occlusion by hair and cavity).
The other models' parameters are derived from these, not chosen
separately (:func:`default_brdf`): Ward α = m (Ward 1992 defines α as the
RMS surface slope, as Beckmann's m); the Phong exponent n = 1 / (2 m²)
matches the width of the lobe (cos^n α ≈ exp(-n α²/2) around the mirror
direction, Beckmann exp(-θh²/m²), α = 2θh in the plane of incidence);
the Phong and Ward ρ_s, and the Lafortune coefficients (a lobe
C_xy = -C, C_z = C is the modified Phong lobe, Lafortune et al. 1997, with
C^n = 2π ρ_s / (n + 2)), take the Cook–Torrance lobe's albedo at normal
incidence, computed with the array API of :mod:`mifaces.brdf`.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..capture import FORMAT, GROUND_TRUTH, MANIFEST, VERSION, Camera
from ..files import atomic_write, write_exr, write_json, write_png
from ..model.geometry import rotation_matrix
from ..render import face_shapes, mitsuba_sensor, rgb as _rgb
from .truth import COOK_TORRANCE_REGIONS, brdf_with_overrides, default_brdf  # noqa: F401

PRESETS = {"paper": {"measurements": 22}}
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


# Studio
# --------------------------------------------------------------------------------------------

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


def studio_camera(width: int, height: int, head: np.ndarray) -> Camera:
    """The fixed camera: on the +z axis through the head centre at
    :data:`CAMERA_DISTANCE`, looking at it, :data:`FIELD_HEIGHT` mm of field
    at the head, principal point at the image centre, no distortion."""
    fy = height * CAMERA_DISTANCE / FIELD_HEIGHT
    rotation = np.diag([1.0, -1.0, -1.0])  # OpenCV axes: x right, y down, z forward (world -z)
    position = head + np.array([0.0, 0.0, CAMERA_DISTANCE])
    return Camera(width, height, fy, fy, width / 2 - 0.5, height / 2 - 0.5, np.zeros(5), rotation,
                  -rotation @ position)


def camera_noise(values: np.ndarray, rng: np.random.Generator, full_well: float = 20000.0,
                 read_noise: float = 0.002) -> np.ndarray:
    """Sensor noise on linear values in full-scale units, clipped to [0, 1].

    Photon (shot) noise with ``full_well`` electrons at full scale (Gaussian
    approximation, variance v / full_well) plus Gaussian read noise of
    standard deviation ``read_noise``.
    """
    v = np.clip(np.asarray(values, np.float64), 0.0, None)
    noisy = v + rng.standard_normal(v.shape) * np.sqrt(v / full_well + read_noise ** 2)
    return np.clip(noisy, 0.0, 1.0).astype(np.float32)


def albedo_map(model, color, rng: np.random.Generator, size: int = 1024, detail: float = 0.12) -> np.ndarray:
    """Per-texel albedo (size, size, 3), linear RGB, in the model's texture space.

    The model's per-vertex albedo for colour coefficients ``color``,
    interpolated over the triangles, times fine multiplicative detail:
    log-normal noise at pore/freckle scales (1-2 texels and ~6 texels;
    ``detail`` is its standard deviation in log units), and a few darker
    spots. Texels no triangle covers take the nearest covered texel.
    """
    import scipy.ndimage as ndi

    from ..model.texture_space import rasterize

    per_vertex = model.texture(color) if model.has_texture else np.full((model.vertex_count, 3), 0.45, np.float32)
    cov = rasterize(model.uv, model.triangles, (size, size))
    covered = cov.covered
    tri = model.triangles[cov.triangle[covered]]
    bary = cov.barycentric[covered]
    image = np.zeros((size, size, 3), np.float64)
    image[covered] = np.einsum("nk,nkc->nc", bary, per_vertex[tri])
    _, (ri, ci) = ndi.distance_transform_edt(~covered, return_indices=True)
    image = image[ri, ci]
    fine = ndi.gaussian_filter(rng.standard_normal((size, size)), 0.8)
    medium = ndi.gaussian_filter(rng.standard_normal((size, size)), 3.0)
    fine /= fine.std()
    medium /= medium.std()
    spots = ndi.gaussian_filter((rng.random((size, size)) < 2e-4).astype(float), 2.0)
    spots /= max(spots.max(), 1e-12)
    log = detail * (0.6 * fine + 0.8 * medium) - 0.5 * spots
    tint = np.array([0.8, 1.0, 1.15])  # spots are melanin: darker in blue than red
    image = image * np.exp(log[..., None] * tint)
    return np.clip(image, 0.0, 0.95).astype(np.float32)


@dataclass
class SimulationResult:
    """What :func:`simulate` wrote and how long it took."""

    path: Path
    measurements: int
    lights: int
    seconds: float
    render_seconds: list[float] = field(default_factory=list)

    @property
    def seconds_per_measurement(self) -> float:
        """Mean time to render one measurement (point-light image and companions)."""
        return float(np.mean(self.render_seconds)) if self.render_seconds else float("nan")


def _render(scene_dict: dict, spp: int, seed: int) -> np.ndarray:
    import mitsuba as mi

    scene = mi.load_dict(scene_dict)
    return np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float32)[..., :3]


def _write_npy(path: Path, array: np.ndarray) -> None:
    with atomic_write(path) as f:
        np.save(f, array)


def simulate(out: str | os.PathLike, model="builtin", brdf: str = "cooktorrance", brdf_params: dict | None = None,
             measurements: int = 6, resolution: tuple[int, int] = (512, 512), seed: int = 0,
             preset: str | None = None, spp: int = 64, companion: str = "diffuse",
             albedo_resolution: int = 1024, progress: bool = True) -> SimulationResult:
    """Simulate a capture session and write it, with ground truth, to ``out``.

    Parameters
    ----------
    out : path
        Capture folder to write (created; files in it are replaced atomically).
    model : str, path or MorphableModel
        ``'builtin'``, a model file for :func:`mifaces.load_model`, or a model.
    brdf : str
        Ground-truth plugin: ``'cooktorrance'`` (default), ``'phong'``, ``'ward'``, ``'lafortune'``.
    brdf_params : dict, optional
        Overrides in the ``brdf.json`` layout (``{"model", "regions": {region: {param: value}}}``).
    measurements : int
        Number of measurements K: ceil(K / 3) light conditions with up to three poses each.
    resolution : (width, height)
    seed : int
        Identity, albedo detail, lights, poses, expressions, noise and Monte Carlo
        seeds all derive from it: a fixed seed reproduces the capture.
    preset : {'paper'}, optional
        ``'paper'``: the paper's 22 measurements (8 lights, 3 poses each for 6, 2 for 2).
    spp : int
        Samples per pixel of the point-light renders (companions use half).
    companion : {'diffuse', 'exposures', 'both'}
        Diffuse-light picture (8-bit sRGB), exposure series (three 8-bit sRGB
        pictures at 1/4, 1 and 4 times the point-light exposure), or both.
    albedo_resolution : int
        Size of the square albedo map.
    progress : bool
        Show a progress bar.

    Returns
    -------
    SimulationResult
    """
    import mitsuba as mi
    from tqdm import tqdm

    from ..model import load_model
    from ..model.landmarks import FEATURE_POINTS

    t_start = time.perf_counter()
    if preset is not None:
        if preset not in PRESETS:
            raise ValueError(f"unknown preset {preset!r}; presets: {sorted(PRESETS)}")
        measurements = PRESETS[preset]["measurements"]
    if measurements < 1:
        raise ValueError(f"measurements must be >= 1, got {measurements}")
    if companion not in ("diffuse", "exposures", "both"):
        raise ValueError(f"companion must be 'diffuse', 'exposures' or 'both', got {companion!r}")
    width, height = (int(r) for r in resolution)
    if width < 16 or height < 16:
        raise ValueError(f"resolution must be at least 16x16, got {width}x{height}")
    out = Path(out)
    face_model = load_model(model)
    truth = brdf_with_overrides(brdf, brdf_params)
    rng = np.random.default_rng(seed)

    # subject: identity and albedo
    coefficients = face_model.random_coefficients(rng)
    coefficients["shape"] *= 0.7  # a typical rather than an extreme face
    if "color" in coefficients:
        coefficients["color"] *= 0.7
    neutral = face_model.shape(coefficients["shape"])
    head = 0.5 * (neutral.min(axis=0) + neutral.max(axis=0))
    albedo = albedo_map(face_model, coefficients.get("color"), rng, albedo_resolution)
    texture = mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(albedo), "raw": True,
                            "filter_type": "bilinear", "wrap_mode": "clamp"})

    camera = studio_camera(width, height, head)
    n_lights = math.ceil(measurements / 3)
    per_light = [3] * n_lights
    for i in range(3 * n_lights - measurements):  # the deficit (at most 2) from the last lights
        per_light[-1 - i % n_lights] -= 1
    directions = light_directions(n_lights, rng)
    distances = LIGHT_DISTANCE * rng.uniform(0.9, 1.1, n_lights)
    light_positions = head + directions * distances[:, None]
    intensity = np.full(3, np.pi * LIGHT_DISTANCE ** 2)  # the white target reads 1 per unit exposure at 1.5 m
    exposure = WHITE_LEVEL  # per unit exposure the white target at LIGHT_DISTANCE reads 1
    poses = [(0.0, 0.0, 0.0), (-25.0, 0.0, 0.0), (25.0, 0.0, 0.0)]

    # steel spheres: around where the head is, all in the field of view, in one plane facing the camera
    # so that for lights in front (azimuth within 70 degrees) none lies in another's shadow
    sphere_centers = head + SPHERE_OFFSETS
    integrator = {"type": "path", "max_depth": 4, "hide_emitters": False}
    sensor = mitsuba_sensor(camera, spp)

    def scene(shapes: dict, emitters: dict, spp_: int) -> dict:
        d = {"type": "scene", "integrator": integrator, "sensor": dict(sensor, sampler={"type": "independent",
                                                                                        "sample_count": spp_})}
        d.update(shapes)
        d.update(emitters)
        return d

    def steel_spheres() -> dict:
        return {f"steel_{i}": {"type": "sphere", "center": c.tolist(), "radius": STEEL_SPHERE_RADIUS,
                               "bsdf": {"type": "conductor", "material": "Cr"}} for i, c in enumerate(sphere_centers)}

    images = out / "images"
    gt = out / GROUND_TRUTH
    frames = sum(1 + (companion in ("diffuse", "both")) + (companion in ("exposures", "both"))
                 for _ in range(measurements)) + 2 * n_lights
    bar = tqdm(total=frames, desc="simulating", unit="frame", disable=not progress)
    render_seconds = []
    manifest_lights, manifest_measurements, gt_lights, gt_measurements = [], [], [], []
    frame_seed = seed * 1000

    # lights: the two steel-sphere pictures each
    for li in range(n_lights):
        name = f"L{li:02d}"
        lamp = {"lamp": {"type": "sphere", "center": light_positions[li].tolist(), "radius": LAMP_RADIUS,
                         "emitter": {"type": "area", "radiance": _rgb(intensity / (np.pi * LAMP_RADIUS ** 2))}}}
        frame_seed += 1
        spp_hl = max(4 * spp, 256)  # the lamp's reflection is a few pixels wide: sample it well
        hl = _render(scene(steel_spheres(), lamp, spp_hl), spp_hl, frame_seed)
        bar.update()
        t_hl = 0.7 / max(float(hl.max()), 1e-12)  # exposed so the brightest highlight reads 0.7
        hl = camera_noise(hl * t_hl, rng)
        frame_seed += 1
        ol = _render(scene(steel_spheres(), {"diffuse_light": {"type": "constant", "radiance": _rgb(1.0)}},
                           max(spp // 2, 4)), max(spp // 2, 4), frame_seed)
        bar.update()
        t_ol = 0.8
        ol = camera_noise(ol * t_ol, rng)
        write_exr(images / f"{name}_spheres_point.exr", hl)
        write_exr(images / f"{name}_spheres_diffuse.exr", ol)
        manifest_lights.append({
            "name": name, "intensity": intensity.tolist(),
            "spheres": {"radius_mm": STEEL_SPHERE_RADIUS,
                        "highlight": {"path": f"images/{name}_spheres_point.exr", "exposure": t_hl,
                                      "saturation": 1.0},
                        "outline": {"path": f"images/{name}_spheres_diffuse.exr", "exposure": t_ol,
                                    "saturation": 1.0}}})
        gt_lights.append({"name": name, "position_mm": light_positions[li].tolist(),
                          "intensity": intensity.tolist(), "lamp_radius_mm": LAMP_RADIUS,
                          "steel_sphere_centers_mm": sphere_centers.tolist()})

    # measurements
    shapes_dir = gt / "shapes"
    _write_npy(shapes_dir / "neutral.npy", neutral)
    feature_names = [n for n in FEATURE_POINTS if FEATURE_POINTS[n] in face_model.ibug_landmarks]
    index = 0
    for li in range(n_lights):
        for pi in range(per_light[li]):
            t0 = time.perf_counter()
            name = f"m{index:02d}"
            yaw, pitch, roll = poses[pi]
            yaw += rng.uniform(-3, 3)
            pitch += rng.uniform(-4, 4)
            roll += rng.uniform(-2, 2)
            rotation = rotation_matrix(yaw, pitch, roll)
            translation = rng.normal(0.0, 3.0, 3)
            expression = None
            if face_model.has_expressions:
                expression = np.abs(rng.normal(0.0, 0.12, face_model.expression_dim))
            local = face_model.shape(coefficients["shape"], expression).astype(np.float64)
            vertices = (local - head) @ rotation.T + head + translation
            normals = face_model.vertex_normals(vertices.astype(np.float32))
            shapes = face_shapes(face_model, vertices.astype(np.float32), truth, texture, normals)
            point = {"light": {"type": "point", "position": light_positions[li].tolist(),
                               "intensity": _rgb(intensity)}}
            frame_seed += 1
            radiance = _render(scene(shapes, point, spp), spp, frame_seed)
            bar.update()
            image = camera_noise(radiance * exposure, rng)
            write_exr(images / f"{name}_point.exr", image)
            entry = {"name": name, "light": f"L{li:02d}", "pose": f"P{li:02d}{pi}",
                     "image": {"path": f"images/{name}_point.exr", "exposure": exposure, "saturation": 1.0}}
            if companion in ("diffuse", "both"):
                frame_seed += 1
                spp_d = max(spp // 2, 4)
                diffuse = _render(scene(shapes, {"diffuse_light": {"type": "constant", "radiance": _rgb(1.0)}},
                                        spp_d), spp_d, frame_seed)
                bar.update()
                t_d = 0.8
                write_png(images / f"{name}_diffuse.png", camera_noise(diffuse * t_d, rng))
                entry["diffuse"] = {"path": f"images/{name}_diffuse.png", "transfer": "srgb", "exposure": t_d}
            if companion in ("exposures", "both"):
                series = []
                for k, factor in enumerate((0.25, 1.0, 4.0)):
                    t_k = exposure * factor
                    write_png(images / f"{name}_exposure{k}.png", camera_noise(radiance * t_k, rng))
                    series.append({"path": f"images/{name}_exposure{k}.png", "transfer": "srgb", "exposure": t_k})
                bar.update()
                entry["exposures"] = series
            # feature points: the visible landmarks, as an annotator would click them (0.5 px noise at 512)
            scene_obj = mi.load_dict({"type": "scene", **shapes})
            targets = np.array([vertices[face_model.ibug_landmarks[FEATURE_POINTS[f]]] for f in feature_names])
            offsets = targets - camera.position
            lengths = np.linalg.norm(offsets, axis=1)
            units = offsets / lengths[:, None]
            origin = [mi.Float(np.full(len(targets), c)) for c in camera.position]
            ray = mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(*[mi.Float(units[:, k]) for k in range(3)]))
            ray.maxt = mi.Float(lengths - 1.0)  # a landmark is visible when nothing is hit before it
            occluded = np.asarray(scene_obj.ray_test(ray))
            points, exact = {}, {}
            for fname, p, hidden in zip(feature_names, targets, occluded):
                if hidden:
                    continue
                xy = camera.project(p)
                exact[fname] = xy.tolist()
                points[fname] = (xy + rng.normal(0.0, 0.5 * width / 512, 2)).round(2).tolist()
            entry["feature_points"] = points
            manifest_measurements.append(entry)
            _write_npy(shapes_dir / f"{name}.npy", vertices.astype(np.float32))
            gt_measurements.append({"name": name, "light": f"L{li:02d}", "shape": f"shapes/{name}.npy",
                                    "rotation": rotation.tolist(), "translation_mm": translation.tolist(),
                                    "rotation_center_mm": head.tolist(), "yaw_pitch_roll_deg": [yaw, pitch, roll],
                                    "expression": {} if expression is None else dict(
                                        zip(face_model.expression_names, map(float, expression))),
                                    "feature_points": exact})
            render_seconds.append(time.perf_counter() - t0)
            index += 1
    bar.close()

    # metric distances on the neutral face, and the white target
    lm = face_model.ibug_landmarks
    pairs = [("right_eye_outer", "left_eye_outer"), ("right_eye_inner", "left_eye_inner"),
             ("mouth_right", "mouth_left")]
    dist_entries = [{"from": a, "to": b, "mm": round(float(np.linalg.norm(
        neutral[lm[FEATURE_POINTS[a]]] - neutral[lm[FEATURE_POINTS[b]]])), 3)} for a, b in pairs]
    white = intensity / (np.pi * LIGHT_DISTANCE ** 2)  # Lambertian, reflectance 1, frontal, per unit exposure
    manifest = {
        "format": FORMAT, "version": VERSION,
        "camera": camera.to_json(),
        "white_target": {"value": white.tolist(), "reflectance": 1.0, "distance_mm": LIGHT_DISTANCE,
                         "intensity": intensity.tolist(), "cos_incidence": 1.0},
        "distances": dist_entries,
        "lights": manifest_lights,
        "measurements": manifest_measurements,
        "metadata": {"source": "mifaces simulate", "units": "mm"},
    }
    write_exr(gt / "albedo.exr", albedo)
    write_json(gt / "brdf.json", truth)
    write_json(gt / "scene.json", {
        "model": face_model.name, "seed": seed, "spp": spp, "resolution": [width, height],
        "coefficients": {k: v.tolist() for k, v in coefficients.items()},
        "head_center_mm": head.tolist(), "camera": camera.to_json(), "lights": gt_lights,
        "steel_sphere_radius_mm": STEEL_SPHERE_RADIUS, "measurements": gt_measurements,
        "albedo": "albedo.exr", "brdf": "brdf.json",
        "integrator": integrator, "noise": {"full_well": 20000.0, "read_noise": 0.002}})
    write_json(out / MANIFEST, manifest)  # last: a capture appears complete or not at all
    return SimulationResult(out, measurements, n_lights, time.perf_counter() - t_start, render_seconds)
