"""The built-in morphable face model: the ICT Face Model Light, shipped inside mifaces.

The ICT Face Model Light (ICT-FaceKit, USC Institute for Creative
Technologies, MIT licence; Li, Bladin, Zhao et al., "Learning Formation of
Physically-Based Face Attributes", CVPR 2020) is a head, not a mask: face,
back of the head, ears, neck and eyeballs, with 100 identity modes that are
principal components of light-stage scans, and ARKit-style expression blend
shapes. :mod:`mifaces.model.ict_convert` turned the toolkit's files into
``data/ict_face.npz`` (millimetres, one atlas of texture coordinates, seams
split; the conversion and what it keeps are described there), and the MIT
notice ships beside it (``data/LICENSE-ICT-FaceKit.txt``).

The model has no albedo (colour) model: the shape fit estimates a per-vertex
albedo with a smoothness prior, and the simulator paints a skin albedo map
(:mod:`mifaces.studio.skin`).
"""

from __future__ import annotations

import json

import numpy as np

from .ict_convert import FORMAT, LICENSE_FILE, MODEL_FILE
from .morphable import MorphableModel

#: The model's name in results and reports.
NAME = "builtin"
#: Identity modes the shape fit uses by default: the leading 50 of 100 (``docs/model.md`` says how
#: this was chosen, on Surrey faces other than those reported). The simulator's faces use all 100.
FIT_SHAPE_MODES = 50

#: Standard deviation of a blend shape's weight in the prior (weights run from 0 to 1): a sitter's face
#: moves a little, not to the extremes the blend shapes reach.
EXPRESSION_SD = 0.2

_memo: dict[str, MorphableModel] = {}


def load_builtin() -> MorphableModel:
    """The built-in model (the ICT Face Model Light), from the package's data file; kept in memory
    after the first call."""
    if NAME in _memo:
        return _memo[NAME]
    if not MODEL_FILE.is_file():
        raise FileNotFoundError(f"the built-in model's data file is missing: {MODEL_FILE} "
                                "(reinstall mifaces, or run python -m mifaces.model.ict_convert)")
    with np.load(MODEL_FILE, allow_pickle=False) as d:
        if int(d["format"]) != FORMAT:
            raise ValueError(f"{MODEL_FILE}: format {int(d['format'])}, this mifaces reads format {FORMAT}")
        rows = d["source_row"]
        k = d["basis"].shape[1]
        basis = (d["basis"] * d["basis_scale"].astype(np.float32)).reshape(-1, 3, k)[rows].reshape(-1, k)
        e = d["expressions"].shape[1]
        expressions = (d["expressions"] * d["expression_scale"].astype(np.float32)).reshape(-1, 3, e)[rows]
        metadata = json.loads(str(d["metadata"]))
        metadata["licence_file"] = str(LICENSE_FILE)
        metadata["fit_shape_modes"] = FIT_SHAPE_MODES
        model = MorphableModel(
            name=NAME, shape_mean=d["neutral"][rows], shape_basis=basis, shape_variance=d["variance"],
            triangles=d["triangles"], uv=d["uv"], region_map=d["region_map"], landmarks=d["landmarks"],
            expression_basis=expressions.reshape(-1, e), expression_variance=np.full(e, EXPRESSION_SD ** 2),
            expression_names=tuple(metadata["expressions"]), metadata=metadata)
    _memo[NAME] = model
    return model
