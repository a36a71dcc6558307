"""The face's region meshes (one Mitsuba mesh per material region) and the meshes a scene keys them by."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from ..model.mesh import mitsuba_mesh
from ..model.regions import region_name, triangle_regions
from .materials import region_bsdf


#: Folder of a face scene's meshes, beside its ``scene.xml``.
MESH_FOLDER = "meshes"


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
    labels = triangle_regions(model.region_map, model.uv, model.triangles)
    meshes = {}
    for label in np.unique(labels):
        name = region_name(int(label))
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


__all__ = ["MESH_FOLDER", "RegionMesh", "region_meshes", "face_meshes"]
