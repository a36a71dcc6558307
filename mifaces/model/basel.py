"""The Basel Face Models: 2009 (``.mat``) and 2017/2019 (``.h5``).

**BFM 2009** (Paysan et al., AVSS 2009), ``01_MorphableModel.mat`` read with
:func:`scipy.io.loadmat`: ``shapeMU`` (3N, 1) in micrometres, ``shapePC``
(3N, K) orthonormal, ``shapeEV`` (K, 1) *standard deviations*, ``texMU``
(3N, 1) in [0, 255], ``texPC`` (3N, K_t), ``texEV`` (K_t, 1) standard
deviations, ``tl`` (T, 3) 1-based triangles. Positions become millimetres,
colours [0, 1], standard deviations variances.

**BFM 2017/2019** (Gerig et al., FG 2018), statismo HDF5 read with h5py:
``shape/model/{mean (3N,), pcaBasis (3N, K), pcaVariance (K,)}``,
``shape/representer/{points (3, N), cells (3, T)}``, likewise
``color/model/...`` (colours in [0, 1]) and ``expression/model/...``
(``mean``, added to the neutral shape, ``pcaBasis``, ``pcaVariance``).
Millimetres.

Neither ships texture coordinates; mifaces gives them the cylindrical
``(h, phi)`` parameterization of the paper (section 4.1), computed from the
mean shape about a vertical axis behind the face
(:func:`cylindrical_uv`). Neither ships iBUG landmarks: pass
``landmarks={ibug: vertex}`` to get them, and with them a region map beyond
``skin``. Triangles are re-oriented, if needed, to face outwards.
"""

from __future__ import annotations

import os

import numpy as np
import scipy.io

from .geometry import face_normals
from .loaders import ModelFormatError, check_shape, existing, require
from .morphable import MorphableModel
from .regions import region_map_from_landmarks

REGION_MAP_SHAPE = (512, 512)


def cylindrical_uv(vertices: np.ndarray, margin: float = 0.02) -> np.ndarray:
    """Cylindrical texture coordinates ``(u, v) = (phi, h)`` of a face, normalised to [0, 1].

    The axis is vertical (y), through the mean x of the face, at a depth of
    0.6 times the face's width behind its most forward point, so that the
    face is a graph over the cylinder; ``u`` grows with azimuth towards +x,
    ``v`` with decreasing height (``v = 0`` the top), each mapped to
    ``[margin, 1 - margin]``.
    """
    v = np.asarray(vertices, dtype=np.float64)
    width = np.ptp(v[:, 0])
    axis_x, axis_z = v[:, 0].mean(), v[:, 2].max() - 0.6 * width
    phi = np.arctan2(v[:, 0] - axis_x, v[:, 2] - axis_z)
    h = v[:, 1]
    u = (phi - phi.min()) / max(np.ptp(phi), 1e-12)
    w = (h.max() - h) / max(np.ptp(h), 1e-12)
    return (margin + (1 - 2 * margin) * np.stack([u, w], axis=1)).astype(np.float32)


