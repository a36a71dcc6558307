"""An estimated environment map as a variable of the refinement (:mod:`mifaces.refine.reflectance`):
its log radiance per texel and channel, the mean held at its start's (the overall scale belongs to
the albedo), with the smoothness prior of the map's estimate
(:func:`mifaces.reflectance.environment.neighbour_pairs`), and the map laid out as Mitsuba's
``envmap`` stores it."""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..reflectance.environment import neighbour_pairs

#: Radiance an estimated map's texel is floored at before its logarithm is taken, relative to the map's mean
#: (a texel the estimate left black can still brighten, and the smoothness prior stays finite).
ENVMAP_FLOOR = 1e-2


def channel_pairs(shape) -> list:
    """Flat index pairs (UInt32, UInt32) of each (H, W, 3) map's texel and channel with the
    neighbours of :func:`~mifaces.reflectance.environment.neighbour_pairs`: the right neighbours,
    then those below (the prior averages each group)."""
    h, w, c = shape
    pairs = neighbour_pairs(w, h)[:, :, None] * c + np.arange(c)  # (P, 2, channel)
    return [(mi.UInt32(group[:, 0].ravel().astype(np.uint32)), mi.UInt32(group[:, 1].ravel().astype(np.uint32)))
            for group in (pairs[:w * h], pairs[w * h:])]


def padded_index(shape) -> mi.UInt32:
    """The flat index into an (H, W, 3) map of each element of :func:`padded_envmap`'s (H, W + 2, 3)."""
    h, w, c = shape
    rows, cols, chans = np.meshgrid(np.arange(h), (np.arange(w + 2) - 1) % w, np.arange(c), indexing="ij")
    return mi.UInt32(((rows * w + cols) * c + chans).ravel().astype(np.uint32))


def padded_envmap(envmap: mi.TensorXf, index: mi.UInt32 | None = None) -> mi.TensorXf:
    """An (H, W, 3) map as Mitsuba's ``envmap`` stores its ``data``: (H, W + 2, 3), the last column
    before the first and the first after the last (it wraps round in azimuth). ``index``:
    :func:`padded_index` of its shape, where it was built once."""
    h, w, c = envmap.shape
    index = padded_index(envmap.shape) if index is None else index
    return mi.TensorXf(dr.gather(mi.Float, envmap.array, index), (h, w + 2, c))


@dataclass(frozen=True)
class EnvironmentVariable:
    """An estimated map the refinement fits: its shape, its start's mean log radiance (held), and
    the index arrays of its smoothness prior (:func:`channel_pairs`) and of Mitsuba's padded
    layout (:func:`padded_index`), built once."""

    shape: tuple
    mean_log: float
    pairs: list
    padded: object

    @staticmethod
    def start(envmap: np.ndarray) -> np.ndarray:
        """The variable's start: the log of the (H, W, 3) ``envmap``, each texel floored at
        :data:`ENVMAP_FLOOR` times the map's mean (float64)."""
        envmap = np.asarray(envmap, np.float64)
        return np.log(np.maximum(envmap, ENVMAP_FLOOR * max(float(envmap.mean()), 1e-30)))

    @classmethod
    def of(cls, log: np.ndarray) -> "EnvironmentVariable":
        """The variable whose start is ``log`` (:meth:`start`)."""
        return cls(log.shape, float(log.mean()), channel_pairs(log.shape), padded_index(log.shape))

    def radiance(self, x) -> mi.TensorXf:
        """The map (H, W, 3) at log radiance ``x`` as a differentiable TensorXf: exp(x), its mean log
        held at the start's."""
        return mi.TensorXf(dr.exp(x.array - dr.mean(x.array) + self.mean_log), self.shape)


__all__ = ["ENVMAP_FLOOR", "EnvironmentVariable", "channel_pairs", "padded_envmap", "padded_index"]
