"""Take the measured face anywhere: glTF 2.0, OBJ and USD with PBR textures.

:func:`export_face` takes a fitted BRDF (the estimate in memory, or a
``fit-brdf`` or ``measure`` model folder) and
writes the face in the format of the output's suffix (:data:`FORMATS`):
geometry in metres, +y up, with normals, tangents and texture coordinates,
and the fitted reflectance mapped onto glTF's metallic-roughness model
(each model by its own mapping, :mod:`mifaces.brdf.gltf_lobe`) as textures through the region map
(:mod:`mifaces.export.face`). The mapping and its error: ``docs/export.md``.

Examples
--------
>>> from mifaces.export import FORMATS
>>> sorted(FORMATS)
['.glb', '.gltf', '.obj', '.usd', '.usda', '.usdc']
"""

from __future__ import annotations

from pathlib import Path

from ..io.paths import check_writable
from .face import ExportedFace, exported_face
from .gltf import write_gltf
from .obj import write_obj
from .usd import write_usd

#: Output suffix -> writer.
FORMATS = {".glb": write_gltf, ".gltf": write_gltf, ".obj": write_obj, ".usd": write_usd, ".usda": write_usd,
           ".usdc": write_usd}


def writer(out):
    """The writer of output file ``out``, from its suffix; a ``ValueError`` naming the known ones."""
    suffix = Path(out).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"cannot tell the format of {out}: its suffix must be one of {sorted(FORMATS)}")
    return FORMATS[suffix]


def export_face(result, out, measurement: str | None = None, shapes=None, face_model=None,
                source: str | None = None) -> list[Path]:
    """Write the face of fitted BRDF ``result`` to file ``out``.

    Parameters
    ----------
    result : BRDFEstimate or path
        The estimate in memory (:func:`mifaces.reflectance.fit_brdf`), or a ``fit-brdf`` or
        ``measure`` model folder (``out/measure/brdf/cooktorrance``) read into one.
    out : path
        The output file; its suffix picks the format (:data:`FORMATS`). OBJ and USD
        write their textures (and OBJ its ``.mtl``) beside it.
    measurement, shapes, face_model, source
        The shape and an estimate's provenance: see :func:`mifaces.export.face.exported_face` (default: the model's mean shape).

    Returns
    -------
    list of Path
        The files written, the main file last.

    Raises
    ------
    ValueError
        An unknown suffix; a measurement without a converged shape fit.
    mifaces.io.result_set.ResultSetError
        An incomplete or mixed result set. Nothing is written.
    """
    write = writer(out)
    out = Path(out)
    if out.is_dir():
        raise IsADirectoryError(f"{out} is a folder; give the file to write (e.g. {out / 'face.glb'})")
    check_writable(out.parent)
    face = exported_face(result, measurement, shapes, face_model, source)  # everything is checked before a file is written
    return write(face, out)


__all__ = ["FORMATS", "ExportedFace", "export_face", "exported_face", "writer"]
