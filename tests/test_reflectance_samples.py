"""Eq. 4, 9 and 10 and the sample mask on hand-made cases."""

from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

from mifaces import brdf
from mifaces.capture.camera import PIXEL_BLUR_STD
from mifaces.capture import Camera, Light
from mifaces.model.mesh import mitsuba_mesh
from mifaces.model.texture_space import rasterize
from mifaces.reflectance.samples import (MIN_COSINE, ReflectanceSamples, confidence, confidence_with_distance,
                                         d_max, distance_to_missing, measurement_samples, reflectance, unsaturated,
                                         valid_samples)


def test_white_lambertian_target_has_reflectance_one():
    # I = 2 W/sr at 0.5 m, lit at 60°: E = 2 · 0.5 / 0.25 = 4 W/m², white Lambertian R = E/π
    radiance = np.full(3, 4.0 / np.pi)
    np.testing.assert_allclose(reflectance(radiance, 0.5, 2.0, 0.5), [1.0, 1.0, 1.0])


def test_reflectance_grows_with_the_square_of_the_light_distance():
    """The physical reading: at twice the distance the same radiance means
    four times the reflectance (the printed eq. 4 would give a quarter)."""
    near = reflectance(np.ones(3), 1.0, 1.0, 1.0)
    far = reflectance(np.ones(3), 2.0, 1.0, 1.0)
    np.testing.assert_allclose(far / near, 4.0)


def test_reflectance_per_channel_intensity_and_invalid_cosine():
    r = reflectance(np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]), np.array([1.0, 1.0]), [1.0, 2.0, 4.0],
                    np.array([1.0, 0.0]), scale=1.0)
    np.testing.assert_allclose(r[0], [1.0, 0.5, 0.25])
    assert np.all(np.isnan(r[1]))


def test_confidence_eq9():
    np.testing.assert_allclose(confidence(1.0, 1.0), 1.0)
    np.testing.assert_allclose(confidence(0.5, 1.0), 4.0)
    np.testing.assert_allclose(confidence(1.0, 0.5), 2.0)
    np.testing.assert_allclose(confidence(np.array([0.5, 0.25]), np.array([0.5, 1.0])), [8.0, 16.0])


def test_confidence_eq10_and_dmax():
    assert d_max(1000) == 10.0 and d_max(512) == 5.12
    # far from any hole, eq. 10 equals eq. 9
    np.testing.assert_allclose(confidence_with_distance(0.5, 1.0, 50.0, 10.0), confidence(0.5, 1.0))
    # at distance 2 of d_max 10: five times less confident
    np.testing.assert_allclose(confidence_with_distance(0.5, 1.0, 2.0, 10.0), 5 * confidence(0.5, 1.0))


def test_distance_to_missing():
    valid = np.ones((7, 7), bool)
    valid[3, 3] = False
    d = distance_to_missing(valid)
    assert d[3, 3] == 0
    assert d[3, 4] == 1 and d[2, 2] == np.sqrt(2)
    # the image border counts as missing
    assert d[0, 0] == 1 and d[3, 0] == 1


def test_valid_samples_drop_shadow_grazing_and_borders():
    n = 21
    light_z = np.full((n, n), 0.9)
    view_z = np.full((n, n), 0.9)
    lit = np.ones((n, n), bool)
    visible = np.ones((n, n), bool)
    lit[:, :5] = False          # cast shadow on the left
    light_z[:, 16:] = 0.05      # grazing light on the right (cos < MIN_COSINE)
    visible[0, :] = False       # occluded top row
    assert 0.05 < MIN_COSINE < 0.9
    mask = valid_samples(light_z, view_z, lit, visible, erosion=1)
    assert not mask[:, :6].any()      # shadow plus one eroded column
    assert not mask[:, 15:].any()     # grazing plus one eroded column
    assert not mask[:2, :].any()      # occluded row plus one
    assert mask[5:15, 7:14].all()
    unchanged = valid_samples(light_z, view_z, lit, visible, erosion=0)
    assert unchanged[1:, 5].all() and not unchanged[:, 4].any()


def test_saturated_pixels_are_dropped():
    pixels = np.array([[0.2, 0.3, 0.4], [0.2, 0.99, 0.4], [1.0, 1.0, 1.0], [0.5, 0.97, 0.1]])
    np.testing.assert_array_equal(unsaturated(pixels, 1.0), [True, False, False, True])


# ---------------------------------------------------------------------------
# Resampling a rendered photograph into texture space

