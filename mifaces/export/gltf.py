"""glTF 2.0 (``.glb`` binary or ``.gltf`` with embedded data) by pygltflib.

One mesh, one primitive (POSITION, NORMAL, TEXCOORD_0, TANGENT with a normal
map, 32-bit indices), one metallic-roughness material with ``KHR_materials_specular``
and ``KHR_materials_ior``, textures as PNG: baseColor (sRGB), metallic-roughness
(linear: G roughness, B metallic), specular (RGB the specular colour, sRGB;
A the specular factor, linear: both extension textures point at it) and the
tangent-space normal map (linear). Layout of :class:`mifaces.export.face.ExportedFace`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib as g

from ..io.atomic import atomic_path
from ..io.image_files import encode_png
from .face import ExportedFace

#: glTF constants (the specification's enums).
FLOAT, UNSIGNED_INT = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
LINEAR, LINEAR_MIPMAP_LINEAR, CLAMP_TO_EDGE = 9729, 9987, 33071
#: The extensions the material uses.
EXTENSIONS = ("KHR_materials_specular", "KHR_materials_ior")
#: Textures of :class:`ExportedFace` -> whether they are sRGB-encoded.
SRGB = {"base_color": True, "metallic_roughness": False, "specular": True, "normal": False}


def gltf_document(face: ExportedFace):
    """The face as a ``pygltflib.GLTF2`` with one binary blob (buffers and images)."""
    blob = bytearray()
    views, accessors = [], []

    def add_view(data: bytes, target=None) -> int:
        while len(blob) % 4:
            blob.append(0)
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
        blob.extend(data)
        return len(views) - 1

    def add_accessor(array: np.ndarray, kind: str, component: int, target, bounds: bool = False) -> int:
        array = np.ascontiguousarray(array)
        view = add_view(array.tobytes(), target)
        extra = {"min": array.min(axis=0).tolist(), "max": array.max(axis=0).tolist()} if bounds else {}
        accessors.append(g.Accessor(bufferView=view, componentType=component, count=len(array), type=kind, **extra))
        return len(accessors) - 1

    attributes = g.Attributes(
        POSITION=add_accessor(face.positions.astype(np.float32), "VEC3", FLOAT, ARRAY_BUFFER, bounds=True),
        NORMAL=add_accessor(face.normals.astype(np.float32), "VEC3", FLOAT, ARRAY_BUFFER),
        TEXCOORD_0=add_accessor(face.uv.astype(np.float32), "VEC2", FLOAT, ARRAY_BUFFER))
    if "normal" in face.textures:  # tangents only serve the normal map
        attributes.TANGENT = add_accessor(face.tangents.astype(np.float32), "VEC4", FLOAT, ARRAY_BUFFER)
    indices = add_accessor(face.triangles.astype(np.uint32).ravel(), "SCALAR", UNSIGNED_INT, ELEMENT_ARRAY_BUFFER)
    images, textures, index = [], [], {}
    for name, srgb in SRGB.items():
        if name not in face.textures:
            continue
        images.append(g.Image(bufferView=add_view(encode_png(face.textures[name], srgb)), mimeType="image/png",
                              name=name))
        textures.append(g.Texture(sampler=0, source=len(images) - 1, name=name))
        index[name] = len(textures) - 1
    material = g.Material(
        name="face", doubleSided=False,
        pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorTexture=g.TextureInfo(index=index["base_color"]), metallicFactor=1.0, roughnessFactor=1.0,
            metallicRoughnessTexture=g.TextureInfo(index=index["metallic_roughness"])),
        extensions={"KHR_materials_specular": {
            "specularFactor": 1.0, "specularTexture": {"index": index["specular"]},
            "specularColorFactor": [face.specular_color_scale] * 3,
            "specularColorTexture": {"index": index["specular"]}},
            "KHR_materials_ior": {"ior": face.ior}})
    if "normal" in index:
        material.normalTexture = g.NormalMaterialTexture(index=index["normal"], scale=1.0)
    while len(blob) % 4:
        blob.append(0)
    document = g.GLTF2(
        asset=g.Asset(version="2.0", generator="mifaces export"), scene=0, scenes=[g.Scene(nodes=[0])],
        nodes=[g.Node(mesh=0, name="face")],
        meshes=[g.Mesh(name="face", primitives=[g.Primitive(attributes=attributes, indices=indices, material=0)])],
        materials=[material], textures=textures, images=images,
        samplers=[g.Sampler(magFilter=LINEAR, minFilter=LINEAR_MIPMAP_LINEAR, wrapS=CLAMP_TO_EDGE,
                            wrapT=CLAMP_TO_EDGE)],
        accessors=accessors, bufferViews=views, buffers=[g.Buffer(byteLength=len(blob))],
        extensionsUsed=list(EXTENSIONS), extras={"mifaces": face.info})
    document.set_binary_blob(bytes(blob))
    return document


def write_gltf(face: ExportedFace, path) -> list[Path]:
    """Write ``path`` (``.glb``: binary; ``.gltf``: JSON with the buffer as a data URI), atomically."""
    path = Path(path)
    document = gltf_document(face)
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".glb":
            document.save_binary(tmp)
        else:
            document.convert_buffers(g.BufferFormat.DATAURI)
            document.save_json(tmp)
    return [path]


__all__ = ["EXTENSIONS", "gltf_document", "write_gltf"]
