"""The ``mifaces`` command line: a thin layer over the Python API.

Each command is one API call that a script could make.
"""

from __future__ import annotations

import click


@click.group()
@click.option("--variant", default=None, help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb).")
def main(variant: str | None) -> None:
    """Measure the reflectance of human faces from photographs."""
    import mifaces

    mifaces.set_variant(variant)


# Commands are added below, one per pipeline stage.


@main.command()
@click.option("--out", "out_dir", default="out/gallery", show_default=True, type=click.Path(file_okay=False),
              help="Folder for gallery.exr and gallery.png.")
@click.option("--spp", default=128, show_default=True, type=click.IntRange(1), help="Samples per pixel.")
@click.option("--size", default=(1200, 340), show_default=True, type=(click.IntRange(8), click.IntRange(8)),
              help="Image width and height.")
def gallery(out_dir: str, spp: int, size: tuple[int, int]) -> None:
    """Render the BSDF gallery: one sphere per plugin (phong, cooktorrance, ward, lafortune)."""
    from .gallery import render_gallery

    result = render_gallery(out_dir, spp=spp, width=size[0], height=size[1])
    click.echo(f"rendered the gallery in {result['seconds']:.1f} s ({result['variant']}, {spp} spp)")
    click.echo(f"  {result['exr']}\n  {result['png']}")
