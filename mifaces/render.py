"""Rendering with Mitsuba: the capture's camera as a sensor, a face with its
fitted (or ground-truth) BRDF per region, lit by a point light or an
environment map; rendering in passes with progress, within the size one pass traces.

A face scene is described once, by :meth:`FaceScene.description`: a Mitsuba
scene dict whose meshes (``meshes/<key>.ply``) and albedo map
(``albedo.exr``) are named by file. :meth:`FaceScene.scene` puts the
in-memory meshes and albedo in place of those files and gives the dict to
``mi.load_dict``; :func:`scene_xml` writes the same dict as Mitsuba XML
(the ``scene.xml`` of ``mifaces fit-brdf``). Units are mm, the frame the
capture's world frame.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import mitsuba as mi
import numpy as np

from . import brdf as brdf_models
from .atomic import atomic_path
from .emitters import light_emitters
from .image_files import check_image_size
from .progress import progress
from .model.mesh import mitsuba_mesh
from .model.regions import REGIONS, triangle_regions

#: Id of the albedo texture in a face scene; its BSDFs refer to it.
ALBEDO = "albedo"
#: The reference to the albedo texture a region's BSDF holds as its diffuse reflectance.
ALBEDO_REF = {"type": "ref", "id": ALBEDO}
#: Id of the tangent-space normal map in a face scene with per-texel normals.
NORMALS = "normals"
#: Id of the per-texel specular reflectance map in a face scene.
SPECULAR = "specular"
#: Folder of a face scene's meshes, beside its ``scene.xml``.
MESH_FOLDER = "meshes"
#: Largest number of samples one render pass traces (Mitsuba's wavefront:
#: width x height x spp must stay below 2^32).
MAX_RENDER_SAMPLES = 2 ** 32 - 1


def check_render_size(width: int, height: int, spp: int, what: str = "render") -> None:
    """A ``ValueError`` unless an image of ``width`` x ``height`` at ``spp``
    samples per pixel fits the image limits and one Mitsuba pass
    (:data:`MAX_RENDER_SAMPLES`)."""
    check_image_size(width, height, what)
    if isinstance(spp, bool) or int(spp) < 1:
        raise ValueError(f"{what}: samples per pixel must be a positive integer, got {spp!r}")
    if width * height * int(spp) > MAX_RENDER_SAMPLES:
        raise ValueError(f"{what}: {width}x{height} pixels at {spp} spp are {width * height * int(spp)} samples, "
                         f"more than one render pass traces ({MAX_RENDER_SAMPLES}); lower the spp or the size")


def render_passes(scene, spp: int, passes: int = 8, desc: str = "rendering") -> np.ndarray:
    """Render ``scene`` with ``spp`` samples per pixel in ``passes`` passes of
    different seeds, averaged, showing progress. Returns a float32 (H, W, C)
    array of linear radiance."""
    passes = max(1, min(passes, spp))
    per_pass = [spp // passes + (1 if i < spp % passes else 0) for i in range(passes)]
    total = None
    for seed, n in enumerate(progress(per_pass, desc=desc, unit="pass", leave=False, detail=True)):
        image = np.array(mi.render(scene, spp=n, seed=seed), dtype=np.float64)
        total = image * n if total is None else total + image * n
    return (total / spp).astype(np.float32)


def mitsuba_sensor(camera, spp: int) -> dict:
    """A Mitsuba ``perspective`` sensor (dict) equal to a
    :class:`mifaces.capture.Camera` without distortion: same pose, field of
    view and principal point, an HDR film of the camera's size with a Gaussian
    pixel filter of 0.5 px (the optics' blur)."""
    if np.any(camera.distortion):
        raise ValueError("Mitsuba renders undistorted images only: the camera has lens distortion")
    fov = 2 * math.degrees(math.atan(camera.height / 2 / camera.fy))
    to_world = np.eye(4)
    # Mitsuba's camera looks along +z with +y up and +x to the left of the image
    to_world[:3, :3] = camera.rotation.T @ np.diag([-1.0, -1.0, 1.0])
    to_world[:3, 3] = camera.position
    return {"type": "perspective", "fov": fov, "fov_axis": "y",
            # Mitsuba shifts the image against its offsets (checked by tests/test_render.py)
            "principal_point_offset_x": (camera.width / 2 - camera.cx - 0.5) / camera.width,
            "principal_point_offset_y": (camera.height / 2 - camera.cy - 0.5) / camera.height,
            "near_clip": 10.0, "far_clip": 1e5, "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                     # the optics' blur: a Gaussian point spread function of 0.5 px
                     "rfilter": {"type": "gaussian", "stddev": 0.5}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp}}


