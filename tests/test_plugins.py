"""The Mitsuba BSDF plugins: sampling, reference agreement, parameters, rendering."""

from __future__ import annotations

import re

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from conftest import REPO
from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

import mifaces
from mifaces import brdf
from mifaces.plugins import plugin_class

PLUGINS = list(brdf.NAMES)

# Rough, medium and sharp settings of each plugin's glossy lobe, with a diffuse part.
SETTINGS = {
    "phong": {"rough": {"exponent": 2.0}, "medium": {"exponent": 30.0}, "sharp": {"exponent": 300.0}},
    "cooktorrance": {"rough": {"roughness": 0.8}, "medium": {"roughness": 0.3}, "sharp": {"roughness": 0.08}},
    "ward": {"rough": {"alpha": 0.8}, "medium": {"alpha": 0.3}, "sharp": {"alpha": 0.08}},
    "lafortune": {"rough": {"exponent": 2.0, "cxy": -0.9, "cz": 0.9},
                  "medium": {"exponent": 30.0, "cxy": -1.0, "cz": 1.0,
                             "cxy_2": 0.5, "cz_2": 0.6, "exponent_2": 3.0},
                  "sharp": {"exponent": 300.0, "cxy": -1.0, "cz": 1.0}},
}
INCIDENCE = {"normal": 0.0, "oblique": 50.0, "grazing": 85.0}


def direction(theta_deg, phi_deg=20.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return [float(np.sin(t) * np.cos(p)), float(np.sin(t) * np.sin(p)), float(np.cos(t))]


def bsdf_dict(name, **params):
    """A plugin with a coloured diffuse part and, where the model has one, a
    coloured ``specular_reflectance`` given as RGB (whose channel mean sets
    how often the glossy part is sampled)."""
    d = {"type": name, "diffuse_reflectance": {"type": "rgb", "value": [0.3, 0.25, 0.2]}}
    if any(p.name == "specular_reflectance" for p in brdf.model(name).specular_parameters()):
        d["specular_reflectance"] = {"type": "rgb", "value": [0.6, 0.5, 0.4]}
    d.update(params)
    return d


@pytest.mark.parametrize("incidence", INCIDENCE)
@pytest.mark.parametrize("setting", ["rough", "medium", "sharp"])
@pytest.mark.parametrize("name", PLUGINS)
def test_chi2_sampling(jit_variant, name, setting, incidence):
    """Mitsuba's chi-square test: sample() draws from the density pdf() states."""
    sample_func, pdf_func = BSDFAdapter(name, bsdf_dict(name, **SETTINGS[name][setting]),
                                        wi=direction(INCIDENCE[incidence]))
    chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, res=201 if setting == "sharp" else 101, ires=16 if setting == "sharp" else 8,
                         sample_count=1_000_000)
    assert chi2.run(), chi2.messages


# --------------------------------------------------------------------------
def random_frame_queries(n, seed=0):
    rng = np.random.default_rng(seed)
    def hemi():
        v = rng.normal(size=(n, 3))
        v[:, 2] = np.abs(v[:, 2]) + 0.02
        return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)
    return hemi(), hemi()


def plugin_eval(bsdf, wi, wo):
    """Plugin eval (with cosine) and pdf at arrays of local directions."""
    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = mi.Vector3f(wi.T)
    si.uv = mi.Point2f(0.5, 0.5)
    ctx = mi.BSDFContext()
    value, pdf = bsdf.eval_pdf(ctx, si, mi.Vector3f(wo.T))
    return np.array(value).T, np.array(pdf)


