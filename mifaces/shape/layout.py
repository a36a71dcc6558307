"""The shape fit's parameter vector (named blocks and their units) and the
mesh's vertex-triangle adjacency."""

from __future__ import annotations

import numpy as np


class Layout:
    """Named blocks of the parameter vector and their natural units (Adam works on theta / unit)."""

    IMAGE_BLOCK = (("light_angles", 2, 0.15), ("light_color", 3, 0.15), ("ambient", 3, 0.1),
                   ("specular", 1, 0.05), ("contrast", 1, 0.1), ("gain", 3, 0.1), ("offset", 3, 0.03))

    def __init__(self, model, images: list[str]):
        self.slices, units = {}, []

        def add(name, n, unit):
            self.slices[name] = slice(len(units), len(units) + n)
            units.extend([unit] * n)

        add("rotation", 3, 0.05)
        add("translation", 3, 5.0)
        add("log_focal", 1, 0.02)
        for image in images:
            for name, n, unit in self.IMAGE_BLOCK:
                add(f"{image}.{name}", n, unit)
        add("shape", model.shape_dim, 1.0)
        add("expression", model.expression_dim, 1.0)
        if model.has_texture:
            add("color", model.color_dim, 0.3)
        else:
            add("albedo", 3 * model.vertex_count, 0.03)
        self.units = np.array(units, np.float64)
        self.size = len(units)

    def __getitem__(self, name):
        return self.slices[name]




def adjacency(triangles: np.ndarray, vertex_count: int) -> np.ndarray:
    """(N, D) triangle indices adjacent to each vertex, padded with -1."""
    t = np.asarray(triangles, np.int64)
    corner_vertex = t.ravel()
    corner_triangle = np.repeat(np.arange(len(t)), 3)
    order = np.argsort(corner_vertex, kind="stable")
    cv, ct = corner_vertex[order], corner_triangle[order]
    counts = np.bincount(cv, minlength=vertex_count)
    d = max(int(counts.max()), 1)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(len(cv)) - starts[cv]
    out = np.full((vertex_count, d), -1, np.int64)
    out[cv, slot] = ct
    return out
