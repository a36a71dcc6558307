"""The albedo offsets' share of a region fit's uncertainty: per cluster, the sums over its texels
with which the jackknife and the sandwich re-estimate the offsets in every replicate
(:mod:`mifaces.reflectance.fit.uncertainty`, "Albedo offsets")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class OffsetSums:
    """Per cluster g, the sums over its texels that the albedo offsets' share of the
    jackknife and the sandwich needs (module docstring; :func:`offset_sums`).

    Attributes
    ----------
    counts : ndarray (G,)
        N_g, samples.
    cross : ndarray (G, P, P)
        Σ_{t ∈ g} Σ_c S_t,cᵀ B_t,c.
    jsum : ndarray (G, 3, P)
        Σ_{t ∈ g} S_t.
    scaled : ndarray (G, 3, P)
        Σ_{t ∈ g} N_t B_t.
    offsets : ndarray (G, 3)
        Σ_{i ∈ g} o_i.
    """

    counts: np.ndarray
    cross: np.ndarray
    jsum: np.ndarray
    scaled: np.ndarray
    offsets: np.ndarray

    def free(self, free: np.ndarray) -> "OffsetSums":
        """The sums of the free entries ``free`` (P,) only."""
        return OffsetSums(self.counts, self.cross[:, free][:, :, free], self.jsum[:, :, free],
                          self.scaled[:, :, free], self.offsets)


def offset_sums(texel, cluster, groups: int, weight, jsum, shrinkage, offsets) -> OffsetSums:
    """The :class:`OffsetSums` of G = ``groups`` clusters.

    Parameters
    ----------
    texel : ndarray (N,)
        Each sample's texel, numbered 0 … T - 1.
    cluster : ndarray (N,)
        Each sample's cluster, numbered 0 … G - 1; a texel's samples must share one.
    weight : ndarray (T,)
        W_t = Σ_{i ∈ t} 1/σ_i².
    jsum : ndarray (T, 3, P)
        S_t = Σ_{i ∈ t} J_i/σ_i per channel (:meth:`mifaces.reflectance.fit.problem.Problem.texel_sums`).
    shrinkage : ndarray (N, 3)
        λ of each sample's region per channel.
    offsets : ndarray (N, 3)
        o_i.
    """
    texel, cluster = np.asarray(texel, np.int64), np.asarray(cluster, np.int64)
    t = len(weight)
    home = np.zeros(t, np.int64)
    home[texel] = cluster
    if np.any(home[texel] != cluster):
        raise ValueError("the albedo offsets' uncertainty needs every texel's samples in one cluster")
    lam = np.zeros((t, 3))
    lam[texel] = np.asarray(shrinkage, np.float64)
    # the texels sorted by cluster: cluster g's are the rows ends[g]:ends[g + 1]
    order = np.argsort(home, kind="stable")
    ends = np.searchsorted(home[order], np.arange(groups + 1))
    empty = ends[:-1] == ends[1:]
    jsum = np.asarray(jsum, np.float64)[order]
    p = jsum.shape[2]
    inverse = 1.0 / (np.asarray(weight, np.float64)[order, None] + lam[order])  # 1/(W_t + λ_c), (T, 3)
    n_t = np.bincount(texel, minlength=t)[order].astype(np.float64)

    def per_cluster(values):  # (T, ...) in cluster order, summed over each cluster's texels
        sums = np.add.reduceat(values.reshape(t, -1), np.minimum(ends[:-1], t - 1), axis=0)
        sums[empty] = 0.0
        return sums.reshape((groups,) + values.shape[1:])

    # Σ_{t ∈ g} Σ_c S_t,cᵀ B_t,c = VᵀV over the rows V = S_t,c / √(W_t + λ_c) of cluster g's texels
    rows = (jsum * np.sqrt(inverse)[:, :, None]).reshape(-1, p)
    cross = np.stack([rows[3 * a:3 * b].T @ rows[3 * a:3 * b] for a, b in zip(ends[:-1], ends[1:])])
    o = np.asarray(offsets, np.float64)
    return OffsetSums(counts=np.bincount(cluster, minlength=groups).astype(np.float64), cross=cross,
                      jsum=per_cluster(jsum), scaled=per_cluster(jsum * (n_t[:, None] * inverse)[:, :, None]),
                      offsets=np.stack([np.bincount(cluster, weights=o[:, c], minlength=groups) for c in range(3)],
                                       axis=1))


__all__ = ["OffsetSums", "offset_sums"]
