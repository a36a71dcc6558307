"""Region parameters blended across region borders (mifaces.render.blend), and a
simulated face with one BRDF everywhere whose fitted render shows no region outline."""

from __future__ import annotations

import copy
import warnings

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import numpy as np
import pytest

from mifaces.capture import load_capture
from mifaces.capture.ground_truth import ground_truth_folder
from mifaces.io.image_files import read_exr
from mifaces.model import load_model
from mifaces.model.regions import REGIONS, texel_regions_of_mesh
from mifaces.reflectance import FitOptions, fit_brdf
from mifaces.reflectance import samples as samples_module
from mifaces.render import FaceScene
from mifaces.render.blend import BLEND_KEY, BLEND_MM, blend_width, blended_parameters, region_maps, texel_parts
from mifaces.render.face_pixels import face_pixels
from mifaces.shape.io import load_geometry
from mifaces.studio.truth import default_brdf

#: Samples per pixel of the seam test's renders.
SPP = 64


@pytest.fixture(scope="module")
def face():
    mifaces.set_variant("llvm_ad_rgb")
    model = load_model()
    return FaceScene(model, model.shape_mean)


def document(values: dict, blend: float | None = BLEND_MM) -> dict:
    """A Cook–Torrance document with ``values`` (region -> specular_reflectance) and the skin's other values."""
    skin = default_brdf("cooktorrance")["regions"]["skin"]
    regions = {r: {**skin, "specular_reflectance": v} for r, v in values.items()}
    return {"model": "cooktorrance", "regions": regions, **({} if blend is None else {BLEND_KEY: blend})}


def test_blended_parameters_are_those_that_differ(face):
    regions = [m.region for m in face.meshes.values()]
    assert blended_parameters(document({"skin": 0.3, "lips": 0.6}), regions) == ["specular_reflectance"]
    assert blended_parameters(document({"skin": 0.3, "lips": 0.3}), regions) == []
    assert blended_parameters(document({"skin": 0.3, "lips": 0.6}, blend=None), regions) == []
    assert blended_parameters(document({"skin": 0.3, "lips": 0.6}), regions, exclude={"specular_reflectance"}) == []
    with pytest.raises(ValueError, match="region_blend_mm must be a finite number"):
        blend_width(document({"skin": 0.3}, blend=-1.0))


def test_region_maps_blend_near_borders_only(face):
    """Each texel its region's value far from a border; between the two values within a few
    millimetres of it; a ground truth (no blend width) gets no map at all."""
    size = 256
    maps = region_maps(document({"skin": 0.2, "lips": 0.8}), face.meshes, size)
    assert list(maps) == ["specular_reflectance"]
    image = maps["specular_reflectance"]
    assert image.shape == (size, size, 3) and image.dtype == np.float32
    assert np.allclose(image[..., 0], image[..., 1]) and np.allclose(image[..., 0], image[..., 2])
    keys = list(face.meshes)
    lips = np.array([face.meshes[k].region == "lips" for k in keys])[texel_parts(face.meshes, size)]
    from scipy.ndimage import distance_transform_edt
    far_inside = distance_transform_edt(lips) > 6
    far_outside = distance_transform_edt(~lips) > 6
    assert far_inside.sum() > 50 and np.allclose(image[far_inside, 0], 0.8, atol=1e-3)
    assert np.allclose(image[far_outside, 0], 0.2, atol=1e-3)
    assert image.min() >= 0.2 - 1e-6 and image.max() <= 0.8 + 1e-6
    border = (distance_transform_edt(lips) == 1) | (distance_transform_edt(~lips) == 1)
    between = (image[border, 0] > 0.25) & (image[border, 0] < 0.75)
    assert between.mean() > 0.5  # a ramp across the border, not a step
    assert region_maps(document({"skin": 0.2, "lips": 0.8}, blend=None), face.meshes, size) == {}


def test_a_fitted_scene_file_carries_its_region_maps(face):
    """The scene description names each blended parameter's map, a reference in every region's BSDF."""
    from conftest import front_camera
    description = face.description(document({"skin": 0.2, "lips": 0.8}), front_camera(), envmap={"type": "constant"})
    key = face.region_map_id("specular_reflectance")
    assert description[key]["filename"] == face.region_map_file("specular_reflectance") == \
        "region_maps/specular_reflectance.exr"
    bsdfs = [v["bsdf"] for k, v in description.items() if k in face.meshes]
    assert bsdfs and all(b["specular_reflectance"] == {"type": "ref", "id": key} for b in bsdfs)
    hard = face.description(document({"skin": 0.2, "lips": 0.8}, blend=None), front_camera(), envmap={"type": "constant"})
    assert key not in hard


# ---------------------------------------------------------------------------
# The seam test: one BRDF everywhere, fitted, rendered

