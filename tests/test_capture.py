"""Captures: the camera model, reading photographs, loading and validating a capture folder.

Corruption tests change a hard-linked copy of the shared simulated capture
(:func:`test_simulate.studio`) and check that loading names the problem.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mifaces.capture import (FEATURE_POINT_RANGE, MANIFEST, Camera, Capture, CaptureError, WhiteTarget, decode,
                             load_capture, read_image)
from mifaces.io.image_files import read_exr, write_exr, write_png
from test_simulate import STUDIO, copy_capture, studio  # noqa: F401  (studio: the shared session fixture)

WIDTH, HEIGHT = STUDIO["resolution"]


# --------------------------------------------------------------------------------------------
# Camera
# --------------------------------------------------------------------------------------------
def _camera(distortion=(-0.2, 0.05, 0.001, -0.002, 0.01)) -> Camera:
    angle = np.radians(10.0)
    rotation = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    return Camera(640, 480, 800.0, 810.0, 320.5, 239.0, np.array(distortion, float), rotation,
                  np.array([10.0, -5.0, 1000.0]))


def test_camera_projects_as_opencv():
    """One point worked by hand with OpenCV's formulas (docs of cv::projectPoints)."""
    camera = _camera()
    point = np.array([50.0, -30.0, 100.0])
    pc = camera.rotation @ point + camera.translation
    x, y = pc[0] / pc[2], pc[1] / pc[2]
    k1, k2, p1, p2, k3 = camera.distortion
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    np.testing.assert_allclose(camera.project(point), [800 * xd + 320.5, 810 * yd + 239.0], rtol=1e-12)
    np.testing.assert_allclose(camera.position, -camera.rotation.T @ camera.translation)
    np.testing.assert_allclose(camera.to_world(camera.to_camera(point)), point, atol=1e-9)


def test_a_scaled_camera_sees_the_same_picture_finer():
    camera, points = _camera(()), np.random.default_rng(1).normal(0.0, 80.0, (20, 3))
    fine = camera.scaled(4)
    assert (fine.width, fine.height) == (2560, 1920)
    np.testing.assert_allclose(fine.project(points), (camera.project(points) + 0.5) * 4 - 0.5, atol=1e-9)
    np.testing.assert_allclose(fine.position, camera.position)


def test_pixel_rays_invert_projection():
    camera = _camera()
    rng = np.random.default_rng(0)
    points = camera.to_world(np.column_stack([rng.uniform(-300, 300, (50, 2)), rng.uniform(800, 1500, 50)]))
    rays = camera.pixel_rays(camera.project(points))
    expected = camera.to_camera(points)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(rays, expected, atol=1e-9)
    # without distortion, undistort is the identity
    plain = _camera(())
    np.testing.assert_array_equal(plain.undistort([[0.1, -0.2]]), [[0.1, -0.2]])


# --------------------------------------------------------------------------------------------
# Reading photographs
# --------------------------------------------------------------------------------------------
def test_decode_transfer_curves():
    codes = np.array([0, 10, 128, 255], np.uint8)
    np.testing.assert_allclose(decode(codes, "linear"), codes / 255.0, rtol=1e-6)
    np.testing.assert_allclose(decode(codes, "gamma", 2.0), (codes / 255.0) ** 2, rtol=1e-6)
    np.testing.assert_allclose(decode(np.array([0, 65535], np.uint16), "srgb"), [0.0, 1.0], atol=1e-7)
    with pytest.raises(ValueError, match="transfer must be one of"):
        decode(codes, "log")


