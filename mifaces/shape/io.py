"""Fitted shapes handed to the next stage (paper sec. 4.2 -> 4.3): in memory, or
written to and read from a folder -- per measurement ``<name>.json`` and, for a
converged fit, ``<name>.npy`` (camera-space vertices), and the index
``shapes.json``.

The index is written last and holds each file's SHA-256: a reader
(:func:`load_fitted_shapes`) refuses a file that is not the one the index
was written with (a run killed between a measurement's files and the index),
so fits of two runs are never mixed. Measurement names become file names
only if they are safe (:func:`mifaces.io.paths.check_name`)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from ..capture import GROUND_TRUTH, Camera, load_capture, read_ground_truth
from ..capture.ground_truth import SCENE
from ..io.atomic import atomic_write, write_json
from ..model import MorphableModel, load_model
from ..io.paths import check_name
from ..io.result_set import ResultSetError, file_sha256
from ..runtime.status import CONVERGED
from .result import ShapeFit

#: Name of the index file :func:`~mifaces.shape.fit.fit_shape` writes beside the per-measurement files.
INDEX = "shapes.json"
#: Suffix of a measurement's fitted albedo file.
ALBEDO_SUFFIX = "_albedo"


def file_stem(measurement: str) -> str:
    """The file name stem of ``measurement``'s fit: its name, if safe
    (:func:`mifaces.io.paths.check_name`), not the index's and not one that
    another measurement's albedo file takes (``<name>_albedo``)."""
    check_name(measurement, "measurement name", reserved=(Path(INDEX).stem,))
    if measurement.lower().endswith(ALBEDO_SUFFIX):
        raise ValueError(f"measurement name {measurement!r} is reserved: it ends like a fitted albedo's file "
                         f"(<name>{ALBEDO_SUFFIX}.npy)")
    return measurement


def write_fit(out, fit: ShapeFit, model) -> None:
    """Write ``<name>.json`` and, if converged, ``<name>.npy`` (camera-space vertices) atomically.
    A diverged fit's stale ``.npy`` from an earlier run is removed, so it is never read as a success."""
    out = Path(out)
    stem = file_stem(fit.measurement)
    out.mkdir(parents=True, exist_ok=True)
    npy = out / f"{stem}.npy"
    if fit.converged:
        with atomic_write(npy) as f:
            np.save(f, fit.vertices_camera.astype(np.float32))
    elif npy.exists():
        npy.unlink()
    data = fit.to_json()
    data["model"] = model.name
    data["vertices"] = npy.name if fit.converged else None
    if fit.albedo is not None and fit.converged:
        alb = out / f"{stem}{ALBEDO_SUFFIX}.npy"
        with atomic_write(alb) as f:
            np.save(f, fit.albedo)
        data["albedo"] = alb.name
    write_json(out / f"{stem}.json", data)


def write_index(out, capture, model, fits: list[ShapeFit], reference=None, model_source=None) -> None:
    """Write ``shapes.json``: the capture, the model (``model_source``: what
    :func:`mifaces.load_model` loads it from), the camera and per measurement
    its status and its files' SHA-256 (measurements of earlier runs kept), and whether the
    directed lights' ambient term was fitted or held at zero (``Capture.ambient_light``)."""
    out = Path(out)
    index = {"format": "mifaces-shapes", "version": 1, "capture": str(capture.path), "model": model.name,
             "model_source": str(model_source if model_source is not None else model.name),
             "vertex_count": model.vertex_count, "shape_modes": model.shape_dim,
             "model_shape_modes": int(model.metadata.get("shape_modes_of", model.shape_dim)),
             "frame": "camera (OpenCV), mm",
             "camera": capture.camera.to_json(), "texture_reference": reference,
             **({"cameras": {ident: camera.to_json() for ident, camera in capture.cameras.items()}}
                if capture.several_cameras else {}),
             "ambient": "fitted" if capture.ambient_light else "held at zero (the capture's \"ambient\": \"none\")",
             "measurements": {}}
    old = out / INDEX
    if old.is_file():
        try:
            index["measurements"].update(json.loads(old.read_text()).get("measurements", {}))
        except (ValueError, OSError):
            pass
    for fit in fits:
        stem = file_stem(fit.measurement)
        entry = {"status": fit.status, "vertices": f"{stem}.npy" if fit.converged else None,
                 "parameters": f"{stem}.json", "seconds": round(fit.seconds, 3),
                 "feature_rms_px": fit.loss.get("feature_rms_px"), "image_rms": fit.loss.get("image_rms"),
                 "message": fit.message,
                 "shared_with": fit.shared_with, "estimated": list(fit.estimated)}
        if capture.several_cameras:  # its vertices are in the frame of the camera that took it
            entry["camera"] = next(m.camera for m in capture.measurements if m.name == fit.measurement)
        entry["sha256"] = {name: file_sha256(out / name) for name in (entry["vertices"], entry["parameters"])
                           if name is not None and (out / name).is_file()}
        index["measurements"][fit.measurement] = entry
    write_json(out / INDEX, index)


def model_source(model) -> str:
    """What :func:`mifaces.load_model` loads ``model`` (a name, a path or a loaded model) from."""
    if not isinstance(model, MorphableModel):
        return str(model)
    source = Path(str(model.metadata.get("source", "")))
    return str(model.metadata["source"]) if source.is_file() else model.name