def test_cooktorrance_smith_matches_roughconductor(jit_variant):
    """Cook-Torrance with Smith G, no Fresnel, no diffuse = Mitsuba's
    roughconductor (Beckmann, all normals sampled, perfect mirror), to 1e-4."""
    wi, wo = random_frame_queries(50000, seed=1)
    for m in (0.05, 0.2, 0.6):
        ours = mi.load_dict({"type": "cooktorrance", "diffuse_reflectance": 0.0, "specular_reflectance": 1.0,
                             "roughness": m, "fresnel": "none", "geometry": "smith"})
        ref = mi.load_dict({"type": "roughconductor", "distribution": "beckmann", "alpha": m,
                            "sample_visible": False, "material": "none"})
        f_ours, pdf_ours = plugin_eval(ours, wi, wo)
        f_ref, pdf_ref = plugin_eval(ref, wi, wo)
        significant = f_ref > 1e-6 * f_ref.max()
        assert significant.sum() > 1000
        np.testing.assert_allclose(f_ours[significant], f_ref[significant], rtol=1e-4)
        assert np.all(np.abs(f_ours[~significant]) <= 2e-6 * f_ref.max())
        sig_pdf = pdf_ref > 1e-6 * pdf_ref.max()
        np.testing.assert_allclose(pdf_ours[sig_pdf], pdf_ref[sig_pdf], rtol=1e-4)


@pytest.mark.parametrize("name", PLUGINS)
def test_pure_diffuse_matches_builtin_diffuse(variant, name):
    """With the glossy part switched off every plugin is Mitsuba's diffuse."""
    zero = {scale: 0.0 for scale in brdf.model(name).lobe_scales()[1]}
    ours = mi.load_dict({"type": name, "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.4, 0.2]}, **zero})
    ref = mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.4, 0.2]}})
    assert ours.flags() == ref.flags()
    ctx = mi.BSDFContext()
    rng = np.random.default_rng(5)
    for _ in range(3 if not dr.is_jit_v(mi.Float) else 1):
        n = 1000 if dr.is_jit_v(mi.Float) else 1
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        wi = rng.normal(size=(3, n)); wi[2] = np.abs(wi[2]); wi /= np.linalg.norm(wi, axis=0)
        wo = rng.normal(size=(3, n)); wo /= np.linalg.norm(wo, axis=0)
        s1, s2 = rng.uniform(size=n), rng.uniform(size=(2, n))
        if not dr.is_jit_v(mi.Float):
            wi, wo, s1, s2 = wi[:, 0], wo[:, 0], float(s1[0]), s2[:, 0]
        si.wi = mi.Vector3f(wi)
        wo = mi.Vector3f(wo)
        np.testing.assert_allclose(np.array(ours.eval(ctx, si, wo)), np.array(ref.eval(ctx, si, wo)), rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(np.array(ours.pdf(ctx, si, wo)), np.array(ref.pdf(ctx, si, wo)), rtol=1e-6, atol=1e-7)
        bs_o, w_o = ours.sample(ctx, si, s1, mi.Point2f(s2))
        bs_r, w_r = ref.sample(ctx, si, s1, mi.Point2f(s2))
        np.testing.assert_allclose(np.array(bs_o.wo), np.array(bs_r.wo), atol=1e-6)
        np.testing.assert_allclose(np.array(w_o), np.array(w_r), rtol=1e-5, atol=1e-6)


PLUGIN_CONFIGS = [
    ("phong", {"specular_reflectance": 0.4, "exponent": 25.0}),
    ("cooktorrance", {"roughness": 0.2, "eta": 1.5, "fresnel": "schlick", "geometry": "vcavity"}),
    ("cooktorrance", {"roughness": 0.35, "fresnel": "dielectric", "geometry": "smith"}),
    ("ward", {"alpha": 0.15, "normalization": "duer2006"}),
    ("ward", {"alpha": 0.3}),
    ("lafortune", {"cxy": -0.8, "cz": 0.9, "exponent": 12.0, "cxy_2": 0.3, "cz_2": 0.4, "exponent_2": 2.0}),
]


@pytest.mark.parametrize("name,params", PLUGIN_CONFIGS, ids=[c[0] for c in PLUGIN_CONFIGS])
def test_array_api_matches_plugin_eval(variant, name, params):
    """The plugin's eval is the array API's f times cos θo, from the same code."""
    options = {k: v for k, v in params.items() if isinstance(v, str)}
    values = {k: v for k, v in params.items() if not isinstance(v, str)}
    bsdf = mi.load_dict({"type": name, "diffuse_reflectance": {"type": "rgb", "value": [0.5, 0.3, 0.2]}, **params})
    if name == "lafortune":
        options["lobes"] = 2
    model = brdf.model(name, **options)
    full = {**model.defaults(), **values, "diffuse_reflectance": mi.Color3f(0.5, 0.3, 0.2)}
    n = 2000 if dr.is_jit_v(mi.Float) else 1
    wi, wo = random_frame_queries(max(n, 1), seed=7)
    if dr.is_jit_v(mi.Float):
        f_plugin, _ = plugin_eval(bsdf, wi, wo)
        f_array = np.array(model.eval(mi.Vector3f(wi.T), mi.Vector3f(wo.T), full)).T * wo[:, 2:3]
    else:
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(wi[0])
        f_plugin = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo[0])))
        f_array = np.array(model.eval(mi.Vector3f(wi[0]), mi.Vector3f(wo[0]), full)) * wo[0, 2]
    np.testing.assert_allclose(f_plugin, f_array, rtol=1e-6, atol=1e-9)