def test_read_image_divides_by_the_exposure_and_flags_clipping(tmp_path):
    values = np.linspace(0, 1, 4 * 5 * 3).reshape(4, 5, 3).astype(np.float32)
    write_png(tmp_path / "a.png", values)
    image = read_image(tmp_path / "a.png", "srgb", exposure=0.5)
    np.testing.assert_allclose(image.pixels, values / 0.5, atol=0.01)
    assert image.saturated[-1, -1] and image.saturated.sum() == 1  # only the last pixel reaches code 255
    write_exr(tmp_path / "a.exr", values * 3)
    image = read_image(tmp_path / "a.exr", exposure=2.0, saturation=2.5)
    np.testing.assert_allclose(image.pixels, values * 1.5, rtol=1e-6)
    np.testing.assert_array_equal(image.saturated, np.any(values * 3 >= 2.5, axis=2))
    with pytest.raises(ValueError, match="EXR images are linear"):
        read_image(tmp_path / "a.exr", "srgb")
    with pytest.raises(FileNotFoundError, match="image not found"):
        read_image(tmp_path / "b.png")


def test_white_target_reflectance_scale():
    """r = s R d^2 / (I cos): a Lambertian target of reflectance rho lit by intensity I at d and
    incidence cosine cos shows radiance rho I cos / (pi d^2); s is chosen so r = rho (independently:
    s = pi), frontal or tilted, near or far. A capture without a target takes s = pi (reflectance
    relative to the lights' stated intensities)."""
    intensity, rho = np.array([1e6, 2e6, 3e6]), 0.9
    for d, cos in ((1500.0, 1.0), (700.0, 0.6)):
        value = rho * intensity * cos / (np.pi * d ** 2)
        target = WhiteTarget(value, rho, d, intensity, cos)
        np.testing.assert_allclose(target.reflectance_scale(), np.pi)
        assert Capture(Path("c"), _camera(), (), (), (), target).reflectance_scale() == pytest.approx([np.pi] * 3)
    np.testing.assert_array_equal(Capture(Path("c"), _camera(), (), (), (), None).reflectance_scale(), np.pi)


# --------------------------------------------------------------------------------------------
# Loading a capture
# --------------------------------------------------------------------------------------------
def test_load_capture_from_the_manifest_path_and_without_calibration(studio):
    capture = load_capture(studio / MANIFEST, calibrate=False)
    assert capture.path == studio
    assert all(light.position is None and light.spheres is not None for light in capture.lights)
    assert capture.light("L01").name == "L01"
    with pytest.raises(KeyError, match="no light 'L99'"):
        capture.light("L99")
    assert "384x384, 2 lights, 4 measurements" in repr(capture)
    assert capture.metadata["units"] == "mm"


def _manifest(path):
    return json.loads((path / MANIFEST).read_text())


def _write_manifest(path, data):
    (path / MANIFEST).unlink()  # a hard link: replace, do not write into it
    (path / MANIFEST).write_text(json.dumps(data))


def _edit(change):
    def apply(path):
        data = _manifest(path)
        change(data)
        _write_manifest(path, data)
    return apply