def border_steps(image: np.ndarray, reference: np.ndarray, labels: np.ndarray, minimum: int = 50) -> dict:
    """The step of log(image / reference) across each border between two regions (pixel
    ``labels``, 0 off the face): region pair -> (mean step from the first region's pixel to the second's over the pairs of
    neighbouring pixels that straddle the border, its standard error, pairs). A face whose
    reflectance each region's fit got equally right has no step there; a region fitted too
    glossy or too dark shows one all along its border."""
    lum_image, lum_ref = image.mean(axis=2), reference.mean(axis=2)
    ok = (lum_image > 1e-3) & (lum_ref > 1e-3) & (labels > 0)
    ratio = np.log(np.where(ok, lum_image, 1.0)) - np.log(np.where(ok, lum_ref, 1.0))
    pairs = {}
    for a, b in (((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
                 ((slice(None), slice(None, -1)), (slice(None), slice(1, None)))):
        across = ok[a] & ok[b] & (labels[a] != labels[b])
        first, second, step = labels[a][across], labels[b][across], (ratio[b] - ratio[a])[across]
        flip = first > second
        step = np.where(flip, -step, step)
        for lo, hi, s in zip(np.where(flip, second, first), np.where(flip, first, second), step):
            pairs.setdefault((int(lo), int(hi)), []).append(s)
    out = {}
    for key, steps in pairs.items():
        if len(steps) >= minimum:
            steps = np.asarray(steps)
            out[key] = (float(steps.mean()), float(steps.std(ddof=1) / np.sqrt(len(steps))), len(steps))
    return out


#: The lids' border, where the fitted render is 12-13 % darker on the eyes' side with or without
#: the region-border samples (an open defect: test_the_eyes_border_has_no_seam).
EYES = "skin/eyes"


def seams(steps: dict, allowance: float = 0.01) -> dict:
    """The region pairs whose step exceeds three standard errors (the Monte Carlo noise, and the
    texture's) plus ``allowance`` (1 % of radiance: below what the eye sees)."""
    names = {v: k for k, v in REGIONS.items()}
    return {f"{names[a]}/{names[b]}": round(mean, 4) for (a, b), (mean, se, _) in steps.items()
            if abs(mean) > 3 * se + allowance}


@pytest.fixture(scope="module")
def one_brdf(small_capture):
    """A simulated face with the skin's Cook–Torrance parameters in every region."""
    skin = default_brdf("cooktorrance")["regions"]["skin"]
    one = {"model": "cooktorrance", "regions": {r: dict(skin) for r in REGIONS if r != "background"}}
    return small_capture("one_brdf", brdf_params=one, measurements=3, resolution=(256, 256), spp=16,
                         albedo_resolution=256, seed=3)


def fitted_render(capture_dir):
    """The fit of ``capture_dir``'s first photograph rendered from the fitted BRDF and albedo, the true
    face rendered at the same seed, and each pixel's region label."""
    mifaces.set_variant("llvm_ad_rgb")
    with warnings.catch_warnings():  # small regions of a small capture warn (few samples, a bound)
        warnings.simplefilter("ignore", UserWarning)
        result = fit_brdf(capture_dir, "cooktorrance", progress=False, options=FitOptions(resolution=256))
    capture = load_capture(capture_dir)
    model, shapes = load_geometry(capture)
    first = capture.measurements[0]
    scene = FaceScene(model, shapes[first.name])
    light = capture.light(first.light)
    truth = ground_truth_folder(capture_dir)
    import json
    true_brdf = json.loads((truth / "brdf.json").read_text())
    true_render = scene.render(true_brdf, read_exr(truth / "albedo.exr"), capture.camera, light, spp=SPP, seed=1)
    labels = face_pixels(scene, capture.camera, spp=None, region_map=texel_regions_of_mesh(
        model.region_map, model.uv, model.triangles, 1024))
    return result, scene, capture, light, true_render, labels


def test_one_brdf_face_renders_without_seams(one_brdf):
    """Issue 50's seam test: every region has the same BRDF, so the fitted render, divided by the
    true one, must not step at region borders beyond the noise. Two controls show that the
    statistic sees a seam: a region rendered with 3 x the skin's gloss on hard borders, and the fit
    with the samples along region borders kept (their pixels mix in the neighbour's light: the
    eyebrows came out with a bright rim)."""
    result, scene, capture, light, true_render, labels = fitted_render(one_brdf)
    fitted = result.to_json()
    assert fitted[BLEND_KEY] == BLEND_MM
    render = scene.render(fitted, result.albedo.albedo, capture.camera, light, spp=SPP, seed=1,
                          normals=result.normal_texture())
    steps = border_steps(render, true_render, labels)
    assert len(steps) >= 5, steps  # brows, beard, hair, lips ... meet the skin in this view
    found = seams(steps)
    assert {k: v for k, v in found.items() if k != EYES} == {}, steps
    # control 1: a step in the skin's gloss at hard borders is seen
    glossy = copy.deepcopy({k: v for k, v in fitted.items() if k != BLEND_KEY})
    glossy["regions"]["skin"]["specular_reflectance"] = \
        (3 * np.asarray(glossy["regions"]["skin"]["specular_reflectance"])).tolist()
    hard = scene.render(glossy, result.albedo.albedo, capture.camera, light, spp=SPP, seed=1,
                        normals=result.normal_texture())
    assert seams(border_steps(hard, true_render, labels))


def test_mixed_samples_would_outline_the_eyebrows(one_brdf, monkeypatch):
    """Control 2: with the samples along region borders kept, the dark eyebrows' border texels read
    the skin's light and the fitted render outlines them."""
    monkeypatch.setattr(samples_module, "region_mixed", lambda xy, *args, **kwargs: np.zeros(len(xy), bool))
    result, scene, capture, light, true_render, labels = fitted_render(one_brdf)
    render = scene.render(result.to_json(), result.albedo.albedo, capture.camera, light, spp=SPP, seed=1,
                          normals=result.normal_texture())
    assert "skin/eyebrows" in seams(border_steps(render, true_render, labels))


@pytest.mark.xfail(strict=True, reason="open defect: the fitted render is darker on the eyes' side of the lids")
def test_the_eyes_border_has_no_seam(one_brdf):
    result, scene, capture, light, true_render, labels = fitted_render(one_brdf)
    render = scene.render(result.to_json(), result.albedo.albedo, capture.camera, light, spp=SPP, seed=1,
                          normals=result.normal_texture())
    assert EYES not in seams(border_steps(render, true_render, labels))
