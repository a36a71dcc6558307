"""``mifaces import photos``: a folder of ordinary pictures of one face as a capture (issue 46): the
focal length guess from EXIF, pictures turned upright, one unknown light and pose per picture (one
pose per instant), feature points detected, a picture without a face left out."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import ExifTags, Image as PillowImage

from mifaces.capture import MANIFEST, load_capture
from mifaces.cli.commands import main
from mifaces.importers.photos import DEFAULT_FOCAL_35MM, FRAME_35MM, exif_focal_35mm, import_photos
from test_simulate import STUDIO, studio  # noqa: F401  (studio: the shared session fixture)

SIDE = STUDIO["resolution"][0]  # square pictures: a turned one keeps its size


def _exif(focal_35mm=None, when=None, orientation=None) -> PillowImage.Exif:
    exif = PillowImage.Exif()
    if orientation is not None:
        exif[ExifTags.Base.Orientation] = orientation
    tags = exif.get_ifd(ExifTags.IFD.Exif)
    if focal_35mm is not None:
        tags[ExifTags.Base.FocalLengthIn35mmFilm] = focal_35mm
    if when is not None:
        tags[ExifTags.Base.DateTimeOriginal] = when
    return exif


@pytest.fixture(scope="module")
def photos(studio, tmp_path_factory):
    """Four pictures: a PNG without EXIF, two JPEGs taken at one instant (EXIF focal lengths 50 and 26
    mm), one of them stored turned with an EXIF orientation, and a picture of no face."""
    folder = tmp_path_factory.mktemp("photos")
    face = PillowImage.open(studio / "images" / "m00_diffuse.png").convert("RGB")
    face.save(folder / "a.png")
    face.save(folder / "b.jpg", quality=95, exif=_exif(50, "2026:12:05 10:00:00"))
    # stored turned 90 degrees clockwise; EXIF orientation 8 says: turn it back
    face.transpose(PillowImage.Transpose.ROTATE_270).save(folder / "c.jpg", quality=95,
                                                             exif=_exif(26, "2026:12:05 10:00:00", orientation=8))
    PillowImage.new("RGB", (SIDE, SIDE), (90, 90, 90)).save(folder / "d.png")
    return folder


def test_a_folder_of_photographs_becomes_a_capture(photos, tmp_path):
    result = import_photos(photos, tmp_path / "capture")
    assert result.skipped.keys() == {"d.png"} and "no face found" in result.skipped["d.png"]
    assert result.focal_px == pytest.approx((50 + 26) / 2 / FRAME_35MM * SIDE)
    assert result.focal_from == "EXIF of 2 of 4 photographs"
    manifest = json.loads((tmp_path / "capture" / MANIFEST).read_text())
    assert manifest["camera"] == {"width": SIDE, "height": SIDE, "calibrated": False,
                                  "focal_guess_px": round(result.focal_px, 2)}
    capture = load_capture(tmp_path / "capture")
    assert [m.name for m in capture.measurements] == ["a", "b", "c"]
    assert all(light.unknown for light in capture.lights) and not capture.camera.calibrated
    poses = {m.name: m.pose for m in capture.measurements}
    assert poses["b"] == poses["c"] != poses["a"]  # one instant, one head pose
    # the turned picture written upright: the same face, where the detector finds the same points
    a, c = (next(m for m in capture.measurements if m.name == n) for n in "ac")
    assert c.image.path.suffix == ".png"
    upright = np.abs(c.image.pixels - a.image.pixels).mean()  # (JPEG's losses)
    assert upright < 0.01 and np.abs(np.rot90(c.image.pixels) - a.image.pixels).mean() > 5 * upright
    shared = [n for n in a.feature_points if n in c.feature_points]
    assert len(shared) >= 7
    assert np.mean([np.linalg.norm(a.feature_points[n] - c.feature_points[n]) for n in shared]) < 5.0  # (turned wrong: ~100 px)


def test_exif_focal_length_and_the_default(photos, tmp_path):
    with PillowImage.open(photos / "b.jpg") as picture:
        assert exif_focal_35mm(picture.getexif()) == 50.0
    with PillowImage.open(photos / "a.png") as picture:
        assert exif_focal_35mm(picture.getexif()) is None
    exif = _exif()  # a focal length with the sensor's size: 6 mm on a 6.4 mm wide sensor
    exif.get_ifd(ExifTags.IFD.Exif).update({
        ExifTags.Base.FocalLength: 6.0, ExifTags.Base.FocalPlaneXResolution: 500.0,
        ExifTags.Base.FocalPlaneResolutionUnit: 4, ExifTags.Base.ExifImageWidth: 3200})
    PillowImage.new("RGB", (8, 8)).save(tmp_path / "phone.jpg", exif=exif)
    with PillowImage.open(tmp_path / "phone.jpg") as picture:
        assert exif_focal_35mm(picture.getexif()) == pytest.approx(6.0 * FRAME_35MM / 6.4)
    folder = tmp_path / "plain"
    folder.mkdir()
    (folder / "a.png").write_bytes((photos / "a.png").read_bytes())
    result = import_photos(folder, tmp_path / "capture")
    assert result.focal_px == pytest.approx(DEFAULT_FOCAL_35MM / FRAME_35MM * SIDE)
    assert import_photos(folder, tmp_path / "capture", force=True, focal_35mm=35.0).focal_from == "given"


def test_bad_folders_are_named(photos, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no photographs"):
        import_photos(empty, tmp_path / "out")
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    (mixed / "a.png").write_bytes((photos / "a.png").read_bytes())
    PillowImage.new("RGB", (64, 48)).save(mixed / "small.png")
    with pytest.raises(ValueError, match=r"of 2 sizes .*64x48: small.png"):
        import_photos(mixed, tmp_path / "out")
    faceless = tmp_path / "faceless"
    faceless.mkdir()
    (faceless / "d.png").write_bytes((photos / "d.png").read_bytes())
    with pytest.raises(ValueError, match="no face found in any photograph"):
        import_photos(faceless, tmp_path / "out")
    assert not (tmp_path / "out" / MANIFEST).exists()


def test_command_line(photos, tmp_path):
    folder = tmp_path / "two"
    folder.mkdir()
    for name in ("a.png", "d.png"):
        (folder / name).write_bytes((photos / name).read_bytes())
    result = CliRunner().invoke(main, ["import", "photos", str(folder), str(tmp_path / "cap")])
    assert result.exit_code == 0, result.output
    assert "d.png: left out, no face found" in result.output and "1 photographs" in result.output
    again = CliRunner().invoke(main, ["import", "photos", str(folder), str(tmp_path / "cap")])
    assert again.exit_code == 1 and "holds a capture already" in again.output