# --------------------------------------------------------------------------
def test_traverse_exposes_every_parameter_as_differentiable(jit_variant):
    for name in PLUGINS:
        bsdf = mi.load_dict({"type": name, "cxy_2": 0.1, "cz_2": 0.2, "exponent_2": 3.0}
                            if name == "lafortune" else {"type": name})
        params = mi.traverse(bsdf)
        model = bsdf.model if name != "lafortune" else brdf.model("lafortune", lobes=2)
        expected = {p.name for p in model.specular_parameters()}
        keys = set(params.keys())
        assert expected <= keys, f"{name}: missing {expected - keys}"
        assert any(k.startswith("diffuse_reflectance") for k in keys)
        for key in keys:
            assert params.flags(key) & mi.ParamFlags.NonDifferentiable.value == 0, key


def test_parameter_update_changes_eval_without_new_kernels(jit_variant):
    bsdf = mi.load_dict({"type": "cooktorrance", "roughness": 0.3})
    wi, wo = random_frame_queries(64, seed=3)
    before, _ = plugin_eval(bsdf, wi, wo)
    params = mi.traverse(bsdf)
    params["roughness"] = 0.1
    params.update()
    after, _ = plugin_eval(bsdf, wi, wo)
    assert not np.allclose(before, after)
    # A further update reuses the compiled kernel: the roughness is opaque.
    params["roughness"] = 0.12
    params.update()
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history()  # clear
        plugin_eval(bsdf, wi, wo)
        history = dr.kernel_history([dr.KernelType.JIT])
    assert history and all(k["cache_hit"] for k in history), history


def test_gradient_of_render_with_respect_to_roughness(jit_variant):
    """Differentiable parameters: the derivative of a rendered image with respect to the plugin's
    roughness, traced through the render, is the central difference of renders with the same samples
    (a point light and emitter sampling only: the image is a smooth function of the roughness);
    ``mi.render``'s gradient, which draws samples of its own, agrees with it in sign and size."""
    scene = mi.load_file(str(REPO / "scenes" / "sphere.xml"), res=32, spp=4, bsdf="cooktorrance")
    params = mi.traverse(scene)
    key = "sphere.bsdf.roughness"
    roughness, h = float(params[key][0]), 0.003

    def mean_image(value):
        params[key] = value
        params.update()
        return float(np.mean(np.array(mi.render(scene, spp=4, seed=3), np.float64)))

    difference = (mean_image(roughness + h) - mean_image(roughness - h)) / (2 * h)
    params[key] = roughness
    dr.enable_grad(params[key])
    params.update()
    traced = scene.integrator().render(scene, scene.sensors()[0], seed=3, spp=4)
    dr.backward(dr.mean(traced, axis=None))
    assert difference != 0 and float(dr.grad(params[key])[0]) == pytest.approx(difference, rel=0.01)
    dr.clear_grad(params[key])
    image = mi.render(scene, params, spp=4)
    dr.backward(dr.mean(image, axis=None))
    grad = np.array(dr.grad(params[key]))
    assert grad.shape == (1,) and np.isfinite(grad[0]) and 0.5 < grad[0] / difference < 2.0


