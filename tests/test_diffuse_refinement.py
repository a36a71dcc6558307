"""Per-texel diffuse refinement (mifaces.reflectance.maps.diffuse)."""

from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

from mifaces import brdf
from mifaces.reflectance.maps.diffuse import FILL_TEXELS, refine_diffuse, specular_reflectance_factor
from mifaces.reflectance.samples import ReflectanceSamples

REGIONS = {
    1: {"diffuse_reflectance": [0.5, 0.35, 0.3], "specular_reflectance": [2.0] * 3, "roughness": 0.3, "eta": 1.38},
    2: {"diffuse_reflectance": [0.6, 0.2, 0.2], "specular_reflectance": [4.0] * 3, "roughness": 0.15, "eta": 1.38},
}


def labelled(light, view, reflectance, sigma, texel, label, resolution=16) -> ReflectanceSamples:
    """The arrays as samples of one measurement with region labels ``label``."""
    return ReflectanceSamples(light, view, reflectance, sigma, texel, np.zeros(len(sigma), np.int16), resolution,
                              label=label)


def samples_on_a_map(resolution=16, per_texel=6, seed=0):
    rng = np.random.default_rng(seed)
    region_map = np.zeros((resolution, resolution), dtype=int)
    region_map[2:14, 2:9] = 1
    region_map[2:14, 9:14] = 2
    albedo = rng.uniform(0.1, 0.8, (resolution, resolution, 3))
    face = np.flatnonzero(region_map.ravel() > 0)
    observed = face[rng.uniform(size=face.size) > 0.1]  # some face texels get no sample
    texel = np.repeat(observed, per_texel)
    n = texel.size
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2]) + 0.2
    v /= np.linalg.norm(v, axis=2, keepdims=True)
    light, view = v[0], v[1]
    region = region_map.ravel()[texel]
    model = brdf.model("cooktorrance")
    rho = albedo.reshape(-1, 3)[texel]
    r = rho + specular_reflectance_factor(model, REGIONS, light, view, region)
    sigma = 1.0 / (light[:, 2] ** 2 * view[:, 2])
    return model, region_map, albedo, observed, light, view, r, sigma, texel, region


def test_refinement_recovers_a_known_albedo_map(jit_variant):
    model, region_map, albedo, observed, light, view, r, sigma, texel, region = samples_on_a_map()
    result = refine_diffuse(model, REGIONS, labelled(light, view, r, sigma, texel, region), region_map)
    flat = result.albedo.reshape(-1, 3)
    np.testing.assert_allclose(flat[observed], albedo.reshape(-1, 3)[observed], atol=2e-5)
    # face texels without samples take the Gaussian-weighted mean of their region's sampled texels
    # around them (never another region's); outside the face is 0
    missing = np.setdiff1d(np.flatnonzero(region_map.ravel() > 0), observed)
    assert missing.size > 0
    size, labels = region_map.shape[0], region_map.ravel()
    seen = np.zeros(size * size, bool)
    seen[observed] = True
    rows, cols = np.divmod(np.arange(size * size), size)
    reach = int(4 * FILL_TEXELS + 0.5)  # scipy's Gaussian truncates there
    for t in missing:
        same = seen & (labels == labels[t]) & (np.abs(rows - rows[t]) <= reach) & (np.abs(cols - cols[t]) <= reach)
        w = np.exp(-((rows[same] - rows[t]) ** 2 + (cols[same] - cols[t]) ** 2) / (2 * FILL_TEXELS ** 2))
        expected = (w[:, None] * albedo.reshape(-1, 3)[same]).sum(0) / w.sum()
        np.testing.assert_allclose(flat[t], expected, rtol=1e-4)
    assert np.all(flat[region_map.ravel() == 0] == 0)
    # a region without a sampled texel near: its region's albedo
    alone = region != 2
    without = refine_diffuse(model, REGIONS, labelled(light[alone], view[alone], r[alone], sigma[alone], texel[alone],
                                                      region[alone]), region_map)
    np.testing.assert_allclose(without.albedo.reshape(-1, 3)[labels == 2], np.broadcast_to(
        REGIONS[2]["diffuse_reflectance"], ((labels == 2).sum(), 3)), rtol=1e-6)
    assert result.samples.sum() == texel.size and np.all(result.weight.ravel()[observed] > 0)


