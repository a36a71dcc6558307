"""The Surrey Face Model (Huber et al., VISAPP 2016), from its npz conversion or eos binaries.

The npz layout (``sfm_shape_3448.npz``) is the one documented beside the
model in ``shared/models/sfm_3448/README.md``: ``shape_mean`` (N, 3),
``shape_basis`` (N, 3, K) orthonormal, ``shape_eigenvalues`` (K,),
``triangles`` (T, 3), ``uv`` (N, 2), ``expression_names`` (E,),
``expression_deformations`` (N, 3, E) and ``ibug_landmarks`` (L, 2) with rows
(iBUG index 1-based, vertex 0-based). The SFM has no colour model; its region
map is derived from its landmarks in texture space
(:func:`mifaces.model.regions.region_map_from_landmarks`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .loaders import ModelFormatError, check_shape, existing, read_ibug_mapping, require
from .morphable import MorphableModel
from .regions import region_map_from_landmarks

#: Keys of the SFM npz layout.
SFM_KEYS = ("shape_mean", "shape_basis", "shape_eigenvalues", "triangles", "uv")

REGION_MAP_SHAPE = (512, 512)


def is_sfm_npz(keys) -> bool:
    return "shape_eigenvalues" in keys and "shape_basis" in keys


def load_sfm_npz(path: str | os.PathLike, region_map_shape=REGION_MAP_SHAPE) -> MorphableModel:
    """Load the Surrey Face Model from its npz conversion (layout in the module docstring)."""
    path = existing(path)
    with np.load(path, allow_pickle=False) as data:
        mean = check_shape(require(data, "shape_mean", path, "mean shape (N, 3)"), (None, 3), "shape_mean", path)
        n = len(mean)
        basis = check_shape(require(data, "shape_basis", path, "PCA basis (N, 3, K)"), (n, 3, None),
                            "shape_basis", path)
        k = basis.shape[2]
        ev = check_shape(require(data, "shape_eigenvalues", path, "PCA variances (K,)"), (k,),
                         "shape_eigenvalues", path)
        tri = check_shape(require(data, "triangles", path, "triangles (T, 3)"), (None, 3), "triangles", path)
        uv = check_shape(require(data, "uv", path, "texture coordinates (N, 2)"), (n, 2), "uv", path)
        landmarks = np.zeros((0, 2), np.int32)
        if "ibug_landmarks" in data:
            landmarks = check_shape(data["ibug_landmarks"], (None, 2), "ibug_landmarks", path)
        expr = names = None
        if "expression_deformations" in data:
            expr = check_shape(data["expression_deformations"], (n, 3, None), "expression_deformations", path)
            names = tuple(str(s) for s in data["expression_names"]) if "expression_names" in data else ()
            if names and len(names) != expr.shape[2]:
                raise ModelFormatError(f"{path}: 'expression_names' has {len(names)} names for "
                                       f"{expr.shape[2]} expression_deformations")
    if tri.size and (tri.min() < 0 or tri.max() >= n):
        raise ModelFormatError(f"{path}: 'triangles' index vertices outside [0, {n})")
    if landmarks.size and (landmarks[:, 1].min() < 0 or landmarks[:, 1].max() >= n):
        raise ModelFormatError(f"{path}: 'ibug_landmarks' name vertices outside [0, {n})")
    return MorphableModel(
        name=path.stem,
        shape_mean=mean, shape_basis=basis.reshape(3 * n, k), shape_variance=ev,
        triangles=tri, uv=uv,
        region_map=region_map_from_landmarks(uv, tri, dict(landmarks.tolist()), region_map_shape),
        landmarks=landmarks,
        expression_basis=None if expr is None else expr.reshape(3 * n, -1),
        expression_variance=None, expression_names=names or (),
        metadata={"source": str(path), "format": "sfm-npz", "units": "mm",
                  "citation": "Huber et al., A Multiresolution 3D Morphable Face Model and Fitting "
                              "Framework, VISAPP 2016"},
    )


def load_eos(path: str | os.PathLike, landmarks: str | os.PathLike | None = None,
             blendshapes: str | os.PathLike | None = None, region_map_shape=REGION_MAP_SHAPE) -> MorphableModel:
    """Load an eos binary model (``.bin``) with the optional package ``eos-py``.

    Parameters
    ----------
    path : path
        The model, e.g. ``sfm_shape_3448.bin``.
    landmarks : path, optional
        An eos landmark mapping (``ibug_to_sfm.txt``); by default
        ``ibug_to_sfm.txt`` beside the model if it exists.
    blendshapes : path, optional
        eos expression blendshapes (``expression_blendshapes_3448.bin``); by
        default ``expression_blendshapes_<N>.bin`` beside the model if it exists.
    """
    path = existing(path)
    try:
        import eos
    except ImportError:
        raise ImportError("loading eos .bin models needs the optional package 'eos-py': "
                          "pip install eos-py (or pip install mifaces[eos])") from None
    try:
        eos_model = eos.morphablemodel.load_model(str(path))
    except Exception as exc:
        raise ModelFormatError(f"{path}: eos could not read it as a morphable model ({exc})") from exc
    shape = eos_model.get_shape_model()
    mean = np.asarray(shape.get_mean(), dtype=np.float64)
    if mean.size % 3:
        raise ModelFormatError(f"{path}: mean has {mean.size} values, not a multiple of 3")
    n = mean.size // 3
    basis = check_shape(shape.get_orthonormal_pca_basis(), (3 * n, None), "orthonormal_pca_basis", path)
    ev = check_shape(np.asarray(shape.get_eigenvalues()).ravel(), (basis.shape[1],), "eigenvalues", path)
    tri = np.asarray(shape.get_triangle_list(), dtype=np.int32).reshape(-1, 3)
    uv = np.asarray(eos_model.get_texture_coordinates(), dtype=np.float32).reshape(-1, 2)
    if uv.shape[0] != n:
        raise ModelFormatError(f"{path}: has {uv.shape[0]} texture coordinates for {n} vertices; mifaces needs "
                               "one per vertex (the common parameterization)")
    color = {}
    if eos_model.has_color_model():
        cm = eos_model.get_color_model()
        color = dict(color_mean=np.asarray(cm.get_mean()).reshape(n, 3),
                     color_basis=np.asarray(cm.get_orthonormal_pca_basis()),
                     color_variance=np.asarray(cm.get_eigenvalues()).ravel())
    expr, names = None, ()
    if blendshapes is None:
        guess = path.parent / f"expression_blendshapes_{n}.bin"
        blendshapes = guess if guess.is_file() else None
    if blendshapes is not None:
        shapes = eos.morphablemodel.load_blendshapes(str(existing(blendshapes)))
        expr = np.stack([np.asarray(b.deformation).ravel() for b in shapes], axis=1)
        check_shape(expr, (3 * n, None), "blendshapes", Path(blendshapes))
        names = tuple(b.name for b in shapes)
    if landmarks is None:
        guess = path.parent / "ibug_to_sfm.txt"
        landmarks = guess if guess.is_file() else None
    lm = read_ibug_mapping(landmarks) if landmarks is not None else {}
    lm = {k: v for k, v in lm.items() if v < n}  # mappings may name vertices of larger resolutions
    lm_array = np.array(sorted(lm.items()), dtype=np.int32).reshape(-1, 2)
    return MorphableModel(
        name=path.stem, shape_mean=mean.reshape(n, 3), shape_basis=basis, shape_variance=ev,
        triangles=tri, uv=uv, region_map=region_map_from_landmarks(uv, tri, lm, region_map_shape),
        landmarks=lm_array, expression_basis=expr, expression_names=names, **color,
        metadata={"source": str(path), "format": "eos-bin", "units": "mm"},
    )
