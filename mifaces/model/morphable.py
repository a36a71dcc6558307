"""The morphable face model as a value type (paper section 4.1).

A morphable model is a linear space of faces: a shape is ::

    S(alpha, delta) = mean + basis @ (sqrt(variance) * alpha) + E @ (sqrt(expression_variance) * delta)

and a texture (diffuse albedo per vertex, linear RGB in [0, 1]) likewise ::

    T(beta) = color_mean + color_basis @ (sqrt(color_variance) * beta),

with coefficients in units of standard deviations, so that the prior of
Blanz and Vetter (1999, eq. 3) is a standard normal: alpha, beta ~ N(0, I).
The shape and texture bases are orthonormal (PCA); an expression basis may
be a PCA basis too (Basel 2017) or a set of blendshapes with unit variances
(the Surrey Face Model).

Flattened coordinate vectors are ordered ``x0, y0, z0, x1, y1, z1, ...``, so
``basis`` has shape ``(3 N, K)``. Positions are in millimetres, y up, the face
looking along +z; triangles are counter-clockwise seen from outside.

Every vertex also has texture coordinates in the model's common
parameterization, and the model carries its a-priori region map in that
parameterization (:mod:`mifaces.model.regions`) and its iBUG 68-point
landmarks.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import numpy as np

from ..io.atomic import atomic_write
from . import geometry
from .export import export_mesh
from .mesh import mitsuba_mesh
from .regions import REGION_NAMES, lookup, regions_present


def _as(array, dtype, name: str, shape: tuple) -> np.ndarray:
    """Convert and check the shape of a field; ``None`` in ``shape`` matches anything."""
    a = np.ascontiguousarray(array, dtype=dtype)
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{name} must have shape {want}, got {a.shape}")
    return a


@dataclass(frozen=True, eq=False)
class MorphableModel:
    """A morphable model of 3D faces: shape, optional texture and expression, parameterization, regions.

    Attributes
    ----------
    name : str
        Where the model came from (``'builtin'``, a file name).
    shape_mean : (N, 3) float32
        Mean shape in millimetres.
    shape_basis : (3N, K) float32
        Orthonormal principal components of shape.
    shape_variance : (K,) float32
        Variance along each component (mm^2), positive.
    triangles : (T, 3) int32
        Counter-clockwise seen from outside.
    uv : (N, 2) float32
        Texture coordinates of the common parameterization, in [0, 1].
    region_map : (H, W) uint8
        Labels from :data:`mifaces.model.regions.REGIONS` in texture space.
    landmarks : (L, 2) int32
        Rows ``(ibug_index, vertex)``: iBUG 68-point index (1-based) and the
        model vertex (0-based) it sits on.
    color_mean, color_basis, color_variance : optional
        Texture (albedo) model with the structure of the shape model, linear RGB.
    expression_basis : (3N, E) float32, optional
    expression_variance : (E,) float32, optional
    expression_names : tuple of str
    metadata : dict
        Free-form provenance (source, units, citation).
    """

    name: str
    shape_mean: np.ndarray
    shape_basis: np.ndarray
    shape_variance: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray
    region_map: np.ndarray
    landmarks: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int32))
    color_mean: np.ndarray | None = None
    color_basis: np.ndarray | None = None
    color_variance: np.ndarray | None = None
    expression_basis: np.ndarray | None = None
    expression_variance: np.ndarray | None = None
    expression_names: tuple[str, ...] = ()
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        setattr_ = object.__setattr__
        mean = _as(self.shape_mean, np.float32, "shape_mean", (None, 3))
        n = len(mean)
        setattr_(self, "shape_mean", mean)
        basis = _as(self.shape_basis, np.float32, "shape_basis", (3 * n, None))
        setattr_(self, "shape_basis", basis)
        var = _as(self.shape_variance, np.float32, "shape_variance", (basis.shape[1],))
        if np.any(~(var > 0)):
            raise ValueError("shape_variance must be positive")
        setattr_(self, "shape_variance", var)
        tri = _as(self.triangles, np.int32, "triangles", (None, 3))
        if tri.size and (tri.min() < 0 or tri.max() >= n):
            raise ValueError(f"triangles index vertices outside [0, {n})")
        setattr_(self, "triangles", tri)
        uv = _as(self.uv, np.float32, "uv", (n, 2))
        setattr_(self, "uv", uv)
        rmap = _as(self.region_map, np.uint8, "region_map", (None, None))
        if rmap.size and rmap.max() >= len(REGION_NAMES):
            raise ValueError(f"region_map holds labels beyond the vocabulary {REGION_NAMES}")
        setattr_(self, "region_map", rmap)
        lm = _as(self.landmarks, np.int32, "landmarks", (None, 2))
        if lm.size and (lm[:, 1].min() < 0 or lm[:, 1].max() >= n):
            raise ValueError(f"landmarks name vertices outside [0, {n})")
        setattr_(self, "landmarks", lm)
        if self.color_mean is not None:
            cm = _as(self.color_mean, np.float32, "color_mean", (n, 3))
            cb = _as(self.color_basis, np.float32, "color_basis", (3 * n, None))
            cv = _as(self.color_variance, np.float32, "color_variance", (cb.shape[1],))
            if np.any(~(cv > 0)):
                raise ValueError("color_variance must be positive")
            setattr_(self, "color_mean", cm)
            setattr_(self, "color_basis", cb)
            setattr_(self, "color_variance", cv)
        if self.expression_basis is not None:
            eb = _as(self.expression_basis, np.float32, "expression_basis", (3 * n, None))
            ev = self.expression_variance
            ev = np.ones(eb.shape[1], np.float32) if ev is None else ev
            ev = _as(ev, np.float32, "expression_variance", (eb.shape[1],))
            setattr_(self, "expression_basis", eb)
            setattr_(self, "expression_variance", ev)
            names = tuple(str(s) for s in self.expression_names) or tuple(
                f"expression_{i}" for i in range(eb.shape[1]))
            if len(names) != eb.shape[1]:
                raise ValueError(f"expression_names has {len(names)} names for {eb.shape[1]} expressions")
            setattr_(self, "expression_names", names)

    # ---- sizes ----------------------------------------------------------------------------
    @property
    def vertex_count(self) -> int:
        return len(self.shape_mean)

    @property
    def triangle_count(self) -> int:
        return len(self.triangles)

    @property
    def shape_dim(self) -> int:
        """Number of shape coefficients."""
        return self.shape_basis.shape[1]

    @property
    def has_texture(self) -> bool:
        return self.color_mean is not None

    @property
    def color_dim(self) -> int:
        return 0 if self.color_basis is None else self.color_basis.shape[1]

    @property
    def has_expressions(self) -> bool:
        return self.expression_basis is not None

    @property
    def expression_dim(self) -> int:
        return 0 if self.expression_basis is None else self.expression_basis.shape[1]

    @property
    def regions(self) -> list[str]:
        """Names of the regions in the region map (without background)."""
        return regions_present(self.region_map)

    @property
    def ibug_landmarks(self) -> dict[int, int]:
        """iBUG 68-point index (1-based) -> vertex index."""
        return {int(i): int(v) for i, v in self.landmarks}

    # ---- linear model ---------------------------------------------------------------------
    @staticmethod
    def _coefficients(c, k: int, name: str) -> np.ndarray:
        if c is None:
            return np.zeros(k)
        c = np.asarray(c, dtype=np.float64).ravel()
        if len(c) > k:
            raise ValueError(f"{name} has {len(c)} coefficients, the model has {k}")
        return np.pad(c, (0, k - len(c)))

    def shape(self, coefficients=None, expression=None) -> np.ndarray:
        """Vertex positions (N, 3) for shape ``coefficients`` (alpha) and ``expression`` (delta).

        Both are in standard deviations of the prior; shorter vectors are
        padded with zeros (the leading components), ``None`` means zeros.
        """
        a = self._coefficients(coefficients, self.shape_dim, "coefficients")
        v = self.shape_mean.astype(np.float64).ravel() + self.shape_basis @ (np.sqrt(self.shape_variance) * a)
        if expression is not None:
            if not self.has_expressions:
                raise ValueError(f"model {self.name!r} has no expression basis")
            d = self._coefficients(expression, self.expression_dim, "expression")
            v = v + self.expression_basis @ (np.sqrt(self.expression_variance) * d)
        return v.reshape(-1, 3).astype(np.float32)

    def texture(self, coefficients=None) -> np.ndarray:
        """Per-vertex albedo (N, 3), linear RGB, for texture ``coefficients`` (beta)."""
        if not self.has_texture:
            raise ValueError(f"model {self.name!r} has no texture (colour) model")
        b = self._coefficients(coefficients, self.color_dim, "coefficients")
        c = self.color_mean.astype(np.float64).ravel() + self.color_basis @ (np.sqrt(self.color_variance) * b)
        return c.reshape(-1, 3).astype(np.float32)

    def project(self, vertices: np.ndarray) -> np.ndarray:
        """Shape coefficients of the model face closest to ``vertices`` (N, 3) in least squares."""
        v = _as(vertices, np.float64, "vertices", (self.vertex_count, 3)).ravel() - self.shape_mean.ravel()
        return (self.shape_basis.T @ v) / np.sqrt(self.shape_variance)

    @staticmethod
    def prior(coefficients) -> float:
        """Squared Mahalanobis distance of a coefficient vector from the mean, ``sum(c**2)``.

        Coefficients are in standard deviations, so this is
        ``-2 log p(c) + const`` under the model's Gaussian prior (Blanz and
        Vetter 1999, eq. 3), the E_P term of the fit (paper section 4.2).
        Accepts numpy arrays and Dr.Jit arrays (then it stays differentiable).
        """
        if dr.is_array_v(coefficients):
            return dr.sum(dr.square(coefficients))
        c = np.asarray(coefficients, dtype=np.float64)
        return float(np.sum(c * c))

    def random_coefficients(self, rng=None) -> dict[str, np.ndarray]:
        """Draw identity coefficients from the prior: ``{'shape', 'color'}``, N(0, I) each.

        ``rng`` is a seed or a :class:`numpy.random.Generator`; ``'color'`` is
        left out for models without texture. Expressions are not drawn (a
        neutral face).
        """
        rng = np.random.default_rng(rng)
        out = {"shape": rng.standard_normal(self.shape_dim)}
        if self.has_texture:
            out["color"] = rng.standard_normal(self.color_dim)
        return out

    def random_face(self, rng=None) -> tuple[np.ndarray, np.ndarray | None]:
        """A random face from the prior: ``(vertices (N, 3), albedo (N, 3) or None)``."""
        c = self.random_coefficients(rng)
        return self.shape(c["shape"]), (self.texture(c["color"]) if "color" in c else None)

    def truncated(self, shape_modes: int | None) -> MorphableModel:
        """The same model with only its leading ``shape_modes`` identity modes (all for None, or
        when the model has no more). The result is memoised per model and count, so fits that
        cache per-model arrays see one object. ``metadata['shape_modes_of']`` records the count
        of the full model."""
        k = self.shape_dim if shape_modes is None else int(shape_modes)
        if k < 1:
            raise ValueError(f"shape_modes must be at least 1, got {shape_modes}")
        if k >= self.shape_dim:
            return self
        memo = self.__dict__.setdefault("_truncated", {})
        if k not in memo:
            memo[k] = dataclasses.replace(
                self, shape_basis=self.shape_basis[:, :k], shape_variance=self.shape_variance[:k],
                metadata=dict(self.metadata, shape_modes_of=self.metadata.get("shape_modes_of", self.shape_dim),
                              fit_shape_modes=k))
        return memo[k]

    @property
    def fit_shape_modes(self) -> int:
        """Identity modes a shape fit uses by default: ``metadata['fit_shape_modes']`` where the
        model names a number (the built-in model does), else all."""
        return int(min(self.metadata.get("fit_shape_modes", self.shape_dim), self.shape_dim))

    # ---- geometry -------------------------------------------------------------------------
    def vertex_normals(self, vertices: np.ndarray | None = None) -> np.ndarray:
        """Unit outward vertex normals (N, 3) of ``vertices`` (default: the mean shape)."""
        return geometry.vertex_normals(self.shape_mean if vertices is None else vertices, self.triangles)

    def tangent_frames(self, vertices: np.ndarray | None = None):
        """``(tangent, bitangent, normal)``, each (N, 3): per-vertex shading frames along ``u``."""
        return geometry.tangent_frames(self.shape_mean if vertices is None else vertices, self.triangles, self.uv)

    def landmark_positions(self, vertices: np.ndarray | None = None) -> dict[int, np.ndarray]:
        """iBUG index -> position (3,) of that landmark on ``vertices`` (default: mean)."""
        v = self.shape_mean if vertices is None else np.asarray(vertices)
        return {int(i): v[int(k)] for i, k in self.landmarks}

    def vertex_regions(self) -> np.ndarray:
        """Region label (N,) of every vertex, looked up in the region map at its uv."""
        return lookup(self.region_map, self.uv)

    # ---- Mitsuba and files ------------------------------------------------------------------
    def mitsuba_mesh(self, coefficients=None, expression=None, color=None, bsdf=None, name: str = "face"):
        """A Mitsuba mesh of one face, built in memory (see :func:`mifaces.model.mesh.mitsuba_mesh`)."""
        albedo = self.texture(color) if (self.has_texture and color is not False) else None
        return mitsuba_mesh(self.shape(coefficients, expression), self.triangles, self.uv,
                            albedo=albedo, bsdf=bsdf, name=name)

    def export(self, path: str | os.PathLike, coefficients=None, expression=None, color=None) -> Path:
        """Write one face as PLY or OBJ with texture coordinates (and vertex colours); see
        :func:`mifaces.model.export.export_mesh`."""
        albedo = self.texture(color) if (self.has_texture and color is not False) else None
        return export_mesh(path, self.shape(coefficients, expression), self.triangles, self.uv, albedo)

    def save(self, path: str | os.PathLike) -> Path:
        """Save as a mifaces model ``.npz`` (uncompressed, written atomically)."""
        arrays = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            if f.name == "metadata":
                value = json.dumps(value)
            elif f.name == "expression_names":
                value = np.array(value, dtype=str)
            arrays[f.name] = value
        arrays["mifaces_model_format"] = np.int32(1)
        path = Path(path)
        with atomic_write(path) as f:
            np.savez(f, **arrays)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> MorphableModel:
        """Load a model written by :meth:`save`."""
        path = Path(path)
        with np.load(path, allow_pickle=False) as data:
            if "mifaces_model_format" not in data:
                raise ValueError(f"{path} is not a mifaces model file (no 'mifaces_model_format' key)")
            kw = {f.name: data[f.name] for f in dataclasses.fields(cls) if f.name in data}
        kw["name"] = str(kw.get("name", path.stem))
        kw["metadata"] = json.loads(str(kw["metadata"])) if "metadata" in kw else {}
        kw["expression_names"] = tuple(str(s) for s in kw.get("expression_names", ()))
        return cls(**kw)

    def __repr__(self) -> str:
        parts = [f"{self.vertex_count} vertices", f"{self.triangle_count} triangles", f"{self.shape_dim} shape modes"]
        if self.has_texture:
            parts.append(f"{self.color_dim} texture modes")
        if self.has_expressions:
            parts.append(f"{self.expression_dim} expressions")
        parts.append(f"{len(self.landmarks)} landmarks")
        parts.append("regions " + ", ".join(self.regions))
        return f"MorphableModel({self.name!r}: " + "; ".join(parts) + ")"