def test_specular_factor_matches_the_array_api_per_region(jit_variant):
    model, region_map, albedo, observed, light, view, r, sigma, texel, region = samples_on_a_map()
    spec = specular_reflectance_factor(model, REGIONS, light, view, region)
    for label, params in REGIONS.items():
        mask = region == label
        p = {k: (mi.Color3f(*v) if isinstance(v, list) else mi.Float(v)) for k, v in params.items()}
        expected = np.pi * np.array(model.eval(mi.Vector3f(light[mask].T.astype(np.float32)),
                                               mi.Vector3f(view[mask].T.astype(np.float32)), p, diffuse=False)).T
        np.testing.assert_allclose(spec[mask], expected, rtol=1e-6, atol=1e-7)


def test_bad_inputs_are_named(jit_variant):
    model, region_map, albedo, observed, light, view, r, sigma, texel, region = samples_on_a_map()
    with pytest.raises(ValueError, match="square"):
        refine_diffuse(model, REGIONS, labelled(light, view, r, sigma, texel, region), region_map[:, :5])
    with pytest.raises(ValueError, match=r"region label\(s\) \[7\]"):
        refine_diffuse(model, REGIONS, labelled(light, view, r, sigma, texel, np.full_like(region, 7)), region_map)
    with pytest.raises(ValueError, match="texel indices"):
        refine_diffuse(model, REGIONS, labelled(light, view, r, sigma, texel + 10_000, region), region_map)


def test_shrinkage_lowers_the_error_of_sparsely_sampled_texels(jit_variant):
    """With noisy samples, texels seen once are pulled towards their region's
    albedo; well-sampled texels barely move; without shrinkage the plain
    per-texel mean is returned."""
    model, region_map, albedo, observed, light, view, r, sigma, texel, region = samples_on_a_map(per_texel=1)
    rng = np.random.default_rng(1)
    # texel albedos scattered around their region's (τ = 0.03), samples with 5 % noise scaled by σ
    regional = np.array([REGIONS[label]["diffuse_reflectance"] for label in region_map.ravel()[observed]])
    true = albedo.reshape(-1, 3).copy()
    true[observed] = regional + rng.normal(0, 0.03, regional.shape)
    # every observed texel gets one sample; a quarter get eight more
    many = observed[: observed.size // 4]
    extra_t = np.repeat(many, 8)
    lz = np.concatenate([light[:, 2], rng.uniform(0.3, 1.0, extra_t.size)])
    texel = np.concatenate([texel, extra_t])
    region = region_map.ravel()[texel]
    light = np.concatenate([light, np.stack([np.sqrt(1 - lz[-extra_t.size:] ** 2), 0 * extra_t, lz[-extra_t.size:]], 1)])
    view = np.concatenate([view, np.tile([0.0, 0.0, 1.0], (extra_t.size, 1))])
    sigma = 1.0 / (light[:, 2] ** 2 * view[:, 2])
    spec = specular_reflectance_factor(model, REGIONS, light, view, region)
    r = true[texel] + spec + rng.normal(0, 0.05, (texel.size, 3)) * sigma[:, None] / sigma.mean()
    plain = refine_diffuse(model, REGIONS, labelled(light, view, r, sigma, texel, region), region_map, shrinkage=False)
    shrunk = refine_diffuse(model, REGIONS, labelled(light, view, r, sigma, texel, region), region_map)
    once = np.setdiff1d(observed, many)

    def rmse(result, where):
        return np.sqrt(np.mean((result.albedo.reshape(-1, 3)[where] - true[where]) ** 2))

    assert rmse(shrunk, once) < 0.8 * rmse(plain, once)
    assert rmse(shrunk, many) < 1.05 * rmse(plain, many)
    # the plain estimate is the weighted mean of each texel's residuals
    w = 1 / sigma ** 2
    t = many[0]
    mask = texel == t
    expected = (w[mask, None] * (r[mask] - spec[mask])).sum(0) / w[mask].sum()
    np.testing.assert_allclose(plain.albedo.reshape(-1, 3)[t], np.clip(expected, 0, None), rtol=1e-5, atol=1e-6)
