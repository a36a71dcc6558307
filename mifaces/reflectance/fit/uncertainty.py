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
(:meth:`mifaces.reflectance.fit.problem.Problem.cluster_sums`), H and E from the
fit's own; all are model-agnostic: they also hold when the model is not the
truth's family (they estimate the spread around the model's best fit).

**Albedo offsets** (``fit_brdf(..., options=FitOptions(albedo_rounds=k))``). The alternated fit
subtracts from each sample its texel's albedo offset o_i = a_t - ā
(:class:`~mifaces.reflectance.maps.diffuse.AlbedoOffsets`), estimated from the same
samples given the glossy fit: a_t = (Σ_{s ∈ t} ω_s (r_s - π f_s) + λ ρ̄)/(W_t + λ),
ω = 1/σ², W_t = Σ_{s ∈ t} ω_s, and ā its mean over the region's samples. Taking
the offsets as known gives intervals far too narrow (the fit no longer sees the
albedo texture the offsets absorbed; tuning seeds: 34-55 % coverage,
validation/results/albedo_rounds.json). The jackknife and the sandwich instead
re-estimate them in every replicate, at the fixed point of the alternation. A texel's offset comes only
from its own samples
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

import numpy as np

from ...brdf.model import DIFFUSE
from ..maps.diffuse import AlbedoOffsets
from .intervals import NOT_IDENTIFIED, PRUNED, Covariance, held_entries, parameter_intervals
from .levenberg_marquardt import levenberg_marquardt
from .offset_uncertainty import OffsetSums, offset_sums
from .parameters import ParameterSpace
from .problem import Problem
from .texel_uncertainty import projected_sums, texel_albedo_interval

#: The estimates of the covariance, the default first.
METHODS = ("jackknife", "sandwich", "laplace", "bootstrap")
#: Side, in texels at texture resolution 128, of the clusters (scaled with the resolution: 4 x 4 tiles over
#: the texture at any resolution). With the method, chosen on tuning captures the coverage tables leave out:
#: first on 5 captures and 2 models (validation/results/uncertainty_tuning.json: the jackknife over single
#: texels covered 54-59 %, over tiles of 4 86-92 %, of 8 95 %, of 16 96-98 %), which chose 8; then, as tiles of
#: 8 covered only 74-87 % on the reported captures, on 20 captures of each of the 4 models
#: (validation/results/uncertainty_tile_tuning.json: tiles of 8, 16, 32 texels covered 81-92 %, 83-93 %,
#: 90-97 %), by the rule there (the tiling whose worst model is nearest 95 %).
TILE_AT_128 = 32
#: Fewest tiles a region is cut into: a region with fewer at :data:`TILE_AT_128` gets smaller tiles
#: (:func:`tile_clusters`). 1 (none): a floor of 8 covered 82-92 % on the same tuning captures, against
#: 90-97 % without.
MIN_TILES = 1
#: Side (texels at texture 128, scaled like :data:`TILE_AT_128`) of the tiles of the intervals of the fit
#: with an albedo per texel (``FitOptions(texel_albedo=True)``): chosen by the same rule on the tuning
#: captures at ``measure``'s size (512², 64 spp, texture 512²; seeds 100-104, Cook-Torrance and Phong;
#: validation/results/texel_albedo_tuning_full.json): tiles of 16, 32 and 64 covered 65-72 %, 80-91 % and
#: 94-98 %. With the texture's part of the error gone, what is left varies over larger parts of the face.
TEXEL_TILE_AT_128 = 64
#: Most clusters when the samples come without any (each sample its own, grouped beyond this number).
MAX_CLUSTERS = 4096
#: Draws of the bootstrap.
BOOTSTRAP_DRAWS = 50


