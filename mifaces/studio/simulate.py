"""The photo studio, simulated: captures with ground truth (paper sec. 3).

:func:`simulate` renders a subject as the paper photographs one: a fixed,
calibrated camera; a point light moved between light conditions on a sphere
around the head; up to three poses per light with small expression changes
between measurements; per measurement a point-light photograph and a
companion under diffuse light (or an exposure series); per light the two
steel-sphere pictures the light is located from; camera noise and exposure.
Rendering is Mitsuba's path tracer (shadows and interreflection) in a black
room (no geometry but the subject: the walls return no light). With
``environment``, every photograph is lit instead by the generated studio or
by the sun and sky, which the capture states as one given environment light
(:mod:`mifaces.studio.environment_light`), and the head turns differently in
each measurement. What to simulate is one value, :class:`~mifaces.studio.options.SimulationOptions`.

The steps: :mod:`mifaces.studio.subject` (the face, its albedo, its poses),
:mod:`mifaces.studio.scene` (the studio and its Mitsuba scenes),
:mod:`mifaces.studio.photograph` (renders, sensor noise, feature points) and
:mod:`mifaces.studio.write` (photographs, manifest, ground truth).

The face is a morphable model face (built-in by default) with a
ground-truth spatially varying BRDF: per region the specular parameters of
one of the plugins ``phong``, ``cooktorrance``, ``ward``, ``lafortune``, or
of one of Mitsuba's built-ins ``roughplastic`` and ``principled``
(:mod:`mifaces.brdf.builtin`: truths outside the fitted families), over a
per-texel albedo map with fine detail. Two options take the truth further
from what the fit can represent: ``varying`` gives the lobe's scale and
width per texel (an oily T-zone, drier cheeks; :mod:`mifaces.studio.varying`),
``detail`` adds wrinkles, pores and asymmetry the model's PCA cannot
express (:mod:`mifaces.studio.detail`), and ``subsurface`` makes the skin
translucent: a rough dielectric boundary over a scattering medium with
measured skin coefficients (:mod:`mifaces.studio.subsurface`). The capture folder it writes
loads with :func:`mifaces.capture.load_capture` and holds only what a real
capture would; ``ground_truth/`` holds the rest.

Published skin parameters
-------------------------
:data:`mifaces.studio.truth.COOK_TORRANCE_REGIONS` holds the Cook–Torrance parameters per region.
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
separately (:func:`mifaces.studio.truth.default_brdf`): Ward α = m (Ward 1992 defines α as the
RMS surface slope, as Beckmann's m); the Phong exponent n = 1 / (2 m²)
matches the width of the lobe (cos^n α ≈ exp(-n α²/2) around the mirror
direction, Beckmann exp(-θh²/m²), α = 2θh in the plane of incidence);
the Phong and Ward ρ_s, and the Lafortune coefficients (a lobe
C_xy = -C, C_z = C is the modified Phong lobe, Lafortune et al. 1997, with
C^n = ρ_s (n + 2) / 2π), take the Cook–Torrance lobe's albedo at normal
incidence, computed with the array API of :mod:`mifaces.brdf`.
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..brdf.cooktorrance import DIGITS
from ..capture import MANIFEST, write_ground_truth
from ..io.result_set import SET_MANIFEST, ResultSetError, check_result_target, result_set, verify_set
from ..options.fields import record
from ..model import load_model
from ..runtime import disk_cache
from ..runtime.progress import progress as progress_bar
from ..render import face_meshes, mitsuba_sensor, region_bsdf, region_meshes
from .photograph import albedo_texture, annotate, photograph_face, photograph_spheres, visible_feature_points
from . import subsurface as translucent
from .detail import fine_detail, span_residual
from .options import SimulationOptions
from .scene import rig_cameras, set_up_studio
from .subject import head_pose, make_subject, with_detail
from .truth import brdf_with_overrides
from .varying import VARYING, map_textures, region_means, varying_maps
from .write import (camera_id, ground_truth, light_names, pose_name, true_measurement, view_name, write_environment,
                    write_manifest, write_photographs, write_sphere_photographs)

#: The result-set kind of a simulated capture's folder.
KIND = "capture"


@dataclass
class SimulationResult:
    """What :func:`simulate` wrote and how long it took; ``cached``: copied from mifaces' disk cache
    (no renders)."""

    path: Path
    measurements: int
    lights: int
    seconds: float
    render_seconds: list[float] = field(default_factory=list)
    cached: bool = False

    @property
    def seconds_per_measurement(self) -> float:
        """Mean time to render one measurement (point-light image and companions)."""
        return float(np.mean(self.render_seconds)) if self.render_seconds else float("nan")


def simulate(out: str | os.PathLike, options: SimulationOptions | None = None, *, progress: bool = True,
             force: bool = False, cache: bool = False) -> SimulationResult:
    """Simulate a capture session and write it, with ground truth, to ``out``.

    Parameters
    ----------
    out : path
        Capture folder to write, as one result set
        (:func:`mifaces.io.result_set.result_set`): the photographs, the manifest and
        the ground truth appear together, or not at all.
    options : SimulationOptions, optional
        What to simulate (:class:`mifaces.studio.options.SimulationOptions`: the face model, the
        true BRDF and how far it lies from what a fit represents, the measurements, lights and
        cameras, the photographs' size and samples, the seed); default: its defaults.
    progress : bool
        Show a progress bar.
    force : bool
        Replace a simulated capture that ``out`` holds. A folder holding
        anything else (a real capture) is never written over.
    cache : bool
        Take the capture from mifaces' disk cache (:mod:`mifaces.runtime.disk_cache`) where the
        same options and the same code made it before, and keep it there otherwise
        (``mifaces measure`` does, for the built-in default capture).

    Returns
    -------
    SimulationResult

    Examples
    --------
    A small capture of the built-in face (``out``: a folder to write into):

    >>> from mifaces import SimulationOptions, load_capture, simulate
    >>> options = SimulationOptions(measurements=2, resolution=(64, 64), spp=4, albedo_resolution=128)
    >>> result = simulate(out / "capture", options, progress=False)
    >>> result.measurements, result.path.name
    (2, 'capture')
    >>> capture = load_capture(result.path)
    >>> capture.camera.width, len(capture.measurements)
    (64, 2)

    Raises
    ------
    ValueError
        A true BRDF that the overrides (``brdf_params``), ``varying`` or ``subsurface`` do not fit.
    FileExistsError
        ``out`` holds a simulated capture and ``force`` is False.
    mifaces.io.result_set.ResultSetError
        ``out`` holds files mifaces did not write (a real capture).
    """
    t_start = time.perf_counter()
    options = SimulationOptions() if options is None else options
    if not isinstance(options, SimulationOptions):
        raise TypeError(f"simulate() takes its options as a SimulationOptions, got {type(options).__name__}")
    out = check_result_target(out, KIND, force)  # before the work: writable, and nothing to lose
    inputs = {"options": record(options)}
    if cache and (kept := _from_cache(out, inputs, force)) is not None:
        seconds = time.perf_counter() - t_start
        if progress:
            print(f"simulating: the same capture as before, copied from mifaces' cache ({disk_cache.cache_root()}) "
                  f"in {seconds:.1f} s", file=sys.stderr, flush=True)
        return SimulationResult(out, options.measurements, kept, seconds, cached=True)
    face_model = load_model(options.face_model)
    truth = brdf_with_overrides(options.brdf, options.brdf_params)
    if options.subsurface and (truth["model"] != "cooktorrance" or options.varying):
        raise ValueError("a subsurface truth (subsurface=True) takes the Cook–Torrance truth's reflection for its "
                         f"boundary: brdf='cooktorrance' without varying maps; got {truth['model']!r}"
                         + (" with varying=True" if options.varying else ""))
    if options.varying and truth["model"] not in VARYING:
        raise ValueError(f"a spatially varying truth (varying=True) needs a BRDF with lobe scale and width maps: "
                         f"{sorted(VARYING)}; got {truth['model']!r}")
    # what the photographs show stays in ground_truth/: the set manifest records only the set's shape
    info = {"measurements": options.measurements, "resolution": list(options.resolution),
            "companion": options.companion}
    if options.environment is not None:
        info["environment"] = options.environment
    if options.cameras > 1:
        info["cameras"] = options.cameras
    with result_set(out, KIND, force=force, info=info) as folder:
        lights, render_seconds = _simulate_into(folder, face_model, truth, options, progress)
    if cache:
        disk_cache.store(KIND, inputs, out)
    return SimulationResult(out, options.measurements, lights, time.perf_counter() - t_start, render_seconds)


def _from_cache(out: Path, inputs: dict, force: bool) -> int | None:
    """Copy the cached capture made from ``inputs`` into ``out``, as one result set; its number of
    light conditions, or None where the cache has none (or a damaged one, then discarded)."""
    kept = disk_cache.lookup(KIND, inputs)
    if kept is None:
        return None
    try:
        manifest = verify_set(kept, KIND)
        lights = len(json.loads((kept / MANIFEST).read_text())["lights"])
    except (ResultSetError, OSError, ValueError, KeyError, TypeError):
        disk_cache.discard(kept)
        return None
    if manifest is None:
        disk_cache.discard(kept)
        return None
    with result_set(out, KIND, force=force, info=manifest["info"]) as folder:
        shutil.copytree(kept, folder, dirs_exist_ok=True, ignore=shutil.ignore_patterns(SET_MANIFEST))
    return lights


def _truth_subject(face_model, truth: dict, rng: np.random.Generator, options: SimulationOptions):
    """The subject, its parameter maps (empty unless ``options.varying``), the ``brdf.json``
    the ground truth records, and the truth's description. Detail and maps draw from their own
    generators, so that a capture with them shows the same face, lights and noise as one without."""
    seed, albedo_resolution = options.seed, options.albedo_resolution
    subject = make_subject(face_model, rng, albedo_resolution)
    description = {"brdf": truth["model"], "varying": bool(options.varying), "detail": bool(options.detail)}
    if options.detail:
        subject = with_detail(subject, fine_detail(face_model, subject.neutral, np.random.default_rng([seed, 1])))
        description["span_residual_mm"] = round(span_residual(face_model, subject.neutral), 4)
    maps, recorded = {}, truth
    if options.varying:
        maps = varying_maps(face_model, subject.neutral, truth, np.random.default_rng([seed, 2]), albedo_resolution)
        recorded = region_means(face_model, maps, truth, DIGITS)
    if options.subsurface:
        subject = replace(subject, albedo=translucent.subsurface_albedo(face_model, subject.albedo, truth))
        description["subsurface"] = translucent.description(truth)
    return subject, maps, recorded, description


def _simulate_into(out: Path, face_model, truth: dict, options: SimulationOptions,
                   progress: bool) -> tuple[int, list[float]]:
    """The simulation of :func:`simulate`, written into folder ``out``: the number of light
    conditions and each measurement's render time."""
    seed, spp, companion, cameras = options.seed, options.spp, options.companion, options.cameras
    width, height = options.resolution
    rng = np.random.default_rng(seed)  # one generator, drawn from in a fixed order: subject, lights, frames
    subject, maps, recorded, description = _truth_subject(face_model, truth, rng, options)
    texture, textures = albedo_texture(subject.albedo), map_textures(maps)
    studio = set_up_studio(width, height, subject.head, options.measurements, rng, spp, options.environment)
    if cameras > 1:
        studio = replace(studio, rig=rig_cameras(studio.camera, subject.head, cameras))
    if studio.environment is not None:
        description.update(studio.environment.description)
    if options.subsurface:
        studio = replace(studio, integrator=translucent.INTEGRATOR)
    seeds = itertools.count(seed * 1000 + 1)  # Monte Carlo seed of each render, in order
    frames = options.measurements * cameras * (1 + (companion in ("diffuse", "both"))
                                               + (companion in ("exposures", "both")))
    spheres = 0 if studio.environment is not None else 2 * len(studio.per_light)
    bar = progress_bar(total=frames + spheres, desc="simulating", unit="frame", enabled=progress)

    if studio.environment is not None:
        lights = [write_environment(out, studio.environment)]
    else:
        lights = []
        for li in range(len(studio.per_light)):
            lights.append(write_sphere_photographs(out, studio, li, photograph_spheres(studio, li, spp, seeds, rng)))
            bar.update(2)
    light_name = light_names(studio)
    entries, true_measurements, render_seconds = [], [], []
    names = visible_feature_points(face_model)
    for index, (li, pi) in enumerate(studio.schedule):
        t0 = time.perf_counter()
        name = f"m{index:02d}"
        pose = head_pose(face_model, subject, studio.poses[pi], rng)
        vertices = pose.vertices.astype(np.float32)
        meshes = true_face_meshes(face_model, vertices, truth, texture, textures, options.subsurface)
        for view, camera in enumerate(studio.views):  # one shot: every camera, the same head pose
            seen_by = replace(studio, sensor=mitsuba_sensor(camera, spp)) if view else studio
            photographs = photograph_face(seen_by, meshes, li, companion, spp, seeds, rng, (camera, vertices))
            bar.update(1 + (photographs.diffuse is not None) + bool(photographs.exposures))
            taken = view_name(name, view)
            entry = write_photographs(out, taken, light_name[li], pose_name(studio, li, pi), photographs)
            if studio.rig:
                entry["camera"], entry["shot"] = camera_id(view), entry.pop("pose")
            # feature points: the visible landmarks, as an annotator would click them
            entry["feature_points"], exact = annotate(meshes, pose.vertices, face_model, names, camera, rng)
            entries.append(entry)
            true_measurements.append(true_measurement(taken, light_name[li], pose, exact, face_model))
        render_seconds.append(time.perf_counter() - t0)
    bar.close()

    write_ground_truth(out, ground_truth(face_model, subject, studio, true_measurements, recorded, seed, spp, maps,
                                         description))
    write_manifest(out, studio, face_model, subject.neutral, lights, entries)
    return len(studio.per_light), render_seconds


def true_face_meshes(face_model, vertices: np.ndarray, truth: dict, texture, maps: dict, subsurface: bool) -> dict:
    """The face's Mitsuba meshes with their truth, as the photographs show it: surfaces (with
    parameter ``maps``, textures of :func:`~mifaces.studio.varying.map_textures`), or translucent
    skin (render with :data:`mifaces.studio.subsurface.INTEGRATOR`). ``texture``: the albedo."""
    normals = face_model.vertex_normals(vertices)
    if subsurface:
        return translucent.subsurface_meshes(region_meshes(face_model, vertices, normals), truth,
                                             lambda region: region_bsdf(truth, region, texture))
    return face_meshes(face_model, vertices, truth, texture, normals, maps=maps)