def _truncate_manifest(path):
    text = (path / MANIFEST).read_text()
    (path / MANIFEST).unlink()
    (path / MANIFEST).write_text(text[: len(text) // 2])


def _remove_image(path):
    (path / "images" / "m01_point.exr").unlink()


def _shrink_image(path):
    write_png(path / "images" / "m00_diffuse.png", np.zeros((48, 64, 3)))


def _nan_pixels(path):
    image = read_exr(path / "images" / "m02_point.exr")
    image[10, 20] = np.nan
    image[11, 20, 1] = np.inf
    write_exr(path / "images" / "m02_point.exr", image)


def _blank_outline(path):
    write_exr(path / "images" / "L01_spheres_diffuse.exr", np.full((HEIGHT, WIDTH, 3), 0.8, np.float32))


def _few_points(data):
    points = data["measurements"][0]["feature_points"]
    data["measurements"][0]["feature_points"] = dict(list(points.items())[:FEATURE_POINT_RANGE[0] - 2])


def _set(*keys, value):
    def change(data):
        node = data
        for k in keys[:-1]:
            node = node[k]
        if value is KeyError:
            del node[keys[-1]]
        else:
            node[keys[-1]] = value
    return change


CORRUPTIONS = {
    "manifest not JSON": (_truncate_manifest, f"{MANIFEST} is not valid JSON"),
    "manifest not an object": (lambda p: _write_manifest(p, [1, 2]), "must hold a JSON object, got list"),
    "wrong format": (_edit(_set("format", value="something")), "format: must be 'mifaces-capture'"),
    "wrong version": (_edit(_set("version", value=7)), "this mifaces reads version 1, got 7"),
    "missing image": (_remove_image, "measurements[1] (m01).image: image file missing: images/m01_point.exr"),
    "image of the wrong size": (_shrink_image, "images/m00_diffuse.png is 64x48 pixels, the camera's images are "
                                               f"{WIDTH}x{HEIGHT}"),
    "NaN pixels": (_nan_pixels, "images/m02_point.exr has 2 pixels with NaN or infinite values "
                                "(first at x=20, y=10)"),
    "not an image file": (_edit(_set("measurements", 0, "image", "path", value="images/m00.txt")),
                          "'images/m00.txt' is not an image file we read"),
    "negative focal length": (_edit(_set("camera", "fx", value=-5)), "camera.fx: must be a finite positive number"),
    "not a rotation": (_edit(_set("camera", "rotation", value=[[1, 0, 0], [0, 2, 0], [0, 0, 1]])),
                       "camera.rotation: must be a rotation matrix"),
    "reflection": (_edit(_set("camera", "rotation", value=[[1, 0, 0], [0, 1, 0], [0, 0, -1]])),
                   "camera.rotation: has determinant -1"),
    "bad distortion": (_edit(_set("camera", "distortion", value=[0.1, 0.2, 0.3])),
                       "camera.distortion: must be 0, 4, 5 or 8"),
    "missing width": (_edit(_set("camera", "width", value=KeyError)), "camera: missing 'width'"),
    "width not an integer": (_edit(_set("camera", "width", value="384")), "camera.width: must be int"),
    "white target not an object": (_edit(_set("white_target", value=[1, 1, 1])), "white_target: must be an object"),
    "direction of a point light": (_edit(_set("lights", 1, "direction", value=[0, 0, 1])),
                                   "lights[1] (L01): give 'direction' (a directional light) or 'spheres'"),
    "white target not positive": (_edit(_set("white_target", "value", value=[1, 0, 1])),
                                  "white_target.value: must be finite and positive"),
    "white target incidence": (_edit(_set("white_target", "cos_incidence", value=1.5)),
                               "white_target.cos_incidence: must be in (0, 1]"),
    "too few distances": (_edit(lambda d: d["distances"].pop()), "need a list of at least three metric distances"),
    "distance to an unknown point": (_edit(_set("distances", 0, "to", value="ear_lobe")),
                                     "distances[0]: unknown feature point 'ear_lobe'"),
    "negative distance": (_edit(_set("distances", 1, "mm", value=-3)), "distances[1].mm: must be a finite positive"),
    "unknown feature point": (_edit(_set("measurements", 2, "feature_points", "chin_tip", value=[10, 10])),
                              "measurements[2] (m02).feature_points: unknown feature point 'chin_tip'"),
    "too few feature points": (_edit(_few_points), "has 5 feature points, a measurement needs 7 to 20"),
    "feature point off the image": (_edit(_set("measurements", 0, "feature_points", "nose_tip",
                                               value=[WIDTH + 10, 5])), "lies outside the 384x384 image"),
    "unknown light": (_edit(_set("measurements", 3, "light", value="L07")),
                      "measurements[3] (m03).light: no light condition named 'L07'"),
    "no companion": (_edit(lambda d: (d["measurements"][1].pop("diffuse"), d["measurements"][1].pop("exposures"))),
                     "measurements[1] (m01): needs a companion picture"),
    "one-picture series": (_edit(lambda d: d["measurements"][0]["exposures"].__delitem__(slice(1, None))),
                           "an exposure series needs at least two pictures"),
    "bad transfer": (_edit(_set("measurements", 0, "diffuse", "transfer", value="log")),
                     "measurements[0] (m00).diffuse.transfer: must be one of"),
    "no light position": (_edit(lambda d: d["lights"][0].pop("spheres")),
                          "lights[0] (L00): needs 'position_mm' or 'spheres'"),
    "malformed light position": (_edit(_set("lights", 0, "position_mm", value=[1, 2])),
                                 "lights[0] (L00).position_mm: must have shape 3"),
    "malformed sphere radius": (_edit(_set("lights", 1, "spheres", "radius_mm", value=0)),
                                "lights[1] (L01).spheres.radius_mm: must be a finite positive number"),
    "duplicate light": (_edit(_set("lights", 1, "name", value="L00")), "lights: name 'L00' used more than once"),
    "duplicate measurement": (_edit(_set("measurements", 1, "name", value="m00")),
                              "measurements: name 'm00' used more than once"),
    "no measurements": (_edit(_set("measurements", value=[])), "measurements: need a non-empty list"),
    "unknown ambient": (_edit(lambda d: d.update(ambient="dim")), "ambient: must be one of ['unknown', 'none'], "
                                                                  "got 'dim'"),
    "spheres not found": (_blank_outline, "light 'L01': steel-sphere calibration failed: found 0 sphere(s) in "
                                          "L01_spheres_diffuse.exr"),
}


@pytest.mark.parametrize("corruption", CORRUPTIONS)
def test_load_capture_names_the_problem(studio, tmp_path, corruption):
    change, message = CORRUPTIONS[corruption]
    copy = copy_capture(studio, tmp_path / "capture")
    change(copy)
    with pytest.raises(CaptureError) as error:
        load_capture(copy)
    assert message in str(error.value), str(error.value)
    assert error.value.path == copy


def test_load_capture_lists_every_problem(studio, tmp_path):
    copy = copy_capture(studio, tmp_path / "capture")
    _remove_image(copy)
    _nan_pixels(copy)
    _edit(_set("camera", "fy", value=0))(copy)
    with pytest.raises(CaptureError) as error:
        load_capture(copy)
    assert len(error.value.problems) == 3, error.value.problems
    assert str(error.value).startswith(f"invalid capture {copy}: 3 problem(s)")


def test_load_capture_without_a_manifest(tmp_path):
    with pytest.raises(CaptureError, match="no manifest"):
        load_capture(tmp_path)


def test_given_light_positions_are_not_calibrated(studio, tmp_path):
    copy = copy_capture(studio, tmp_path / "capture")
    _edit(lambda d: d["lights"][0].update(position_mm=[1.0, 2.0, 3.0]))(copy)
    capture = load_capture(copy)
    np.testing.assert_array_equal(capture.light("L00").position, [1.0, 2.0, 3.0])
    assert capture.light("L00").calibration is None and capture.light("L01").calibration is not None


def test_white_target_and_distances_are_optional(studio, tmp_path):
    """Without them reflectance is relative and there is no absolute scale (real setups)."""
    copy = copy_capture(studio, tmp_path / "capture")
    _edit(lambda d: (d.pop("white_target"), d.update(distances=[])))(copy)
    capture = load_capture(copy, calibrate=False)
    assert capture.white_target is None and capture.distances == () and capture.relative_reflectance
    assert load_capture(studio, calibrate=False).white_target is not None


def test_point_lights_and_colour_images_stay_as_they_were(studio):
    capture = load_capture(studio, calibrate=False)
    assert not any(light.directional or light.relative for light in capture.lights)
    assert capture.camera.calibrated and not capture.greyscale
    assert all(m.image.channels == 3 and m.feature_points for m in capture.measurements)


def test_a_capture_may_say_no_light_reaches_the_face_but_its_own(studio, tmp_path):
    assert load_capture(studio).ambient_light  # default: an ambient term is fitted
    copy = copy_capture(studio, tmp_path / "capture")
    _edit(lambda d: d.update(ambient="none"))(copy)
    capture = load_capture(copy)
    assert capture.ambient == "none" and not capture.ambient_light
