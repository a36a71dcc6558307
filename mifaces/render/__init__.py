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

from .sensor import MAX_RENDER_SAMPLES, check_render_size, mitsuba_sensor, render_passes
from .materials import ALBEDO, ALBEDO_REF, NORMALS, SPECULAR, region_bsdf
from .meshes import MESH_FOLDER, RegionMesh, face_meshes, region_meshes
from .scene import FaceScene, face_scene, render_face
from .scene_xml import scene_xml

__all__ = ["MAX_RENDER_SAMPLES", "check_render_size", "render_passes", "mitsuba_sensor", "ALBEDO", "ALBEDO_REF",
           "NORMALS", "SPECULAR", "region_bsdf", "MESH_FOLDER", "RegionMesh", "region_meshes",
           "face_meshes", "FaceScene", "face_scene", "render_face", "scene_xml"]
