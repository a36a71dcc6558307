"""Writing model faces as PLY or OBJ with texture coordinates, through trimesh.

OBJ stores texture coordinates with ``v = 0`` at the bottom of the image
(OpenGL), so :func:`export_mesh` writes ``(u, 1 - v)`` there; Mitsuba flips
``v`` back when it loads an OBJ, so the texture coordinates it reads equal
the model's. PLY stores ``(u, v)`` as they are, with vertex colours.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_path


def export_mesh(path: str | os.PathLike, vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray,
                albedo: np.ndarray | None = None) -> Path:
    """Write a mesh with per-vertex texture coordinates to ``path`` (``.ply`` or ``.obj``).

    Parameters
    ----------
    path : path
        The suffix picks the format.
    vertices : (N, 3) array
    triangles : (T, 3) int array
    uv : (N, 2) array
        Texture coordinates in mifaces' convention (``v = 0`` the top row).
    albedo : (N, 3) array, optional
        Linear RGB in [0, 1], written as 8-bit vertex colours (PLY only).

    Returns
    -------
    Path
    """
    import trimesh  # trimesh takes about half a second to import: only where a mesh is written

    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("ply", "obj"):
        raise ValueError(f"export format is picked by the suffix, .ply or .obj; got {path.name!r}")
    vertices = np.asarray(vertices, dtype=np.float64)
    uv = np.asarray(uv, dtype=np.float64)
    if uv.shape != (len(vertices), 2):
        raise ValueError(f"uv must have shape ({len(vertices)}, 2), got {uv.shape}")
    mesh = trimesh.Trimesh(vertices=vertices, faces=np.asarray(triangles), process=False)
    if fmt == "obj":
        mesh.visual = trimesh.visual.TextureVisuals(uv=np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1))
        data = trimesh.exchange.obj.export_obj(mesh, include_normals=True, include_texture=True,
                                               write_texture=False, mtl_name=None)
        with atomic_path(path) as tmp:
            Path(tmp).write_text(data)
    else:
        vertex_attributes = {"s": uv[:, 0].astype(np.float32), "t": uv[:, 1].astype(np.float32)}
        mesh.vertex_attributes.update(vertex_attributes)
        if albedo is not None:
            srgb = np.clip(np.asarray(albedo, dtype=np.float64), 0.0, 1.0) ** (1.0 / 2.2)
            mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=np.round(srgb * 255).astype(np.uint8))
        data = trimesh.exchange.ply.export_ply(mesh, encoding="binary", vertex_normal=True,
                                               include_attributes=True)
        with atomic_path(path) as tmp:
            Path(tmp).write_bytes(data)
    return path