def _warn_left_out(skipped: list[str]) -> None:
    if skipped:
        warnings.warn(f"fitted shapes not converged, left out: {', '.join(skipped)}", stacklevel=3)


def shapes_in_world(fits: list[ShapeFit], capture) -> dict[str, np.ndarray]:
    """The converged fits' vertices in the capture's **world** frame: what
    :func:`load_fitted_shapes` reads back from the folder these fits were written to.

    Parameters
    ----------
    fits : list of ShapeFit
        As :func:`~mifaces.shape.fit.fit_shape` returns them.
    capture : Capture or path
        The capture whose camera maps camera space to world space.

    Returns
    -------
    dict
        Measurement name -> (N, 3) float32 vertices, world frame, mm. Fits that
        did not converge are left out, with a warning.
    """
    capture = load_capture(capture)
    _warn_left_out([f"{fit.measurement} ({fit.status})" for fit in fits if not fit.converged])
    return {fit.measurement: capture.camera_of(fit.measurement).to_world(fit.vertices_camera.astype(np.float32))
            .astype(np.float32) for fit in fits if fit.converged}


def _load_vertices(path: Path, name: str, entry: dict) -> np.ndarray:
    """The camera-space vertices of measurement ``name``'s index ``entry``,
    checked against the SHA-256 the index holds (indices without one, from
    older versions, are trusted)."""
    stem = file_stem(name)
    if entry["vertices"] != f"{stem}.npy":
        raise ResultSetError(f"{path / INDEX}: measurement {name!r} names vertices {entry['vertices']!r}, "
                             f"not {stem}.npy")
    file = path / entry["vertices"]
    expected = (entry.get("sha256") or {}).get(entry["vertices"])
    if expected is not None and (not file.is_file() or file_sha256(file) != expected):
        raise ResultSetError(f"{path}: {entry['vertices']} is not the file {INDEX} was written with (changed, "
                             f"missing or from an interrupted run); fit {name} again")
    return np.load(file, allow_pickle=False)


def load_fitted_shapes(path, capture=None) -> dict[str, np.ndarray]:
    """Fitted shapes written by :func:`~mifaces.shape.fit.fit_shape`, in the capture's **world** frame.

    Parameters
    ----------
    path : path
        The ``out`` folder of :func:`~mifaces.shape.fit.fit_shape` (holding ``shapes.json``).
    capture : Capture or path, optional
        The capture whose camera maps camera space to world space (default:
        the camera stored in ``shapes.json``).

    Returns
    -------
    dict
        Measurement name -> (N, 3) float32 vertices, world frame, mm -- the
        same quantity as the simulator's ``ground_truth/shapes/<name>.npy``.
        Measurements whose fit diverged are left out, with a warning.
    """
    path = Path(path)
    index_path = path / INDEX
    if not index_path.is_file():
        raise FileNotFoundError(f"no {INDEX} in {path}: not a fit-shape output folder")
    index = json.loads(index_path.read_text())
    if capture is not None:
        capture = load_capture(capture)
        camera_of = capture.camera_of
    else:
        cameras = {ident: Camera.from_json(c) for ident, c in index.get("cameras", {}).items()}
        first = Camera.from_json(index["camera"])

        def camera_of(name):
            return cameras.get(index["measurements"][name].get("camera"), first)
    out = {}
    skipped = []
    for name, entry in index["measurements"].items():
        if entry.get("status") != CONVERGED or not entry.get("vertices"):
            skipped.append(f"{name} ({entry.get('status')})")
            continue
        out[name] = camera_of(name).to_world(_load_vertices(path, name, entry)).astype(np.float32)
    _warn_left_out(skipped)
    return out


def load_geometry(capture, geometry="ground-truth", face_model=None
                  ) -> tuple[MorphableModel, dict[str, np.ndarray]]:
    """The face model and per-measurement world-space vertices to sample with.

    Parameters
    ----------
    capture : Capture
    geometry : ``'ground-truth'``, path or mapping
        ``'ground-truth'``: the simulator's ``ground_truth/`` of this capture.
        A path: a folder written by ``mifaces fit-shape``. A mapping:
        measurement name -> (V, 3) vertices in the capture's world frame (mm).
    face_model : MorphableModel, path or ``'builtin'``, optional
        The model the shapes belong to; default: the one the ground truth or
        the fitted shapes name.
    """
    if isinstance(geometry, dict):
        return load_model(face_model or "builtin"), {k: np.asarray(v, np.float64) for k, v in geometry.items()}
    if str(geometry) == "ground-truth":
        truth = read_ground_truth(capture)
        if truth is None:
            raise FileNotFoundError(f"{capture.path} has no {GROUND_TRUTH}/{SCENE} (only simulated captures "
                                    "have ground truth): give fitted shapes instead")
        return load_model(face_model or truth.model), {k: v.astype(np.float64) for k, v in truth.shapes.items()}
    path = Path(geometry)
    if not (path / INDEX).is_file():
        raise FileNotFoundError(f"no fitted shapes at {path}: expected the folder mifaces fit-shape wrote "
                                f"(with {INDEX}), or 'ground-truth'")
    if face_model is None:
        index = json.loads((path / INDEX).read_text())
        face_model = index.get("model_source", index.get("model", "builtin"))
    return load_model(face_model), load_fitted_shapes(path, capture)
