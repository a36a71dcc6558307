"""Atomic output and image files."""

from __future__ import annotations

import numpy as np
import pytest

from mifaces.io.atomic import atomic_write, write_json
from mifaces.io.image_files import read_exr, write_exr, write_png


def test_atomic_write_keeps_the_old_file_on_failure(tmp_path):
    path = tmp_path / "result.json"
    write_json(path, {"loss": 1.0})
    with pytest.raises(RuntimeError):
        with atomic_write(path, "w") as f:
            f.write('{"loss": ')
            raise RuntimeError("interrupted")
    assert path.read_text().strip().startswith("{") and '"loss": 1.0' in path.read_text()
    assert [p.name for p in tmp_path.iterdir()] == ["result.json"]  # no temporary left behind


def test_exr_round_trip_is_exact(tmp_path):
    image = np.random.default_rng(0).uniform(0, 5, (7, 5, 3)).astype(np.float32)
    write_exr(tmp_path / "a.exr", image)
    np.testing.assert_array_equal(read_exr(tmp_path / "a.exr"), image)
    write_exr(tmp_path / "gray.exr", image[:, :, 0])
    np.testing.assert_array_equal(read_exr(tmp_path / "gray.exr"), image[:, :, 0])


def test_png_is_srgb_encoded(tmp_path):
    import skimage.io

    write_png(tmp_path / "a.png", np.full((2, 2, 3), 0.5, dtype=np.float32))
    data = skimage.io.imread(tmp_path / "a.png")
    assert data.dtype == np.uint8 and data.shape == (2, 2, 3)
    assert data[0, 0, 0] == 188  # sRGB encoding of 0.5


def test_missing_exr_and_bad_shapes_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.exr"):
        read_exr(tmp_path / "nothere.exr")
    with pytest.raises(ValueError, match="1, 3 or 4 channels"):
        write_exr(tmp_path / "b.exr", np.zeros((2, 2, 2)))
