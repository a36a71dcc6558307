"""How sure a region fit is: the covariance of its parameters at the optimum,
and 95 % intervals that stay inside each parameter's range.

The fit minimises E(x) = ½ Σ_i |ρ_i(x)|² over the unconstrained vector x of
:class:`~mifaces.reflectance.fit.parameters.ParameterSpace` (ρ_i the weighted RGB
residual (r_i - π f)/σ_i of sample i). With H = JᵀJ (the Gauss-Newton
Hessian the LM step already forms) Cov(x̂) is estimated by one of:

``jackknife`` (the default)
    The cluster jackknife (CR3; MacKinnon & White 1985, Cameron & Miller 2015,
    sec. VI.B): Cov = (G-1)/G Σ_g d_g d_gᵀ, d_g = (H - H_g)⁻¹ u_g the one-step
    change of x̂ when cluster g is left out, with u_g = Σ_{i ∈ g} J_iᵀ ρ_i the
    cluster's score and H_g = Σ_{i ∈ g} J_iᵀ J_i its share of H. The clusters
    are texel tiles (:data:`TILE_AT_128` texels a side at texture resolution
    128): the samples of one texel share its albedo's departure from the
    region's (a texel-level effect the region fit does not model), and
    neighbouring texels of one photograph share the pixel they were resampled
    from and much of their albedo; those correlations stay inside a tile. Unlike
    the plain sandwich it does not shrink when a few tiles carry a parameter (the
    highlight of a lamp is seen on a few patches of the face).
``sandwich``
    The cluster-robust sandwich (CR1; Liang & Zeger 1986; Cameron & Miller
    2015, eq. 11) over the same tiles: Cov = c H⁻¹ (Σ_g u_g u_gᵀ) H⁻¹ with
    c = G/(G-1) · (N-1)/(N-P).
``laplace``
    The Laplace approximation Cov = s² H⁻¹ with s² = 2 E / (3N - P): every
    colour channel of every sample an independent draw of equal weighted noise
    (Bates & Watts 1988, sec. 2.3). Far too narrow on faces (docs/uncertainty.md).
``bootstrap``
    Refits on tiles drawn with replacement (:data:`BOOTSTRAP_DRAWS` draws, each
    a weighted refit from the optimum, at most 10 LM steps): no linearisation,
    but a refit per draw.

The sums u_g and H_g come from one Dr.Jit kernel at the optimum
(:meth:`mifaces.reflectance.fit.regions._Problem.cluster_sums`), H and E from the
fit's own; all are model-agnostic: they also hold when the model is not the
truth's family (they estimate the spread around the model's best fit).

**Albedo offsets** (``fit_brdf(..., albedo_rounds=k)``). The alternated fit
subtracts from each sample its texel's albedo offset o_i = a_t - ā
(:class:`~mifaces.reflectance.maps.diffuse.AlbedoOffsets`), estimated from the same
samples given the glossy fit: a_t = (Σ_{s ∈ t} ω_s (r_s - π f_s) + λ ρ̄)/(W_t + λ),
ω = 1/σ², W_t = Σ_{s ∈ t} ω_s, and ā its mean over the region's samples. Taking
the offsets as known gives intervals far too narrow (the fit no longer sees the
albedo texture the offsets absorbed; tuning seeds: 34-55 % coverage,
validation/results/albedo_rounds.json). The jackknife and the sandwich instead
re-estimate them in every replicate, at the fixed point of the alternation. A texel's offset comes only from its own samples
(texels nest in tiles), so leaving tile g out removes its texels' offsets with
its scores, shifts ā of the others by δ_g = -Σ_{i ∈ g} o_i / (N - N_g), and
makes every offset follow the fit: ∂o_i/∂x = B_t - B̄, B_t = S_t/(W_t + λ) per
channel, S_t = Σ_{s ∈ t} J_s/σ_s, B̄ the mean of B over the samples (the diffuse
albedo's share of a_t cancels in the difference). The one-step replicate is then

    d_g = (H - H_g - K_{-g})⁻¹ (u_g - Σ_c (S - S_g)_cᵀ δ_g,c),
    K_{-g} = Σ_{t ∉ g} Σ_c S_t,cᵀ B_t,c - Σ_c (S - S_g)_cᵀ B̄^{(-g)}_c,

(S, S_g the sums of S_t over all texels and over tile g's; B̄^{(-g)} the mean of
B without tile g), H - K being the Jacobian of the alternation's fixed point
(the glossy parameters are then measured by how a texel's samples differ from
each other, not from other texels). The sandwich takes H - K as bread and the
scores u_g + Σ_c S_cᵀ Σ_{i ∈ g} o_i,c / N. The shrinkage weights λ are held (a
region-wide quantity; ``fit_brdf`` uses unshrunk texel means, λ = 0). Laplace
and the bootstrap take the offsets as known. The replicates agree with refitting the
alternation per tile left out within 3-5 % on a simulated face
(validation/results/albedo_rounds_exact.json), yet the intervals hold the truth
only 49-67 % of the time on the tuning seeds: the alternated fit's remaining error
is a bias shared by the whole capture (docs/uncertainty.md).

Intervals are symmetric in x, the fit's own coordinates (the logit of a
parameter's position within its range, on a log scale for parameters
spanning decades), and mapped back, so they never leave the range and are
asymmetric in the parameter's units; ``std`` is the delta-method standard
deviation in the parameter's units. Quantiles are Student's t with G - 1
(jackknife, sandwich, bootstrap) or 3N - P (Laplace) degrees of freedom. A Lafortune
coefficient, which the fit scales by its lobe's energy bound, gets the
delta-method interval ± t·std in its own units, clipped to that bound.

Parameters the fit does not estimate get a status instead of numbers:
``fixed`` (held at a given value, e.g. Cook-Torrance's η), ``at_bound``
(within 10⁻³ of either end of its range in the reparameterised scale, or a
Lafortune lobe at its energy bound: there the curvature says nothing about
how far the optimum could move), ``pruned`` (a Lafortune lobe set to zero),
``not_identified`` (the samples do not constrain it: JᵀJ is singular in its
direction) and ``prior`` (a region that borrowed its BRDF). Parameters at a bound are
held there while the others' covariance is computed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.stats

from .parameters import ParameterSpace

#: The estimates of the covariance, the default first.
METHODS = ("jackknife", "sandwich", "laplace", "bootstrap")
#: The intervals' coverage.
LEVEL = 0.95
#: Side, in texels at texture resolution 128, of the clusters (scaled with the resolution). With the
#: method, chosen on tuning captures the coverage tables leave out (validation/results/
#: uncertainty_tuning.json: the jackknife over single texels covers 54-59 %, over tiles of 4 86-92 %,
#: of 8 95 %, of 16 96-98 %; the sandwich over tiles of 8 89-93 %).
TILE_AT_128 = 8
#: Most clusters when the samples come without any (each sample its own, grouped beyond this number).
MAX_CLUSTERS = 4096
#: Draws of the bootstrap.
BOOTSTRAP_DRAWS = 50
#: Statuses of parameters without an interval.
FIXED, AT_BOUND, PRUNED, PRIOR, ESTIMATED = "fixed", "at_bound", "pruned", "prior", "estimated"
#: Status of a parameter the samples do not constrain (JᵀJ singular in its direction).
NOT_IDENTIFIED = "not_identified"


def tile_clusters(texel: np.ndarray, resolution: int, tile: int | None = None) -> np.ndarray:
    """The sandwich's cluster of each sample: the square tile of ``tile``
    texels a side (default :data:`TILE_AT_128` scaled to ``resolution``,
    at least 1) holding its texel (flat index row · R + column)."""
    texel = np.asarray(texel, np.int64)
    if resolution < 1:
        raise ValueError(f"resolution must be positive, got {resolution}")
    tile = max(1, round(TILE_AT_128 * resolution / 128)) if tile is None else int(tile)
    if tile < 1:
        raise ValueError(f"tile must be at least 1 texel, got {tile}")
    row, col = texel // resolution, texel % resolution
    tiles = -(-resolution // tile)
    return (row // tile) * tiles + col // tile


@dataclass
class Covariance:
    """The covariance of the free variables x at the optimum.

    Attributes
    ----------
    x : ndarray (P,)
        The optimum.
    covariance : ndarray (P, P)
        Cov(x̂); rows and columns of held entries are 0.
    held : ndarray (P,) of bool
        Entries at a bound or pruned, held where they are.
    dof : float
        Degrees of freedom of the t quantile.
    method : str
    """

    x: np.ndarray
    covariance: np.ndarray
    held: np.ndarray
    dof: float
    method: str

    def quantile(self, level: float = LEVEL) -> float:
        """Two-sided ``level`` quantile of Student's t with :attr:`dof`."""
        return float(scipy.stats.t.ppf(0.5 + level / 2, max(self.dof, 1.0)))


