"""The measured face as a file format needs it: geometry in metres and
glTF-style PBR textures, built from a fitted BRDF: the
:class:`~mifaces.reflectance.BRDFEstimate` in memory, or a ``fit-brdf`` or
``measure`` model folder read into one.

:func:`exported_face` takes the estimate (a folder must be a complete, unmixed
result set: :func:`mifaces.io.result_set.verify_set`), the face's shape (the model's mean,
or the shape fitted to one photograph), and maps every region's BRDF onto
glTF's model, each model by its own mapping
(:meth:`mifaces.brdf.model.BRDFModel.gltf_lobe`), spread over texture space by
the region map. The writers (:mod:`mifaces.export.gltf`, ``obj``, ``usd``)
only lay the :class:`ExportedFace` out in their format.

Frames. Positions are the model's frame (y up, the face looking along +z)
scaled from mm to metres, as glTF asks (+y up, metres). Texture coordinates
are the model's, ``v = 0`` the first row of every texture (glTF's
convention; OBJ and USD count v from the bottom and the writers flip it).
The tangent is ∂p/∂u accumulated per vertex and made orthogonal to the
vertex normal (:meth:`mifaces.model.MorphableModel.tangent_frames`), with
w = +1: glTF's bitangent n × t·w is then the samples' bitangent. Mitsuba's
``normalmap`` frame differs (per triangle ∂p/∂u), so the normal map is
re-expressed texel by texel from Mitsuba's frame into the interpolated one
(:func:`gltf_normals`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..brdf import model as brdf_model
from ..brdf.gltf_lobe import GltfLobe
from ..brdf.materials import SKIN_REFRACTIVE_INDEX
from ..brdf.model import BRDFModel
from ..io.result_set import ResultSetError, verify_set
from ..model import MorphableModel, load_model
from ..model.regions import FALLBACK_REGION, REGION_NAMES, REGIONS, texel_regions_of_mesh
from ..reflectance.io import KIND, read_estimate
from ..reflectance.result import FILES, BRDFEstimate
from ..reflectance.maps.normals import decode, encode, mitsuba_frames
from ..shape.io import INDEX as SHAPES_INDEX, file_stem
from ..runtime.status import CONVERGED

#: Millimetres (the model's unit) per metre (glTF's and the exports' unit).
MM_PER_METRE = 1000.0
#: The index of refraction of the exported material (``KHR_materials_ior``, USD's ``ior``); regions
#: of another index carry the difference in the specular colour.
MATERIAL_IOR = SKIN_REFRACTIVE_INDEX


@dataclass
class ExportedFace:
    """A face ready to be written in any format.

    Attributes
    ----------
    positions, normals : (N, 3) float32
        Metres, model frame (+y up, the face along +z); unit outward normals.
    tangents : (N, 4) float32
        glTF tangents: ∂p/∂u made orthogonal to the normal, w = +1.
    uv : (N, 2) float32
        ``v = 0`` the first texture row.
    triangles : (T, 3) uint32
        Counter-clockwise seen from outside.
    textures : dict
        ``base_color`` (R, R, 3) linear (written sRGB-encoded),
        ``metallic_roughness`` (R, R, 3) linear (G roughness √α, B metallic 0),
        ``specular`` (R, R, 4): RGB the specular colour divided by
        ``specular_color_scale`` (written sRGB-encoded), A the specular factor f90;
        ``normal`` (R, R, 3) encoded (n + 1) / 2 in glTF's frame, or absent.
    specular_color_scale : float
        ``specularColorFactor`` (the specular colour may exceed 1; the texture holds it divided by this).
    ior : float
    lobes : dict
        Region name -> :class:`~mifaces.brdf.gltf_lobe.GltfLobe`.
    info : dict
        Provenance: the result folder, the BRDF model, the shape's source.
    """

    positions: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    uv: np.ndarray
    triangles: np.ndarray
    textures: dict
    specular_color_scale: float
    ior: float = MATERIAL_IOR
    lobes: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)


def check_result(folder) -> Path:
    """``folder`` if it is a complete fitted-BRDF result set: its manifest lists
    every file and each one is the one written with the rest.

    Raises
    ------
    FileNotFoundError
        No ``brdf.json`` there.
    mifaces.io.result_set.ResultSetError
        No set manifest (not written as a set, or cut short), files missing,
        changed or from another run.
    """
    folder = Path(folder)
    if not (folder / FILES["brdf"]).is_file():
        raise FileNotFoundError(f"no {FILES['brdf']} in {folder}: give a model folder of mifaces fit-brdf or "
                                "measure (e.g. out/measure/brdf/cooktorrance)")
    if verify_set(folder, KIND) is None:
        raise ResultSetError(f"{folder}: no result-set manifest, so its files cannot be told complete and of one "
                             "run; write the result again with this mifaces")
    return folder


def fitted_shape(face_model: MorphableModel, shapes, measurement: str) -> np.ndarray:
    """The model-frame vertices (N, 3, mm) fitted to ``measurement``, from a
    ``fit-shape`` folder ``shapes`` or the fits in memory (:class:`~mifaces.shape.ShapeFit`
    sequence): their coefficients and expression; the pose is dropped."""
    if not isinstance(shapes, (str, Path)):
        fit = next((f for f in shapes if f.measurement == measurement), None)
        if fit is None or not fit.converged:
            raise ValueError(f"measurement {measurement!r} has no converged shape fit")
        return face_model.shape(fit.coefficients, fit.expression if face_model.has_expressions else None)
    shapes = Path(shapes)
    if not (shapes / SHAPES_INDEX).is_file():
        raise FileNotFoundError(f"no fitted shapes at {shapes} (no {SHAPES_INDEX}): give the fit-shape folder "
                                "(measure's shapes/), or leave out the measurement to export the model's mean shape")
    index = json.loads((shapes / SHAPES_INDEX).read_text())
    entry = index.get("measurements", {}).get(measurement)
    if entry is None:
        raise ValueError(f"measurement {measurement!r} has no fitted shape in {shapes}; fitted: "
                         f"{sorted(index.get('measurements', {}))}")
    if entry.get("status") != CONVERGED:
        raise ValueError(f"the shape fit of measurement {measurement!r} did not converge ({entry.get('status')})")
    fit = json.loads((shapes / f"{file_stem(measurement)}.json").read_text())
    expression = fit.get("expression") if face_model.has_expressions else None
    return face_model.shape(fit["coefficients"], expression)


def gltf_normals(texture: np.ndarray, face_model: MorphableModel, vertices: np.ndarray) -> np.ndarray:
    """A Mitsuba ``normalmap`` texture (R, R, 3, encoded) re-expressed in glTF's
    tangent frame (interpolated vertex normal and tangent, bitangent n × t):
    per covered texel n_glTF = S Mᵀ n_Mitsuba with M, S the two frames' rows
    (:func:`mifaces.reflectance.maps.normals.mitsuba_frames`); encoded."""
    resolution = texture.shape[0]
    normals = decode(texture).reshape(-1, 3)
    texel, mitsuba, samples = mitsuba_frames(face_model, vertices, resolution)
    world = np.einsum("mji,mj->mi", mitsuba, normals[texel])
    local = np.einsum("mij,mj->mi", samples, world)
    out = normals.copy()
    out[texel] = local / np.maximum(np.linalg.norm(local, axis=1, keepdims=True), 1e-30)
    return encode(out.reshape(texture.shape))


def _region_table(brdf: BRDFModel, regions: dict, labels: np.ndarray) -> dict[int, GltfLobe]:
    """Label -> glTF lobe for every label in ``labels`` (background and unfitted regions:
    :data:`~mifaces.model.regions.FALLBACK_REGION`'s)."""
    lobes, known = {}, {}
    for label in np.unique(labels):
        name = REGION_NAMES[label] if REGION_NAMES[label] in regions else FALLBACK_REGION
        values = brdf.region_values(regions[name], name)
        key = json.dumps({k: np.asarray(v, np.float64).tolist() for k, v in values.items()}, sort_keys=True)
        if key not in known:  # regions of equal values (fallen back to another's) share its lobe
            known[key] = brdf.gltf_lobe(values)
        lobes[int(label)] = known[key]
    return lobes


def material_textures(document: dict, albedo: np.ndarray, labels: np.ndarray, specular=None,
                      ior: float = MATERIAL_IOR) -> tuple[dict, float, dict]:
    """The PBR textures of :class:`ExportedFace` from a BRDF (``{"model", "options", "regions"}``,
    as ``brdf.json`` and :meth:`BRDFEstimate.to_json <mifaces.reflectance.BRDFEstimate.to_json>`
    give it), its albedo map (R, R, 3), the texel labels (R, R) and an optional per-texel
    specular map. Returns ``(textures, specular_color_scale, lobes by region name)``."""
    brdf = brdf_model(document["model"], **document.get("options", {}))
    lobes = _region_table(brdf, document["regions"], labels)
    r = labels.shape[0]
    base, rough = np.zeros((r, r, 3)), np.zeros((r, r, 3))
    color, factor = np.zeros((r, r, 3)), np.zeros((r, r))
    for label, lobe in lobes.items():
        where = labels == label
        scale = 1.0
        if specular is not None and "specular_reflectance" in document["regions"].get(REGION_NAMES[label], {}):
            region_rho = float(np.mean(document["regions"][REGION_NAMES[label]]["specular_reflectance"]))
            scale = np.mean(specular[where], axis=1) / max(region_rho, 1e-12)
        base[where] = lobe.base_color(albedo[where])
        rough[where, 1] = lobe.roughness
        color[where] = lobe.specular_color(ior)
        factor[where] = np.clip(lobe.f90 * scale, 0.0, 1.0)
    color_scale = max(float(color.max()), 1e-6)
    textures = {"base_color": base, "metallic_roughness": rough,
                "specular": np.concatenate([color / color_scale, factor[..., None]], axis=2)}
    return textures, color_scale, {REGION_NAMES[k]: v for k, v in lobes.items()}


def exported_face(result, measurement: str | None = None, shapes=None, face_model=None,
                  source: str | None = None) -> ExportedFace:
    """Build the face to export from a fitted BRDF (module docstring).

    Parameters
    ----------
    result : BRDFEstimate or path
        The estimate (:func:`mifaces.reflectance.fit_brdf`), or a ``fit-brdf`` or ``measure``
        model folder (``brdf.json``, ``albedo.exr``, ...) read into one
        (:func:`mifaces.reflectance.io.read_estimate`).
    measurement : str, optional
        Export the shape fitted to this photograph; default: the model's mean shape.
    shapes : path or sequence of ShapeFit, optional
        The ``fit-shape`` folder holding that fit, or the fits in memory; default (a folder
        ``result``): ``shapes/`` of the ``measure`` run the folder belongs to (``RESULT/../../shapes``).
    face_model : str, path or MorphableModel, optional
        The face model; default: the one the fitted shapes name, else ``'builtin'``.
    source : str, optional
        Where an estimate in memory was written, recorded as its provenance (``info['result']``);
        a folder ``result`` is its own.

    Raises
    ------
    mifaces.io.result_set.ResultSetError
        An incomplete or mixed result set (:func:`check_result`).
    """
    if not isinstance(result, BRDFEstimate):
        folder = check_result(result)
        result, source = read_estimate(folder), str(folder)
        if result.albedo.albedo is None:
            raise ResultSetError(f"{folder}: {FILES['albedo']} is missing")
        shapes = folder.parent.parent / "shapes" if shapes is None else shapes
    if isinstance(shapes, (str, Path)) and face_model is None:
        index = Path(shapes) / SHAPES_INDEX
        face_model = json.loads(index.read_text()).get("model_source", "builtin") if index.is_file() else "builtin"
    face_model = load_model("builtin" if face_model is None else face_model)
    if measurement is not None and shapes is None:
        raise ValueError(f"the shape fitted to {measurement!r}: give its fits (shapes=)")
    vertices = face_model.shape_mean if measurement is None else fitted_shape(face_model, shapes, measurement)
    albedo = np.asarray(result.albedo.albedo, np.float32)  # as the result's files keep it
    resolution = albedo.shape[0]
    labels = texel_regions_of_mesh(face_model.region_map, face_model.uv, face_model.triangles, resolution)
    specular = result.specular_texture()
    brdf = {"model": result.model, "options": result.options, "regions": result.regions()}
    textures, color_scale, lobes = material_textures(brdf, albedo, labels,
                                                     None if specular is None else np.asarray(specular, np.float32))
    normals = result.normal_texture()
    if normals is not None:
        if normals.shape[:2] != (resolution, resolution):
            raise ResultSetError(f"{source}: the normal map is {normals.shape[1]}x{normals.shape[0]}"
                                 f" but the albedo map {resolution}x{resolution}: files of different runs")
        textures["normal"] = gltf_normals(normals, face_model, vertices)
    tangent, _, normal = face_model.tangent_frames(vertices)
    info = {"result": str(source), "model": result.model, "face_model": face_model.name,
            "shape": "mean" if measurement is None else f"fitted to {measurement}",
            "regions": sorted(REGIONS[name] for name in lobes)}
    return ExportedFace(positions=(np.asarray(vertices, np.float64) / MM_PER_METRE).astype(np.float32),
                        normals=normal, tangents=np.concatenate([tangent, np.ones((len(tangent), 1))], 1)
                        .astype(np.float32), uv=face_model.uv.astype(np.float32),
                        triangles=face_model.triangles.astype(np.uint32), textures=textures,
                        specular_color_scale=color_scale, lobes=lobes, info=info)


__all__ = ["ExportedFace", "MM_PER_METRE", "MATERIAL_IOR", "check_result", "exported_face", "fitted_shape",
           "gltf_normals", "material_textures"]
