"""Writing and reading a fitted BRDF: the files of ``mifaces fit-brdf``.

:func:`write_estimate` writes, each atomically, ``brdf.json`` in the layout
of the simulator's ``--brdf-params`` (so a fitted BRDF can be put on another
face: ``mifaces simulate --brdf-params brdf.json``), with per region the
fit's loss, sample count, time and status under ``"fit"``; the albedo map
``albedo.exr`` (linear, row 0 at v = 0) and a PNG preview; and
``scene.xml``, the Mitsuba scene of :meth:`mifaces.render.FaceScene.description`
that renders the fitted face with the plugins as the camera saw it in the
first measurement (meshes in ``meshes/``); with per-texel normals, the
normal map ``normals.exr`` (Mitsuba's ``normalmap`` encoding, see
:mod:`mifaces.reflectance.maps.normals`), which ``scene.xml`` wraps every
region's BSDF in; ``albedo_std.exr``, the albedo's posterior standard
deviation per texel (:attr:`mifaces.reflectance.maps.diffuse.DiffuseMap.std`),
when known. ``brdf.json``'s ``"uncertainty"`` holds each region's parameter
intervals (:mod:`mifaces.reflectance.fit.uncertainty`). The files are one result set
(:func:`mifaces.io.result_set.result_set`): written together into a sibling folder
and swapped in, so a killed run leaves the earlier set whole.
:func:`load_estimate` reads ``brdf.json`` and the albedo map back and refuses
a mixed set.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .. import brdf as brdf_models
from ..io.atomic import atomic_write, write_json
from ..io.image_files import read_exr, write_exr, write_png
from ..io.result_set import ResultSetError, result_set, verify_set
from ..lights.environment import Environment, environment_emitter
from ..render import FaceScene, scene_xml
from ..model.regions import REGIONS
from .fit.region_fit import RegionFit
from .maps.diffuse import DiffuseMap
from .maps.specular import SpecularMap
from .result import FILES, FIT_KEYS, BRDFEstimate

#: Samples per pixel of ``scene.xml`` (``mi.load_file(path, spp=N)`` overrides it).
SCENE_SPP = 64
#: The key path of the sample count in a scene dict.
SPP_PATH = ("sensor", "sampler", "sample_count")
#: The result-set kind of a fitted BRDF's folder.
KIND = "brdf"


def write_estimate(estimate: BRDFEstimate, out, face: FaceScene, camera, light, *,
                   force: bool = False) -> dict[str, Path]:
    """Write ``brdf.json``, ``albedo.exr`` (+ ``albedo.png``), ``meshes/*.ply``
    and ``scene.xml`` into folder ``out`` as one result set
    (:func:`mifaces.io.result_set.result_set`): all of them or none.

    Parameters
    ----------
    estimate : BRDFEstimate
    out : path
    face : FaceScene
        The geometry the scene shows (world frame, mm).
    camera : mifaces.capture.Camera
    light : mifaces.capture.Light
        The scene's light (:func:`mifaces.lights.emitters.light_emitters`), as the
        estimate was fitted under it (:meth:`BRDFEstimate.fitted_light`: a map
        the refinement refined is the refined one). An environment map is
        written beside the scene as ``environment.exr``.
    force : bool
        Replace a fitted BRDF that ``out`` holds (else a ``FileExistsError``).
    """
    out = Path(out)
    document = estimate.to_json()
    normals, specular = estimate.normal_texture(), estimate.specular_texture()
    lamp = estimate.fitted_light(light)
    envmap = lamp.radiance_map
    environment = None if envmap is None else Environment(environment_emitter(FILES["environment"], camera))  # by file
    scene = face.description(document, camera, lamp if envmap is None else None, environment=environment,
                             spp=SCENE_SPP, albedo=FILES["albedo"],
                             normals=None if normals is None else FILES["normals"],
                             specular=None if specular is None else FILES["specular"])
    # (description checks the BRDF and the light before anything is written)
    comment = (f"The face as fitted by mifaces fit-brdf: per-region {estimate.model} BSDFs over the refined albedo "
               "map, seen by the capture's camera under the light of its first measurement. Render: "
               "mitsuba.load_file(path, spp=N) after `import mifaces` (which registers the plugins). Units: mm.")
    info = {"model": estimate.model, "options": document["options"], "resolution": document["resolution"],
            "measurements": document["measurements"]}
    with result_set(out, KIND, force=force, info=info) as folder:
        write_json(folder / FILES["brdf"], document)
        write_exr(folder / FILES["albedo"], estimate.albedo.albedo)
        write_png(folder / FILES["preview"], estimate.albedo.albedo)
        if normals is not None:
            write_exr(folder / FILES["normals"], normals)
        if specular is not None:
            write_exr(folder / FILES["specular"], specular)
        if estimate.albedo.std is not None:
            write_exr(folder / FILES["albedo_std"], estimate.albedo.std)
        if envmap is not None:
            write_exr(folder / FILES["environment"], envmap)
        for name, image in face.region_maps(document, estimate.resolution, specular is not None).items():
            write_exr(folder / face.region_map_file(name), image)
        face.write_meshes(folder)
        with atomic_write(folder / FILES["scene"], "w") as f:
            f.write(scene_xml(scene, {"spp": SPP_PATH}, comment))
    optional = {"normals": normals is not None, "specular": specular is not None,
                "albedo_std": estimate.albedo.std is not None, "environment": envmap is not None}
    return {key: out / name for key, name in FILES.items() if optional.get(key, True)}


def write_fitted(estimate: BRDFEstimate, out, capture, face_model, shapes: dict, *,
                 force: bool = False) -> dict[str, Path]:
    """:func:`write_estimate` with the scene of the estimate's first photograph: its face
    (``shapes[name]``, world vertices of ``face_model``), the capture's camera and its light."""
    first = next(m for m in capture.measurements if m.name == estimate.measurements[0])
    return write_estimate(estimate, out, FaceScene(face_model, shapes[first.name]), capture.camera,
                          capture.light(first.light), force=force)


def load_estimate(path) -> dict:
    """Read a ``brdf.json`` (path to it or its folder) and the albedo map beside it:
    the JSON document with ``"albedo"`` replaced by the (R, R, 3) array, and
    ``"normals"`` by the normal map's texture ((n + 1) / 2, (R, R, 3); None without one) and
    ``"specular"`` by the per-texel specular reflectance map (None without one).

    Raises
    ------
    mifaces.io.result_set.ResultSetError
        Files that were not written together (a ``brdf.json`` and an albedo
        map of different runs: changed checksums, or, in a folder without a
        set manifest, an albedo map of another resolution).
    mifaces.brdf.ParameterError
        Parameters that are not finite or outside their range, a missing
        ``skin`` region (the one other regions fall back to).
    """
    path = Path(path)
    path = path / FILES["brdf"] if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"no brdf.json at {path}")
    try:
        data = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: not valid JSON: {error}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: not a brdf.json, not a JSON object")
    for key in ("model", "regions"):
        if key not in data:
            raise ValueError(f"{path}: not a brdf.json, no {key!r}")
    name = data.get("albedo", FILES["albedo"])
    if not isinstance(name, str) or Path(name).name != name:
        raise ValueError(f"{path}: 'albedo' must name a file beside brdf.json, got {name!r}")
    albedo = path.parent / name
    maps = {}
    for key in ("normals", "specular"):
        value = data.get(key)
        if value is not None and (not isinstance(value, str) or Path(value).name != value
                                  or not (path.parent / value).is_file()):
            raise ValueError(f"{path}: {key!r} must name a map beside brdf.json, got {value!r}")
        maps[key] = value
    verify_set(path.parent, KIND, [path.name] + ([name] if albedo.is_file() else []) + [v for v in maps.values() if v])
    data = brdf_models.validate_brdf(data)
    data["albedo"] = read_exr(albedo) if albedo.is_file() else None
    for key, value in maps.items():
        data[key] = read_exr(path.parent / value) if value else None
    resolution = data.get("resolution")
    if data["albedo"] is not None and isinstance(resolution, int) and data["albedo"].shape[:2] != (resolution,) * 2:
        raise ResultSetError(f"{path.parent}: brdf.json was fitted at resolution {resolution} but {name} is "
                             f"{data['albedo'].shape[1]}x{data['albedo'].shape[0]}: files of different runs")
    return data


def read_estimate(path) -> BRDFEstimate:
    """A result folder (or its ``brdf.json``) as the :class:`BRDFEstimate` that :func:`fit_brdf
    <mifaces.reflectance.estimate.fit_brdf>` returned and :func:`write_estimate` wrote, read by
    :func:`load_estimate` (and refused as it refuses). What the files keep comes back as it was
    (the region fits and their records, the albedo map, the normal and specular maps as written,
    float32); what they do not keep is None: the region map (the face model's, which a reader
    has), the albedo's sample counts and weights, the specular map's scales and information,
    the fits' histories."""
    data = load_estimate(path)
    records = data.get("fit") or {}
    fits = {name: RegionFit(data["model"], data["options"], dict(params, **{
        k: v for k, v in records.get(name, {}).items() if k == "diffuse_reflectance"}),
        **{k: records.get(name, {}).get(k) for k in FIT_KEYS if k != "diffuse_reflectance"},
        uncertainty=(data.get("uncertainty") or {}).get(name) or {}) for name, params in data["regions"].items()}
    specular = None if data["specular"] is None else SpecularMap(
        None, data["specular"], None, {REGIONS[k]: v for k, v in (data.get("specular_shrinkage") or {}).items()})
    return BRDFEstimate(
        model=data["model"], options=data["options"], fits=fits, albedo=DiffuseMap(data["albedo"], None, None),
        region_map=None, samples=data.get("samples", 0), measurements=tuple(data.get("measurements", ())),
        seconds=data.get("seconds") or {}, refinement=data.get("refinement"),
        normals=None if data["normals"] is None else 2.0 * np.asarray(data["normals"], np.float64) - 1.0,
        normal_refinement=data.get("normal_refinement"), specular=specular, lighting=data.get("lighting"),
        light_balance=data.get("light_balance"), interreflection=data.get("interreflection"),
        texel_albedo=bool(data.get("texel_albedo", False)))


__all__ = ["KIND", "write_estimate", "write_fitted", "load_estimate", "read_estimate"]
