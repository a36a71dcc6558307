"""The Extended Yale Face Database B reader (mifaces.importers.yaleb)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mifaces.capture import MANIFEST
from mifaces.importers import yaleb

YALE = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "yaleb"
SUBJECTS = ["yaleB01", "yaleB02", "yaleB03"]


@pytest.fixture(scope="module", params=SUBJECTS)
def subject(request):
    folder = YALE / request.param
    if not folder.is_dir():
        pytest.skip(f"Yale faces not found at {folder}")
    return folder


@pytest.mark.parametrize("azimuth, elevation, expected", [
    (0, 0, (0, 0, -1)),  # at the camera: towards it, -z in the OpenCV frame
    (0, 90, (0, -1, 0)),  # straight above: -y (y points down)
    (90, 0, (-1, 0, 0)),  # the subject's right, the image's left: -x
    (-90, 0, (1, 0, 0)),
    (180, 0, (0, 0, 1)),  # behind the head
])
def test_light_direction_conventions(azimuth, elevation, expected):
    np.testing.assert_allclose(yaleb.light_direction(azimuth, elevation), expected, atol=1e-12)


def test_read_subject(subject):
    images = yaleb.read_subject(subject)
    assert len(images) == 64
    assert len({image.stem for image in images}) == 64
    by_light = {image.light: image for image in images}
    frontal = by_light["A+000E+00"]
    assert frontal.stem == f"{subject.name}_P00A+000E+00"
    np.testing.assert_allclose(frontal.direction, [0, 0, -1], atol=1e-12)
    side = by_light["A+035E-20"]
    assert (side.azimuth, side.elevation) == (35.0, -20.0)
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    np.testing.assert_allclose(side.direction, [-c * np.sin(np.radians(35)), s, -c * np.cos(np.radians(35))])
    for image in images:
        assert image.pixels.dtype == np.float32 and image.pixels.shape == (192, 168)
        assert np.isclose(np.linalg.norm(image.direction), 1.0)
    assert 0.0 <= frontal.pixels.min() and frontal.pixels.max() <= 1.0
    # the subject's right (the image's left) is brighter under a light on that side
    lit_right = by_light["A+050E+00"].pixels
    assert lit_right[:, :84].mean() > 1.5 * lit_right[:, 84:].mean()
    ambient = yaleb.read_ambient(subject)
    assert ambient.shape == (192, 168) and ambient.mean() < frontal.pixels.mean()


def test_default_split(subject):
    images = yaleb.read_subject(subject)
    train, held_out = yaleb.default_split(images)
    assert len(train) == 8 and len(held_out) == 56
    assert not {i.stem for i in train} & {i.stem for i in held_out}
    assert train[0].light == "A+000E+00"
    assert all(i.elevation <= yaleb.MAX_ELEVATION and abs(i.azimuth) <= yaleb.MAX_AZIMUTH for i in train)
    again, _ = yaleb.default_split(yaleb.read_subject(subject))
    assert [i.stem for i in again] == [i.stem for i in train]
    # spread: both sides, above and below the camera
    d = np.stack([i.direction for i in train])
    assert d[:, 0].min() < -0.5 < 0.5 < d[:, 0].max() and d[:, 1].min() < -0.5 < 0.5 < d[:, 1].max()
    # the smallest angle between two training lights is far larger than between neighbouring lights
    cos = d @ d.T - 2 * np.eye(len(d))
    assert np.degrees(np.arccos(cos.max())) > 30


def test_explicit_split(subject):
    images = yaleb.read_subject(subject)
    train, held_out = yaleb.default_split(images, ["A+000E+00", f"{subject.name}_P00A+035E-20"])
    assert [i.light for i in train] == ["A+000E+00", "A+035E-20"] and len(held_out) == 62
    with pytest.raises(ValueError, match="A\\+999E\\+00"):
        yaleb.default_split(images, ["A+999E+00"])
    with pytest.raises(ValueError, match="train"):
        yaleb.default_split(images, 100)


def test_missing_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="no Yale light images"):
        yaleb.read_subject(tmp_path)


# --------------------------------------------------------------------------------------------
# A subject as a capture
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """yaleB01 imported with the default split, and its folder."""
    folder = YALE / "yaleB01"
    if not folder.is_dir():
        pytest.skip(f"Yale faces not found at {folder}")
    return yaleb.import_subject(folder, tmp_path_factory.mktemp("yale") / "capture"), folder


def test_import_subject_loads(imported, monkeypatch):
    pytest.importorskip("dlib")
    from mifaces.capture import loader

    out, folder = imported
    calls = []
    detect = loader.detect_feature_points
    monkeypatch.setattr(loader, "detect_feature_points", lambda *a, **k: calls.append(a) or detect(*a, **k))
    capture = loader.load_capture(out)
    assert len(calls) == 1  # the eight measurements share their companion: detected once
    assert len(capture.measurements) == 8 and len(capture.lights) == 8
    assert not capture.camera.calibrated and capture.white_target is None and capture.distances == ()
    assert capture.greyscale and capture.relative_reflectance
    assert (capture.camera.width, capture.camera.height) == (168, 192)
    assert capture.camera.fx == capture.camera.fy == yaleb.FOCAL_GUESS * 192
    assert (capture.camera.cx, capture.camera.cy) == (83.5, 95.5)
    np.testing.assert_array_equal(capture.camera.rotation, np.eye(3))
    np.testing.assert_array_equal(capture.camera.position, np.zeros(3))
    train = json.loads((out / yaleb.SPLIT).read_text())["train"]
    assert [m.name for m in capture.measurements] == train
    for m in capture.measurements:
        assert m.pose == yaleb.POSE and m.face_box == (0, 0, 167, 191)
        assert m.diffuse.path.name == "yaleB01_P00A+000E+00.pgm"  # nearest the camera axis, a training one
        assert m.image.path.parent == out / "images"
        assert m.image.path.read_bytes() == (folder / m.image.path.name).read_bytes()  # copied as is
        light = capture.light(m.light)
        assert m.name.endswith(m.light) and light.directional and light.relative
        points = m.feature_points
        assert len(points) >= 12
        for xy in points.values():
            assert 0 <= xy[0] <= 167 and 0 <= xy[1] <= 191
        eyes = [points[n][1] for n in ("right_eye_outer", "right_eye_inner", "left_eye_inner", "left_eye_outer")]
        mouth = [points[n][1] for n in ("mouth_right", "mouth_left", "upper_lip")]
        assert max(eyes) + 40 < min(mouth) and points["nose_tip"][1] < min(mouth)
        assert points["right_eye_outer"][0] < points["right_eye_inner"][0] < points["left_eye_inner"][0] \
            < points["left_eye_outer"][0]  # the subject's right eye on the image's left
    # known stems: at the camera, and 50 degrees to the subject's right (the image's left, -x)
    np.testing.assert_allclose(capture.light("A+000E+00").direction, [0, 0, -1], atol=1e-12)
    a = np.radians(50)
    np.testing.assert_allclose(capture.light("A+050E+00").direction, [-np.sin(a), 0, -np.cos(a)], atol=1e-12)
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    np.testing.assert_allclose(capture.light("A-085E+20").direction,
                               [c * np.sin(np.radians(85)), -s, -c * np.cos(np.radians(85))], atol=1e-12)


def test_import_subject_split(imported):
    out, folder = imported
    split = json.loads((out / yaleb.SPLIT).read_text())
    present = {p.stem for p in folder.glob("*_P00A*E*.pgm")}
    assert len(split["train"]) == 8 and not set(split["train"]) & set(split["heldout"])
    assert set(split["train"]) | set(split["heldout"]) == present
    assert len(split["train"]) + len(split["heldout"]) == len(present)
    assert sorted(p.stem for p in (out / "images").iterdir()) == sorted(split["train"])  # held-out ones not copied


def test_import_subject_refuses_to_overwrite(imported, tmp_path):
    out, folder = imported
    before = (out / MANIFEST).read_bytes()
    with pytest.raises(FileExistsError, match="holds a capture already"):
        yaleb.import_subject(folder, out, train=3)
    assert (out / MANIFEST).read_bytes() == before
    # --force and --train-lights through the command line; the companion is the training light nearest the axis
    from click.testing import CliRunner

    from mifaces.cli.commands import main

    copy = tmp_path / "capture"
    args = ["import", "yaleb", str(folder), str(copy), "--train-lights", "A+035E-20,A+010E+00"]
    assert CliRunner().invoke(main, args).exit_code == 0
    assert CliRunner().invoke(main, args).exit_code != 0
    result = CliRunner().invoke(main, args + ["--force", "--train", "3"])
    assert result.exit_code != 0 and "not both" in result.output
    assert CliRunner().invoke(main, args + ["--force"]).exit_code == 0
    data = json.loads((copy / MANIFEST).read_text())
    assert [m["light"] for m in data["measurements"]] == ["A+035E-20", "A+010E+00"]
    assert {m["diffuse"]["path"] for m in data["measurements"]} == {"images/yaleB01_P00A+010E+00.pgm"}
    assert json.loads((copy / yaleb.SPLIT).read_text())["train"] == ["yaleB01_P00A+035E-20", "yaleB01_P00A+010E+00"]


def test_import_subject_with_unknown_lights(imported, tmp_path):
    """``--unknown-lights``: the same capture, its lights the same names with no direction, marked unknown."""
    from click.testing import CliRunner

    from mifaces.capture import load_capture
    from mifaces.cli.commands import main

    out, folder = imported
    hidden = tmp_path / "hidden"
    result = CliRunner().invoke(main, ["import", "yaleb", str(folder), str(hidden), "--unknown-lights"])
    assert result.exit_code == 0, result.output
    given, unknown = load_capture(out, detect=False), load_capture(hidden, detect=False)
    assert [l.name for l in unknown.lights] == [l.name for l in given.lights]
    assert unknown.unknown_lights == unknown.lights and not given.unknown_lights
    for light in unknown.lights:
        assert light.kind == "directional" and light.direction is None and light.guess is None
    assert json.loads((hidden / MANIFEST).read_text())["lights"][0] == {"name": "A+000E+00", "unknown": True}
    assert [(m.name, m.light, m.pose) for m in unknown.measurements] == \
        [(m.name, m.light, m.pose) for m in given.measurements]
    assert (hidden / yaleb.SPLIT).read_text() == (out / yaleb.SPLIT).read_text()


def test_import_says_the_dome_has_no_ambient_light(imported, tmp_path):
    """The ambient-only frame is about 1.5 % of the photographs: the capture says ``"ambient": "none"``
    and records the ratio; without that frame (or with a bright one) ``ambient`` is left out (fitted)."""
    import shutil

    from mifaces.capture import load_capture

    out, folder = imported
    data = json.loads((out / MANIFEST).read_text())
    assert data["ambient"] == "none" and 0.005 < data["metadata"]["ambient_fraction"] < yaleb.AMBIENT_NEGLIGIBLE
    assert not load_capture(out, detect=False).ambient_light
    bare = tmp_path / "subject"
    shutil.copytree(folder, bare, ignore=shutil.ignore_patterns("*_Ambient.pgm"))
    data = json.loads((yaleb.import_subject(bare, tmp_path / "capture") / MANIFEST).read_text())
    assert "ambient" not in data and data["metadata"]["ambient_fraction"] is None
    bright = next(bare.glob("*_P00A+000E+00.pgm"))  # the frontal photograph as the ambient frame
    shutil.copy(bright, bare / f"{folder.name}_P00_Ambient.pgm")
    data = json.loads((yaleb.import_subject(bare, tmp_path / "lit", force=True) / MANIFEST).read_text())
    assert "ambient" not in data and data["metadata"]["ambient_fraction"] > 1.0