def spherical_cap(n=96, radius=80.0, centre_z=260.0, half=50.0):
    """A cap of a sphere facing a camera at the origin (looking along +z),
    as a grid mesh with uv = ((x + half), (y + half)) / (2 half)."""
    u = np.linspace(0, 1, n)
    uu, vv = np.meshgrid(u, u)
    x, y = (uu - 0.5) * 2 * half, (vv - 0.5) * 2 * half
    z = centre_z - np.sqrt(radius ** 2 - x ** 2 - y ** 2)
    vertices = np.stack([x, y, z], -1).reshape(-1, 3)
    uv = np.stack([uu, vv], -1).reshape(-1, 2)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    # counter-clockwise seen from the camera: normals (b - a) x (c - a) towards -z
    triangles = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    return vertices, triangles, uv


def render_photo(camera, vertices, triangles, uv, light, intensity, bsdf, spp=64, directional=False):
    fov = np.degrees(2 * np.arctan(camera.width / (2 * camera.fx)))
    emitter = ({"type": "directional", "direction": [-float(x) for x in light],
                "irradiance": {"type": "rgb", "value": list(map(float, intensity))}} if directional else
               {"type": "point", "position": list(map(float, light)),
                "intensity": {"type": "rgb", "value": list(map(float, intensity))}})
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "perspective", "fov": fov, "fov_axis": "x",
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, -1, 0]),
                   "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "light": emitter,
        "face": mitsuba_mesh(vertices, triangles, uv, bsdf=bsdf)})
    return np.array(mi.render(scene), dtype=np.float32)


def test_resampled_reflectance_matches_the_brdf(jit_variant):
    """Render a surface of known BRDF, resample the picture into texture
    space: every sample's reflectance is π f(l̂, v̂) of that BRDF."""
    camera = Camera(width=160, height=160, fx=230.0, fy=230.0, cx=79.5, cy=79.5)
    vertices, triangles, uv = spherical_cap()
    light, intensity = np.array([-120.0, -90.0, 20.0]), np.array([3e4, 2.5e4, 2e4])
    params = {"diffuse_reflectance": [0.5, 0.35, 0.3], "specular_reflectance": [1.5] * 3, "roughness": 0.35}
    bsdf = {"type": "cooktorrance", "diffuse_reflectance": {"type": "rgb", "value": params["diffuse_reflectance"]},
            "specular_reflectance": 1.5, "roughness": 0.35}
    photo = render_photo(camera, vertices, triangles, uv, light, intensity, bsdf)
    raster = rasterize(uv, triangles, (128, 128))
    samples = measurement_samples(camera, Light("L0", light, intensity), photo, vertices, triangles, uv, raster,
                                  name="m0")
    assert len(samples) > 0.5 * 128 * 128
    assert np.all(np.isfinite(samples.sigma)) and np.all(samples.sigma >= 1)
    assert np.all(samples.light[:, 2] > 0.17) and np.all(samples.view[:, 2] > 0.17)
    model = brdf.model("cooktorrance")
    p = {"diffuse_reflectance": mi.Color3f(*params["diffuse_reflectance"]), "specular_reflectance": 1.5,
         "roughness": 0.35, "eta": 1.4}
    expected = np.pi * np.array(model.eval(mi.Vector3f(samples.light.T), mi.Vector3f(samples.view.T), p)).T
    rel = np.abs(samples.reflectance - expected) / expected
    assert np.median(rel) < 0.01, np.median(rel)
    assert np.percentile(rel, 95) < 0.05, np.percentile(rel, 95)
    # each sample carries its pixel's footprint: the cap's normals turn by (depth / fx) / radius per
    # pixel where it faces the camera (depth 180 mm), more where it turns away (foreshortening)
    assert samples.footprint.shape == (len(samples), 3)
    facing = 2 * (PIXEL_BLUR_STD ** 2 + 1 / 6) * (180.0 / 230.0 / 80.0) ** 2  # the bilinear read's mean f(1 - f)
    ratio = np.median(samples.footprint[:, 0] + samples.footprint[:, 2]) / facing
    assert 1.0 < ratio < 2.0, ratio


