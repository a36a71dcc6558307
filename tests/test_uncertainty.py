"""Parameter uncertainty of the region fits (mifaces.reflectance.fit.uncertainty): on synthetic samples
of a known BRDF with known noise, the estimated standard deviations match the spread over repeated
noise draws, the intervals hold the truth at about the nominal rate, samples that share a texel
effect need the clustered estimate, and parameters at a bound or fixed are flagged; the per-texel
albedo's posterior standard deviation matches its error; the fit alternated with per-texel albedo
offsets gets intervals that re-estimate the offsets per replicate (as refitting each does)."""

from __future__ import annotations

import mifaces  # first: libLLVM  # isort: skip

import mitsuba as mi
import numpy as np
import pytest

from mifaces import brdf as brdf_models
from mifaces.reflectance.maps.diffuse import AlbedoOffsets, refine_diffuse
from mifaces.reflectance.fit.intervals import _value_jacobian
from mifaces.reflectance.fit.offset_uncertainty import offset_sums
from mifaces.reflectance.fit.parameters import ParameterSpace
from mifaces.reflectance.fit.region_fit import FULL_DATA, RegionFitOptions, RegionSamples, Uncertainty, fit_region
from mifaces.reflectance.fit.regions import prior_fit
from mifaces.reflectance.fit.uncertainty import TILE_AT_128, cluster_index, covariance, tile_clusters
from mifaces.reflectance.samples import ReflectanceSamples

TRUTH = {"diffuse_reflectance": [0.5, 0.35, 0.25], "specular_reflectance": [0.8, 0.8, 0.8], "roughness": 0.5,
         "eta": 1.4}
FIXED = {"eta": 1.4}
#: The region fit with η held, in one stage over all samples.
ONE_STAGE = RegionFitOptions(fixed=FIXED, schedule=FULL_DATA)


