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
