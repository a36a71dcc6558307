"""The morphable model cut to one sample set of a shape fit, on the Dr.Jit side (paper sec. 4.2).

E's image term (:class:`~mifaces.shape.energy.Energy`) reads the model at a few thousand sample
vertices, drawn anew at each level; its other terms at the feature points and the ends of the
metric distances. :class:`SampledModel` holds the rows of the model those vertices and the samples'
one-rings need -- the mean shape and the shape and expression bases scaled by their standard
deviations (coefficients in standard deviations), the rings' triangles, the samples' colour model
-- and makes the face of parameters theta from them: the morphable model's positions (Blanz and
Vetter 1999, eq. 1: mean plus basis times coefficients; eq. 2 for the colour), those of the identity
shape without expression, the samples' normals and their albedo. Model space, mm.
"""

from __future__ import annotations

import copy

import drjit as dr
import mitsuba as mi
import numpy as np

from ..runtime.arrays import device_array

#: The needed vertices' rows on the Dr.Jit side are padded to a multiple of this.
ROWS = 1024
#: The name of the samples' own rows in :attr:`SampledModel.dr_local`.
SAMPLES = "samples"


def lanes(theta, i: int, width: int):
    """``theta[i]`` on ``width`` lanes: its gradient is a scatter-add in the kernel that uses it,
    not a reduction of its own as a broadcast single value's would be."""
    return dr.gather(mi.Float, theta, dr.full(mi.UInt32, i, width))


