"""Universal Scene Description (``.usd``, ``.usda``, ``.usdc``) by ``usd-core`` (pxr).

One ``UsdGeom.Mesh`` (metres, ``upAxis`` Y, ``metersPerUnit`` 1) with vertex
normals and the texture coordinates ``primvars:st`` (v counted from the
bottom, as USD does), bound to a ``UsdPreviewSurface`` in its metallic
workflow: ``diffuseColor`` from the base-colour texture (sRGB),
``roughness`` from the green channel of the metallic-roughness texture,
``metallic`` 0, ``ior`` the material's index, and the tangent-space normal
map (scale 2, bias −1). The textures are PNG files beside the layer,
``<stem>_<texture>.png``. UsdPreviewSurface has no specular factor or colour
for its metallic workflow: the glTF export keeps them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.atomic import atomic_path, atomic_write
from ..io.image_files import encode_png
from .face import ExportedFace

#: The textures written beside the layer, and whether they are sRGB-encoded.
TEXTURES = {"base_color": True, "metallic_roughness": False, "normal": False}


def texture_name(stem: str, name: str) -> str:
    """File name of texture ``name`` of the export ``stem``."""
    return f"{stem}_{name}.png"


def _texture(stage, material_path: str, name: str, file: str, st, color_space: str):
    from pxr import Sdf, UsdShade

    reader = UsdShade.Shader.Define(stage, f"{material_path}/{name}")
    reader.CreateIdAttr("UsdUVTexture")
    reader.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(f"./{file}")
    reader.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(color_space)
    reader.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
    return reader


def build_stage(face: ExportedFace, path: str, stem: str):
    """A new stage at ``path`` holding the face (module docstring); not saved."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt

    stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Face")
    stage.SetDefaultPrim(root.GetPrim())
    root.GetPrim().SetCustomDataByKey("mifaces", {k: str(v) for k, v in face.info.items()})
    mesh = UsdGeom.Mesh.Define(stage, "/Face/Mesh")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(face.positions, np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(face.triangles), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(face.triangles.astype(np.int32).ravel()))
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(face.normals, np.float32)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)  # counter-clockwise seen from outside
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateExtentAttr([Gf.Vec3f(*map(float, face.positions.min(0))), Gf.Vec3f(*map(float, face.positions.max(0)))])
    st = np.stack([face.uv[:, 0], 1.0 - face.uv[:, 1]], axis=1).astype(np.float32)
    primvar = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                      UsdGeom.Tokens.vertex)
    primvar.Set(Vt.Vec2fArray.FromNumpy(st))

    material = UsdShade.Material.Define(stage, "/Face/Material")
    surface = UsdShade.Shader.Define(stage, "/Face/Material/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(stage, "/Face/Material/st")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
    st_out = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    base = _texture(stage, "/Face/Material", "BaseColor", texture_name(stem, "base_color"), st_out, "sRGB")
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        base.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    rough = _texture(stage, "/Face/Material", "MetallicRoughness", texture_name(stem, "metallic_roughness"), st_out,
                     "raw")
    surface.CreateInput("roughness", Sdf.ValueTypeNames.Float).ConnectToSource(
        rough.CreateOutput("g", Sdf.ValueTypeNames.Float))
    surface.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    surface.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(0)
    surface.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(float(face.ior))
    if "normal" in face.textures:
        normal = _texture(stage, "/Face/Material", "Normal", texture_name(stem, "normal"), st_out, "raw")
        normal.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(2.0, 2.0, 2.0, 1.0))
        normal.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(-1.0, -1.0, -1.0, 0.0))
        surface.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(
            normal.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    return stage


def write_usd(face: ExportedFace, path) -> list[Path]:
    """Write the layer ``path`` (format from its suffix; ``.usd`` is binary) and its
    textures beside it, each atomically, the layer last."""
    path = Path(path)
    written = []
    for name, srgb in TEXTURES.items():
        if name in face.textures:
            target = path.parent / texture_name(path.stem, name)
            with atomic_write(target) as f:
                f.write(encode_png(face.textures[name], srgb))
            written.append(target)
    with atomic_path(path) as tmp:
        stage = build_stage(face, tmp, path.stem)
        stage.GetRootLayer().Save()
        del stage
    return written + [path]


__all__ = ["TEXTURES", "build_stage", "texture_name", "write_usd"]