@pytest.mark.parametrize("name", PLUGINS)
def test_zero_parts_are_left_out(variant, name):
    """A zero-weight part sets no flag and is neither evaluated nor sampled."""
    glossy_off = {scale: 0.0 for scale in brdf.model(name).lobe_scales()[1]}
    only_glossy = mi.load_dict({"type": name, "diffuse_reflectance": 0.0})
    only_diffuse = mi.load_dict({"type": name, **glossy_off})
    both = mi.load_dict({"type": name})
    G, D = mi.BSDFFlags.GlossyReflection, mi.BSDFFlags.DiffuseReflection
    assert mi.has_flag(only_glossy.flags(), G) and not mi.has_flag(only_glossy.flags(), D)
    assert mi.has_flag(only_diffuse.flags(), D) and not mi.has_flag(only_diffuse.flags(), G)
    assert mi.has_flag(both.flags(), G) and mi.has_flag(both.flags(), D)
    assert both.component_count() == 2 and only_glossy.component_count() == 1


def test_zero_lafortune_lobe_is_dropped(jit_variant):
    bsdf = mi.load_dict({"type": "lafortune", "cxy_2": 0.0, "cz_2": 0.0, "exponent_2": 5.0,
                         "cxy_3": -0.5, "cz_3": 0.5, "exponent_3": 4.0})
    assert bsdf.model.lobes == (1, 3)
    params = mi.traverse(bsdf)
    assert "cxy_2" in params  # still exposed, so it can be set again
    params["cz_2"] = mi.Color3f(0.3)
    params.update()
    assert bsdf.model.lobes == (1, 2, 3)


def test_one_sided_zero_below_horizon(variant):
    for name in PLUGINS:
        bsdf = mi.load_dict({"type": name})
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(direction(30))
        ctx = mi.BSDFContext()
        below = mi.Vector3f(direction(120))
        assert dr.all(bsdf.eval(ctx, si, below) == 0, axis=None)
        assert dr.all(bsdf.pdf(ctx, si, below) == 0, axis=None)
        si.wi = mi.Vector3f(direction(100))
        bs, w = bsdf.sample(ctx, si, 0.3, mi.Point2f(0.2, 0.7))
        assert dr.all(w == 0, axis=None)


def test_bad_options_are_named(variant):
    with pytest.raises(Exception, match="fresnel='conductor'"):
        mi.load_dict({"type": "cooktorrance", "fresnel": "conductor"})
    with pytest.raises(Exception, match="normalization"):
        mi.load_dict({"type": "ward", "normalization": "ashikhmin"})
    with pytest.raises(Exception, match="roughness = 4.0 is outside"):
        mi.load_dict({"type": "cooktorrance", "roughness": {"type": "checkerboard", "color0": 4.0}})
    with pytest.raises(Exception, match="must be a number or a texture"):
        mi.load_dict({"type": "cooktorrance", "roughness": {"type": "diffuse"}})


def test_bitmap_diffuse_reflectance(jit_variant, tmp_path):
    image = np.zeros((4, 4, 3), dtype=np.float32)
    image[:, :2] = [0.8, 0.1, 0.1]
    image[:, 2:] = [0.1, 0.1, 0.8]
    path = tmp_path / "albedo.exr"
    mi.Bitmap(image).write(str(path))
    bsdf = mi.load_dict({"type": "ward", "specular_reflectance": 0.0,
                         "diffuse_reflectance": {"type": "bitmap", "filename": str(path), "raw": True,
                                                 "filter_type": "nearest"}})
    si = dr.zeros(mi.SurfaceInteraction3f, 2)
    si.wi = mi.Vector3f(0, 0, 1)
    si.uv = mi.Point2f([0.1, 0.9], [0.5, 0.5])
    value = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0, 0, 1))).T
    np.testing.assert_allclose(value, np.array([[0.8, 0.1, 0.1], [0.1, 0.1, 0.8]]) / np.pi, rtol=1e-5)


