"""The albedo as a variable of the refinement by differentiable rendering
(:mod:`mifaces.refine.reflectance`): a smooth multiplicative correction of
the texture-space albedo on a coarse grid."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


class AlbedoCorrection:
    """The albedo as a variable: the texture-space albedo ``base`` (R, R, 3)
    times exp(c), c a correction grid of (R/cell)² RGB cells interpolated
    bilinearly (cell centres at their texels' centre), capped at 1.

    Per-texel detail stays the texture-space fit's (which it has from every
    sample of the texel); the correction takes out the smooth biases the
    texture-space reading leaves (light interreflected in cavities, the blur of
    thin regions, the albedo that absorbs a mis-fitted highlight), from many
    pixels per cell rather than the few of a texel.
    """

    def __init__(self, base: np.ndarray, cell: int):
        r = base.shape[0]
        self.shape = base.shape
        self.cells = max(1, -(-r // cell))
        self.base = mi.Float(np.ascontiguousarray(base, np.float32).ravel())
        x = (np.arange(r) + 0.5) * self.cells / r - 0.5  # texel centres in cell coordinates
        lo = np.clip(np.floor(x).astype(np.int64), 0, self.cells - 1)
        hi = np.clip(lo + 1, 0, self.cells - 1)
        t = np.clip(x - lo, 0.0, 1.0)
        self.taps = []
        for rows, wr in ((lo, 1 - t), (hi, t)):
            for cols, wc in ((lo, 1 - t), (hi, t)):
                index = ((rows[:, None, None] * self.cells + cols[None, :, None]) * 3 + np.arange(3)).ravel()
                weight = np.broadcast_to((wr[:, None] * wc[None, :])[..., None], (r, r, 3)).ravel()
                self.taps.append((mi.UInt32(index.astype(np.uint32)), mi.Float(weight.astype(np.float32))))

    def start(self) -> np.ndarray:
        """The correction that leaves the albedo as it is: zeros (cells, cells, 3)."""
        return np.zeros((self.cells, self.cells, 3), np.float32)

    def albedo(self, correction) -> mi.TensorXf:
        """The albedo texture (R, R, 3) of ``correction`` (a TensorXf of
        :meth:`start`'s shape), differentiable."""
        c = correction.array
        log_scale = sum(w * dr.gather(mi.Float, c, i) for i, w in self.taps)
        return mi.TensorXf(dr.minimum(self.base * dr.exp(log_scale), 1.0), self.shape)
