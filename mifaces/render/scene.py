"""The one face-scene builder: :class:`FaceScene`, the dict the renderer loads and ``scene.xml`` serialises."""

from __future__ import annotations

import os
from pathlib import Path

import mitsuba as mi
import numpy as np

from .. import brdf as brdf_models
from ..io.atomic import atomic_path
from ..lights.emitters import light_emitters
from ..lights.environment import Environment
from .blend import blended_parameters, region_maps
from .crop import CroppedScene, dark_background
from .materials import ALBEDO, ALBEDO_REF, NORMALS, SPECULAR, region_bsdf, with_textures
from .meshes import MESH_FOLDER, region_meshes
from .sensor import check_render_size, mitsuba_sensor


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
    vertices : (V, 3) float64 array
        The face's vertices (world, mm): where a render can show it.
    """

    def __init__(self, face_model, vertices: np.ndarray, normals: np.ndarray | None = None):
        self.meshes = region_meshes(face_model, vertices, normals)
        self.vertices = np.asarray(vertices, np.float64)

    @staticmethod
    def mesh_file(key: str) -> str:
        """The file of mesh ``key``, relative to the scene's folder."""
        return f"{MESH_FOLDER}/{key}.ply"

    def region_of_key(self, key: str) -> tuple[str, str] | None:
        """The region and the BSDF parameter (``roughness.value``, ``diffuse_reflectance.data``) of a key of
        ``mi.traverse`` of a scene of this face (meshes keyed as :attr:`meshes`); None for other keys."""
        mesh, _, parameter = key.partition(".bsdf.")
        return (self.meshes[mesh].region, parameter) if mesh in self.meshes and parameter else None

    def blended(self, brdf: dict, specular_map: bool = False) -> list[str]:
        """The parameters of ``brdf`` this face renders from blended textures
        (:func:`mifaces.render.blend.blended_parameters`; not ``specular_reflectance``
        where a per-texel ``specular_map`` replaces it)."""
        return blended_parameters(brdf, [m.region for m in self.meshes.values()],
                                  exclude={"specular_reflectance"} if specular_map else ())

    def region_maps(self, brdf: dict, size: int, specular_map: bool = False) -> dict[str, np.ndarray]:
        """:meth:`blended`'s textures on this face, (size, size, 3) each
        (:func:`mifaces.render.blend.region_maps`)."""
        return region_maps(brdf, self.meshes, size,
                           exclude={"specular_reflectance"} if specular_map else ())

    @staticmethod
    def region_map_id(name: str) -> str:
        """The scene id of parameter ``name``'s blended texture."""
        return f"region_{name}"

    @staticmethod
    def region_map_file(name: str) -> str:
        """The file of parameter ``name``'s blended texture, relative to the scene's folder."""
        return f"region_maps/{name}.exr"

    def description(self, brdf: dict, camera, light=None, *, environment: Environment | None = None,
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
        light : mifaces.capture.Light, optional
            A point, directional or environment-map light.
        environment : mifaces.lights.environment.Environment, optional
            An environment (a map and its scale, or a sky's emitter) instead of ``light`` or besides
            it (:func:`mifaces.lights.emitters.light_emitters`): a scene holds only the emitters it is given.
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

        A ``brdf`` with ``region_blend_mm`` (a fit's) takes each parameter that differs
        between regions from a blended texture (:mod:`mifaces.render.blend`), named
        :meth:`region_map_file` (:meth:`region_maps` makes them).
        """
        brdf = brdf_models.validate_brdf(brdf)
        check_render_size(camera.width, camera.height, spp, "face scene")
        emitters = light_emitters(light, camera, environment)
        scene = {"type": "scene", "integrator": {"type": "path", "max_depth": int(max_depth)},
                 "sensor": mitsuba_sensor(camera, spp),
                 ALBEDO: {"type": "bitmap", "filename": albedo, "raw": True, "filter_type": "bilinear",
                          "wrap_mode": "clamp"}}
        for name, filename in ((NORMALS, normals), (SPECULAR, specular)):
            if filename is not None:
                scene[name] = {"type": "bitmap", "filename": filename, "raw": True, "filter_type": "bilinear",
                               "wrap_mode": "clamp"}
        maps = {} if specular is None else {"specular_reflectance": {"type": "ref", "id": SPECULAR}}
        for name in self.blended(brdf, specular is not None):
            scene[self.region_map_id(name)] = {"type": "bitmap", "filename": self.region_map_file(name), "raw": True,
                                               "filter_type": "bilinear", "wrap_mode": "clamp"}
            maps[name] = {"type": "ref", "id": self.region_map_id(name)}
        for key, part in self.meshes.items():
            bsdf = region_bsdf(brdf, part.region, ALBEDO_REF, maps=maps)
            if normals is not None:
                bsdf = {"type": "normalmap", "normalmap": {"type": "ref", "id": NORMALS}, "bsdf": bsdf}
            scene[key] = {"type": "ply", "filename": self.mesh_file(key), "bsdf": bsdf}
        scene.update(emitters)
        return scene

    def scene(self, brdf: dict, albedo: np.ndarray, camera, light=None, *, environment: Environment | None = None,
              spp: int = 64, max_depth: int = 4, normals: np.ndarray | None = None,
              specular: np.ndarray | None = None) -> dict:
        """:meth:`description` with the meshes, the ``albedo`` array (R, R, 3), the
        tangent-space ``normals`` texture (R', R', 3, encoded, or None) and the ``specular``
        reflectance map (R', R', 3 or None) in memory in place of their files: a dict for
        ``mi.load_dict``."""
        scene = self.description(brdf, camera, light, environment=environment, spp=spp,
                                 max_depth=max_depth, normals=None if normals is None else NORMALS,
                                 specular=None if specular is None else SPECULAR)
        textures = {}
        blended = self.region_maps(brdf, albedo.shape[0], specular is not None).items()
        for name, data in ((ALBEDO, albedo), (NORMALS, normals), (SPECULAR, specular),
                           *((self.region_map_id(k), v) for k, v in blended)):
            if data is not None:
                texture = {k: v for k, v in scene.pop(name).items() if k != "filename"}
                textures[name] = mi.load_dict({**texture, "bitmap": mi.Bitmap(np.ascontiguousarray(data, np.float32))})
        for key, part in self.meshes.items():
            scene[key] = part.mesh(with_textures(scene[key]["bsdf"], textures))
        return scene

    def render(self, brdf: dict, albedo: np.ndarray, camera, light=None, *, environment: Environment | None = None,
               spp: int = 64, seed: int = 0, max_depth: int = 4, normals: np.ndarray | None = None,
               specular: np.ndarray | None = None) -> np.ndarray:
        """Render :meth:`scene`: (H, W, 3) float32 linear radiance, at Monte Carlo ``seed``; the
        arguments as :meth:`description` takes them (``light`` and/or ``environment``), the maps
        (``albedo``, ``normals``, ``specular``) as :meth:`scene` does.

        Examples
        --------
        A simulated capture's true face as its first photograph shows it (``capture_folder`` is a capture folder (one :func:`mifaces.simulate` wrote, here)):

        >>> import mifaces
        >>> from mifaces.capture import load_capture, read_ground_truth
        >>> from mifaces.render import FaceScene
        >>> capture = load_capture(capture_folder)
        >>> truth = read_ground_truth(capture)
        >>> first = capture.measurements[0]
        >>> scene = FaceScene(mifaces.load_model(truth.model), truth.shapes[first.name])
        >>> image = scene.render(truth.brdf, truth.albedo, capture.camera, capture.light(first.light), spp=4)
        >>> image.shape, image.dtype
        ((96, 96, 3), dtype('float32'))
        >>> bool(image.max() > 0)  # lit
        True

        The same face in the generated studio instead of the capture's light:

        >>> from mifaces.lights.environment import Environment, studio_environment
        >>> studio = scene.render(truth.brdf, truth.albedo, capture.camera,
        ...                       environment=Environment(studio_environment(32)), spp=4)
        >>> bool(studio.max() > 0)
        True
        """
        return self.render_seeds(brdf, albedo, camera, light, environment=environment, spp=spp, seeds=(seed,),
                                 max_depth=max_depth, normals=normals, specular=specular)[0]

    def render_seeds(self, brdf: dict, albedo: np.ndarray, camera, light=None, *,
                     environment: Environment | None = None, spp: int = 64, seeds=(0,), max_depth: int = 4,
                     normals: np.ndarray | None = None, specular: np.ndarray | None = None) -> list[np.ndarray]:
        """:meth:`render` at each Monte Carlo seed of ``seeds``, the scene loaded once for all of them: a
        list of (H, W, 3) float32 images, each the image :meth:`render` gives at that seed. Lit by point
        or directional lights only, only the face's window of the image is rendered
        (:mod:`mifaces.render.crop`): nothing else can show."""
        scene = self.cropped(self.scene(brdf, albedo, camera, light, environment=environment, spp=spp,
                                        max_depth=max_depth, normals=normals, specular=specular), camera)
        return [scene.render(spp, seed) for seed in seeds]

    def cropped(self, scene: dict, camera) -> CroppedScene:
        """Scene dict ``scene`` of this face (:meth:`scene`, perhaps with other meshes of the same face)
        loaded to render only the face's window of ``camera``'s image where nothing else can show
        (:func:`~mifaces.render.crop.dark_background`), else the whole image."""
        return CroppedScene(scene, camera, [self.vertices] if dark_background(scene) else None)

    def write_meshes(self, folder: str | os.PathLike) -> dict[str, Path]:
        """Write each region mesh as ``<folder>/``:meth:`mesh_file` (PLY), atomically."""
        paths = {}
        for key, part in self.meshes.items():
            paths[key] = Path(folder) / self.mesh_file(key)
            with atomic_path(paths[key]) as tmp:
                part.mesh({"type": "diffuse"}).write_ply(str(tmp))
        return paths


def face_scene(brdf: dict, albedo: np.ndarray, face_model, vertices: np.ndarray, camera, light=None, *,
               environment: Environment | None = None, spp: int = 64, max_depth: int = 4) -> dict:
    """The Mitsuba scene (a dict for ``mi.load_dict``) of a face with a
    per-region BRDF over an albedo map, as ``camera`` sees it: a
    :class:`FaceScene` of ``face_model`` and ``vertices`` (world, mm) built
    for one scene; see :meth:`FaceScene.description` for the arguments."""
    return FaceScene(face_model, vertices).scene(brdf, albedo, camera, light, environment=environment, spp=spp,
                                                 max_depth=max_depth)


def render_face(brdf: dict, albedo: np.ndarray, face_model, vertices: np.ndarray, camera, light=None, *,
                environment: Environment | None = None, spp: int = 64, seed: int = 0,
                max_depth: int = 4) -> np.ndarray:
    """Render :func:`face_scene`: (H, W, 3) float32 linear radiance."""
    return FaceScene(face_model, vertices).render(brdf, albedo, camera, light, environment=environment, spp=spp,
                                                  seed=seed, max_depth=max_depth)


__all__ = ["FaceScene", "face_scene", "render_face"]