def _inverse(h: np.ndarray) -> np.ndarray:
    """H⁻¹ of a symmetric positive semi-definite H, scaled to unit diagonal
    first; directions the samples do not constrain (eigenvalues below 10⁻¹²
    of the largest) get infinite variance."""
    d = np.sqrt(np.maximum(np.diag(h), 1e-300))
    scaled = h / np.outer(d, d)
    w, v = np.linalg.eigh(scaled)
    small = w <= 1e-12 * max(float(w.max()), 1e-300)
    inv = (v[:, ~small] / w[~small]) @ v[:, ~small].T
    if np.any(small):
        loose = np.any(np.abs(v[:, small]) > 1e-6, axis=1)
        inv[loose, :] = inv[:, loose] = 0.0
        inv[loose, loose] = np.inf
    return inv / np.outer(d, d)


def independent_clusters(samples: int) -> np.ndarray:
    """Clusters for samples taken as independent: each its own, or, beyond
    :data:`MAX_CLUSTERS`, that many blocks of consecutive samples (any partition of
    independent samples gives a valid cluster-robust estimate; fewer clusters keep the
    jackknife's per-cluster sums small)."""
    return np.arange(samples) * min(samples, MAX_CLUSTERS) // max(samples, 1)


def cluster_index(cluster) -> tuple[np.ndarray, int]:
    """Clusters (non-negative integers, N) renumbered 0 … G - 1 in order, and G."""
    cluster = np.asarray(cluster, np.int64)
    if cluster.size == 0:
        return cluster, 0
    if cluster.min() < 0:
        raise ValueError("cluster numbers must be non-negative")
    used = np.bincount(cluster) > 0
    lookup = np.cumsum(used) - 1
    return lookup[cluster], int(used.sum())


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
        S_t = Σ_{i ∈ t} J_i/σ_i per channel (:meth:`mifaces.reflectance.fit.regions._Problem.texel_sums`).
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