def region_bsdf(truth: dict, region: str, texture, *, maps: Mapping | None = None) -> dict:
    """The Mitsuba BSDF dict of one region of a ``brdf.json`` document: its
    parameters over ``texture`` (a texture dict, a loaded texture, a reference,
    an ``rgb`` dict, or None for the plugin's own diffuse default). The
    simulator, the scene writer and the validation's BRDF comparison all build
    a region's BSDF here.

    ``truth["model"]`` is one of the analytic plugins
    (:data:`mifaces.brdf.MODELS`) or a Mitsuba built-in
    (:data:`mifaces.brdf.BUILTINS`: ``roughplastic``, ``principled``), whose
    albedo property (``diffuse_reflectance``, ``base_color``) takes
    ``texture``: :func:`mifaces.brdf.bsdf`'s ``region_plugin`` builds it.
    ``maps`` (parameter name -> texture) puts spatially varying parameters in
    place of the region's values (a spatially varying ground truth,
    :mod:`mifaces.studio.varying`)."""
    model = truth["model"]
    d = brdf_models.bsdf(model, **truth.get("options", {})).region_plugin(truth, region, texture)
    for k, value in (maps or {}).items():
        if k not in d:
            raise ValueError(f"a {model} BSDF has no parameter {k!r} to take a map")
        d[k] = value
    return d


# --------------------------------------------------------------------------------------------
# The face's meshes, one per material region
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RegionMesh:
    """The triangles of a face in one material region (world frame, mm), with
    the shading normals of the whole face so that seams stay invisible.
    ``index`` holds each of its vertices' index in the whole face (the model's
    vertex order), for writers of per-vertex data such as a refined shape."""

    region: str
    vertices: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray
    normals: np.ndarray
    index: np.ndarray | None = None

    def mesh(self, bsdf, interior=None) -> mi.Mesh:
        """A ``mi.Mesh`` of this region with BSDF ``bsdf`` (a dict or a loaded BSDF)
        and, optionally, a medium inside (``interior``)."""
        return mitsuba_mesh(self.vertices, self.triangles, self.uv, normals=self.normals, bsdf=bsdf,
                            name=f"face_{self.region}", interior=interior)


def region_meshes(model, vertices: np.ndarray, normals: np.ndarray | None = None) -> dict[str, RegionMesh]:
    """The face ``vertices`` of ``model`` cut into one mesh per region: triangles
    labelled by the region map at their uv centroid, shading normals from the
    whole face (``normals``, default the model's vertex normals of
    ``vertices``). Keys are ``face_<region>_<label>``."""
    vertices = np.asarray(vertices, np.float32)
    normals = model.vertex_normals(vertices) if normals is None else normals
    names = {label: name for name, label in REGIONS.items()}
    labels = triangle_regions(model.region_map, model.uv, model.triangles)
    meshes = {}
    for label in np.unique(labels):
        name = names.get(int(label), "skin")
        name = "skin" if name == "background" else name
        tri = model.triangles[labels == label]
        used, inverse = np.unique(tri, return_inverse=True)
        meshes[f"face_{name}_{int(label)}"] = RegionMesh(name, vertices[used], inverse.reshape(-1, 3), model.uv[used],
                                                         normals[used], used)
    return meshes


def face_meshes(model, vertices: np.ndarray, truth: dict, texture=None, normals: np.ndarray | None = None, *,
                maps: Mapping | None = None) -> dict:
    """One Mitsuba mesh per region (:func:`region_meshes`), each with its
    region's BSDF from ``truth`` (the ``brdf.json`` layout) over the albedo
    ``texture`` (the plugin's default diffuse if None), and parameter
    ``maps`` (see :func:`region_bsdf`). Keys are ``face_<region>_<label>``."""
    return {key: part.mesh(region_bsdf(truth, part.region, texture, maps=maps))
            for key, part in region_meshes(model, vertices, normals).items()}


