"""Mitsuba meshes of model faces, built in memory and differentiable in the shape coefficients.

:func:`mitsuba_mesh` turns arrays (positions, triangles, uv, albedo) into a
``mi.Mesh`` without a file round trip. :class:`FaceMesh` keeps the model's
mean and scaled basis as Dr.Jit arrays and writes
``mean + basis @ (sqrt(variance) * alpha)`` into the mesh's
``vertex_positions``, so that a loss on a render (or on the vertices) has
gradients with respect to the coefficients alpha: the shape fit of paper
section 4.2.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


def mitsuba_mesh(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray | None = None,
                 normals: np.ndarray | None = None, albedo: np.ndarray | None = None, bsdf=None,
                 name: str = "face", interior=None) -> mi.Mesh:
    """Build a ``mi.Mesh`` from arrays, in the current variant.

    Parameters
    ----------
    vertices : (N, 3) array
        Positions (model space, mm).
    triangles : (T, 3) int array
        Counter-clockwise seen from outside.
    uv : (N, 2) array, optional
        Texture coordinates (Mitsuba's convention, ``v = 0`` the top row).
    normals : (N, 3) array, optional
        Vertex normals; computed by Mitsuba (area-and-angle weighted) if omitted.
    albedo : (N, 3) array, optional
        Per-vertex linear RGB, stored as the mesh attribute ``vertex_color``
        (read it with a ``mesh_attribute`` texture; when ``bsdf`` is None the
        mesh gets a ``diffuse`` BSDF with that reflectance).
    bsdf : mi.BSDF or dict, optional
        The mesh's BSDF; default ``diffuse``.
    interior : mi.Medium or dict, optional
        The medium on the mesh's inner side (opposite its normals), for
        Mitsuba's volumetric path tracer.

    Returns
    -------
    mi.Mesh
    """
    vertices = np.asarray(vertices, dtype=np.float32)
    triangles = np.asarray(triangles, dtype=np.uint32)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must have shape (N, 3), got {vertices.shape}")
    if triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f"triangles must have shape (T, 3), got {triangles.shape}")
    props = mi.Properties()
    if bsdf is None:
        bsdf = {"type": "diffuse"}
        if albedo is not None:
            bsdf["reflectance"] = {"type": "mesh_attribute", "name": "vertex_color"}
    props["bsdf"] = mi.load_dict(bsdf) if isinstance(bsdf, dict) else bsdf
    if interior is not None:
        props["interior"] = mi.load_dict(interior) if isinstance(interior, dict) else interior
    mesh = mi.Mesh(name, len(vertices), len(triangles), props,
                   has_vertex_normals=True, has_vertex_texcoords=uv is not None)
    params = mi.traverse(mesh)
    # The mesh's own buffer types: mi.Float/UInt32 in JIT variants, dynamic
    # arrays in scalar ones.
    Float, UInt = type(params["vertex_positions"]), type(params["faces"])
    params["vertex_positions"] = Float(vertices.ravel())
    params["faces"] = UInt(triangles.ravel())
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float32)
        if uv.shape != (len(vertices), 2):
            raise ValueError(f"uv must have shape ({len(vertices)}, 2), got {uv.shape}")
        params["vertex_texcoords"] = Float(uv.ravel())
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float32)
        if normals.shape != vertices.shape:
            raise ValueError(f"normals must have shape {vertices.shape}, got {normals.shape}")
        params["vertex_normals"] = Float(normals.ravel())
        params.update()
    else:
        params.update()
        mesh.recompute_vertex_normals()
    if albedo is not None:
        albedo = np.asarray(albedo, dtype=np.float32)
        if albedo.shape != vertices.shape:
            raise ValueError(f"albedo must have shape {vertices.shape}, got {albedo.shape}")
        mesh.add_attribute("vertex_color", 3, Float(np.clip(albedo, 0.0, 1.0).ravel()))
    return mesh


def _linear_combination(mean, basis, weights, k: int, n: int):
    """``mean + basis @ weights`` on the Dr.Jit side: ``basis`` is the (n, k)
    matrix flattened row-major, ``weights`` a Float of length k."""
    if k == 0:
        return mean
    w = dr.gather(type(weights), weights, dr.arange(mi.UInt32, n * k) % k)
    return mean + dr.block_sum(basis * w, k)


class FaceMesh:
    """A Mitsuba mesh whose vertex positions follow a model's shape coefficients.

    The mean, the basis scaled by the standard deviations and the expression
    basis live on the Dr.Jit side; :meth:`vertex_positions` evaluates
    ``mean + B diag(sigma) alpha (+ E diag(sigma_e) delta)`` with one
    gather and one block sum (no Python loop over modes or vertices), and
    :meth:`update` writes the result into the mesh. In an AD variant, with
    gradients enabled on ``alpha``, the gradient of any loss on the mesh's
    vertices (or on a differentiable render of the scene holding it) flows
    back to ``alpha``.

    Parameters
    ----------
    model : MorphableModel
    coefficients, expression : array, optional
        Initial coefficients.
    modes : int, optional
        Use only the leading ``modes`` shape components (faster fits).
    bsdf : optional
        As in :func:`mitsuba_mesh`.
    """

    def __init__(self, model, coefficients=None, expression=None, modes: int | None = None, bsdf=None,
                 name: str = "face", color=None):
        if not dr.is_jit_v(mi.Float):
            raise RuntimeError(f"FaceMesh needs a vectorised Mitsuba variant (llvm_ad_rgb, cuda_ad_rgb), "
                               f"not {mi.variant()!r}; switch with mifaces.set_variant()")
        self.model = model
        self.modes = model.shape_dim if modes is None else int(min(modes, model.shape_dim))
        n = 3 * model.vertex_count
        self._n = n
        sigma = np.sqrt(model.shape_variance[: self.modes]).astype(np.float32)
        self._mean = mi.Float(model.shape_mean.ravel())
        self._basis = mi.Float((model.shape_basis[:, : self.modes] * sigma).ravel())
        if model.has_expressions:
            es = np.sqrt(model.expression_variance).astype(np.float32)
            self._expr = mi.Float((model.expression_basis * es).ravel())
        else:
            self._expr = None
        albedo = model.texture(color) if model.has_texture and color is not False else None
        c = self._np(coefficients)
        self.mesh = mitsuba_mesh(model.shape(None if c is None else c[: self.modes], self._np(expression)),
                                 model.triangles, model.uv, albedo=albedo, bsdf=bsdf, name=name)
        self.params = mi.traverse(self.mesh)

    @staticmethod
    def _np(c):
        return None if c is None else np.asarray(c, dtype=np.float64)

    def _weights(self, c, k: int, what: str):
        if c is None:
            return mi.Float(np.zeros(k, np.float32))
        if not isinstance(c, mi.Float):
            c = mi.Float(np.asarray(c, dtype=np.float32).ravel())
        if dr.width(c) != k:
            raise ValueError(f"{what} must have {k} entries, got {dr.width(c)}")
        return c

    def vertex_positions(self, coefficients=None, expression=None) -> mi.Float:
        """Flattened positions ``x0, y0, z0, ...`` (Dr.Jit Float, differentiable)
        for shape ``coefficients`` (``modes`` entries) and ``expression``."""
        a = self._weights(coefficients, self.modes, "coefficients")
        p = _linear_combination(self._mean, self._basis, a, self.modes, self._n)
        if expression is not None:
            if self._expr is None:
                raise ValueError(f"model {self.model.name!r} has no expression basis")
            d = self._weights(expression, self.model.expression_dim, "expression")
            p = _linear_combination(p, self._expr, d, self.model.expression_dim, self._n)
        return p

    def update(self, coefficients=None, expression=None) -> mi.Float:
        """Write the positions for these coefficients into the mesh (normals are
        recomputed by Mitsuba); returns the positions."""
        p = self.vertex_positions(coefficients, expression)
        self.params["vertex_positions"] = p
        self.params.update()
        return p
