"""The face geometry a BRDF is sampled on: per measurement, the face model's
vertices in the capture's world frame, from the simulator's ground truth,
from the shapes ``mifaces fit-shape`` wrote, or given in memory."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .capture import GROUND_TRUTH, Capture, read_ground_truth
from .capture.ground_truth import SCENE
from .model import MorphableModel, load_model
from .shape.io import INDEX, load_fitted_shapes


def load_geometry(capture: Capture, geometry="ground-truth", face_model=None
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