# --------------------------------------------------------------------------------------------
# One face scene: the description, in memory, rendered, written
# --------------------------------------------------------------------------------------------
class FaceScene:
    """A face's region meshes, built once, in scenes under any per-region
    BRDF, albedo map, camera and light.

    Parameters
    ----------
    face_model : MorphableModel
    vertices : (V, 3) array
        The face in world coordinates (mm).
    normals : (V, 3) array, optional
        Shading normals (default: the model's vertex normals of ``vertices``).

    Attributes
    ----------
    meshes : dict
        ``face_<region>_<label>`` -> :class:`RegionMesh`. Only arrays: a
        scene's Mitsuba objects (meshes, BSDFs, emitters) live as long as
        that scene does.
    """

    def __init__(self, face_model, vertices: np.ndarray, normals: np.ndarray | None = None):
        self.meshes = region_meshes(face_model, vertices, normals)

    @staticmethod
    def mesh_file(key: str) -> str:
        """The file of mesh ``key``, relative to the scene's folder."""
        return f"{MESH_FOLDER}/{key}.ply"

    def region_of_key(self, key: str) -> tuple[str, str] | None:
        """The region and the BSDF parameter (``roughness.value``, ``diffuse_reflectance.data``) of a key of
        ``mi.traverse`` of a scene of this face (meshes keyed as :attr:`meshes`); None for other keys."""
        mesh, _, parameter = key.partition(".bsdf.")
        return (self.meshes[mesh].region, parameter) if mesh in self.meshes and parameter else None

    def description(self, brdf: dict, camera, light=None, *, envmap=None, envmap_scale: float = 1.0,
                    spp: int = 64, max_depth: int = 4, albedo: str = "albedo.exr", normals: str | None = None,
                    specular: str | None = None) -> dict:
        """The Mitsuba scene dict of the face with a per-region BRDF over an
        albedo map, as ``camera`` sees it; meshes and albedo map named by
        file (:meth:`mesh_file`, ``albedo``), relative to the scene's folder.

        Parameters
        ----------
        brdf : dict
            The ``brdf.json`` layout: ``model``, ``options``, ``regions``.
        camera : mifaces.capture.Camera
        light, envmap, envmap_scale : optional
            A :class:`~mifaces.capture.Light` and an environment instead of it or besides it
            (:func:`mifaces.emitters.light_emitters`): a scene holds only the emitters it is given.
        spp, max_depth : int
            Samples per pixel and the path tracer's depth (shadows and
            interreflection).
        albedo : str
            The albedo map's file: diffuse albedo in the model's texture space
            (row 0 at v = 0), linear.
        normals : str, optional
            A tangent-space normal map's file (texture space as ``albedo``,
            Mitsuba's ``normalmap`` encoding (n + 1) / 2 relative to the
            mesh's shading frame: :mod:`mifaces.reflectance.maps.normals`):
            each region's BSDF is then wrapped in a ``normalmap`` BSDF.
        specular : str, optional
            A per-texel specular reflectance map's file (texture space as
            ``albedo``, linear RGB: :mod:`mifaces.reflectance.maps.specular`),
            read by every region's ``specular_reflectance`` in place of the
            region's value (models that have one).
        """
        brdf = brdf_models.validate_brdf(brdf)
        check_render_size(camera.width, camera.height, spp, "face scene")
        emitters = light_emitters(light, camera, envmap, envmap_scale)
        scene = {"type": "scene", "integrator": {"type": "path", "max_depth": int(max_depth)},
                 "sensor": mitsuba_sensor(camera, spp),
                 ALBEDO: {"type": "bitmap", "filename": albedo, "raw": True, "filter_type": "bilinear",
                          "wrap_mode": "clamp"}}
        for name, filename in ((NORMALS, normals), (SPECULAR, specular)):
            if filename is not None:
                scene[name] = {"type": "bitmap", "filename": filename, "raw": True, "filter_type": "bilinear",
                               "wrap_mode": "clamp"}
        maps = None if specular is None else {"specular_reflectance": {"type": "ref", "id": SPECULAR}}
        for key, part in self.meshes.items():
            bsdf = region_bsdf(brdf, part.region, ALBEDO_REF, maps=maps)
            if normals is not None:
                bsdf = {"type": "normalmap", "normalmap": {"type": "ref", "id": NORMALS}, "bsdf": bsdf}
            scene[key] = {"type": "ply", "filename": self.mesh_file(key), "bsdf": bsdf}
        scene.update(emitters)
        return scene

    def scene(self, brdf: dict, albedo: np.ndarray, camera, light=None, *, envmap=None, envmap_scale: float = 1.0,
              spp: int = 64, max_depth: int = 4, normals: np.ndarray | None = None,
              specular: np.ndarray | None = None) -> dict:
        """:meth:`description` with the meshes, the ``albedo`` array (R, R, 3), the
        tangent-space ``normals`` texture (R', R', 3, encoded, or None) and the ``specular``
        reflectance map (R', R', 3 or None) in memory in place of their files: a dict for
        ``mi.load_dict``."""
        scene = self.description(brdf, camera, light, envmap=envmap, envmap_scale=envmap_scale, spp=spp,
                                 max_depth=max_depth, normals=None if normals is None else NORMALS,
                                 specular=None if specular is None else SPECULAR)
        textures = {}
        for name, data in ((ALBEDO, albedo), (NORMALS, normals), (SPECULAR, specular)):
            if data is not None:
                texture = {k: v for k, v in scene.pop(name).items() if k != "filename"}
                textures[name] = mi.load_dict({**texture, "bitmap": mi.Bitmap(np.ascontiguousarray(data, np.float32))})
        for key, part in self.meshes.items():
            scene[key] = part.mesh(_with_textures(scene[key]["bsdf"], textures))
        return scene

    def render(self, brdf: dict, albedo: np.ndarray, camera, light=None, *, envmap=None, envmap_scale: float = 1.0,
               spp: int = 64, seed: int = 0, max_depth: int = 4, normals: np.ndarray | None = None,
               specular: np.ndarray | None = None) -> np.ndarray:
        """Render :meth:`scene`: (H, W, 3) float32 linear radiance."""
        scene = self.scene(brdf, albedo, camera, light, envmap=envmap, envmap_scale=envmap_scale, spp=spp,
                           max_depth=max_depth, normals=normals, specular=specular)
        return np.array(mi.render(mi.load_dict(scene), spp=spp, seed=seed), dtype=np.float32)[..., :3]

    def write_meshes(self, folder: str | os.PathLike) -> dict[str, Path]:
        """Write each region mesh as ``<folder>/``:meth:`mesh_file` (PLY), atomically."""
        paths = {}
        for key, part in self.meshes.items():
            paths[key] = Path(folder) / self.mesh_file(key)
            with atomic_path(paths[key]) as tmp:
                part.mesh({"type": "diffuse"}).write_ply(str(tmp))
        return paths