class SampledModel:
    """The rows of a morphable model that one sample set needs, on the Dr.Jit side.

    Parameters
    ----------
    model : MorphableModel
    adjacency : (N, D) int array
        The model's vertex-triangle adjacency (:func:`~mifaces.shape.layout.adjacency`).
    samples : (S,) int array
        The sample vertices.
    vertices : dict
        The other vertices read, by name: int arrays (the feature points, the ends of the metric
        distances, ...). Their rows are kept as well, and :attr:`dr_local` says where.

    Attributes
    ----------
    n_samples, degree, n_modes : int
        The samples, the most triangles around a vertex, the columns of the basis (shape and
        expression modes).
    dr_local : dict
        Name -> UInt32, the rows of the vertices of that name (:data:`SAMPLES`: the samples') in
        :meth:`positions`; a name whose vertices are none has no entry (an empty array cannot enter
        a frozen function).

    Notes
    -----
    The rows are padded with zeros to a multiple of :data:`ROWS`: the backward kernels' scatter into
    the positions' gradient has their number as a literal, the same for most sample draws. The
    Dr.Jit arrays are the attributes named ``dr_*`` (:meth:`arrays`): a frozen evaluation takes them
    as its input and reads them through :meth:`bound`.
    """

    def __init__(self, model, adjacency: np.ndarray, samples: np.ndarray, vertices: dict):
        self.model = model
        adj = adjacency[samples]  # (S, D)
        valid = adj >= 0
        ring_tris = model.triangles[np.where(valid, adj, 0)]  # (S, D, 3)
        needed = np.unique(np.concatenate([samples, ring_tris[valid].ravel()]
                                          + [np.asarray(v, np.int64).ravel() for v in vertices.values()]))
        local = np.full(model.vertex_count, -1, np.int64)
        local[needed] = np.arange(len(needed))
        self.n_samples, self.degree = len(samples), adj.shape[1]
        rows = (3 * needed[:, None] + np.arange(3)).ravel()
        sigma = np.sqrt(model.shape_variance).astype(np.float64)
        columns = [model.shape_basis[rows] * sigma]
        if model.has_expressions:
            columns.append(model.expression_basis[rows] * np.sqrt(model.expression_variance))
        pad = (-len(needed)) % ROWS
        basis = np.pad(np.concatenate(columns, axis=1).astype(np.float32), ((0, 3 * pad), (0, 0)))
        self.n_modes = basis.shape[1]
        self.dr_mean = device_array(np.float32, np.pad(model.shape_mean[needed], ((0, pad), (0, 0))))
        columns = np.ascontiguousarray(basis.T)  # one contiguous row per mode: no strided copies
        self.dr_basis = [device_array(np.float32, columns[k]) for k in range(self.n_modes)]
        self.dr_local = {name: device_array(np.uint32, local[np.asarray(v, np.int64)])
                         for name, v in {SAMPLES: samples, **vertices}.items() if len(v)}
        corners = np.where(valid[..., None], local[ring_tris], 0).astype(np.uint32)  # (S, D, 3)
        corners = np.ascontiguousarray(corners.transpose(1, 2, 0))  # (D, 3, S): contiguous rows
        self.dr_corners = [[device_array(np.uint32, corners[j, c]) for c in range(3)]
                           for j in range(self.degree)]
        self.dr_slot_valid = [device_array(np.float32, valid[:, j]) for j in range(self.degree)]
        if model.has_texture:
            crow = (3 * samples[:, None] + np.arange(3)).ravel()
            cbasis = (model.color_basis[crow] * np.sqrt(model.color_variance)).astype(np.float32).reshape(
                len(samples), 3, -1)
            cmean = model.color_mean[samples].astype(np.float32)
            self.dr_color_mean = [device_array(np.float32, cmean[:, c]) for c in range(3)]
            self.dr_color_basis = [[device_array(np.float32, cbasis[:, c, k]) for c in range(3)]
                                   for k in range(model.color_dim)]
        self.dr_sample_vertex = device_array(np.uint32, samples)
        self.dr_inv_samples = dr.opaque(mi.Float, 1.0 / len(samples))

    def arrays(self) -> dict:
        """The Dr.Jit arrays (the attributes named ``dr_*``)."""
        return {k: v for k, v in vars(self).items() if k.startswith("dr_")}

    def bound(self, arrays: dict) -> SampledModel:
        """This sample set reading ``arrays`` (:meth:`arrays`' layout) in place of its own."""
        sampled = copy.copy(self)
        vars(sampled).update(arrays)
        return sampled

    def positions(self, theta, start: int):
        """Positions of the needed vertices (flat Float ``x0, y0, z0, ...``) for the shape
        coefficients at ``start`` of ``theta``, the expression coefficients after them (as the
        basis' columns follow each other); evaluated, as the samples, their rings and the other
        vertices gather from it."""
        p = self.dr_mean
        width = dr.width(self.dr_mean)
        for k in range(self.n_modes):
            p = p + self.dr_basis[k] * lanes(theta, start + k, width)
        dr.eval(p)
        return p

    def identity_positions(self, theta, start: int, name: str):
        """Positions of the vertices ``name`` (:attr:`dr_local`) on the identity shape of the shape
        coefficients at ``start`` of ``theta`` (without expression), as a Vector3f."""
        idx = self.dr_local[name]
        width = dr.width(idx)
        p = []
        for c in range(3):
            x = dr.gather(mi.Float, self.dr_mean, 3 * idx + c)
            for k in range(self.model.shape_dim):
                x = x + dr.gather(mi.Float, self.dr_basis[k], 3 * idx + c) * lanes(theta, start + k, width)
            p.append(x)
        return mi.Vector3f(*p)

    def normals(self, pos):
        """Unit normals of the samples from their one-rings (area weighted) at positions ``pos``
        (:meth:`positions`)."""
        n = mi.Vector3f(0.0)
        for j in range(self.degree):
            a, b, c = (dr.gather(mi.Vector3f, pos, self.dr_corners[j][k]) for k in range(3))
            n = n + dr.cross(b - a, c - a) * self.dr_slot_valid[j]
        return dr.normalize(n)

    def albedo(self, theta, start: int):
        """The samples' albedo (Vector3f): the colour model's for the texture coefficients at
        ``start`` of ``theta``, or, for a model without one, the per-vertex albedo, three values a
        vertex from ``start``."""
        width = self.n_samples
        if self.model.has_texture:
            alb = list(self.dr_color_mean)
            for k in range(self.model.color_dim):
                beta = lanes(theta, start + k, width)
                alb = [alb[c] + self.dr_color_basis[k][c] * beta for c in range(3)]
            return mi.Vector3f(*alb)
        return mi.Vector3f(*[dr.gather(mi.Float, theta, 3 * self.dr_sample_vertex + (start + k)) for k in range(3)])
