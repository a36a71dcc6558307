"""Fitted shapes handed to the next stage (paper sec. 4.2 -> 4.3): in memory, or
written to and read from a folder -- per measurement ``<name>.json`` and, for a
converged fit, ``<name>.npy`` (camera-space vertices), and the index
``shapes.json``."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from ..capture import Camera, Capture, load_capture
from ..files import atomic_write, write_json
from ..status import CONVERGED
from .result import ShapeFit

#: Name of the index file :func:`~mifaces.shape.fit.fit_shape` writes beside the per-measurement files.
INDEX = "shapes.json"


def as_capture(capture) -> Capture:
    """A loaded capture, or the one at the folder ``capture``."""
    return capture if isinstance(capture, Capture) else load_capture(capture)


def write_fit(out, fit: ShapeFit, model) -> None:
    """Write ``<name>.json`` and, if converged, ``<name>.npy`` (camera-space vertices) atomically.
    A diverged fit's stale ``.npy`` from an earlier run is removed, so it is never read as a success."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    npy = out / f"{fit.measurement}.npy"
    if fit.converged:
        with atomic_write(npy) as f:
            np.save(f, fit.vertices_camera.astype(np.float32))
    elif npy.exists():
        npy.unlink()
    data = fit.to_json()
    data["model"] = model.name
    data["vertices"] = npy.name if fit.converged else None
    if fit.albedo is not None and fit.converged:
        alb = out / f"{fit.measurement}_albedo.npy"
        with atomic_write(alb) as f:
            np.save(f, fit.albedo)
        data["albedo"] = alb.name
    write_json(out / f"{fit.measurement}.json", data)


def write_index(out, capture, model, fits: list[ShapeFit], reference=None, model_source=None) -> None:
    """Write ``shapes.json``: the capture, the model (``model_source``: what
    :func:`mifaces.load_model` loads it from), the camera and per measurement its status."""
    out = Path(out)
    index = {"format": "mifaces-shapes", "version": 1, "capture": str(capture.path), "model": model.name,
             "model_source": str(model_source if model_source is not None else model.name),
             "vertex_count": model.vertex_count, "frame": "camera (OpenCV), mm",
             "camera": capture.camera.to_json(), "texture_reference": reference, "measurements": {}}
    old = out / INDEX
    if old.is_file():
        try:
            index["measurements"].update(json.loads(old.read_text()).get("measurements", {}))
        except (ValueError, OSError):
            pass
    for fit in fits:
        index["measurements"][fit.measurement] = {
            "status": fit.status, "vertices": f"{fit.measurement}.npy" if fit.converged else None,
            "parameters": f"{fit.measurement}.json", "seconds": round(fit.seconds, 3),
            "feature_rms_px": fit.loss.get("feature_rms_px"), "message": fit.message,
            "shared_with": fit.shared_with, "estimated": list(fit.estimated)}
    write_json(out / INDEX, index)


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
    camera = as_capture(capture).camera
    _warn_left_out([f"{fit.measurement} ({fit.status})" for fit in fits if not fit.converged])
    return {fit.measurement: camera.to_world(fit.vertices_camera.astype(np.float32)).astype(np.float32)
            for fit in fits if fit.converged}


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
        camera = as_capture(capture).camera
    else:
        c = index["camera"]
        camera = Camera(c["width"], c["height"], c["fx"], c["fy"], c["cx"], c["cy"], np.asarray(c["distortion"]),
                        np.asarray(c["rotation"]), np.asarray(c["translation"]))
    out = {}
    skipped = []
    for name, entry in index["measurements"].items():
        if entry.get("status") != CONVERGED or not entry.get("vertices"):
            skipped.append(f"{name} ({entry.get('status')})")
            continue
        verts = np.load(path / entry["vertices"])
        out[name] = camera.to_world(verts).astype(np.float32)
    _warn_left_out(skipped)
    return out
