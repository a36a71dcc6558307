"""Captures' calibrations for other tools and back (mifaces.importers.calibration_io): a simulated
capture's camera exported as a COLMAP model and a transforms.json, imported back as a capture with the
same camera; a rig's cameras exported and imported as a capture of several cameras; the command line."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from mifaces.capture import MANIFEST, Camera, load_capture
from mifaces.cli.commands import main
from mifaces.io.image_files import write_png
from mifaces.importers.calibration_io import (POSE, export_calibration, import_calibration, import_colmap,
                                              camera_groups, import_transforms, photographs)
from mifaces.importers.colmap import read_colmap
from mifaces.importers.transforms import read_transforms


@pytest.fixture(scope="module")
def simulated(small_capture):
    return small_capture("calibration_io", measurements=2, resolution=(64, 64), spp=1, albedo_resolution=64, seed=1)


def assert_same_camera(a: Camera, b: Camera, atol: float = 1e-9):
    assert (a.width, a.height) == (b.width, b.height)
    np.testing.assert_allclose([a.fx, a.fy, a.cx, a.cy], [b.fx, b.fy, b.cx, b.cy], rtol=0, atol=atol)
    np.testing.assert_allclose(a._coefficients(), b._coefficients(), rtol=0, atol=atol)
    np.testing.assert_allclose(a.rotation, b.rotation, rtol=0, atol=atol)
    np.testing.assert_allclose(a.translation, b.translation, rtol=0, atol=atol * 1e3)


def test_export_and_import_a_simulated_capture(simulated, tmp_path):
    capture = load_capture(simulated, calibrate=False, detect=False)
    out = export_calibration(simulated, tmp_path / "calibration")
    names = list(photographs(capture))
    # every picture the camera took: photographs, diffuse companions, steel-sphere pictures
    assert "images/m00_point.exr" in names and "images/m00_diffuse.png" in names
    assert "images/L00_spheres_point.exr" in names and len(set(names)) == len(names)
    assert sorted(p.name for p in (out / "sparse" / "0").iterdir()) == ["cameras.txt", "images.txt", "points3D.txt"]
    model = read_colmap(out / "sparse" / "0")
    assert list(model.cameras) == names and len(model.points) == 0
    for camera in model.cameras.values():
        assert_same_camera(camera, capture.camera)
    frames = read_transforms(out / "transforms.json")
    assert [(out / name).resolve() for name in frames] == [(simulated / name).resolve() for name in names]
    for camera in frames.values():
        assert_same_camera(camera, capture.camera)

    # ... and back: a capture of the one camera, one unknown light per picture
    back = load_capture(import_colmap(out / "sparse" / "0", simulated, tmp_path / "from_colmap"), calibrate=False,
                        detect=False)
    assert_same_camera(back.camera, capture.camera)
    # named after the pictures, less the folder they all share
    assert [m.name for m in back.measurements] == [n.split("/")[1].rsplit(".", 1)[0] for n in names]
    assert all(light.unknown for light in back.lights) and {m.pose for m in back.measurements} == {POSE}
    assert all(m.diffuse.path == back.measurements[0].image.path for m in back.measurements)
    first = capture.measurements[0].image  # the same file; the calibration knows no exposures
    np.testing.assert_allclose(back.measurements[0].image.pixels, first.pixels * first.exposure, rtol=1e-6)
    # the transforms.json's file paths lead to the same pictures; scale: mm per unit of its world frame
    again = load_capture(import_transforms(out / "transforms.json", tmp_path / "from_transforms", scale=2.0),
                         calibrate=False, detect=False)
    assert_same_camera(replace(again.camera, translation=again.camera.translation / 2), capture.camera)


def test_import_chooses_the_diffuse_companion_and_refuses_to_overwrite(tmp_path):
    camera = Camera(8, 6, 10.0, 10.0, 3.5, 2.5)
    for name in ("a.png", "b.png"):
        write_png(tmp_path / "in" / name, np.full((6, 8, 3), 0.5, np.float32))
    out = import_calibration({"a.png": camera, "b.png": camera}, tmp_path / "in", tmp_path / "cap", "test",
                             diffuse="b.png")
    manifest = json.loads((out / MANIFEST).read_text())
    assert [m["diffuse"]["path"] for m in manifest["measurements"]] == ["images/b.png"] * 2
    assert manifest["measurements"][0]["image"] == {"path": "images/a.png", "transfer": "srgb"}
    assert manifest["metadata"]["images"] == {"a": "a.png", "b": "b.png"}
    with pytest.raises(FileExistsError, match="holds a capture already"):
        import_calibration({"a.png": camera}, tmp_path / "in", out, "test")
    with pytest.raises(ValueError, match="diffuse: no image 'c.png'"):
        import_calibration({"a.png": camera}, tmp_path / "in", out, "test", force=True, diffuse="c.png")
    with pytest.raises(ValueError, match=r"image 'a.png' is 8x6 pixels, its camera's images 9x6"):
        import_calibration({"a.png": Camera(9, 6, 10.0, 10.0, 3.5, 2.5)}, tmp_path / "in", out, "test", force=True)
    with pytest.raises(FileNotFoundError, match="image 'z.png'"):
        import_calibration({"z.png": camera}, tmp_path / "in", out, "test", force=True)
    with pytest.raises(ValueError, match="the measurement name of image 'a b.png'"):
        import_calibration({"a b.png": camera}, tmp_path / "in", out, "test", force=True)


def test_images_of_one_camera_are_grouped():
    camera = Camera(8, 6, 10.0, 10.0, 3.5, 2.5)
    moved = Camera(8, 6, 10.0, 10.0, 3.5, 2.5, translation=np.array([0.0, 0.0, 1.0]))
    zoomed = Camera(8, 6, 12.0, 12.0, 3.5, 2.5)
    groups = camera_groups({"a.png": camera, "b.png": moved, "c.png": Camera(8, 6, 10.0, 10.0, 3.5, 2.5),
                            "d.png": zoomed})
    assert [(g is camera, images) for g, images in groups][0] == (True, ["a.png", "c.png"])
    assert [images for _, images in groups] == [["a.png", "c.png"], ["b.png"], ["d.png"]]
    with pytest.raises(ValueError, match="no images"):
        camera_groups({})


def test_a_rig_goes_out_and_comes_back_with_its_cameras(small_capture, tmp_path):
    rig = small_capture("calibration_rig", measurements=1, resolution=(64, 64), spp=1, albedo_resolution=64, seed=2,
                        cameras=3)
    capture = load_capture(rig, calibrate=False, detect=False)
    taken = photographs(capture)
    assert taken["images/m00_c2_point.exr"] is capture.cameras["c2"]
    assert taken["images/L00_spheres_point.exr"] is capture.camera
    out = export_calibration(rig, tmp_path / "calibration")
    model = read_colmap(out / "sparse" / "0")
    for name, camera in taken.items():
        assert_same_camera(model.cameras[name], camera)
    back = load_capture(import_colmap(out / "sparse" / "0", rig, tmp_path / "back"), calibrate=False, detect=False)
    assert list(back.cameras) == ["cam0", "cam1", "cam2"]
    for original, imported in zip(capture.cameras.values(), back.cameras.values()):
        assert_same_camera(imported, original)
    assert {m.pose for m in back.measurements} == {POSE}  # a calibration is of one rigid scene: one shot
    for m in back.measurements:  # each photograph with its own camera, its companion of that camera
        assert back.camera_of(m).width == m.image.pixels.shape[1]
        assert back.camera_of(m) is back.camera_of(m.name)
        assert m.name in back.metadata["images"]
    c2 = next(m for m in back.measurements if m.name == "m00_c2_point")
    assert c2.camera == "cam2" and c2.diffuse.path.parent == c2.image.path.parent
    assert next(m for m in back.measurements if m.name == "m00_c2_diffuse").camera == "cam2"


def test_command_line(simulated, tmp_path):
    runner = CliRunner()
    result = runner.invoke(main, ["export-calibration", str(simulated), str(tmp_path / "cal")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "cal" / "sparse" / "0" / "images.txt").is_file()
    assert (tmp_path / "cal" / "transforms.json").is_file()
    result = runner.invoke(main, ["import", "colmap", str(tmp_path / "cal" / "sparse" / "0"), str(simulated),
                                  str(tmp_path / "cap"), "--diffuse", "images/m00_diffuse.png"])
    assert result.exit_code == 0, result.output
    assert load_capture(tmp_path / "cap", calibrate=False, detect=False).measurements[0].diffuse.path.name == \
        "m00_diffuse.png"
    result = runner.invoke(main, ["import", "transforms", str(tmp_path / "cal" / "transforms.json"),
                                  str(tmp_path / "cap")])
    assert result.exit_code == 1 and "holds a capture already" in result.output
    result = runner.invoke(main, ["import", "transforms", str(tmp_path / "cal" / "transforms.json"),
                                  str(tmp_path / "cap"), "--force", "--scale", "1000", "--transfer", "linear"])
    assert result.exit_code == 0, result.output
    (tmp_path / "cal" / "sparse" / "0" / "cameras.txt").write_text("1 OPENCV_FISHEYE 64 64 1 1 1 1 0 0 0 0\n")
    result = runner.invoke(main, ["import", "colmap", str(tmp_path / "cal" / "sparse" / "0"), str(simulated),
                                  str(tmp_path / "cap2")])
    assert result.exit_code == 1 and "camera 1 uses the camera model OPENCV_FISHEYE" in result.output
