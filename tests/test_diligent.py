"""The DiLiGenT reader and importer (mifaces.importers.diligent), and normals on the real ball."""

from __future__ import annotations

import json
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np
import pytest
from click.testing import CliRunner

from mifaces import photometric_stereo as ps
from mifaces.io.image_files import read_codes
from mifaces.cli.commands import main
from mifaces.importers import diligent
from mifaces.photometric_stereo import nonlambertian as nm

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="module")
def ball():
    folder = DATA / "diligent_ball"
    if not folder.is_dir():
        pytest.skip(f"DiLiGenT ball not found at {folder}")
    return folder, diligent.read_object(folder)


def _fake_object(folder: Path, lights=4, size=5) -> dict:
    """A tiny DiLiGenT-like folder: 16-bit RGB PNGs, lights, intensities, mask."""
    import png

    rng = np.random.default_rng(0)
    codes = rng.integers(0, 65536, size=(lights, size, size, 3), dtype=np.uint16)
    codes[0, 0, 0, 1] = 65535  # one saturated pixel
    names = [f"{i + 1:03d}.png" for i in range(lights)]
    folder.mkdir(parents=True, exist_ok=True)
    for name, c in zip(names, codes):
        png.from_array(c.reshape(size, size * 3), "RGB;16").save(folder / name)
    directions = rng.normal(size=(lights, 3))
    directions[:, 2] = np.abs(directions[:, 2])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    intensities = rng.uniform(0.5, 2.5, size=(lights, 3))
    np.savetxt(folder / "light_directions.txt", directions)
    np.savetxt(folder / "light_intensities.txt", intensities)
    (folder / "filenames.txt").write_text("\n".join(names) + "\n")
    mask = np.zeros((size, size), np.uint8)
    mask[1:4, 1:4] = 255
    png.from_array(mask, "L").save(folder / "mask.png")
    return {"codes": codes, "directions": directions, "intensities": intensities, "mask": mask > 0, "names": names}


def test_reader_divides_by_the_intensities(tmp_path):
    fake = _fake_object(tmp_path / "obj")
    obj = diligent.read_object(tmp_path / "obj")
    expected = fake["codes"] / 65535.0 / fake["intensities"][:, None, None, :]
    np.testing.assert_allclose(obj.images, expected, rtol=1e-6)
    np.testing.assert_allclose(obj.directions, fake["directions"], atol=1e-12)
    assert obj.filenames == fake["names"] and (obj.mask == fake["mask"]).all()
    assert obj.saturated[0, 0, 0] and obj.saturated.sum() == np.any(fake["codes"] == 65535, axis=3).sum()
    with pytest.raises(FileNotFoundError, match="light_directions.txt"):
        (tmp_path / "obj" / "light_directions.txt").unlink()
        diligent.read_object(tmp_path / "obj")


def test_split_is_fixed_alternate_halves():
    train, heldout = diligent.light_split(96)
    assert len(train) == len(heldout) == 48 and train[0] == 0 and heldout[0] == 1
    assert sorted(np.concatenate([train, heldout]).tolist()) == list(range(96))


def test_import_command_round_trips(tmp_path):
    fake = _fake_object(tmp_path / "obj")
    result = CliRunner().invoke(main, ["import", "diligent", str(tmp_path / "obj"), str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    loaded = diligent.load_imported(tmp_path / "out")
    original = diligent.read_object(tmp_path / "obj")
    np.testing.assert_array_equal(loaded.images, original.images)
    np.testing.assert_array_equal(loaded.directions, fake["directions"])
    assert loaded.filenames == fake["names"] and loaded.name == "obj"
    split = json.loads((tmp_path / "out" / diligent.SPLIT).read_text())
    assert split["train"] == fake["names"][0::2] and split["heldout"] == fake["names"][1::2]
    again = CliRunner().invoke(main, ["import", "diligent", str(tmp_path / "obj"), str(tmp_path / "out")])
    assert again.exit_code == 1 and "--force" in again.output


def test_ball_frames_and_intensities(ball):
    """Each light's highlight lies where the ground-truth normal is the half vector of the light and the
    viewer (0, 0, 1): the lights and the normals share the frame x right, y up, z towards the camera."""
    folder, obj = ball
    assert obj.images.shape == (96, 162, 162, 3) and obj.mask.sum() == 15791
    codes = read_codes(folder / obj.filenames[5])
    np.testing.assert_allclose(obj.images[5], codes / 65535.0 / obj.intensities[5], rtol=1e-6)
    truth = diligent.read_normals(folder)
    assert truth[10, 81, 1] > 0.5 and truth[151, 81, 1] < -0.5  # row 0 is the top (y up)
    angles = []
    for k in range(0, 96, 7):
        grey = np.where(obj.mask, obj.images[k].mean(axis=2), 0.0)
        row, col = np.unravel_index(np.argmax(grey), grey.shape)
        half = obj.directions[k] + [0.0, 0.0, 1.0]
        angles.append(np.degrees(np.arccos(truth[row, col] @ (half / np.linalg.norm(half)))))
    assert np.median(angles) < 3.0


def test_ball_normals_end_to_end_on_a_subsampled_mask(ball):
    """Cook-Torrance from the training half of the lights, on every 5th pixel in each direction."""
    folder, obj = ball
    train = obj.select(diligent.light_split(96)[0])
    mask = obj.mask.copy()
    mask[np.arange(162) % 5 != 0] = False
    mask[:, np.arange(162) % 5 != 0] = False
    albedo, start = ps.fit(train.images, train.directions, mask, train.saturated)
    values = train.images[:, mask]
    weights = nm.observation_weights(values, train.saturated[:, mask])
    estimate = nm.fit_normals_and_brdf("cooktorrance", nm.LitPixels(values, train.directions, weights), start[mask],
                                       albedo[mask], options=nm.AlternationOptions(rounds=3))
    truth = diligent.read_normals(folder)[mask]
    error = np.degrees(np.arccos(np.clip(np.sum(estimate.normals * truth, axis=1), -1.0, 1.0)))
    lambertian = np.degrees(np.arccos(np.clip(np.sum(start[mask] * truth, axis=1), -1.0, 1.0)))
    assert np.mean(error) < 0.85 * np.mean(lambertian) and np.mean(error) < 3.0
