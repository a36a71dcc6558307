"""The pixel's footprint in the fit (mifaces.reflectance.footprint): the normals' spread over a
pixel, its tilts, and a fit that recovers the material's lobe from samples that averaged it."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

from dataclasses import replace

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mifaces import brdf
from mifaces.capture.camera import PIXEL_BLUR_STD
from mifaces.reflectance.fit.region_fit import FULL_DATA, RegionFitOptions, RegionSamples, fit_region
from mifaces.reflectance.footprint import (MAX_TILT, POINTS, normal_spread, seen_by_pixel, spread_arrays, tilted,
                                          tilts)
from mifaces.reflectance.samples import ReflectanceSamples

TRUTH = {"diffuse_reflectance": [0.3, 0.2, 0.15], "specular_reflectance": [0.9, 0.9, 0.9], "roughness": 0.25,
         **brdf.model("cooktorrance").fixed_defaults()}


def _spread(values: np.ndarray) -> tuple:
    return tuple(mi.Float(np.ascontiguousarray(c, np.float32)) for c in np.asarray(values).T)


def _vectors(a: np.ndarray) -> mi.Vector3f:
    return mi.Vector3f(np.ascontiguousarray(np.asarray(a, np.float32).T))


def test_the_tilts_have_the_footprints_covariance():
    cov = np.array([[0.004, 0.001, 0.002], [0.0, 0.0, 0.003], [0.01, -0.004, 0.002]])
    points = [(np.array(x, np.float64) * np.ones(3), np.array(y, np.float64) * np.ones(3), w)
              for x, y, w in tilts(_spread(cov))]
    assert len(points) == POINTS
    x = np.stack([p[0] for p in points])
    y = np.stack([p[1] for p in points])
    w = np.array([p[2] for p in points])[:, None]
    assert w.sum() == pytest.approx(1.0)
    np.testing.assert_allclose((w * x).sum(0), 0.0, atol=1e-7)
    np.testing.assert_allclose((w * y).sum(0), 0.0, atol=1e-7)
    np.testing.assert_allclose(np.stack([(w * x * x).sum(0), (w * x * y).sum(0), (w * y * y).sum(0)], 1), cov,
                               rtol=1e-5, atol=1e-9)
    # and a Gaussian's fourth moment along an axis, 3 σ⁴ (what keeps a lobe narrower than the footprint right)
    np.testing.assert_allclose((w * x ** 4).sum(0)[:2], 3 * cov[:2, 0] ** 2, rtol=1e-5)


def test_what_the_pixel_saw_is_the_weighted_sum_over_the_tilted_normals():
    rng = np.random.default_rng(4)
    light = rng.normal(size=(40, 3)) * [0.4, 0.4, 0.2] + [0, 0, 1]
    light /= np.linalg.norm(light, axis=1, keepdims=True)
    view = np.tile([0.1, 0.0, 1.0], (40, 1)) / np.hypot(0.1, 1.0)
    wi, wo = _vectors(light), _vectors(view)
    model = brdf.model("cooktorrance")
    params = {k: (mi.Color3f(v) if np.ndim(v) else v) for k, v in TRUTH.items()}

    def f(a, b):
        return model.eval(a, b, params)

    points = np.array(seen_by_pixel(f, wi, wo, ()))
    np.testing.assert_array_equal(points, np.array(f(wi, wo)))  # no footprint: the lobe at the normal
    spread = spread_arrays(np.tile([0.004, 0.001, 0.003], (40, 1)), 40)
    by_hand = sum(np.array(f(a, b)) * np.array(w) for a, b, w in tilted(wi, wo, spread))
    np.testing.assert_allclose(np.array(seen_by_pixel(f, wi, wo, spread)), by_hand, rtol=1e-6)
    assert not np.allclose(by_hand, points, rtol=1e-3)  # the footprint changed what was seen
    with pytest.raises(ValueError, match=r"footprint must have shape \(40, 3\)"):
        spread_arrays(np.zeros((39, 3)), 40)


def test_tilted_frames_turn_the_directions_and_weigh_by_the_lights_cosine():
    rng = np.random.default_rng(1)
    light = rng.normal(size=(50, 3)) * [0.5, 0.5, 0.2] + [0, 0, 1]
    light /= np.linalg.norm(light, axis=1, keepdims=True)
    view = np.tile([0.0, 0.0, 1.0], (50, 1))
    spread = _spread(np.tile([0.003, 0.0, 0.001], (50, 1)))
    out = tilted(_vectors(light), _vectors(view), spread)
    weights = np.stack([np.array(w) for _, _, w in out])
    for (a, b, w), (_, _, share) in zip(out, tilts(spread)):
        a, b = np.array(a).T, np.array(b).T
        # each normal's f counts as the pixel saw it: its share times cos θl' of that normal over cos θl
        np.testing.assert_allclose(np.array(w), share * np.maximum(a[:, 2], 0) / light[:, 2], rtol=1e-5)
        np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-5)  # rotations keep lengths
        np.testing.assert_allclose(np.sum(a * b, 1), np.sum(light * view, 1), atol=1e-5)  # and angles
    # the view along the normal: unturned by the centre point, turned by the tilt itself by the next
    # (a normal (x, y, 1) normalised: atan x)
    np.testing.assert_allclose(np.array(out[0][1]).T, view, atol=1e-6)
    angle = np.arctan(np.sqrt(3 * 0.003))
    np.testing.assert_allclose(np.array(out[1][1]).T[0], [-np.sin(angle), 0.0, np.cos(angle)], atol=1e-5)
    # the weights are cos θl' / (POINTS cos θl): their sum is the mean cosine ratio, 1 - O(tilt²)
    np.testing.assert_allclose(weights.sum(0), 1.0, atol=0.01)


def _cylinder(radius: float, pixel_mm: float, resolution: int = 64):
    """A cylinder along y of ``radius`` mm, seen along -z by an orthographic camera of ``pixel_mm`` mm
    per pixel; texture u along the arc (``resolution`` texels over ±0.5 rad), v along y."""
    u, v = np.meshgrid(np.linspace(-0.5, 0.5, resolution), np.linspace(-10, 10, resolution))
    position = np.stack([radius * np.sin(u), v, radius * np.cos(u)], -1).reshape(-1, 3)
    normal = np.stack([np.sin(u), 0 * u, np.cos(u)], -1).reshape(-1, 3)
    tangent = np.stack([np.cos(u), 0 * u, -np.sin(u)], -1).reshape(-1, 3)
    bitangent = np.cross(normal, tangent)
    xy = position[:, :2] / pixel_mm + 100.0  # pixel centres at integers: frac 0
    return xy, normal, tangent, bitangent, np.arange(resolution * resolution)


def _expected(xy, radius, pixel_mm):
    """tt of the cylinder: a pixel along x turns the normal by pixel_mm / (radius cos u), over the
    blur's and the bilinear read's variance; bb and tb are 0 (along y the normal does not turn)."""
    u = np.arcsin(np.clip((xy[:, 0] - 100.0) * pixel_mm / radius, -1, 1))
    frac = xy[:, 0] - np.floor(xy[:, 0])
    return (PIXEL_BLUR_STD ** 2 + frac * (1 - frac)) * (pixel_mm / (radius * np.cos(u))) ** 2


def test_the_normals_spread_over_a_pixel_of_a_cylinder():
    radius, pixel_mm = 20.0, 0.1
    xy, n, t, b, texel = _cylinder(radius, pixel_mm)
    spread = normal_spread(xy, n, t, b, texel, 64)
    inner = np.zeros((64, 64), bool)
    inner[1:-1, 1:-1] = True
    inner = inner.ravel()
    np.testing.assert_allclose(spread[inner, 0], _expected(xy, radius, pixel_mm)[inner], rtol=0.02)
    np.testing.assert_allclose(spread[:, 1:], 0.0, atol=1e-12)


def test_the_bilinear_read_widens_the_footprint_between_pixel_centres():
    xy, n, t, b, texel = _cylinder(20.0, 0.1)
    centred = normal_spread(xy - (xy - np.floor(xy)), n, t, b, texel, 64)  # same derivatives, frac 0 ...
    halfway = normal_spread(np.floor(xy) + 0.5, n, t, b, texel, 64)  # ... and frac ½
    assert np.all(halfway[:, 0] >= centred[:, 0])
    ratio = (halfway[:, 0] / np.maximum(centred[:, 0], 1e-30)).reshape(64, 64)[5:-5, 5:-5]
    np.testing.assert_allclose(np.median(ratio), (PIXEL_BLUR_STD ** 2 + 0.25) / PIXEL_BLUR_STD ** 2, rtol=0.05)


def test_no_derivative_across_a_seam_and_no_tilt_beyond_the_cap():
    xy, n, t, b, texel = _cylinder(20.0, 0.1)
    xy = xy.reshape(64, 64, 2).copy()
    xy[:, 32:] += 500.0  # the right half lies elsewhere in the photograph: a seam of the layout
    spread = normal_spread(xy.reshape(-1, 2), n, t, b, texel, 64).reshape(64, 64, 3)
    assert np.all(np.isfinite(spread))
    assert spread[:, 31:33, 0].max() < 2 * spread[:, 20, 0].max()
    sharp = normal_spread(np.round(_cylinder(0.05, 0.1)[0]), *_cylinder(0.05, 0.1)[1:], 64)
    assert np.all(sharp[:, 0] + sharp[:, 2] <= MAX_TILT ** 2 * (1 + 1e-9))


def _footprint_truth(light, view, spread, grid: int = 9):
    """r = π Σ f(l', v') cos θl' / cos θl over a Gauss–Hermite grid of the Gaussian tilts: what a
    pixel of that footprint sees (the reference the four-point average must approach)."""
    model = brdf.model("cooktorrance")
    nodes, weights = np.polynomial.hermite_e.hermegauss(grid)
    weights = weights / weights.sum()
    total = np.zeros((len(light), 3))
    cov = np.stack([np.stack([spread[:, 0], spread[:, 1]], 1), np.stack([spread[:, 1], spread[:, 2]], 1)], 1)
    root = np.linalg.cholesky(cov + 1e-15 * np.eye(2))
    for i, (xi, wx) in enumerate(zip(nodes, weights)):
        for yi, wy in zip(nodes, weights):
            tilt = np.einsum("nij,j->ni", root, [xi, yi])
            normal = np.concatenate([tilt, np.ones((len(light), 1))], 1)
            normal /= np.linalg.norm(normal, axis=1, keepdims=True)
            axis = np.stack([-normal[:, 1], normal[:, 0], 0 * normal[:, 0]], 1)

            def turned(w):
                return w * normal[:, 2:] - np.cross(axis, w) + axis * (np.sum(axis * w, 1) / (1 + normal[:, 2]))[:, None]

            a, b = turned(light), turned(view)
            f = np.array(model.eval(_vectors(a), _vectors(b), TRUTH)).T
            total += wx * wy * f * np.maximum(a[:, 2:], 0) / light[:, 2:]
    return np.pi * total


def _directions(rng, n: int, spread: float) -> np.ndarray:
    """``n`` random unit directions about the normal, their tangent parts of standard deviation ``spread``
    before normalising (the light's draws first, then the view's: the order fixes the samples)."""
    w = rng.normal(size=(n, 3)) * [spread, spread, 0.0] + [0, 0, 1]
    return w / np.linalg.norm(w, axis=1, keepdims=True)


@pytest.fixture(scope="module")
def averaged_samples():
    rng = np.random.default_rng(4)
    n = 4000
    light, view = _directions(rng, n, 0.6), _directions(rng, n, 0.5)
    tt, bb = rng.uniform(0.001, 0.008, n), rng.uniform(0.0005, 0.004, n)
    tb = rng.uniform(-0.5, 0.5, n) * np.sqrt(tt * bb)
    spread = np.stack([tt, tb, bb], 1)
    return light, view, _footprint_truth(light, view, spread), np.ones(n), spread


def test_the_fit_recovers_the_lobe_that_the_pixels_averaged(averaged_samples):
    light, view, r, sigma, spread = averaged_samples
    options = RegionFitOptions(schedule=FULL_DATA)
    with_footprint = fit_region("cooktorrance", RegionSamples(light, view, r, sigma, footprint=spread),
                                options=options, uncertainty=None)
    as_points = fit_region("cooktorrance", RegionSamples(light, view, r, sigma), options=options, uncertainty=None)
    m = TRUTH["roughness"]
    assert abs(with_footprint.params["roughness"] / m - 1) < 0.005, with_footprint.params
    np.testing.assert_allclose(with_footprint.params["specular_reflectance"], TRUTH["specular_reflectance"], rtol=0.01)
    # read as points, the same samples show a wider lobe: the bias the footprint takes out
    assert as_points.params["roughness"] / m - 1 > 0.02, as_points.params


def test_the_footprint_rejects_what_is_no_covariance(averaged_samples):
    light, view, r, sigma, spread = averaged_samples
    bad = spread.copy()
    bad[0] = [0.001, 0.01, 0.001]  # |tb| > √(tt bb)
    with pytest.raises(ValueError, match="covariances"):
        RegionSamples(light, view, r, sigma, footprint=bad)
    with pytest.raises(ValueError, match="shape"):
        RegionSamples(light, view, r, sigma, footprint=spread[:10])


def test_samples_keep_their_footprint_through_select_concatenate_and_save(tmp_path):
    n = 6
    part = ReflectanceSamples(light=np.zeros((n, 3), np.float32), view=np.zeros((n, 3), np.float32),
                              reflectance=np.zeros((n, 3), np.float32), sigma=np.ones(n, np.float32),
                              texel=np.arange(n, dtype=np.int32), measurement=np.zeros(n, np.int16), resolution=8,
                              measurement_names=("a",), footprint=np.arange(3 * n, dtype=np.float32).reshape(n, 3))
    both = ReflectanceSamples.concatenate([part, part])
    np.testing.assert_array_equal(both.footprint, np.concatenate([part.footprint] * 2))
    np.testing.assert_array_equal(both.select(np.arange(12) % 2 == 0).footprint, both.footprint[::2])
    both.save(tmp_path / "s.npz")
    np.testing.assert_array_equal(ReflectanceSamples.load(tmp_path / "s.npz").footprint, both.footprint)


def test_the_normal_step_shades_with_the_footprint():
    from mifaces.reflectance.maps.observations import Observations

    model = brdf.model("cooktorrance")
    glossy = {k: TRUTH[k] for k in ("specular_reflectance", "roughness", "eta")}
    rng = np.random.default_rng(2)
    k, p = 3, 40
    light = rng.normal(size=(k, p, 3)) * [0.4, 0.4, 0.0] + [0, 0, 1]
    light /= np.linalg.norm(light, axis=2, keepdims=True)
    view = np.tile([0.1, 0.0, 1.0], (k, p, 1)) / np.sqrt(1.01)
    normals = np.tile([0.0, 0.0, 1.0], (p, 1))
    spread = np.tile([0.006, 0.001, 0.003], (k, p, 1))
    _, g = Observations(model, glossy, light, view, p, footprint=spread).shading(normals)
    _, g_point = Observations(model, glossy, light, view, p).shading(normals)
    # by hand: π f_s cos θl over the four tilted normals, averaged
    flat = spread.reshape(-1, 3)
    expected = np.zeros((k * p, 3))
    for x, y, share in tilts(_spread(flat)):
        n = np.stack([np.array(x) * np.ones(len(flat)), np.array(y) * np.ones(len(flat)), np.ones(len(flat))], 1)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        frame = mi.Frame3f(_vectors(n))
        wi, wo = frame.to_local(_vectors(light.reshape(-1, 3))), frame.to_local(_vectors(view.reshape(-1, 3)))
        cos = np.maximum(np.array(wi.z), 0.0) * (np.array(wo.z) > 0)
        expected += np.pi * np.array(model.eval(wi, wo, glossy, diffuse=False)).T * cos[:, None] * share
    np.testing.assert_allclose(g.reshape(-1, 3), expected, rtol=1e-4, atol=1e-7)
    assert np.max(np.abs(g - g_point)) > 1e-3 * np.max(g_point)  # and it differs from the point's shading


def test_a_lobe_as_narrow_as_the_footprint_keeps_its_scale(monkeypatch):
    """The eyes' case: a lobe of roughness 0.06 under a tilt of 0.05 rad per axis. The five tilted
    normals (the centre one among them) keep ρs within 10 % and the width within 15 %; read as points
    the lobe is half again as wide (four outer normals alone took the peak for a third of itself)."""
    monkeypatch.setitem(TRUTH, "roughness", 0.06)
    rng = np.random.default_rng(5)
    n = 6000
    light, view = _directions(rng, n, 0.3), _directions(rng, n, 0.3)
    spread = np.tile([0.0025, 0.0, 0.0025], (n, 1))
    r = _footprint_truth(light, view, spread, grid=15)
    one_stage = RegionFitOptions(schedule=FULL_DATA)
    fit = fit_region("cooktorrance", RegionSamples(light, view, r, np.ones(n), footprint=spread), options=one_stage,
                     uncertainty=None)
    assert abs(fit.params["roughness"] / 0.06 - 1) < 0.15, fit.params  # measured +11 %
    assert abs(fit.params["specular_reflectance"][0] / 0.9 - 1) < 0.1, fit.params  # measured +6.8 %
    points = fit_region("cooktorrance", RegionSamples(light, view, r, np.ones(n)), options=one_stage, uncertainty=None)
    assert points.params["roughness"] / 0.06 - 1 > 0.4, points.params


def test_the_albedo_map_takes_out_the_gloss_that_the_pixel_saw(monkeypatch):
    """The per-texel albedo (``refine_diffuse``) subtracts the fitted glossy part as the fit predicts it,
    averaged over each sample's footprint. Read at the sample's normal alone, a narrow lobe's peak
    was taken for the pixel's: the texels where the highlights lay came out too dark (the eyes, by 0.15)."""
    from mifaces.model.regions import REGIONS
    from mifaces.reflectance.maps.diffuse import refine_diffuse

    monkeypatch.setitem(TRUTH, "roughness", 0.06)
    rng = np.random.default_rng(6)
    size, per_texel = 8, 40
    n = size * size * per_texel
    light, view = _directions(rng, n, 0.3), _directions(rng, n, 0.3)
    spread = np.tile([0.0025, 0.0, 0.0025], (n, 1))
    r = _footprint_truth(light, view, spread, grid=15)
    skin = REGIONS["skin"]
    samples = ReflectanceSamples(light=light.astype(np.float32), view=view.astype(np.float32),
                                 reflectance=r.astype(np.float32), sigma=np.ones(n, np.float32),
                                 texel=np.repeat(np.arange(size * size), per_texel).astype(np.int32),
                                 measurement=np.zeros(n, np.int16), resolution=size, measurement_names=("a",),
                                 footprint=spread.astype(np.float32))
    samples.label = np.full(n, skin, np.uint8)
    region_map = np.full((size, size), skin, np.uint8)
    truth = np.asarray(TRUTH["diffuse_reflectance"])

    def worst(s):
        albedo = refine_diffuse("cooktorrance", {skin: TRUTH}, s, region_map, shrinkage=False).albedo
        return np.abs(albedo.reshape(-1, 3) / truth - 1).max()

    assert worst(samples) < 0.08  # measured 4.9 % (the five normals' error on a lobe this narrow)
    assert worst(replace(samples, footprint=None)) > 0.3  # measured 50 %
    from mifaces.reflectance.maps.diffuse import specular_reflectance_factor
    with pytest.raises(ValueError, match="footprint must have shape"):
        specular_reflectance_factor("cooktorrance", {skin: TRUTH}, light, view, samples.label, spread[:5])
