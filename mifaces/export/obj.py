"""Wavefront OBJ (with its ``.mtl`` and textures) by trimesh's exporter.

OBJ's material has no microfacet model: the file carries the geometry
(metres, +y up), normals, texture coordinates (v counted from the bottom, as
OBJ does) and the base-colour texture (``map_Kd``); the exporter writes the
rest of trimesh's PBR material as it knows it. The glTF and USD exports keep
the full material.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

from ..io.atomic import atomic_write
from ..io.image_files import encode_png
from .face import ExportedFace


def trimesh_mesh(face: ExportedFace, name: str = "face"):
    """The face as a ``trimesh.Trimesh`` with a textured PBR material ``name`` (trimesh's uv: v up)."""
    import trimesh  # trimesh takes about half a second to import: only where a mesh is written

    def image(name, srgb):
        return Image.open(io.BytesIO(encode_png(face.textures[name], srgb)))

    material = trimesh.visual.material.PBRMaterial(
        name=name, baseColorTexture=image("base_color", True), metallicFactor=1.0, roughnessFactor=1.0,
        metallicRoughnessTexture=image("metallic_roughness", False),
        normalTexture=image("normal", False) if "normal" in face.textures else None)
    uv = np.stack([face.uv[:, 0], 1.0 - face.uv[:, 1]], axis=1)
    return trimesh.Trimesh(face.positions, face.triangles.astype(np.int64), vertex_normals=face.normals,
                           visual=trimesh.visual.TextureVisuals(uv=uv, material=material), process=False)


def write_obj(face: ExportedFace, path) -> list[Path]:
    """Write ``path`` (``.obj``), its ``.mtl`` and textures beside it, each atomically, the OBJ last."""
    import trimesh  # trimesh takes about half a second to import: only where a mesh is written

    path = Path(path)
    text, files = trimesh.exchange.obj.export_obj(trimesh_mesh(face, path.stem), include_normals=True, include_texture=True,
                                                  mtl_name=f"{path.stem}.mtl", return_texture=True)
    written = []
    for name, data in files.items():
        if Path(name).name != name:
            raise ValueError(f"trimesh named an OBJ companion {name!r} outside the folder")
        target = path.parent / name
        if target.exists() and target.is_dir():
            raise IsADirectoryError(f"cannot write {target}: a folder is in the way")
        with atomic_write(target) as f:
            f.write(data)
        written.append(target)
    with atomic_write(path, "w") as f:
        f.write(text)
    return written + [path]


__all__ = ["trimesh_mesh", "write_obj"]
