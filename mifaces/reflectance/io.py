"""Writing and reading a fitted BRDF: the files of ``mifaces fit-brdf``.

:func:`write_estimate` writes, each atomically, ``brdf.json`` in the layout
of the simulator's ``--brdf-params`` (so a fitted BRDF can be put on another
face: ``mifaces simulate --brdf-params brdf.json``), with per region the
fit's loss, sample count, time and status under ``"fit"``; the albedo map
``albedo.exr`` (linear, row 0 at v = 0) and a PNG preview; and
``scene.xml``, the Mitsuba scene of :meth:`mifaces.render.FaceScene.description`
that renders the fitted face with the plugins as the camera saw it in the
first measurement (meshes in ``meshes/``). :func:`load_estimate` reads
``brdf.json`` and the albedo map back.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

from ..files import atomic_write, read_exr, write_exr, write_json, write_png
from ..render import FaceScene, scene_xml

if TYPE_CHECKING:
    from .estimate import BRDFEstimate

#: The fitted BRDF's files in an output folder.
FILES = {"brdf": "brdf.json", "albedo": "albedo.exr", "preview": "albedo.png", "scene": "scene.xml"}
#: Samples per pixel of ``scene.xml`` (``mi.load_file(path, spp=N)`` overrides it).
SCENE_SPP = 64
#: The key path of the sample count in a scene dict.
SPP_PATH = ("sensor", "sampler", "sample_count")


def write_estimate(estimate: BRDFEstimate, out, face: FaceScene, camera, light_position, intensity, *,
                   light_direction=None) -> dict[str, Path]:
    """Write ``brdf.json``, ``albedo.exr`` (+ ``albedo.png``), ``meshes/*.ply``
    and ``scene.xml`` into folder ``out``, each atomically; ``scene.xml``
    last, so a scene never names a file not yet written.

    Parameters
    ----------
    estimate : BRDFEstimate
    out : path
    face : FaceScene
        The geometry the scene shows (world frame, mm).
    camera : mifaces.capture.Camera
    light_position, intensity : (3,) arrays
        The point light of the scene (world, mm) and its radiant intensity.
    light_direction : (3,) array, optional
        A directional light instead (world frame, towards the light;
        ``intensity`` is then its irradiance).
    """
    out = Path(out)
    paths = {key: out / name for key, name in FILES.items()}
    document = estimate.to_json()
    write_json(paths["brdf"], document)
    write_exr(paths["albedo"], estimate.albedo.albedo)
    write_png(paths["preview"], estimate.albedo.albedo)
    face.write_meshes(out)
    scene = face.description(document, camera, light_position, intensity, spp=SCENE_SPP, albedo=FILES["albedo"],
                             light_direction=light_direction)
    comment = (f"The face as fitted by mifaces fit-brdf: per-region {estimate.model} BSDFs over the refined albedo "
               "map, seen by the capture's camera under the light of its first measurement. Render: "
               "mitsuba.load_file(path, spp=N) after `import mifaces` (which registers the plugins). Units: mm.")
    with atomic_write(paths["scene"], "w") as f:
        f.write(scene_xml(scene, {"spp": SPP_PATH}, comment))
    return paths


def load_estimate(path) -> dict:
    """Read a ``brdf.json`` (path to it or its folder) and the albedo map beside it:
    the JSON document with ``"albedo"`` replaced by the (R, R, 3) array."""
    path = Path(path)
    path = path / FILES["brdf"] if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"no brdf.json at {path}")
    data = json.loads(path.read_text())
    for key in ("model", "regions"):
        if key not in data:
            raise ValueError(f"{path}: not a brdf.json, no {key!r}")
    albedo = path.parent / data.get("albedo", FILES["albedo"])
    data["albedo"] = read_exr(albedo) if albedo.is_file() else None
    return data


__all__ = ["FILES", "write_estimate", "load_estimate"]