def _with_textures(bsdf: dict, textures: dict) -> dict:
    """``bsdf`` (a dict, nested BSDFs included) with each reference to a texture of ``textures`` (id ->
    loaded texture) replaced by the texture."""
    out = {}
    for k, v in bsdf.items():
        if isinstance(v, dict) and v.get("type") == "ref" and v.get("id") in textures:
            out[k] = textures[v["id"]]
        elif isinstance(v, dict):
            out[k] = _with_textures(v, textures)
        else:
            out[k] = v
    return out


def face_scene(brdf: dict, albedo: np.ndarray, face_model, vertices: np.ndarray, camera, light=None, *,
               envmap=None, envmap_scale: float = 1.0, spp: int = 64, max_depth: int = 4) -> dict:
    """The Mitsuba scene (a dict for ``mi.load_dict``) of a face with a
    per-region BRDF over an albedo map, as ``camera`` sees it: a
    :class:`FaceScene` of ``face_model`` and ``vertices`` (world, mm) built
    for one scene; see :meth:`FaceScene.description` for the arguments."""
    return FaceScene(face_model, vertices).scene(brdf, albedo, camera, light, envmap=envmap,
                                                 envmap_scale=envmap_scale, spp=spp, max_depth=max_depth)


def render_face(brdf: dict, albedo: np.ndarray, face_model, vertices: np.ndarray, camera, light=None, *,
                envmap=None, envmap_scale: float = 1.0, spp: int = 64, seed: int = 0, max_depth: int = 4) -> np.ndarray:
    """Render :func:`face_scene`: (H, W, 3) float32 linear radiance."""
    return FaceScene(face_model, vertices).render(brdf, albedo, camera, light, envmap=envmap,
                                                  envmap_scale=envmap_scale, spp=spp, seed=seed, max_depth=max_depth)


# --------------------------------------------------------------------------------------------
# A scene dict as Mitsuba XML
# --------------------------------------------------------------------------------------------
#: Mitsuba object type -> XML tag.
_TAGS = {mi.ObjectType.Shape: "shape", mi.ObjectType.BSDF: "bsdf", mi.ObjectType.Emitter: "emitter",
         mi.ObjectType.Sensor: "sensor", mi.ObjectType.Film: "film", mi.ObjectType.ReconstructionFilter: "rfilter",
         mi.ObjectType.Sampler: "sampler", mi.ObjectType.Integrator: "integrator",
         mi.ObjectType.Texture: "texture", mi.ObjectType.Medium: "medium", mi.ObjectType.Volume: "volume",
         mi.ObjectType.PhaseFunction: "phase"}


