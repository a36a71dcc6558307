"""The uncertainty of a fit with an albedo per texel (``RegionFitOptions(texel_albedo=True)``), from the fit itself.

The fit eliminates each texel's albedo a_t (variable projection,
:meth:`mifaces.reflectance.fit.problem.Problem.system`): its sums are JᵀJ − Σ_t S_t S_tᵀ/W_t and
Jᵀρ − Σ_t S_t A_t/W_t, with W_t, A_t and S_t texel t's sums
(:meth:`~mifaces.reflectance.fit.problem.Problem.texel_sums`). Where every texel's samples lie in one
cluster, both are sums over the clusters of the same per-cluster terms. The cluster estimates of
:func:`mifaces.reflectance.fit.uncertainty.covariance` then apply to them as they stand
(:func:`projected_sums`). In the jackknife, leaving a cluster out leaves its texels' albedos out
with it, and each other texel's albedo follows the glossy part, at no extra cost. These are the
intervals of the albedo offsets re-estimated per replicate
(:mod:`mifaces.reflectance.fit.offset_uncertainty`) at the alternation's fixed point, without
refitting to reach it.

The region's albedo is not a parameter of that fit but a summary of it: the texels' weighted mean
ā = Σ_t A_t / Σ_t W_t. Its interval is the jackknife's over the same clusters
(:func:`texel_albedo_interval`): replicate g is (A − A_g + (S − S_g)·d_g) / (W − W_g), with d_g
the glossy part's one-step change when cluster g is left out.
"""

from __future__ import annotations

import numpy as np
import scipy.stats

from .intervals import LEVEL, NOT_IDENTIFIED, Covariance


def projected_sums(problem, x, index: np.ndarray, groups: int) -> tuple:
    """Per cluster, the projected score u_g (G, P) and H_g (G, P, P), the projected loss, and the
    region albedo's sums per cluster (W_g (G,), A_g (G, 3), S_g (G, 3, P)), at ``x`` of ``problem``
    (a fit with an albedo per texel, ``Problem(texel=...)``); ``index`` (N,) numbers the clusters
    0 … ``groups`` - 1.

    Raises
    ------
    ValueError
        If a texel's samples lie in more than one cluster.
    """
    u, hg, loss = problem.cluster_sums(x, index, groups)
    tex = problem.texel_index
    weight, a, s = problem.texel_sums(x, tex, problem.texels)
    home = np.zeros(len(weight), np.int64)
    home[tex] = index
    if np.any(home[tex] != index):
        raise ValueError("the intervals of a fit with an albedo per texel need every texel's samples in one cluster")
    p = s.shape[2]
    root = 1.0 / np.sqrt(weight)[:, None]
    rows, values = (s * root[:, :, None]).reshape(-1, p), (a * root).reshape(-1)  # S_t, A_t over √W_t
    u, hg = u.copy(), hg.copy()
    wg, ag, sg = np.zeros(groups), np.zeros((groups, 3)), np.zeros((groups, 3, p))
    order = np.argsort(home, kind="stable")  # each cluster's texels: a slice of ``order``
    ends = np.searchsorted(home[order], np.arange(groups + 1))
    for g in range(groups):
        mine = order[ends[g]:ends[g + 1]]
        channels = (3 * mine[:, None] + np.arange(3)).reshape(-1)  # their rows, one per channel
        own = rows[channels]
        u[g] -= own.T @ values[channels]
        hg[g] -= own.T @ own
        wg[g], ag[g], sg[g] = weight[mine].sum(), a[mine].sum(axis=0), s[mine].sum(axis=0)
    loss = loss - 0.5 * float(np.sum(a * a / weight[:, None]))
    return u, hg, loss, (wg, ag, sg)


def texel_albedo_interval(cov: Covariance, u: np.ndarray, hg: np.ndarray, albedo: tuple, bounds: tuple,
                          level: float = LEVEL) -> dict:
    """The region albedo's ``{"std", "interval95"}`` (lists per channel) by the jackknife over the
    clusters (module docstring): ā ± t·std, Student's t at G - 1 degrees of freedom, clipped to
    ``bounds`` (lower, upper); ``{"status": "not_identified"}`` with fewer than two clusters with
    samples, or where a replicate leaves nothing. ``cov`` gives the held entries of the glossy part."""
    weight, a, s = albedo
    used = weight > 0
    if used.sum() < 2 or np.any(weight.sum() - weight[used] <= 0):
        return {"status": NOT_IDENTIFIED}
    free = ~np.asarray(cov.held, bool)
    h = hg.sum(axis=0)
    mean = a.sum(axis=0) / weight.sum()
    replicates = []
    for g in np.flatnonzero(used):
        d = np.zeros(h.shape[0])
        if free.any():
            d[free] = np.linalg.lstsq((h - hg[g])[np.ix_(free, free)], u[g][free], rcond=None)[0]
        rest = a.sum(axis=0) - a[g] + (s.sum(axis=0) - s[g]) @ d
        replicates.append(rest / (weight.sum() - weight[g]))
    g = len(replicates)
    std = np.sqrt((g - 1) / g * np.sum(np.square(np.array(replicates) - mean), axis=0))
    if not np.all(np.isfinite(std)):
        return {"status": NOT_IDENTIFIED}
    q = float(scipy.stats.t.ppf(0.5 + level / 2, g - 1))
    lo, hi = np.clip(mean - q * std, *bounds), np.clip(mean + q * std, *bounds)
    return {"std": [float(v) for v in std], "interval95": [[float(v) for v in lo], [float(v) for v in hi]]}


__all__ = ["projected_sums", "texel_albedo_interval"]
