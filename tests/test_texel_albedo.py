"""The glossy fit with an albedo per texel (``RegionFitOptions(texel_albedo=True)``, ``FitOptions(texel_albedo=True)``):
the per-texel albedo eliminated from the problem (variable projection), so that an albedo texture that
follows the highlights does not leak into the lobe."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip


import mitsuba as mi
import numpy as np
import pytest

from mifaces import brdf
from mifaces.reflectance.fit.parameters import ParameterSpace
from mifaces.reflectance.fit.problem import Problem
from mifaces.reflectance.fit.region_fit import RegionFitOptions, RegionSamples, Uncertainty, fit_region

TRUTH = {"specular_reflectance": [1.3, 1.3, 1.3], "roughness": 0.3, "eta": 1.38}


def _hemisphere(rng, n, min_cos=0.2):
    v = rng.normal(size=(4 * n, 3))
    v[:, 2] = np.abs(v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v[v[:, 2] > min_cos][:n]


def textured_samples(texels=3000, per_texel=5, seed=0, noise=0.01):
    """Reflectance samples of a Cook–Torrance surface (:data:`TRUTH`) whose albedo differs per texel
    and is darker the nearer the texel sees the highlight, as on a face whose highlights fall on its
    paler or darker parts: each texel's samples lie a texel-specific spread from the mirror
    direction, its albedo grows with that spread; r = a_t + π f_s, relative noise."""
    rng = np.random.default_rng(seed)
    n = texels * per_texel
    texel = np.repeat(np.arange(texels), per_texel)
    spread = rng.uniform(0.05, 0.8, texels)
    view = _hemisphere(rng, n, min_cos=0.4)
    light = view * np.array([-1.0, -1.0, 1.0]) + spread[texel, None] * rng.normal(size=(n, 3))
    light[:, 2] = np.maximum(light[:, 2], 0.2)
    light /= np.linalg.norm(light, axis=1, keepdims=True)
    model = brdf.model("cooktorrance")
    params = {**TRUTH, "diffuse_reflectance": [0.0, 0.0, 0.0]}
    p = {k: (mi.Color3f(*v) if isinstance(v, list) else mi.Float(v)) for k, v in params.items()}
    glossy = np.pi * np.array(model.eval(mi.Vector3f(light.T.astype(np.float32)),
                                        mi.Vector3f(view.T.astype(np.float32)), p)).T
    albedo = 0.15 + 0.4 * spread / spread.max() + 0.05 * rng.random(texels)  # darker under the highlights
    albedo = np.stack([albedo, 0.7 * albedo, 0.5 * albedo], axis=1)
    r = (albedo[texel] + glossy) * (1 + noise * rng.normal(size=glossy.shape))
    sigma = 1.0 / (light[:, 2] ** 2 * view[:, 2])
    return light, view, r.astype(np.float32), sigma.astype(np.float32), texel, albedo


def test_the_projected_system_is_the_fit_with_each_texels_albedo_eliminated(jit_variant):
    """Problem(texel=...).system: the normal equations of the residuals with each texel's best albedo
    subtracted, as formed from the residuals and Jacobian by the long way (weighted centring per texel)."""
    light, view, r, sigma, texel, _ = textured_samples(texels=200, per_texel=4)
    model = brdf.model("cooktorrance")
    space = ParameterSpace(model, {"eta": 1.38, "diffuse_reflectance": [0.0, 0.0, 0.0]})
    x = space.vector({"specular_reflectance": [1.0, 1.1, 1.2], "roughness": 0.35})
    projected = Problem(model, space, light, view, r, sigma, texel=texel)
    jtj, jtr, loss = projected.system(x)
    res, jac = Problem(model, space, light, view, r, sigma).residuals_and_jacobian(x)
    w = np.tile(1.0 / sigma.astype(np.float64), 3)  # residuals are channel-major: (3, N) raveled
    group = np.concatenate([texel + c * 200 for c in range(3)])  # a texel's albedo per channel

    def centre(v):
        mean = np.bincount(group, w * v) / np.bincount(group, w * w)
        return v - w * mean[group]

    rc = centre(res.astype(np.float64))
    jc = np.stack([centre(jac[:, k].astype(np.float64)) for k in range(jac.shape[1])], axis=1)
    np.testing.assert_allclose(loss, 0.5 * rc @ rc, rtol=1e-4)
    np.testing.assert_allclose(jtr, jc.T @ rc, rtol=1e-3, atol=1e-6 * np.abs(jc.T @ rc).max())
    np.testing.assert_allclose(jtj, jc.T @ jc, rtol=1e-3, atol=1e-6 * np.abs(jc.T @ jc).max())
    assert loss < Problem(model, space, light, view, r, sigma).loss(x)  # the albedo at 0 fits worse


def test_a_texture_darker_under_the_highlights_biases_the_one_albedo_fit_not_the_texel_one(jit_variant):
    light, view, r, sigma, texel, albedo = textured_samples()
    samples, options = RegionSamples(light, view, r, sigma, texel=texel), RegionFitOptions(fixed={"eta": 1.38})
    one = fit_region("cooktorrance", samples, options=options, uncertainty=None)
    per_texel = fit_region("cooktorrance", samples, start=one.params, uncertainty=None,
                           options=RegionFitOptions(fixed={"eta": 1.38}, texel_albedo=True))
    truth_s = TRUTH["specular_reflectance"][0]
    # the one albedo reads the texture's departures from it as part of the lobe
    assert abs(np.mean(one.params["specular_reflectance"]) / truth_s - 1) > 0.15, one.params
    np.testing.assert_allclose(per_texel.params["specular_reflectance"], truth_s, rtol=0.03)
    assert per_texel.params["roughness"] == pytest.approx(TRUTH["roughness"], rel=0.03)
    assert per_texel.status == "converged" and per_texel.uncertainty == {}
    # the region's albedo: the texels' albedos, weighted by their samples' weights
    weight = np.bincount(texel, 1.0 / sigma.astype(np.float64) ** 2)
    expected = (albedo * weight[:, None]).sum(axis=0) / weight.sum()
    np.testing.assert_allclose(per_texel.params["diffuse_reflectance"], expected, rtol=0.03)


def test_a_texel_fit_is_refused_bad_texels_the_bootstrap_and_split_texels(jit_variant):
    light, view, r, sigma, texel, _ = textured_samples(texels=100, per_texel=3)
    samples, per_texel = RegionSamples(light, view, r, sigma, texel=texel), RegionFitOptions(texel_albedo=True)
    with pytest.raises(ValueError, match="no\\s+bootstrap"):
        fit_region("cooktorrance", samples, options=per_texel, uncertainty=Uncertainty("bootstrap"))
    with pytest.raises(ValueError, match="texel must have shape"):
        RegionSamples(light, view, r, sigma, texel=texel[:-1])
    with pytest.raises(ValueError, match="needs each sample's texel"):
        fit_region("cooktorrance", RegionSamples(light, view, r, sigma), options=per_texel, uncertainty=None)
    with pytest.raises(ValueError, match="every texel's samples in one cluster"):  # a cluster splits texels
        fit_region("cooktorrance", samples, options=per_texel,
                   uncertainty=Uncertainty(cluster=np.arange(len(texel)) % 7))


def test_the_texel_fits_intervals_match_refitting_with_each_cluster_left_out(jit_variant):
    """The jackknife of the fit with an albedo per texel, from its projected sums in one pass, against
    the jackknife that refits (the texels' albedos and the lobe) with each cluster of whole texels left
    out: the glossy parameters' and the region albedo's standard deviations agree within 3 % (the albedo's
    replicates without the glossy part's change: up to 14 % off here)."""
    light, view, r, sigma, texel, _ = textured_samples(texels=150, per_texel=3, seed=1, noise=0.2)
    cluster = texel % 12  # whole texels, each cluster spread over the hemisphere
    options = RegionFitOptions(fixed={"eta": 1.38}, texel_albedo=True)
    fit = fit_region("cooktorrance", RegionSamples(light, view, r, sigma, texel=texel), options=options,
                     uncertainty=Uncertainty("jackknife", cluster),
                     start={**TRUTH, "diffuse_reflectance": [0.3, 0.2, 0.15]})
    assert fit.status == "converged", fit.reason
    replicates = []
    for g in range(12):
        keep = cluster != g
        kept = RegionSamples(light[keep], view[keep], r[keep], sigma[keep], texel=texel[keep])
        refit = fit_region("cooktorrance", kept, options=options, uncertainty=None, start=fit.params)
        replicates.append(np.concatenate([refit.params["specular_reflectance"], [refit.params["roughness"]],
                                          refit.params["diffuse_reflectance"]]))
    replicates = np.array(replicates)
    exact = np.sqrt(11 / 12 * np.sum(np.square(replicates - replicates.mean(axis=0)), axis=0))
    entry = fit.uncertainty
    one_pass = np.concatenate([entry["specular_reflectance"]["std"], [entry["roughness"]["std"]],
                               entry["diffuse_reflectance"]["std"]])
    np.testing.assert_allclose(one_pass, exact, rtol=0.03)
    lo, hi = entry["diffuse_reflectance"]["interval95"]
    assert np.all(np.array(lo) < fit.params["diffuse_reflectance"]) and np.all(fit.params["diffuse_reflectance"] < np.array(hi))


def test_cli_texel_albedo_flag_reaches_the_fit(monkeypatch, tmp_path):
    from click.testing import CliRunner

    import mifaces.cli.commands as cli

    calls = {}

    def fake(*args, **kwargs):
        # fit-brdf: one FitOptions by keyword; measure: one MeasureOptions holding it, the third argument
        options = kwargs["options"] if "options" in kwargs else args[2]
        calls.update(vars(getattr(options, "fit", options)))
        raise SystemExit(0)

    monkeypatch.setattr(cli, "fit_brdf_model", fake)
    monkeypatch.setattr(cli, "measure_capture", fake)
    capture = tmp_path / "capture"
    capture.mkdir()
    for command in ("fit-brdf", "measure"):
        for flags, expected in (([], True), (["--no-texel-albedo"], False), (["--texel-albedo"], True)):
            calls.clear()
            CliRunner().invoke(cli.main, [command, str(capture), "--out", str(tmp_path / command), *flags])
            assert calls.get("texel_albedo") is expected, (command, flags)