def tile_clusters(texel: np.ndarray, resolution: int, tile: int | None = None, label=None,
                  min_tiles: int | None = None) -> np.ndarray:
    """The sandwich's cluster of each sample: the square tile of ``tile``
    texels a side (default :data:`TILE_AT_128` scaled to ``resolution``,
    at least 1) holding its texel (flat index row · R + column).

    With ``label`` (each sample's region), a region whose texels fall into fewer
    than ``min_tiles`` tiles (default :data:`MIN_TILES`) gets tiles half as wide,
    again until it has that many or they are single texels; clusters are then
    numbered 0 … G - 1 over all regions, none spanning two."""
    texel = np.asarray(texel, np.int64)
    if resolution < 1:
        raise ValueError(f"resolution must be positive, got {resolution}")
    tile = max(1, round(TILE_AT_128 * resolution / 128)) if tile is None else int(tile)
    if tile < 1:
        raise ValueError(f"tile must be at least 1 texel, got {tile}")
    if label is None:
        return _tiles(texel, resolution, tile)
    label = np.asarray(label)
    if label.shape != texel.shape:
        raise ValueError(f"label must have the texels' shape {texel.shape}, got {label.shape}")
    floor = MIN_TILES if min_tiles is None else int(min_tiles)
    out = np.empty_like(texel)
    base = 0
    for region in np.flatnonzero(np.bincount(label.astype(np.int64))) if label.size else []:
        members = label == region
        size = tile
        tiles, count = cluster_index(_tiles(texel[members], resolution, size))
        while size > 1 and count < floor:
            size = max(1, size // 2)
            tiles, count = cluster_index(_tiles(texel[members], resolution, size))
        out[members] = base + tiles  # numbered 0 ... G - 1 over all regions: small sums per cluster
        base += count
    return out


def _tiles(texel: np.ndarray, resolution: int, tile: int) -> np.ndarray:
    row, col = texel // resolution, texel % resolution
    tiles = -(-resolution // tile)
    return (row // tile) * tiles + col // tile


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


def region_uncertainty(space: ParameterSpace, problem: Problem, params: dict, pruned: list, cluster,
                       method: str, data: tuple, seed: int = 0, offsets: AlbedoOffsets | None = None) -> dict:
    """The parameters' uncertainty at the optimum ``params`` of ``problem`` (all
    the region's samples), by ``method``
    (:mod:`mifaces.reflectance.fit.uncertainty`): the clusters' sums (and JᵀJ, E) from
    one kernel pass at the optimum; the bootstrap refits instead.
    ``pruned`` lobes' scales and exponents get the status ``pruned``; ``data``
    is the region's (light, view, reflectance, sigma, footprint or None), for the bootstrap; ``offsets``
    the albedo offsets the reflectance was corrected by (:func:`fit_region`). Where ``problem``
    has an albedo per texel (``Problem(texel=...)``), the sums are the projected ones and the
    region's albedo gets the jackknife's interval (:mod:`mifaces.reflectance.fit.texel_uncertainty`;
    :func:`fit_region` refuses the bootstrap there)."""
    x = space.vector(params)
    held = held_entries(space, x)
    model, statuses = space.model, {}
    names = {s for j in pruned for s in model.lobe_scales()[j]}
    names |= {space.coupled[s] for s in names if s in space.coupled}
    for k, f in enumerate(space.free):
        if f.name in names:
            held[k], statuses[k] = True, PRUNED
    # a lobe whose every scale sits at 0 has no width to measure
    t = 0.5 * (1.0 + np.tanh(0.5 * x))
    for j, scales in model.lobe_scales().items():
        entries = [k for k, f in enumerate(space.free) if f.name in scales]
        width = _lobe_width(space, j, scales)
        if entries and all(held[k] and t[k] < 0.5 for k in entries) and width is not None:
            for k, f in enumerate(space.free):
                if f.name == width and not held[k]:
                    held[k], statuses[k] = True, NOT_IDENTIFIED
    if method == "bootstrap":
        cov = bootstrap_covariance(space, x, held, cluster, data, seed=seed)
    elif problem.texel_index is not None:
        index, groups = cluster_index(independent_clusters(problem.n) if cluster is None else cluster)
        u, hg, loss, albedo = projected_sums(problem, x, index, groups)
        cov = covariance(x, hg.sum(axis=0), loss, problem.n, u, hg, held, method)
        out = parameter_intervals(space, cov, statuses)
        out[DIFFUSE.name] = texel_albedo_interval(cov, u, hg, albedo, (DIFFUSE.lower, DIFFUSE.upper))
        return out
    else:
        index, groups = cluster_index(independent_clusters(problem.n) if cluster is None else cluster)
        u, hg, loss = problem.cluster_sums(x, index, groups)  # one pass: JᵀJ = Σ_g H_g
        terms = None
        if offsets is not None and method != "laplace":
            texel, texels = cluster_index(offsets.texel)
            weight, _, jsum = problem.texel_sums(x, texel, texels)
            terms = offset_sums(texel, index, groups, weight, jsum, offsets.shrinkage, offsets.offsets)
        cov = covariance(x, hg.sum(axis=0), loss, problem.n, u, hg, held, method, offsets=terms)
    return parameter_intervals(space, cov, statuses)


def _lobe_width(space: ParameterSpace, lobe: int, scales: tuple) -> str | None:
    """The parameter that sets lobe ``lobe``'s width: its scales' exponent (Lafortune), or the
    model's :attr:`~mifaces.brdf.model.BRDFModel.WIDTH_GRID` parameter for the first lobe."""
    for name in scales:
        if name in space.coupled:
            return space.coupled[name]
    grid = space.model.WIDTH_GRID
    return grid[0] if lobe == 1 and grid is not None else None


def bootstrap_covariance(space: ParameterSpace, x, held, cluster, data: tuple, draws: int = BOOTSTRAP_DRAWS,
                         iterations: int = 10, seed: int = 0) -> Covariance:
    """Cov(x̂) from ``draws`` refits on clusters drawn with replacement (a
    cluster drawn m times weighs m times: σ/√m), each started at ``x`` with at
    most ``iterations`` LM steps; ``held`` entries are left out."""
    light, view, reflectance, sigma, footprint = data
    cluster = independent_clusters(len(sigma)) if cluster is None else np.asarray(cluster)
    index, g = cluster_index(cluster)
    rng = np.random.default_rng(seed)
    xs = []
    for _ in range(draws):
        m = np.bincount(rng.integers(0, g, g), minlength=g)[index]
        keep = m > 0
        problem = Problem(space.model, space, light[keep], view[keep], reflectance[keep],
                           sigma[keep] / np.sqrt(m[keep]),
                           footprint=None if footprint is None else footprint[keep])
        xs.append(levenberg_marquardt(None, None, x, system=problem.system, max_iterations=iterations,
                                      ftol=1e-6).x)
    free = ~np.asarray(held, bool)
    cov = np.zeros((len(x), len(x)))
    if free.any():
        cov[np.ix_(free, free)] = np.atleast_2d(np.cov(np.array(xs)[:, free], rowvar=False))
    return Covariance(x=np.asarray(x, np.float64), covariance=cov, held=np.asarray(held, bool), dof=float(g - 1),
                      method="bootstrap")

__all__ = ["METHODS", "TILE_AT_128", "MIN_TILES", "MAX_CLUSTERS", "BOOTSTRAP_DRAWS", "covariance", "cluster_index",
           "independent_clusters", "tile_clusters", "region_uncertainty", "bootstrap_covariance"]
