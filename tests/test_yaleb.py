"""The Extended Yale Face Database B reader (mifaces.importers.yaleb)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

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