def _tag(plugin: str) -> str:
    """The XML tag of plugin ``plugin``; Python plugins are unknown to Mitsuba's
    plugin manager, and those of mifaces are BSDFs."""
    kind = mi.PluginManager.instance().plugin_type(plugin)
    if kind in _TAGS:
        return _TAGS[kind]
    if plugin in brdf_models.MODELS:
        return "bsdf"
    raise ValueError(f"unknown Mitsuba plugin {plugin!r}")


def _numbers(values) -> str:
    return ", ".join(repr(float(x)) for x in values)


def _element(key: str, value, path: tuple[str, ...], parameters: Mapping[tuple[str, ...], str],
             top: bool) -> ET.Element:
    """The XML element of ``value`` under name (or, at the top, id) ``key``."""
    name = {"id" if top else "name": key}
    if path in parameters:
        return ET.Element("integer" if isinstance(value, int) else "float", name=key, value=f"${parameters[path]}")
    if isinstance(value, dict) and value.get("type") == "ref":
        return ET.Element("ref", id=value["id"], name=key)
    if isinstance(value, dict) and value.get("type") == "rgb":
        v = np.broadcast_to(np.asarray(value["value"], np.float64), 3)
        return ET.Element("rgb", name=key, value=_numbers(v))
    if isinstance(value, dict):
        element = ET.Element(_tag(value["type"]), type=value["type"], **name)
        for k, v in value.items():
            if k != "type":
                element.append(_element(k, v, path + (k,), parameters, False))
        return element
    if isinstance(value, (bool, np.bool_)):
        return ET.Element("boolean", name=key, value=str(bool(value)).lower())
    if isinstance(value, (int, np.integer)):
        return ET.Element("integer", name=key, value=str(int(value)))
    if isinstance(value, (float, np.floating)):
        return ET.Element("float", name=key, value=repr(float(value)))
    if isinstance(value, str):
        return ET.Element("string", name=key, value=value)
    if isinstance(value, (list, tuple, np.ndarray)) and np.shape(value) == (3,):
        return ET.Element("point", name=key, value=_numbers(value))
    if isinstance(value, mi.ScalarTransform4f):
        element = ET.Element("transform", name=key)
        ET.SubElement(element, "matrix", value=" ".join(repr(float(x)) for x in np.ravel(value.matrix)))
        return element
    raise TypeError(f"{'.'.join(path)}: a {type(value).__name__} has no Mitsuba XML form (write it to a file "
                    "and name the file)")


def scene_xml(scene: dict, parameters: Mapping[str, tuple[str, ...]] | None = None, comment: str = "") -> str:
    """A Mitsuba scene dict (``mi.load_dict``'s layout) as Mitsuba XML text.

    Values may be nested plugin dicts, ``rgb`` and ``ref`` dicts, booleans,
    numbers, strings, 3-vectors (written as points) and
    ``mi.ScalarTransform4f``; meshes, bitmaps and other data must be named by
    file. Top-level keys become ids, nested keys names.

    Parameters
    ----------
    scene : dict
        ``{"type": "scene", ...}``.
    parameters : mapping, optional
        Name -> key path of a value that ``mi.load_file(path, name=...)`` may
        override, e.g. ``{"spp": ("sensor", "sampler", "sample_count")}``:
        written as ``<default name="spp" value="..."/>`` and ``$spp``.
    comment : str
        A comment written before the scene.
    """
    if scene.get("type") != "scene":
        raise ValueError(f"not a scene dict: type {scene.get('type')!r}")
    parameters = dict(parameters or {})
    root = ET.Element("scene", version="3.0.0")
    for name, path in parameters.items():
        value = scene
        for key in path:
            value = value[key]
        ET.SubElement(root, "default", name=name, value=str(value))
    by_path = {tuple(path): name for name, path in parameters.items()}
    for key, value in scene.items():
        if key != "type":
            root.append(_element(key, value, (key,), by_path, True))
    ET.indent(root, space="    ")
    header = f"<!-- {comment} -->\n" if comment else ""
    return header + ET.tostring(root, encoding="unicode") + "\n"


__all__ = ["ALBEDO", "ALBEDO_REF", "NORMALS", "SPECULAR", "MESH_FOLDER", "MAX_RENDER_SAMPLES", "check_render_size",
           "render_passes", "mitsuba_sensor", "region_bsdf", "RegionMesh", "region_meshes", "face_meshes",
           "FaceScene", "face_scene", "render_face", "scene_xml"]
