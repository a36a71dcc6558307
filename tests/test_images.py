"""Integer photographs read at their true bit depth (mifaces.io.image_files, mifaces.capture.images)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mifaces.capture.images import read_image
from mifaces.io.image_files import read_codes

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def _codes16(shape, seed=0) -> np.ndarray:
    """16-bit codes that are not multiples of 257 (an 8-bit reader scaled up cannot give them back)."""
    codes = np.random.default_rng(seed).integers(0, 65535, shape).astype(np.uint16)
    codes[codes % 257 == 0] += 1
    return codes


def test_16bit_rgb_png_keeps_every_code(tmp_path):
    import png

    codes = _codes16((5, 7, 3))
    png.from_array(codes.reshape(5, 21), "RGB;16").save(tmp_path / "a.png")
    image = read_image(tmp_path / "a.png")
    np.testing.assert_array_equal(np.round(image.pixels * 65535.0), codes)
    assert not image.saturated.any()
    np.testing.assert_array_equal(read_codes(tmp_path / "a.png"), codes)


def test_8bit_png_is_unchanged(tmp_path):
    import png

    codes = np.random.default_rng(1).integers(0, 256, (4, 6)).astype(np.uint8)
    png.from_array(codes, "L;8").save(tmp_path / "a.png")
    data = read_codes(tmp_path / "a.png")
    assert data.dtype == np.uint8
    np.testing.assert_array_equal(data, codes)


@pytest.mark.parametrize("magic, planes", [(b"P5", 1), (b"P6", 3)])
@pytest.mark.parametrize("top", [255, 65535, 1023])
def test_netpbm_at_its_depth(tmp_path, magic, planes, top):
    codes = np.random.default_rng(top).integers(0, top + 1, (3, 4, planes))
    sample = ">u2" if top > 255 else "u1"
    header = magic + b"\n# a comment\n4 3\n" + str(top).encode() + b"\n"
    (tmp_path / "a.pnm").write_bytes(header + codes.astype(sample).tobytes())
    data = read_codes(tmp_path / "a.pnm")
    assert data.dtype == (np.uint8 if top == 255 else np.uint16)
    expected = codes[:, :, 0] if planes == 1 else codes
    full = np.iinfo(data.dtype).max
    np.testing.assert_allclose(data / full, expected / top, atol=0.5 / full)


def test_16bit_tiff(tmp_path):
    import tifffile

    codes = _codes16((4, 5, 3), seed=2)
    tifffile.imwrite(tmp_path / "a.tif", codes)
    np.testing.assert_array_equal(read_codes(tmp_path / "a.tif"), codes)


def test_diligent_image_at_16_bits():
    path = DATA / "diligent_ball" / "001.png"
    if not path.is_file():
        pytest.skip(f"DiLiGenT ball not found at {path.parent}")
    codes = np.round(read_image(path).pixels * 65535.0)
    assert codes.shape == (162, 162, 3)
    assert np.mean(codes % 257 != 0) > 0.5  # codes an 8-bit read cannot give


def test_yale_pgm():
    path = DATA / "yaleb" / "yaleB01" / "yaleB01_P00A+000E+00.pgm"
    if not path.is_file():
        pytest.skip(f"Yale faces not found at {path.parent}")
    import PIL.Image

    data = read_codes(path)
    assert data.dtype == np.uint8 and data.shape == (192, 168)
    np.testing.assert_array_equal(data, np.asarray(PIL.Image.open(path)))
