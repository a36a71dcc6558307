"""Named facial feature points, the vocabulary captures and fitters share.

A capture marks 7-20 feature points per photograph by these names (paper
sec. 4.2); the shape fitter finds each one on the model through its iBUG
68-point index (1-based; Sagonas et al., "300 Faces in-the-Wild", 2013),
which every mifaces model maps to a vertex (``MorphableModel.ibug_landmarks``).

"right" and "left" are the subject's own: the right eye is on the image's
left in a frontal photograph (iBUG's convention).
"""

from __future__ import annotations

#: feature point name -> iBUG 68-point index (1-based)
FEATURE_POINTS: dict[str, int] = {
    "chin": 9,
    "right_eyebrow_outer": 18,
    "right_eyebrow_inner": 22,
    "left_eyebrow_inner": 23,
    "left_eyebrow_outer": 27,
    "nose_bridge": 28,
    "nose_tip": 31,
    "right_nostril": 32,
    "subnasale": 34,
    "left_nostril": 36,
    "right_eye_outer": 37,
    "right_eye_inner": 40,
    "left_eye_inner": 43,
    "left_eye_outer": 46,
    "mouth_right": 49,
    "upper_lip": 52,
    "mouth_left": 55,
    "lower_lip": 58,
}


def feature_vertices(ibug_landmarks: dict[int, int], names=None) -> dict[str, int]:
    """Vertex of each named feature point on a model.

    Parameters
    ----------
    ibug_landmarks : dict
        The model's iBUG index -> vertex map.
    names : iterable of str, optional
        The names wanted (default: all the model has).

    Raises
    ------
    ValueError
        For a name outside :data:`FEATURE_POINTS`, or one the model lacks.
    """
    if names is None:
        return {n: ibug_landmarks[i] for n, i in FEATURE_POINTS.items() if i in ibug_landmarks}
    out = {}
    for name in names:
        if name not in FEATURE_POINTS:
            raise ValueError(f"unknown feature point {name!r}; known: {sorted(FEATURE_POINTS)}")
        index = FEATURE_POINTS[name]
        if index not in ibug_landmarks:
            raise ValueError(f"feature point {name!r} (iBUG {index}) is not defined on this model")
        out[name] = ibug_landmarks[index]
    return out