def directions(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.4
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def reflectance(params, light, view, model="cooktorrance"):
    """π f of ``params`` at the directions, (N, 3), evaluated by the model's own Dr.Jit function."""
    m = brdf_models.model(model)
    p = {k: (mi.Color3f(*v) if np.ndim(v) else mi.Float(v)) for k, v in params.items()}
    f = m.eval(mi.Vector3f(np.ascontiguousarray(light.T)), mi.Vector3f(np.ascontiguousarray(view.T)), p)
    return np.pi * np.array(f).T


def draws(method, texels, per_texel, texel_sd, noise_sd, repeats, seed=0):
    """Fits to ``repeats`` noise draws of the same directions: samples in ``texels`` groups of
    ``per_texel`` with nearby directions (as a texel's samples, or a tile's, are), each group's albedo
    offset by N(0, texel_sd²) (a shared texel effect), each sample's reflectance by N(0, noise_sd²). Returns the fitted roughness, specular scale and diffuse albedo
    (channel 0), their estimated std and whether the interval held the truth, per draw."""
    rng = np.random.default_rng(seed)
    n = texels * per_texel
    cluster = np.repeat(np.arange(texels), per_texel)
    light, view = (directions(rng, texels)[cluster] + 0.1 * rng.normal(size=(n, 3)) for _ in range(2))
    for v in (light, view):
        v[:, 2] = np.abs(v[:, 2])
        v /= np.linalg.norm(v, axis=1, keepdims=True)
    clean = reflectance(TRUTH, light, view)
    rows = []
    for _ in range(repeats):
        r = clean + texel_sd * rng.normal(size=(texels, 3))[cluster] + noise_sd * rng.normal(size=(n, 3))
        fit = fit_region("cooktorrance", RegionSamples(light, view, r, np.ones(n)), options=ONE_STAGE,
                         uncertainty=Uncertainty(method, cluster))
        row = []
        for name, true, channel in (("roughness", TRUTH["roughness"], None), ("specular_reflectance", 0.8, 0),
                                    ("diffuse_reflectance", 0.5, 0)):
            u = fit.uncertainty[name]
            value = fit.params[name] if channel is None else fit.params[name][channel]
            std = u["std"] if channel is None else u["std"][channel]
            lo, hi = u["interval95"] if channel is None else (u["interval95"][0][channel], u["interval95"][1][channel])
            row.append((value, std, lo <= true <= hi))
        rows.append(row)
    return np.array(rows, dtype=float)  # (repeats, 3 parameters, (value, std, covered))


@pytest.mark.parametrize("method", ["laplace", "sandwich"])
def test_std_matches_spread_of_independent_noise(method):
    """Independent noise: both estimates' std within 35 % of the empirical spread over 40 draws (the
    spread itself is known to ±11 % at 40 draws; the sandwich runs low where few samples see the
    lobe), and the intervals hold the truth in 80-100 % of them."""
    rows = draws(method, texels=3000, per_texel=1, texel_sd=0.0, noise_sd=0.03, repeats=40)
    for k in range(3):
        spread, std = np.std(rows[:, k, 0], ddof=1), np.mean(rows[:, k, 1])
        assert std == pytest.approx(spread, rel=0.35), (k, std, spread)
        assert 0.8 <= rows[:, k, 2].mean() <= 1.0


def test_shared_texel_effect_needs_the_clustered_estimate():
    """Samples sharing a texel's albedo offset: the Laplace std of the albedo (every sample
    independent) is too small by more than half, the sandwich over texels matches the spread of every
    parameter within 35 % and covers at 80 % or more."""
    laplace = draws("laplace", texels=400, per_texel=8, texel_sd=0.05, noise_sd=0.002, repeats=30, seed=3)
    sandwich = draws("sandwich", texels=400, per_texel=8, texel_sd=0.05, noise_sd=0.002, repeats=30, seed=3)
    assert np.mean(laplace[:, 2, 1]) < 0.5 * np.std(laplace[:, 2, 0], ddof=1)
    for k in range(3):
        spread = np.std(sandwich[:, k, 0], ddof=1)
        assert np.mean(sandwich[:, k, 1]) == pytest.approx(spread, rel=0.35), k
        assert sandwich[:, k, 2].mean() >= 0.8


@pytest.mark.parametrize("design", [dict(texels=3000, per_texel=1, texel_sd=0.0, noise_sd=0.03, repeats=40),
                                    dict(texels=400, per_texel=8, texel_sd=0.05, noise_sd=0.002, repeats=30, seed=3)],
                         ids=["independent", "texel-effect"])
def test_jackknife_is_conservative_not_wild(design):
    """The default, the cluster jackknife: never narrower than the spread over the draws (at least 0.9
    of it), at most 2.5 times it (it widens where a few samples or texels carry the lobe: on these
    synthetic designs 1.4-2.3 times for the lobe, 1.0-1.1 for the albedo), covering 90 % or more."""
    rows = draws("jackknife", **design)
    for k in range(3):
        ratio = np.mean(rows[:, k, 1]) / np.std(rows[:, k, 0], ddof=1)
        assert 0.9 <= ratio <= 2.5, (k, ratio)
        assert rows[:, k, 2].mean() >= 0.9


def test_bootstrap_agrees_with_sandwich():
    """On one draw with a shared texel effect, the bootstrap's std (50 refits over texels) is of the
    sandwich's size: between 0.5 and 3 times it (it runs wider where a few texels carry the lobe, see
    docs/uncertainty.md), for every parameter."""
    options = dict(texels=400, per_texel=8, texel_sd=0.05, noise_sd=0.002, repeats=1, seed=3)
    bootstrap, sandwich = draws("bootstrap", **options), draws("sandwich", **options)
    np.testing.assert_allclose(bootstrap[:, :, 0], sandwich[:, :, 0], rtol=1e-6)  # the same fit (parallel sums)
    for k in range(3):
        assert 0.5 * sandwich[0, k, 1] < bootstrap[0, k, 1] < 3 * sandwich[0, k, 1], k


def test_bound_fixed_and_prior_parameters_are_flagged():
    """No glossy lobe in the samples: the lobe scale ends at its lower bound and is reported
    ``at_bound`` (no interval); η held fixed is ``fixed``; a borrowed fit is ``prior``."""
    rng = np.random.default_rng(1)
    n = 1500
    light, view = directions(rng, n), directions(rng, n)
    r = np.array([0.5, 0.35, 0.25]) + 0.01 * rng.normal(size=(n, 3))
    fit = fit_region("cooktorrance", RegionSamples(light, view, r, np.ones(n)), options=ONE_STAGE)
    assert fit.uncertainty["specular_reflectance"] == {"status": "at_bound"}
    assert fit.uncertainty["eta"] == {"status": "fixed"}
    # the lobe gone, its width is not identified: no made-up interval
    assert "interval95" not in fit.uncertainty["roughness"]
    lo, hi = fit.uncertainty["diffuse_reflectance"]["interval95"]
    assert all(a < v < b for a, v, b in zip(lo, [0.5, 0.35, 0.25], hi))
    prior = prior_fit(brdf_models.model("cooktorrance"), TRUTH, 3, "test")
    assert prior.uncertainty["roughness"] == {"status": "prior"}


def test_intervals_stay_inside_the_range():
    """A faint lobe near the lower bound of its scale: the interval is asymmetric and above 0."""
    rng = np.random.default_rng(2)
    n = 400
    light, view = directions(rng, n), directions(rng, n)
    truth = {**TRUTH, "specular_reflectance": [0.02] * 3}
    r = reflectance(truth, light, view) + 0.02 * rng.normal(size=(n, 3))
    fit = fit_region("cooktorrance", RegionSamples(light, view, r, np.ones(n)), options=ONE_STAGE)
    u = fit.uncertainty["specular_reflectance"]
    if u.get("status") == "at_bound":
        pytest.fail("the faint lobe was expected inside the range")
    value = fit.params["specular_reflectance"][0]
    lo, hi = u["interval95"][0][0], u["interval95"][1][0]
    assert 0.0 < lo < value < hi
    assert hi - value > value - lo  # symmetric in the logit, longer upwards in the parameter's units


def test_covariance_rejects_bad_input():
    with pytest.raises(ValueError, match="method"):
        covariance(np.zeros(2), np.eye(2), 1.0, 5, np.zeros((5, 2)), None, np.zeros(2, bool), "bayes")
    with pytest.raises(ValueError, match="disagree"):
        covariance(np.zeros(3), np.eye(2), 1.0, 5, np.zeros((5, 2)), None, np.zeros(2, bool), "sandwich")
    with pytest.raises(ValueError, match="hessians"):
        covariance(np.zeros(2), np.eye(2), 1.0, 5, np.zeros((5, 2)), None, np.zeros(2, bool), "jackknife")
    with pytest.raises(ValueError, match="non-negative"):
        cluster_index(np.array([0, -1]))
    with pytest.raises(ValueError, match=r"Uncertainty\.method must be one of"):
        Uncertainty("bayes")
    with pytest.raises(ValueError, match="cluster"):
        unit = np.ones((20, 3)) / 3 ** 0.5
        fit_region("cooktorrance", RegionSamples(unit, unit, np.ones((20, 3)), np.ones(20)),
                   uncertainty=Uncertainty(cluster=np.zeros(3)))


def _linear_problem(rng, samples=40, clusters=6):
    """A linear least-squares problem ρ = J x - y, three rows (channels) per sample, with a shared
    error per cluster: x̂, J (N, 3, P), ρ (N, 3) at x̂ and the clusters."""
    jac = rng.normal(size=(samples, 3, 3))
    cluster = np.arange(samples) % clusters
    y = jac @ np.array([0.3, -1.2, 0.7]) + rng.normal(0, 0.1, (samples, 3)) + rng.normal(0, 0.2, (clusters, 1))[cluster]
    x = np.linalg.lstsq(jac.reshape(-1, 3), y.ravel(), rcond=None)[0]
    return x, jac, jac @ x - y, y, cluster


def test_covariance_estimates_match_their_definitions_on_a_linear_problem():
    """Where one Newton step is exact (a linear problem): the jackknife is (G-1)/G Σ_g d_g d_gᵀ over the
    refits d_g = x̂_{-g} - x̂ with cluster g left out (MacKinnon and White 1985), the sandwich
    c H⁻¹ (Σ_g u_g u_gᵀ) H⁻¹ with c = G/(G-1)·(N-1)/(N-P) (Cameron and Miller 2015, eq. 11), Laplace
    |ρ|²/(3N-P) H⁻¹; the t quantiles have G-1 and 3N-P degrees of freedom."""
    rng = np.random.default_rng(3)
    x, jac, res, y, cluster = _linear_problem(rng)
    n, p, g = len(res), len(x), cluster.max() + 1
    scores = np.stack([np.einsum("ncp,nc->p", jac[cluster == k], res[cluster == k]) for k in range(g)])
    hessians = np.stack([np.einsum("ncp,ncq->pq", jac[cluster == k], jac[cluster == k]) for k in range(g)])
    h = hessians.sum(axis=0)
    loss, held = 0.5 * np.sum(res ** 2), np.zeros(p, bool)
    refits = np.array([np.linalg.lstsq(jac[cluster != k].reshape(-1, p), y[cluster != k].ravel(), rcond=None)[0]
                       for k in range(g)]) - x
    inverse = np.linalg.inv(h)
    expected = {"jackknife": ((g - 1) / g * refits.T @ refits, g - 1),
                "sandwich": (g / (g - 1) * (n - 1) / (n - p) * inverse @ scores.T @ scores @ inverse, g - 1),
                "laplace": (np.sum(res ** 2) / (3 * n - p) * inverse, 3 * n - p)}
    for method, (cov, dof) in expected.items():
        estimate = covariance(x, h, loss, n, scores, hessians, held, method)
        np.testing.assert_allclose(estimate.covariance, cov, rtol=1e-8, err_msg=method)
        assert estimate.dof == dof, method


def test_intervals_are_t_quantiles_of_the_covariance_mapped_back(monkeypatch):
    """x̂_k ± t_{0.975, dof} √Cov_kk in the fit's coordinates, mapped to the parameter's units; std by the
    delta method |∂p/∂x| √Cov_kk; fixed and held parameters get a status instead (no systematic term)."""
    from scipy.stats import t

    from mifaces.reflectance.fit import intervals
    from mifaces.reflectance.fit.intervals import Covariance, parameter_intervals

    monkeypatch.setattr(intervals, "SYSTEMATIC", {})

    space = ParameterSpace(brdf_models.model("cooktorrance"), FIXED)
    x = space.vector({**TRUTH, "specular_reflectance": [0.8, 0.05, 0.8]})
    var = np.array([0.01, 0.04, 0.09, 0.02, 0.5, 0.03, 0.06])
    held = np.arange(len(x)) == 5  # the specular scale's blue channel
    out = parameter_intervals(space, Covariance(x, np.diag(np.where(held, 0.0, var)), held, 4.0, "jackknife"))
    q = t.ppf(0.975, 4)
    assert out["eta"] == {"status": "fixed"}
    assert out["specular_reflectance"]["status"] == ["estimated", "estimated", "at_bound"]
    for k, f in enumerate(space.free):
        if held[k]:
            continue
        u = out[f.name]
        ends = u["interval95"]
        lo, hi = ends if f.channel is None else (ends[0][f.channel], ends[1][f.channel])
        std = u["std"] if f.channel is None else u["std"][f.channel]
        half = q * np.sqrt(var[k])
        assert (lo, hi) == pytest.approx((space.entry_value(f, x[k] - half), space.entry_value(f, x[k] + half)),
                                         rel=1e-9), f
        slope = (space.entry_value(f, x[k] + 1e-5) - space.entry_value(f, x[k] - 1e-5)) / 2e-5
        assert std == pytest.approx(abs(slope) * np.sqrt(var[k]), rel=1e-5), f
        assert f.lower <= lo < space.entry_value(f, x[k]) < hi <= f.upper


def test_a_lafortune_coefficients_interval_stays_within_its_energy_bound(monkeypatch):
    """A coefficient the fit scales by its lobe's energy bound c_max(n) gets value ± t·std, clipped to
    ±c_max."""
    from mifaces.reflectance.fit import intervals
    from mifaces.reflectance.fit.intervals import Covariance, parameter_intervals

    monkeypatch.setattr(intervals, "SYSTEMATIC", {})

    model = brdf_models.model("lafortune")
    space = ParameterSpace(model)
    x = np.zeros(len(space))
    x[[k for k, f in enumerate(space.free) if f.name == "cz"]] = 3.0  # 0.9 of the bound
    out = parameter_intervals(space, Covariance(x, np.eye(len(x)), np.zeros(len(x), bool), 50.0, "jackknife"))
    values = space.values(x)
    bound = float(model.coefficient_bound(values["exponent"], np.log, np.exp))
    (lo, hi), std = out["cz"]["interval95"], out["cz"]["std"]
    assert hi == pytest.approx([bound] * 3) and all(v + 2 * s > bound for v, s in zip(values["cz"], std))
    assert lo == pytest.approx([v - 2.0086 * s for v, s in zip(values["cz"], std)], rel=1e-3)


def test_the_systematic_term_widens_the_interval_in_quadrature(monkeypatch):
    """With a relative systematic s for a parameter, its interval is x̂_k ± √((t√Cov_kk)² + (z·s·p/|∂p/∂x|)²)
    mapped back (t Student's quantile, z the normal one); ``std`` stays the statistical one and
    ``systematic_std`` is s·p; a parameter without one keeps the statistical interval; an energy-coupled
    coefficient takes value ± √((t·std)² + (z·s·p)²)."""
    from scipy.stats import norm, t

    from mifaces.reflectance.fit import intervals
    from mifaces.reflectance.fit.intervals import Covariance, parameter_intervals

    space = ParameterSpace(brdf_models.model("cooktorrance"), FIXED)
    x = space.vector({**TRUTH, "specular_reflectance": [0.8, 0.6, 0.7]})
    var = np.full(len(x), 1e-4)
    cov = Covariance(x, np.diag(var), np.zeros(len(x), bool), 40.0, "jackknife")
    monkeypatch.setattr(intervals, "SYSTEMATIC", {})
    plain = parameter_intervals(space, cov)
    monkeypatch.setattr(intervals, "SYSTEMATIC", {"cooktorrance": {"specular_reflectance": 0.05}})
    out = parameter_intervals(space, cov)
    q, values = t.ppf(0.975, 40.0), space.values(x)
    assert out["roughness"] == plain["roughness"]  # no term named for it
    for k, f in enumerate(space.free):
        if f.name != "specular_reflectance":
            continue
        value = values[f.name][f.channel]
        slope = (space.entry_value(f, x[k] + 1e-6) - space.entry_value(f, x[k] - 1e-6)) / 2e-6
        half = np.hypot(q * np.sqrt(var[k]), norm.ppf(0.975) * 0.05 * value / slope)
        lo, hi = out[f.name]["interval95"][0][f.channel], out[f.name]["interval95"][1][f.channel]
        assert (lo, hi) == pytest.approx((space.entry_value(f, x[k] - half), space.entry_value(f, x[k] + half)),
                                         rel=1e-6)
        assert out[f.name]["std"][f.channel] == pytest.approx(plain[f.name]["std"][f.channel])
        assert out[f.name]["systematic_std"][f.channel] == pytest.approx(0.05 * value)
        assert hi - lo > 0.05 * 2 * 1.9 * value > plain[f.name]["interval95"][1][f.channel] - \
            plain[f.name]["interval95"][0][f.channel]
    model = brdf_models.model("lafortune")
    space = ParameterSpace(model)
    x = np.zeros(len(space))
    x[[k for k, f in enumerate(space.free) if f.name == "cz"]] = 1.0
    cov = Covariance(x, np.eye(len(x)) * 1e-6, np.zeros(len(x), bool), 50.0, "jackknife")
    monkeypatch.setattr(intervals, "SYSTEMATIC", {"lafortune": {"cz": 0.1}})
    out, values = parameter_intervals(space, cov), space.values(x)
    (lo, hi), std = out["cz"]["interval95"], out["cz"]["std"]
    half = np.hypot(t.ppf(0.975, 50.0) * np.asarray(std), norm.ppf(0.975) * 0.1 * np.abs(values["cz"]))
    assert np.all(half > 4 * np.asarray(std))  # the systematic part dominates here
    assert lo == pytest.approx(np.asarray(values["cz"]) - half, rel=1e-6)


def test_the_systematic_terms_are_those_the_tuning_chose():
    """:data:`intervals.SYSTEMATIC` holds what ``validation/reflectance_coverage.py --tune`` chose, model by
    model and parameter by parameter (a zero choice is left out)."""
    import json
    from pathlib import Path

    from mifaces.reflectance.fit.intervals import SYSTEMATIC

    tuning = json.loads((Path(__file__).resolve().parents[1] / "validation/results/"
                         "reflectance_coverage_tuning.json").read_text())
    chosen = {model: {name: row["chosen_systematic"] for name, row in params.items() if row["chosen_systematic"]}
              for model, params in tuning["summary"].items()}
    assert SYSTEMATIC == {model: params for model, params in chosen.items() if params}


def _cooktorrance_problem(rng, n: int):
    """The LM problem of ``n`` noisy samples of the Cook–Torrance :data:`TRUTH`, and a point near it."""
    from mifaces.reflectance.fit.problem import Problem
    from mifaces.reflectance.fit.parameters import ParameterSpace

    light, view = directions(rng, n), directions(rng, n)
    r = reflectance(TRUTH, light, view) + 0.02 * rng.normal(size=(n, 3))
    space = ParameterSpace(brdf_models.model("cooktorrance"), FIXED)
    problem = Problem(space.model, space, light.astype(np.float32), view.astype(np.float32), r.astype(np.float32),
                      np.full(n, 0.5, np.float32))
    return problem, space.vector(TRUTH) + 0.1


def test_cluster_sums_match_the_per_sample_jacobian():
    """The kernel's per-cluster u_g and H_g equal sums of the host-side residuals and Jacobian; they
    add up to the fit's own JᵀJ, and its loss is the fit's."""
    rng = np.random.default_rng(7)
    n = 300
    problem, x = _cooktorrance_problem(rng, n)
    index, groups = cluster_index(rng.integers(0, 40, n) * 3)
    u, hg, loss = problem.cluster_sums(x, index, groups)
    jtj, _, fit_loss = problem.system(x)
    np.testing.assert_allclose(hg.sum(axis=0), jtj, rtol=1e-5)
    assert loss == pytest.approx(fit_loss, rel=1e-6)
    res, jac = problem.residuals_and_jacobian(x)
    res, jac = res.reshape(3, n).T.astype(np.float64), jac.reshape(3, n, -1).transpose(1, 0, 2).astype(np.float64)
    for g in (0, groups // 2, groups - 1):
        members = index == g
        np.testing.assert_allclose(u[g], np.einsum("ncp,nc->p", jac[members], res[members]), rtol=1e-4, atol=1e-6)
        np.testing.assert_allclose(hg[g], np.einsum("ncp,ncq->pq", jac[members], jac[members]), rtol=1e-4, atol=1e-6)


def test_regions_with_different_numbers_of_clusters_share_one_kernel():
    """The per-cluster sums' accumulator is padded to a power of two: 37 and 45 clusters run the same
    compiled kernel (its per-thread copies' size is a literal of the kernel), with the right sums."""
    import drjit as dr

    n = 400
    problem, x = _cooktorrance_problem(np.random.default_rng(8), n)
    jtj = problem.system(x)[0]
    hashes = []
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for groups in (37, 45):
            dr.kernel_history()
            _, hg, _ = problem.cluster_sums(x, np.arange(n) % groups, groups)
            launched = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
            hashes.append(max(launched, key=lambda k: k["operation_count"])["hash"])
            assert hg.shape[0] == groups
            np.testing.assert_allclose(hg.sum(axis=0), jtj, rtol=1e-5)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert hashes[0] == hashes[1]


def test_tile_clusters():
    """Texels (row · R + column) fall into tiles of ``tile`` texels a side, numbered row by row."""
    r = 8
    texel = np.array([0, 1, 2, 8, 9, 18, 63])  # (0,0) (0,1) (0,2) (1,0) (1,1) (2,2) (7,7)
    assert tile_clusters(texel, r, 2).tolist() == [0, 0, 1, 0, 0, 5, 15]
    many = np.random.default_rng(0).integers(0, 256 * 256, 500)
    assert np.array_equal(tile_clusters(many, 256), tile_clusters(many, 256, 2 * TILE_AT_128))  # scaled
    with pytest.raises(ValueError, match="tile"):
        tile_clusters(texel, r, 0)


def test_tile_clusters_give_small_regions_smaller_tiles():
    """A region in fewer than ``min_tiles`` tiles gets tiles half as wide until it has that many (or they
    are single texels); a large region keeps the full tile, and no cluster spans two regions."""
    r = 64
    rows, cols = np.meshgrid(np.arange(r), np.arange(r), indexing="ij")
    texel = (rows * r + cols).ravel()
    small = (rows < 8) & (cols < 8)  # one 8-texel tile of 64 texels
    label = np.where(small, 2, 1).ravel()
    cluster = tile_clusters(texel, r, 8, label=label, min_tiles=4)
    assert len(np.unique(cluster[label == 2])) == 4  # halved once: 4 tiles of 4 texels a side
    assert len(np.unique(cluster[label == 1])) == 63  # the rest keeps its 8-texel tiles
    assert not set(cluster[label == 1]) & set(cluster[label == 2])
    # without a floor the small region is one tile, and so is the partition within each region
    plain = tile_clusters(texel, r, 8, label=label, min_tiles=1)
    assert len(np.unique(plain[label == 2])) == 1
    assert np.array_equal(np.unique(plain[label == 1], return_inverse=True)[1],
                          np.unique(tile_clusters(texel[label == 1], r, 8), return_inverse=True)[1])
    # a floor no tiling reaches ends at single texels
    tiny = tile_clusters(texel[:3], r, 8, label=np.zeros(3, int), min_tiles=10)
    assert len(np.unique(tiny)) == 3
    with pytest.raises(ValueError, match="label"):
        tile_clusters(texel, r, 8, label=label[:5])


def test_albedo_posterior_std_matches_its_error():
    """Texel albedos drawn around the region's with spread τ, samples with noise s₀: the shrunk
    albedo's error over the texels has the RMS the posterior std predicts (within 10 %), and a texel
    without samples gets τ."""
    rng = np.random.default_rng(4)
    r, per = 64, rng.integers(1, 6, size=64 * 64)
    per[0] = 0  # one texel without samples
    texel = np.repeat(np.arange(r * r), per)
    n = len(texel)
    true = 0.4 + 0.05 * rng.normal(size=(r * r, 3))
    light, view = directions(rng, n), directions(rng, n)
    params = {1: {**TRUTH, "diffuse_reflectance": [0.4] * 3}}
    spec = reflectance({**params[1], "diffuse_reflectance": [0.0] * 3}, light, view)
    obs = true[texel] + spec + 0.08 * rng.normal(size=(n, 3))
    samples = ReflectanceSamples(light, view, obs, np.ones(n), texel, np.zeros(n, np.int16), r,
                                 label=np.ones(n, np.uint8))
    diffuse = refine_diffuse("cooktorrance", params, samples, np.ones((r, r), np.uint8))
    err = diffuse.albedo.reshape(-1, 3) - true
    std = diffuse.std.reshape(-1, 3)
    seen = per > 0
    z = err[seen] / std[seen]
    assert np.sqrt(np.mean(z ** 2)) == pytest.approx(1.0, rel=0.1)
    assert std[0] == pytest.approx([0.05] * 3, rel=0.25)


def _alternated(light, view, r, texel, cluster, rounds=6, aware=True, method="jackknife", start=None):
    """The region fit alternated ``rounds`` times with the texel albedo, as ``fit_brdf(...,
    albedo_rounds=rounds)`` does for one region (unshrunk texel means as offsets); the last fit's
    intervals with the offsets re-estimated per replicate (``aware``) or taken as known."""
    n = len(r)
    sigma, label = np.ones(n), np.ones(n, int)
    side = int(np.ceil(np.sqrt(texel.max() + 1)))
    fit = fit_region("cooktorrance", RegionSamples(light, view, r, sigma), options=ONE_STAGE, start=start,
                     uncertainty=Uncertainty(method, cluster) if rounds == 0 and method else None)
    for k in range(rounds):
        samples = ReflectanceSamples(light, view, r, sigma, texel, np.zeros(n, np.int16), side, label=label)
        albedo = refine_diffuse("cooktorrance", {1: fit.params}, samples, np.ones((side, side), int), shrinkage=False)
        offsets = AlbedoOffsets.of(albedo, texel, label)
        last = k == rounds - 1
        intervals = Uncertainty(method, cluster, offsets if aware else None) if last and method else None
        fit = fit_region("cooktorrance", RegionSamples(light, view, r - offsets.offsets, sigma), options=ONE_STAGE,
                         uncertainty=intervals, start=fit.params)
    return fit


def _texel_problem(rng, texels, per_texel=6, tile=4):
    """Samples of ``texels`` texels seen ``per_texel`` times from random directions (a face's texel
    under several lamps and poses), in tiles of ``tile`` texels."""
    n = texels * per_texel
    texel = np.repeat(np.arange(texels), per_texel)
    light, view = directions(rng, n), directions(rng, n)
    return light, view, reflectance(TRUTH, light, view), texel, texel // tile


def _draw(rng, clean, texel, texel_sd=0.08, noise_sd=0.02):
    return clean + texel_sd * rng.normal(size=(texel.max() + 1, 3))[texel] + noise_sd * rng.normal(size=clean.shape)


def test_offset_aware_jackknife_matches_refitting_each_replicate():
    """The one-step replicate with the offsets folded in against the jackknife done the long way:
    per tile left out, the whole alternation rerun on the other tiles (offsets re-estimated, the fit
    refitted) to convergence. The intervals that take the offsets as known are far too narrow on the
    diffuse albedo, whose spread between texels the offsets absorbed."""
    rng = np.random.default_rng(1)
    light, view, clean, texel, cluster = _texel_problem(rng, texels=60)
    r = _draw(rng, clean, texel)
    fit = _alternated(light, view, r, texel, cluster, rounds=12)
    naive = _alternated(light, view, r, texel, cluster, rounds=12, aware=False)
    space = ParameterSpace(brdf_models.model("cooktorrance"), FIXED)
    x = space.vector(fit.params)
    groups = cluster.max() + 1
    steps = np.array([space.vector(_alternated(light[cluster != g], view[cluster != g], r[cluster != g],
                                               texel[cluster != g], cluster[cluster != g], rounds=12,
                                               method=None, start=fit.params).params) - x for g in range(groups)])
    jac = _value_jacobian(space, x)
    exact = np.sqrt(np.diag(jac @ ((groups - 1) / groups * steps.T @ steps) @ jac.T))
    names = [(f.name, f.channel) for f in space.free]
    for k, (name, channel) in enumerate(names):
        std = fit.uncertainty[name]["std"]
        std = std if channel is None else std[channel]
        assert std == pytest.approx(exact[k], rel=0.15), (name, channel, std, exact[k])
    assert naive.uncertainty["diffuse_reflectance"]["std"][0] < 0.3 * fit.uncertainty["diffuse_reflectance"]["std"][0]


def test_offset_aware_intervals_hold_the_truth():
    """Over repeated draws of texel albedos and noise, the intervals of the alternated fit hold the true
    diffuse albedo about as often as they say when the offsets are re-estimated per replicate, almost
    never when the offsets are taken as known."""
    rng = np.random.default_rng(5)
    light, view, clean, texel, cluster = _texel_problem(rng, texels=80)
    hits = {True: [], False: []}
    for _ in range(16):
        r = _draw(rng, clean, texel)
        for aware in (True, False):
            fit = _alternated(light, view, r, texel, cluster, rounds=4, aware=aware)
            row = []
            for name, true, channel in (("diffuse_reflectance", 0.5, 0), ("specular_reflectance", 0.8, 0),
                                        ("roughness", 0.5, None)):
                lo, hi = fit.uncertainty[name]["interval95"]
                row.append(bool((lo if channel is None else lo[channel]) <= true
                                <= (hi if channel is None else hi[channel])))
            hits[aware].append(row)
    aware, naive = np.mean(hits[True], axis=0), np.mean(hits[False], axis=0)
    assert aware[0] >= 0.75 and naive[0] <= 0.25, (aware, naive)
    assert np.all(aware[1:] >= 0.75), aware


def test_offset_sums_need_texels_inside_clusters():
    texel = np.array([0, 0, 1, 1])
    with pytest.raises(ValueError, match="one cluster"):
        offset_sums(texel, np.array([0, 1, 1, 1]), 2, np.ones(2), np.zeros((2, 3, 1)), np.zeros((4, 3)),
                    np.zeros((4, 3)))