def covariance(x, jtj, loss: float, samples: int, scores: np.ndarray | None, hessians: np.ndarray | None, held,
               method: str = METHODS[0], offsets: OffsetSums | None = None) -> Covariance:
    """Cov(x̂) by ``sandwich``, ``jackknife`` or ``laplace`` (module docstring).

    Parameters
    ----------
    x : ndarray (P,)
        The optimum.
    jtj : ndarray (P, P)
        JᵀJ at ``x`` (summed over samples and channels).
    loss : float
        E = ½ Σ |ρ|² at ``x``.
    samples : int
        N, the samples behind the sums.
    scores : ndarray (G, P) or None
        Per cluster, u_g = Σ_{i ∈ g} J_iᵀ ρ_i (not needed by ``laplace``).
    hessians : ndarray (G, P, P) or None
        Per cluster, H_g = Σ_{i ∈ g} J_iᵀ J_i (needed by ``jackknife`` only).
    held : ndarray (P,) of bool
        Entries held fixed (their rows and columns are left out).
    method : str
        ``sandwich``, ``jackknife`` or ``laplace``.
    offsets : OffsetSums, optional
        The clusters' sums of the albedo offsets the fit's reflectance was corrected
        by: the jackknife and the sandwich re-estimate them per replicate (module
        docstring); Laplace ignores them.
    """
    x, jtj = np.asarray(x, np.float64), np.asarray(jtj, np.float64)
    held = np.asarray(held, bool)
    n, p = int(samples), len(x)
    if method not in METHODS or method == "bootstrap":
        raise ValueError(f"method must be one of {[m for m in METHODS if m != 'bootstrap']} here, got {method!r}")
    needs = {"sandwich": ("scores",), "jackknife": ("scores", "hessians"), "laplace": ()}[method]
    given = {"scores": scores, "hessians": hessians}
    for name in needs:
        if given[name] is None:
            raise ValueError(f"the {method} covariance needs the clusters' {name}")
    g = 0 if scores is None else len(scores)
    if (jtj.shape != (p, p) or held.shape != (p,) or (scores is not None and np.shape(scores) != (g, p))
            or (hessians is not None and np.shape(hessians) != (g, p, p))):
        raise ValueError(f"x {x.shape}, jtj {jtj.shape}, held {held.shape}, scores {np.shape(scores)} and "
                         f"hessians {np.shape(hessians)} disagree")
    free = ~held
    k = int(free.sum())
    cov = np.zeros((p, p))
    block = None
    if method == "laplace":
        dof = float(3 * n - k)
        if k:
            block = 2.0 * float(loss) / max(dof, 1.0) * _inverse(jtj[np.ix_(free, free)])
    else:
        dof = float(g - 1)
        u = np.asarray(scores, np.float64)[:, free]
        if k and g < 2:
            block = np.diag(np.full(k, np.inf))
        elif k and method == "sandwich":
            c = g / (g - 1) * (n - 1) / max(n - k, 1)
            h = jtj[np.ix_(free, free)]
            if offsets is None:
                block = _sandwich(_inverse(h), u.T @ u, c)
            else:
                o = offsets.free(free)
                total = o.jsum.sum(axis=0)
                bread = h - (o.cross.sum(axis=0) - np.einsum("ca,cb->ab", total, o.scaled.sum(axis=0)) / n)
                u = u + np.einsum("ca,gc->ga", total, o.offsets) / n
                inv = _general_inverse(bread)
                block = _sandwich(inv, u.T @ u, c, inv.T)
        elif k:
            hg = np.asarray(hessians, np.float64)[:, free][:, :, free]
            h = jtj[np.ix_(free, free)]
            if offsets is None:
                block = _jackknife(h, hg, u)
            else:
                o = offsets.free(free)
                rest = n - o.counts  # samples left in each replicate
                jsum = o.jsum.sum(axis=0)[None] - o.jsum  # Σ_{t ∉ g} S_t (G, 3, P)
                mean_b = (o.scaled.sum(axis=0)[None] - o.scaled) / np.maximum(rest, 1)[:, None, None]
                k_left = o.cross.sum(axis=0)[None] - o.cross - np.einsum("gca,gcb->gab", jsum, mean_b)
                delta = -o.offsets / np.maximum(rest, 1)[:, None]  # ā_{-g} - ā
                block = _jackknife(h, hg + k_left, u - np.einsum("gca,gc->ga", jsum, delta))
    if block is not None:
        cov[np.ix_(free, free)] = block
    return Covariance(x=x, covariance=cov, held=held, dof=dof, method=method)


