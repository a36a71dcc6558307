"""The main job: the BSDF gallery, through the API and the CLI."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from mifaces.cli.commands import main
from mifaces.io.image_files import read_exr


def test_gallery_cli_writes_exr_and_png_with_four_lit_spheres(tmp_path):
    result = CliRunner().invoke(main, ["gallery", "--out", str(tmp_path), "--spp", "4", "--size", "240", "68"])
    assert result.exit_code == 0, result.output
    assert "rendered the gallery" in result.output
    image = read_exr(tmp_path / "gallery.exr")
    assert image.shape == (68, 240, 3) and np.all(np.isfinite(image))
    assert (tmp_path / "gallery.png").stat().st_size > 0
    # one lit sphere in each quarter of the image, black between and around them
    columns = image.mean(axis=(0, 2))
    for quarter in np.split(columns, 4):
        assert quarter.max() > 0.05
    assert image[0].max() == 0 and image[-1].max() == 0