def _orient_outwards(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Flip the winding if the area-weighted normals point towards the axis behind the face."""
    n = face_normals(vertices, triangles, normalize=False)
    centre = vertices[triangles].mean(axis=1)
    axis = np.array([vertices[:, 0].mean(), 0.0, vertices[:, 2].max() - 0.6 * np.ptp(vertices[:, 0])])
    radial = centre - axis
    radial[:, 1] = 0.0
    if np.sum(n * radial) < 0:
        return triangles[:, [0, 2, 1]]
    return triangles


def _assemble(path, mean, basis, var, tri, color, expression, landmarks, region_map_shape, fmt, scale=1.0):
    n = len(mean)
    if tri.size and (tri.min() < 0 or tri.max() >= n):
        raise ModelFormatError(f"{path}: triangles index vertices outside [0, {n})")
    tri = _orient_outwards(mean, tri.astype(np.int64)).astype(np.int32)
    uv = cylindrical_uv(mean)
    lm = dict(landmarks or {})
    bad = [k for k, v in lm.items() if not 0 <= int(v) < n]
    if bad:
        raise ValueError(f"landmarks {bad} name vertices outside [0, {n})")
    return MorphableModel(
        name=path.stem, shape_mean=mean, shape_basis=basis, shape_variance=var, triangles=tri, uv=uv,
        region_map=region_map_from_landmarks(uv, tri, lm, region_map_shape),
        landmarks=np.array(sorted(lm.items()), dtype=np.int32).reshape(-1, 2),
        **color, **expression,
        metadata={"source": str(path), "format": fmt, "units": "mm",
                  "parameterization": "cylindrical (h, phi) of the mean shape"},
    )


def load_basel2009(path: str | os.PathLike, landmarks: dict[int, int] | None = None,
                   region_map_shape=REGION_MAP_SHAPE) -> MorphableModel:
    """Load the Basel Face Model 2009 ``.mat`` (layout in the module docstring)."""
    path = existing(path)
    try:
        data = scipy.io.loadmat(str(path))
    except Exception as exc:
        raise ModelFormatError(f"{path}: not a MATLAB .mat file scipy can read ({exc})") from exc
    mu = check_shape(require(data, "shapeMU", path, "mean shape (3N, 1)"), (None, 1), "shapeMU", path)
    if mu.shape[0] % 3:
        raise ModelFormatError(f"{path}: 'shapeMU' has {mu.shape[0]} rows, not a multiple of 3")
    n3 = mu.shape[0]
    pc = check_shape(require(data, "shapePC", path, "shape basis (3N, K)"), (n3, None), "shapePC", path)
    ev = check_shape(require(data, "shapeEV", path, "shape standard deviations (K, 1)"), (pc.shape[1], 1),
                     "shapeEV", path)
    tl = check_shape(require(data, "tl", path, "triangles (T, 3), 1-based"), (None, 3), "tl", path)
    um = 1e-3  # micrometres -> millimetres
    color = {}
    if "texMU" in data:
        tmu = check_shape(data["texMU"], (n3, 1), "texMU", path)
        tpc = check_shape(require(data, "texPC", path, "texture basis (3N, K)"), (n3, None), "texPC", path)
        tev = check_shape(require(data, "texEV", path, "texture standard deviations (K, 1)"), (tpc.shape[1], 1),
                          "texEV", path)
        color = dict(color_mean=tmu.reshape(-1, 3) / 255.0, color_basis=tpc,
                     color_variance=(tev.ravel() / 255.0) ** 2)
    return _assemble(path, mu.reshape(-1, 3).astype(np.float64) * um, pc, (ev.ravel().astype(np.float64) * um) ** 2,
                     tl.astype(np.int64) - 1, color, {}, landmarks, region_map_shape, "basel2009-mat")


def load_basel2017(path: str | os.PathLike, landmarks: dict[int, int] | None = None,
                   region_map_shape=REGION_MAP_SHAPE) -> MorphableModel:
    """Load a Basel Face Model 2017 or 2019 ``.h5`` (layout in the module docstring)."""
    import h5py

    path = existing(path)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ModelFormatError(f"{path}: not an HDF5 file h5py can read ({exc})") from exc
    with f:
        def get(key, what):
            return np.asarray(require(f, key, path, what)[()])

        mean = check_shape(get("shape/model/mean", "mean shape (3N,)"), (None,), "shape/model/mean", path)
        if mean.size % 3:
            raise ModelFormatError(f"{path}: 'shape/model/mean' has {mean.size} values, not a multiple of 3")
        n3 = mean.size
        basis = check_shape(get("shape/model/pcaBasis", "shape basis (3N, K)"), (n3, None),
                            "shape/model/pcaBasis", path)
        var = check_shape(get("shape/model/pcaVariance", "shape variances (K,)"), (basis.shape[1],),
                          "shape/model/pcaVariance", path)
        points = check_shape(get("shape/representer/points", "vertices (3, N)"), (3, n3 // 3),
                             "shape/representer/points", path)
        cells = check_shape(get("shape/representer/cells", "triangles (3, T)"), (3, None),
                            "shape/representer/cells", path)
        del points  # the representer's points are the reference mesh; the model mean is used
        color = {}
        if "color" in f:
            cm = check_shape(get("color/model/mean", "colour mean (3N,)"), (n3,), "color/model/mean", path)
            cb = check_shape(get("color/model/pcaBasis", "colour basis (3N, K)"), (n3, None),
                             "color/model/pcaBasis", path)
            cv = check_shape(get("color/model/pcaVariance", "colour variances (K,)"), (cb.shape[1],),
                             "color/model/pcaVariance", path)
            color = dict(color_mean=cm.reshape(-1, 3), color_basis=cb, color_variance=cv)
        expression = {}
        if "expression" in f:
            em = check_shape(get("expression/model/mean", "expression mean (3N,)"), (n3,),
                             "expression/model/mean", path)
            eb = check_shape(get("expression/model/pcaBasis", "expression basis (3N, E)"), (n3, None),
                             "expression/model/pcaBasis", path)
            ev = check_shape(get("expression/model/pcaVariance", "expression variances (E,)"), (eb.shape[1],),
                             "expression/model/pcaVariance", path)
            mean = mean + em
            expression = dict(expression_basis=eb, expression_variance=ev)
    return _assemble(path, mean.reshape(-1, 3).astype(np.float64), basis, var, cells.T.astype(np.int64),
                     color, expression, landmarks, region_map_shape, "basel-h5")