def test_parameter_textures_vary_per_texel(jit_variant):
    """specular_reflectance and roughness as bitmaps: each texel evaluates as
    the plugin with that texel's values; the textures are traversed and a
    value set out of range through them is refused."""
    def bitmap(values):
        return {"type": "bitmap", "bitmap": mi.Bitmap(np.array([[[v] for v in values]], np.float32)), "raw": True,
                "filter_type": "nearest"}

    scales, widths = [0.5, 1.6], [0.15, 0.4]
    textured = mi.load_dict({"type": "cooktorrance", "diffuse_reflectance": 0.2,
                             "specular_reflectance": bitmap(scales), "roughness": bitmap(widths)})
    si = dr.zeros(mi.SurfaceInteraction3f, 2)
    si.wi = mi.Vector3f(direction(30))
    si.uv = mi.Point2f([0.25, 0.75], [0.5, 0.5])
    wo = mi.Vector3f(direction(35, 200))
    value = np.array(textured.eval(mi.BSDFContext(), si, wo))
    for texel, (scale, width) in enumerate(zip(scales, widths)):
        plain = mi.load_dict({"type": "cooktorrance", "diffuse_reflectance": 0.2, "specular_reflectance": scale,
                              "roughness": width})
        expected = np.array(plain.eval(mi.BSDFContext(), si, wo))[:, 0]  # the same directions everywhere
        np.testing.assert_allclose(value[:, texel], expected, rtol=1e-5)
    assert not np.allclose(value[:, 0], value[:, 1])
    params = mi.traverse(textured)
    assert "roughness.data" in params and "specular_reflectance.data" in params
    params["roughness.data"] = mi.TensorXf(np.full((1, 2, 1), 3.0, np.float32))
    with pytest.raises(Exception, match="roughness"):
        params.update()


def test_xml_documentation_is_present(variant):
    """help() of every plugin shows the formula, a row per option and
    parameter, and an XML example that loads as that plugin."""
    for name in PLUGINS:
        doc = plugin_class(name).__doc__
        cls = brdf.MODELS[name]
        assert "f(wi, wo)" in doc and "Example" in doc and "diffuse_reflectance" in doc
        model = cls(**cls.EXAMPLE_OPTIONS)
        for key in [*cls.OPTIONS, *(p.name for p in model.parameters())]:
            assert re.search(rf"^    {key} +", doc, re.M), (name, key)
        example = doc[doc.index("<bsdf", doc.index("Example::")):doc.index("</bsdf>") + len("</bsdf>")]
        bsdf = mi.load_string(example.replace("<bsdf ", '<bsdf version="3.0.0" ', 1))
        assert type(bsdf.model) is cls and bsdf.model.options == model.options


# --------------------------------------------------------------------------
# Rendering: the sphere scene, against the array API at the analytic normals.