def _sandwich(inv: np.ndarray, meat: np.ndarray, c: float, inv_t: np.ndarray | None = None) -> np.ndarray:
    """c A⁻¹ B A⁻ᵀ (``inv`` = A⁻¹, ``inv_t`` = A⁻ᵀ, default A⁻¹: a symmetric A), infinite in the
    directions A⁻¹ is."""
    inv_t = inv if inv_t is None else inv_t
    finite = np.all(np.isfinite(inv), axis=1)
    block = np.diag(np.where(finite, 0.0, np.inf))
    f = np.ix_(finite, finite)
    block[f] = c * inv[f] @ meat[f] @ inv_t[f]
    return block


def _general_inverse(a: np.ndarray) -> np.ndarray:
    """A⁻¹ of a square A that need not be symmetric (H - K of the albedo offsets), scaled by
    √diag(H)-like factors first; all infinite if A is singular (condition above 10¹²)."""
    d = np.sqrt(np.maximum(np.abs(np.diag(a)), 1e-300))
    scaled = a / np.outer(d, d)
    if not np.all(np.isfinite(scaled)) or np.linalg.cond(scaled) > 1e12:
        return np.full(a.shape, np.inf)
    return np.linalg.inv(scaled) / np.outer(d, d)


def _jackknife(h: np.ndarray, hg: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(G-1)/G Σ_g d_g d_gᵀ with d_g = (H - H_g)⁻¹ u_g, the one-step change of x̂ when
    cluster g is left out: the cluster jackknife (CR3, MacKinnon & White 1985; Cameron &
    Miller 2015, sec. VI.B), meant not to shrink when a few clusters carry a parameter.
    A parameter that one cluster alone constrains is infinite. (With albedo offsets, ``hg``
    carries H_g + K_{-g} and ``u`` the scores with the shift of ā, module docstring.)"""
    g, k = u.shape
    d = np.sqrt(np.maximum(np.diag(h), 1e-300))
    left = (h[None] - hg) / np.outer(d, d)  # scaled to a unit diagonal of H
    try:
        steps = np.linalg.solve(left, (u / d)[:, :, None])[:, :, 0] / d
    except np.linalg.LinAlgError:
        steps = np.stack([np.linalg.lstsq(m, v / d, rcond=None)[0] / d for m, v in zip(left, u)])
    cond = np.linalg.cond(left)
    steps[~np.isfinite(cond) | (cond > 1e12)] = np.inf
    block = (g - 1) / g * steps.T @ steps
    block[~np.isfinite(block)] = np.inf
    return block


def parameter_intervals(space: ParameterSpace, cov: Covariance, statuses: dict | None = None,
                        level: float = LEVEL) -> dict:
    """Per parameter of the model, ``{"std", "interval95"}`` or ``{"status"}``.

    ``std`` and the interval's ends are floats, or lists per channel for RGB
    parameters (``interval95`` is then ``[[lo_r, lo_g, lo_b], [hi_r, hi_g, hi_b]]``,
    with ``None`` and a per-channel ``status`` list where only some channels
    are held). ``statuses`` names a status for held entries (free-vector
    index -> status; default ``at_bound``). The diffuse reflectance is
    included; fixed parameters are ``{"status": "fixed"}``.
    """
    statuses = statuses or {}
    x, var = cov.x, np.diag(cov.covariance)
    q = cov.quantile(level)
    values = space.values(x)
    jac = _value_jacobian(space, x)
    out: dict = {name: {"status": FIXED} for name in space.fixed}
    entries: dict = {}
    for k, f in enumerate(space.free):
        if cov.held[k]:
            entry = (statuses.get(k, AT_BOUND), None, None, None)
        else:
            std = _std(jac[k], cov.covariance)
            if np.isfinite(std):
                lo, hi = _interval(space, x, k, f, q * np.sqrt(var[k]), std, q, values)
                entry = (ESTIMATED, std, lo, hi)
            else:
                entry = (NOT_IDENTIFIED, None, None, None)
        entries.setdefault(f.name, {})[f.channel] = entry
    for name, channels in entries.items():
        if None in channels:
            status, std, lo, hi = channels[None]
            out[name] = {"status": status} if status != ESTIMATED else {"std": std, "interval95": [lo, hi]}
            continue
        parts = [channels[c] for c in range(3)]
        kinds = {p[0] for p in parts}
        if kinds != {ESTIMATED} and len(kinds) == 1:
            out[name] = {"status": parts[0][0]}
            continue
        out[name] = {"std": [p[1] for p in parts], "interval95": [[p[2] for p in parts], [p[3] for p in parts]]}
        if kinds != {ESTIMATED}:
            out[name]["status"] = [p[0] for p in parts]
    return out


def _std(row: np.ndarray, cov: np.ndarray) -> float:
    """√(row Cov rowᵀ), the delta-method standard deviation; inf where an entry it needs is."""
    idx = np.flatnonzero(row != 0)
    block = cov[np.ix_(idx, idx)]
    if not np.all(np.isfinite(block)):
        return float("inf")  # it depends on an entry the samples do not constrain
    return float(np.sqrt(max(float(row[idx] @ block @ row[idx]), 0.0)))


def _interval(space: ParameterSpace, x, k: int, f, half_x: float, std: float, q: float, values: dict):
    """Ends of the interval of free entry ``k``: x ± ``half_x`` mapped back, or for an
    energy-coupled coefficient the value ± q·std clipped to its bound."""
    if f.name in space.coupled:
        value = values[f.name][f.channel] if f.channel is not None else values[f.name]
        bound = float(space.model.coefficient_bound(float(values[space.coupled[f.name]]), np.log, np.exp))
        return max(value - q * std, -bound), min(value + q * std, bound)
    return space.entry_value(f, x[k] - half_x), space.entry_value(f, x[k] + half_x)


def _value_jacobian(space: ParameterSpace, x, h: float = 1e-6) -> np.ndarray:
    """d value / d x: row k is the derivative of free entry k's parameter value (its channel)
    with respect to every entry of x, by central differences: of the entry's own map for the
    parameters that depend on their entry alone, of all values for energy-coupled ones."""
    x = np.asarray(x, np.float64)
    p = len(x)
    jac = np.zeros((p, p))
    for k, f in enumerate(space.free):
        if f.name not in space.coupled:
            jac[k, k] = (space.entry_value(f, x[k] + h) - space.entry_value(f, x[k] - h)) / (2 * h)
    coupled = [k for k, f in enumerate(space.free) if f.name in space.coupled]
    if coupled:
        def flat(v):
            return np.array([float(v[space.free[k].name][space.free[k].channel] if space.free[k].channel is not None
                                   else v[space.free[k].name]) for k in coupled])

        for j in range(p):
            step = np.zeros(p)
            step[j] = h
            jac[coupled, j] = (flat(space.values(x + step)) - flat(space.values(x - step))) / (2 * h)
    return jac


def held_entries(space: ParameterSpace, x, margin: float = 1e-3) -> np.ndarray:
    """Free entries at either end of their range (within ``margin`` of it in
    the reparameterised scale), or energy-coupled coefficients whose lobe is at
    its energy bound (:meth:`ParameterSpace.at_bounds`)."""
    t = 0.5 * (1.0 + np.tanh(0.5 * np.asarray(x, np.float64)))
    upper = set(space.at_bounds(x, margin))
    held = np.zeros(len(space.free), bool)
    for k, (f, tk) in enumerate(zip(space.free, t)):
        label = f.name if f.channel is None else f"{f.name}[{f.channel}]"
        held[k] = label in upper or (f.name not in space.coupled and tk < margin)
    return held


def prior_intervals(params: dict) -> dict:
    """``{"status": "prior"}`` for every parameter of a borrowed fit."""
    return {name: {"status": PRIOR} for name in params}


__all__ = ["METHODS", "LEVEL", "TILE_AT_128", "MAX_CLUSTERS", "BOOTSTRAP_DRAWS", "Covariance", "covariance",
           "OffsetSums", "offset_sums", "cluster_index", "independent_clusters", "parameter_intervals",
           "held_entries", "prior_intervals", "tile_clusters"]
