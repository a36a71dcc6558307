"""Resampling a rendered photograph into texture space (mifaces.reflectance.resampling): the samples of
a surface of known BRDF are π f of it; shadowed, hidden and bad photographs' texels give none."""

from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

from mifaces import brdf
from mifaces.capture.camera import PIXEL_BLUR_STD
from mifaces.capture import Camera, Light
from mifaces.model.mesh import mitsuba_mesh
from mifaces.model.texture_space import rasterize
from mifaces.reflectance.resampling import FaceTexture, Photograph, measurement_samples


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
    texture = FaceTexture(triangles, uv, rasterize(uv, triangles, (128, 128)))
    photograph = Photograph(camera, Light("L0", light, intensity), photo, name="m0")
    samples = measurement_samples(photograph, vertices, texture)
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
    texture = FaceTexture(triangles, uv, rasterize(uv, triangles, (128, 128)))
    photograph = Photograph(camera, Light("L0", None, irradiance, direction=towards), photo, name="m0")
    samples = measurement_samples(photograph, vertices, texture)
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
    texture = FaceTexture(triangles, uv, rasterize(uv, triangles, (48, 48)))
    photo = np.full((64, 64, 3), 0.1, np.float32)
    behind = measurement_samples(Photograph(camera, Light("L0", np.array([0.0, 0.0, 600.0]), np.ones(3)), photo),
                                 vertices, texture)
    assert len(behind) == 0
    narrow = Camera(width=64, height=64, fx=400.0, fy=400.0, cx=31.5, cy=31.5)  # sees only the middle
    side = Light("L0", np.array([0.0, -50.0, 0.0]), np.ones(3))
    middle = measurement_samples(Photograph(narrow, side, photo), vertices, texture)
    full = measurement_samples(Photograph(camera, side, photo), vertices, texture)
    assert 0 < len(middle) < 0.5 * len(full)


def test_bad_photographs_are_named(jit_variant):
    camera = Camera(width=64, height=64, fx=60.0, fy=60.0, cx=31.5, cy=31.5)
    vertices, triangles, uv = spherical_cap(n=20)
    lamp = Light("L0", np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match="does not match the camera"):
        Photograph(camera, lamp, np.zeros((32, 64, 3)))
    photo = np.zeros((64, 64, 3), np.float32)
    with pytest.raises(ValueError, match="bounced light of shape"):
        Photograph(camera, lamp, photo, indirect=np.zeros((32, 64, 3)))
    photo[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="1 NaN"):
        Photograph(camera, lamp, photo)
    raster = rasterize(uv, triangles, (16, 16))
    with pytest.raises(ValueError, match="do not match the 16x16 texture"):
        FaceTexture(triangles, uv, raster, np.zeros((8, 8), np.uint8))
