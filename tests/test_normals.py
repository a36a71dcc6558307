"""Normals with a fitted analytic BRDF (mifaces.photometric_stereo.nonlambertian)."""

from __future__ import annotations

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np
import pytest

from mifaces import brdf, photometric_stereo as ps
from mifaces.photometric_stereo import nonlambertian as nm

#: The glossy part of the synthetic sphere: a sharp Cook-Torrance lobe.
GLOSSY = {"specular_reflectance": [0.4] * 3, "roughness": 0.15, "eta": 1.4}
NOISE = 0.005


def _sphere(size=31):
    """Orthographic unit sphere (x right, y up, z to the camera): mask (H, W), normals (P, 3)."""
    u = np.linspace(-1.0, 1.0, size)
    x, y = np.meshgrid(u, -u)
    mask = x ** 2 + y ** 2 < 0.9
    normals = np.stack([x[mask], y[mask], np.sqrt(1.0 - x[mask] ** 2 - y[mask] ** 2)], axis=1)
    return mask, normals


def _lights(count=24, seed=0):
    d = np.random.default_rng(seed).normal(size=(count, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.0
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _local(vectors, normals):
    """Vectors (P, 3) in a frame with z = normal, built independently (Gram-Schmidt from x or y)."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = helper - np.sum(helper * normals, axis=1, keepdims=True) * normals
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(normals, t)
    return np.stack([np.sum(vectors * t, 1), np.sum(vectors * b, 1), np.sum(vectors * normals, 1)], axis=1)


def _render(normals, albedo, lights, seed=1):
    """(ρ + π f_s) max(0, n·l) + noise with mifaces.brdf's array API, (K, P, 3)."""
    import mitsuba as mi

    model = brdf.model("cooktorrance")
    view = _local(np.tile([0.0, 0.0, 1.0], (len(normals), 1)), normals)
    out = []
    for light in lights:
        wi = _local(np.tile(light, (len(normals), 1)), normals)
        f = model.eval(mi.Vector3f(wi.T.astype(np.float32)), mi.Vector3f(view.T.astype(np.float32)),
                       {**GLOSSY, "diffuse_reflectance": 0.0}, diffuse=False)
        cos = np.maximum(wi[:, 2], 0.0)[:, None]
        out.append((albedo + np.pi * np.array(f, np.float64).T) * cos)
    values = np.stack(out)
    return values + np.random.default_rng(seed).normal(scale=NOISE, size=values.shape)


@pytest.fixture(scope="module")
def sphere():
    mask, normals = _sphere()
    lights = _lights()
    albedo = np.array([0.5, 0.4, 0.3]) * (1.0 + 0.2 * normals[:, :1])
    values = _render(normals, albedo, lights)
    images = np.zeros((len(lights),) + mask.shape + (3,))
    images[:, mask] = values
    ps_albedo, ps_normals = ps.fit(images, lights, mask)
    return {"mask": mask, "normals": normals, "albedo": albedo, "lights": lights, "values": values,
            "weights": nm.observation_weights(values), "ps_normals": ps_normals[mask], "ps_albedo": ps_albedo[mask]}


def _degrees(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


def test_predict_is_the_array_api_rendering(sphere):
    predicted = nm.predict("cooktorrance", GLOSSY, sphere["albedo"], sphere["normals"], sphere["lights"])
    noise_free = _render(sphere["normals"], sphere["albedo"], sphere["lights"]) - \
        np.random.default_rng(1).normal(scale=NOISE, size=predicted.shape)
    np.testing.assert_allclose(predicted, noise_free, atol=2e-5, rtol=1e-4)


def test_normal_step_with_the_true_brdf_beats_lambertian_stereo(sphere):
    lambertian = _degrees(sphere["ps_normals"], sphere["normals"]).mean()
    pixels = nm.LitPixels(sphere["values"], sphere["lights"], sphere["weights"])
    fit = nm.refine_normals("cooktorrance", GLOSSY, pixels, sphere["ps_normals"], albedo=sphere["ps_albedo"],
                            options=nm.NormalStepOptions(iterations=40))
    error = _degrees(fit.normals, sphere["normals"])
    assert lambertian > 1.0  # measured 1.2: the highlights tilt the Lambertian normals
    assert error.mean() < 0.45 and error.mean() < lambertian / 3  # measured 0.29 (41 x 41: 0.29)
    np.testing.assert_allclose(fit.albedo, sphere["albedo"], atol=0.03)
    assert all(b <= a for a, b in zip(fit.history, fit.history[1:]))


def test_alternation_recovers_normals_and_brdf(sphere):
    lambertian = _degrees(sphere["ps_normals"], sphere["normals"]).mean()
    pixels = nm.LitPixels(sphere["values"], sphere["lights"], sphere["weights"])
    estimate = nm.fit_normals_and_brdf("cooktorrance", pixels, sphere["ps_normals"], sphere["ps_albedo"],
                                       options=nm.AlternationOptions(rounds=4))
    error = _degrees(estimate.normals, sphere["normals"])
    assert error.mean() < 0.5 and error.mean() < lambertian / 2.5
    assert estimate.brdf.params["roughness"] == pytest.approx(GLOSSY["roughness"], rel=0.1)
    losses = [entry["loss"] for entry in estimate.history]
    assert estimate.loss == min(losses) and estimate.loss < 0.5 * losses[0]


def test_prior_keeps_an_unobserved_pixel_at_its_prior_normal(sphere):
    weights = sphere["weights"].copy()
    weights[:, 7] = 0.0  # pixel 7: no usable observation
    prior = sphere["ps_normals"].copy()
    prior[7] = [0.6, 0.0, 0.8]
    fit = nm.refine_normals("cooktorrance", GLOSSY, nm.LitPixels(sphere["values"], sphere["lights"], weights),
                            sphere["ps_normals"], albedo=sphere["ps_albedo"], prior=prior,
                            options=nm.NormalStepOptions(iterations=10))
    np.testing.assert_allclose(fit.normals[7], prior[7], atol=1e-6)
    # a well-observed pixel is held by its data, not by a far prior
    assert _degrees(fit.normals[8:9], sphere["normals"][8:9])[0] < 2.0


def test_brdf_samples_carry_the_image_residual(sphere):
    """With the true normals and BRDF, r - (ρ̄ + π f_s) of every sample is the noise / cos θ_i."""
    import mitsuba as mi

    light, view, reflectance, sigma = nm.brdf_samples(sphere["values"], sphere["lights"], sphere["weights"],
                                                      sphere["normals"], sphere["albedo"], max_samples=None)
    used = (sphere["weights"] > 0).sum(axis=0)
    mean_albedo = (used[:, None] * sphere["albedo"]).sum(axis=0) / used.sum()
    f = brdf.model("cooktorrance").eval(mi.Vector3f(light.T.astype(np.float32)),
                                        mi.Vector3f(view.T.astype(np.float32)), {**GLOSSY, "diffuse_reflectance": 0.0})
    residual = (reflectance - mean_albedo - np.pi * np.array(f, np.float64).T) / sigma[:, None]
    assert np.all(light[:, 2] >= nm.MIN_COSINE) and np.allclose(sigma, 1.0 / light[:, 2], rtol=1e-5)
    assert np.sqrt(np.mean(residual ** 2)) == pytest.approx(NOISE, rel=0.15)


def test_shapes_are_checked(sphere):
    with pytest.raises(ValueError, match="weights"):
        nm.LitPixels(sphere["values"], sphere["lights"], sphere["weights"][:, :5])
    with pytest.raises(ValueError, match="directions"):
        nm.LitPixels(sphere["values"], sphere["lights"][:3], sphere["weights"])
    pixels = nm.LitPixels(sphere["values"], sphere["lights"], sphere["weights"])
    with pytest.raises(ValueError, match="normals"):
        nm.refine_normals("ward", {"specular_reflectance": 0.1, "alpha": 0.2}, pixels, sphere["ps_normals"][:5])


def test_the_normal_step_shades_each_observation_once_per_loss_and_per_system(jit_variant):
    """The shading of an observation (the BRDF at every tilt of its footprint) is the step's cost: a loss
    evaluates it in one kernel, not once more in each block sum that reads it, and the Gauss-Newton
    system in its two forward-mode passes alone (the first one also gives s and g)."""
    import drjit as dr
    from mifaces.reflectance.maps.normal_fit import LitPixels
    from mifaces.reflectance.maps.observations import tangents

    rng = np.random.default_rng(3)
    pixels, lights = 500, _lights(8)
    normals = np.tile([0.0, 0.0, 1.0], (pixels, 1)) + rng.normal(scale=0.05, size=(pixels, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    footprint = np.abs(rng.normal(scale=0.01, size=(len(lights), pixels, 3)))
    obs = LitPixels(rng.uniform(0.1, 0.5, (len(lights), pixels, 3)), lights, np.ones((len(lights), pixels)),
                    footprint=footprint).observations(brdf.model("cooktorrance"), GLOSSY)
    t1, t2 = tangents(normals)
    albedo = np.full((pixels, 3), 0.3)

    def kernels(call):
        call()  # compiled once
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history()  # clear
            call()
            return [k["operation_count"] for k in dr.kernel_history([dr.KernelType.JIT])
                    if k["size"] == pixels * len(lights)]

    # a kernel that shades has about as many operations as s and g alone (one kernel); the others a few dozen
    heavy = max(kernels(lambda: obs.shading(normals))) / 2
    assert sum(n >= heavy for n in kernels(lambda: obs.losses(normals))) == 1
    assert sum(n >= heavy for n in kernels(lambda: obs.losses(normals, albedo))) == 1
    assert sum(n >= heavy for n in kernels(lambda: obs.system(normals, albedo, t1, t2))) == 2