def analytic_sphere_image(scene_args, model, params, res):
    """Radiance of the sphere scene at pixel centres from the array API:
    L = f(l, v) · cos θl · I / d², with the sphere's analytic normals."""
    fov, dist, radius = 17.0, 0.8, 0.1
    light = np.array([scene_args["light_x"], scene_args["light_y"], scene_args["light_z"]])
    half = np.tan(np.radians(fov) / 2)
    px = (np.arange(res) + 0.5) / res * 2 - 1
    x, y = np.meshgrid(px * half, -px * half)
    d = np.stack([x, y, -np.ones_like(x)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array([0, 0, dist])
    b = (d @ o)
    c = o @ o - radius ** 2
    disc = b * b - c
    hit = disc > 0
    t = -b - np.sqrt(np.maximum(disc, 0))
    p = o + t[..., None] * d
    n = p / radius
    to_light = light - p
    dist2 = np.sum(to_light ** 2, axis=-1)
    l = to_light / np.sqrt(dist2)[..., None]
    v = -d
    # local frame: any tangent frame works for isotropic models
    t1 = np.cross(n, [0.0, 1.0, 0.3])
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    t2 = np.cross(n, t1)
    def local(w):
        return np.stack([np.sum(w * t1, -1), np.sum(w * t2, -1), np.sum(w * n, -1)], -1)
    wl, wv = local(l).reshape(-1, 3), local(v).reshape(-1, 3)
    f = np.array(model.eval(mi.Vector3f(wl.T.astype(np.float32)), mi.Vector3f(wv.T.astype(np.float32)),
                            params)).T.reshape(res, res, 3)
    radiance = f * np.maximum(wl[:, 2], 0).reshape(res, res, 1) * scene_args["intensity"] / dist2[..., None]
    # pixels whose whole footprint is on the sphere (no silhouette)
    inner = np.zeros_like(hit)
    inner[1:-1, 1:-1] = hit[:-2, 1:-1] & hit[2:, 1:-1] & hit[1:-1, :-2] & hit[1:-1, 2:] & hit[1:-1, 1:-1]
    return radiance * hit[..., None], inner


@pytest.mark.parametrize("render_variant", ["llvm_ad_rgb", "scalar_rgb"])
@pytest.mark.parametrize("name", PLUGINS)
def test_sphere_scene_matches_array_api(render_variant, name):
    mifaces.set_variant(render_variant)
    res = 64 if render_variant == "llvm_ad_rgb" else 24
    args = {"light_x": -0.35, "light_y": 0.35, "light_z": 0.6, "intensity": 1.0}
    scene = mi.load_file(str(REPO / "scenes" / "sphere.xml"), bsdf=name, res=res, spp=64, **args)
    image = np.array(mi.render(scene))
    mifaces.set_variant("llvm_ad_rgb")
    bsdf = mi.load_dict({"type": name, "diffuse_reflectance": {"type": "rgb", "value": [0.55, 0.38, 0.30]}})
    model = brdf.model(name, **bsdf.model.options) if name != "lafortune" else bsdf.model
    params = {**model.defaults(), "diffuse_reflectance": mi.Color3f(0.55, 0.38, 0.30)}
    expected, inner = analytic_sphere_image(args, model, params, res)
    assert inner.sum() > 0.3 * res * res
    # pixel averages against pixel-centre values: compare where the image is smooth
    err = np.abs(image - expected)[inner]
    scale = np.abs(expected[inner]).max()
    assert np.median(err) < 2e-3 * scale, np.median(err) / scale
    assert np.percentile(err, 95) < 3e-2 * scale, np.percentile(err, 95) / scale
    assert np.all(image[~inner.astype(bool) & (expected.sum(-1) == 0)][:, :] >= 0)


def test_skin_boundary_reflects_cook_torrance_and_transmits_the_rest(jit_variant):
    """skinboundary: outside, the Cook–Torrance glossy lobe; straight through with
    weight 1 - F (what a volumetric path tracer's shadow rays see); sampling picks
    the null transmission with probability 1 - F, outside and inside."""
    params = {"specular_reflectance": 0.8, "roughness": 0.3, "eta": 1.38}
    boundary = mi.load_dict({"type": "skinboundary", **params})
    lobe = mi.load_dict({"type": "cooktorrance", "diffuse_reflectance": 0.0, **params})
    n = 4096
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(direction(60))
    ctx = mi.BSDFContext()
    wo = mi.Vector3f(direction(40, 200))
    np.testing.assert_allclose(np.array(boundary.eval(ctx, si, wo)), np.array(lobe.eval(ctx, si, wo)), rtol=1e-5)
    fresnel = float(np.asarray(mi.fresnel(mi.Float(np.cos(np.radians(60))), mi.Float(1.38))[0])[0])
    np.testing.assert_allclose(np.array(boundary.eval_null_transmission(si))[:, 0], 1 - fresnel, rtol=1e-5)
    u = (np.arange(n) + 0.5) / n
    for wi in (direction(60), [-x for x in direction(60)]):  # from outside, from inside the medium
        si.wi = mi.Vector3f(wi)
        bs, weight = boundary.sample(ctx, si, mi.Float(u), mi.Point2f(mi.Float(u[::-1]), mi.Float(u)))
        null = np.array(bs.sampled_type) == int(mi.BSDFFlags.Null)
        assert abs(null.mean() - (1 - fresnel)) < 0.01
        np.testing.assert_allclose(np.array(weight)[:, null], 1.0)
        np.testing.assert_allclose(np.array(bs.wo)[:, null], -np.array(wi)[:, None] * np.ones(null.sum()), atol=1e-6)