def test_directional_light_reflectance_matches_the_brdf(jit_variant):
    """Under a directional light of irradiance E the samples' reflectance is
    π f of the rendered BRDF: one direction for every texel, no falloff."""
    camera = Camera(width=160, height=160, fx=230.0, fy=230.0, cx=79.5, cy=79.5)
    vertices, triangles, uv = spherical_cap()
    towards = np.array([-0.6, -0.45, -0.66])
    towards /= np.linalg.norm(towards)
    irradiance = np.array([0.8, 0.7, 0.6])
    bsdf = {"type": "cooktorrance", "diffuse_reflectance": {"type": "rgb", "value": [0.5, 0.35, 0.3]},
            "specular_reflectance": 1.5, "roughness": 0.35}
    photo = render_photo(camera, vertices, triangles, uv, towards, irradiance, bsdf, directional=True)
    raster = rasterize(uv, triangles, (128, 128))
    samples = measurement_samples(camera, Light("L0", None, irradiance, direction=towards), photo, vertices,
                                  triangles, uv, raster, name="m0")
    assert len(samples) > 0.4 * 128 * 128
    model = brdf.model("cooktorrance")
    p = {"diffuse_reflectance": mi.Color3f(0.5, 0.35, 0.3), "specular_reflectance": 1.5, "roughness": 0.35,
         "eta": 1.4}
    expected = np.pi * np.array(model.eval(mi.Vector3f(samples.light.T), mi.Vector3f(samples.view.T), p)).T
    rel = np.abs(samples.reflectance - expected) / expected
    assert np.median(rel) < 0.01, np.median(rel)
    assert np.percentile(rel, 95) < 0.05, np.percentile(rel, 95)


def test_shadowed_and_hidden_texels_give_no_sample(jit_variant):
    """A light behind the surface lights nothing; texels outside the image
    give nothing either."""
    camera = Camera(width=64, height=64, fx=60.0, fy=60.0, cx=31.5, cy=31.5)
    vertices, triangles, uv = spherical_cap(n=40)
    raster = rasterize(uv, triangles, (48, 48))
    photo = np.full((64, 64, 3), 0.1, np.float32)
    behind = measurement_samples(camera, Light("L0", np.array([0.0, 0.0, 600.0]), np.ones(3)), photo, vertices,
                                 triangles, uv, raster)
    assert len(behind) == 0
    narrow = Camera(width=64, height=64, fx=400.0, fy=400.0, cx=31.5, cy=31.5)  # sees only the middle
    side = Light("L0", np.array([0.0, -50.0, 0.0]), np.ones(3))
    middle = measurement_samples(narrow, side, photo, vertices, triangles, uv, raster)
    full = measurement_samples(camera, side, photo, vertices, triangles, uv, raster)
    assert 0 < len(middle) < 0.5 * len(full)


def test_bad_photographs_are_named(jit_variant):
    camera = Camera(width=64, height=64, fx=60.0, fy=60.0, cx=31.5, cy=31.5)
    vertices, triangles, uv = spherical_cap(n=20)
    raster = rasterize(uv, triangles, (16, 16))
    with pytest.raises(ValueError, match="does not match the camera"):
        measurement_samples(camera, Light("L0", np.zeros(3), np.ones(3)), np.zeros((32, 64, 3)), vertices, triangles,
                            uv, raster)
    photo = np.zeros((64, 64, 3), np.float32)
    photo[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="1 NaN"):
        measurement_samples(camera, Light("L0", np.zeros(3), np.ones(3)), photo, vertices, triangles, uv, raster)


def test_samples_round_trip_and_concatenate(tmp_path):
    rng = np.random.default_rng(0)

    def part(n, name):
        return ReflectanceSamples(rng.normal(size=(n, 3)).astype(np.float32), rng.normal(size=(n, 3)).astype(np.float32),
                                  rng.uniform(size=(n, 3)).astype(np.float32), rng.uniform(1, 2, n).astype(np.float32),
                                  rng.integers(0, 64, n).astype(np.int32), np.zeros(n, np.int16), 8, (name,))

    both = ReflectanceSamples.concatenate([part(5, "a"), part(7, "b")])
    assert len(both) == 12 and both.measurement_names == ("a", "b")
    assert both.measurement.tolist() == [0] * 5 + [1] * 7
    both.save(tmp_path / "s.npz")
    back = ReflectanceSamples.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(back.reflectance, both.reflectance)
    assert back.measurement_names == ("a", "b") and back.resolution == 8
    region_map = np.arange(64).reshape(8, 8)
    np.testing.assert_array_equal(both.region(region_map), both.texel)
    with pytest.raises(ValueError, match="does not match"):
        both.region(np.zeros((4, 4)))
