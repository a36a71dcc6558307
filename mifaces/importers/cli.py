"""The command line of the importers (:mod:`mifaces.cli.commands` adds them): ``mifaces import yaleb |
diligent | colmap | transforms | photos`` and ``mifaces export-calibration``, each one API call."""

from __future__ import annotations

import click

from ..capture.types import TRANSFERS
from ..cli.options import default
from .calibration_io import SPARSE, TRANSFORMS, export_calibration, import_calibration, import_colmap, import_transforms
from .diligent import ARCHIVE as DILIGENT_ARCHIVE, SPLIT as DILIGENT_SPLIT, import_object as import_diligent
from .photos import DEFAULT_FOCAL_35MM, import_photos
from .yaleb import SPLIT, import_subject


@click.group("import")
def import_() -> None:
    """Convert public data sets and other tools' calibrations into captures."""


@import_.command("yaleb")
@click.argument("subject_dir", type=click.Path(exists=True, file_okay=False))
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--train", "count", default=None, type=click.IntRange(1),
              help="Number of training lights, spread over the directions (default 8).")
@click.option("--train-lights", default=None, help="Training lights instead: stems or tags, e.g. A+000E+00,A+035E-20.")
@click.option("--force", is_flag=True, help="Write over an existing capture at OUT.")
@click.option("--unknown-lights", is_flag=True,
              help="Hide the light directions: same light names, marked unknown, estimated with the face.")
def yaleb(subject_dir: str, out: str, count: int | None, train_lights: str | None, force: bool,
          unknown_lights: bool) -> None:
    """Write the Extended Yale B subject in SUBJECT_DIR as a capture at OUT: the training photographs with
    their directional lights, the held-out ones named in OUT/split.json."""
    if count is not None and train_lights is not None:
        raise click.UsageError("give --train or --train-lights, not both")
    train = [s.strip() for s in train_lights.split(",") if s.strip()] if train_lights is not None else count or 8
    try:
        path = import_subject(subject_dir, out, train, force=force, unknown_lights=unknown_lights)
    except (FileExistsError, FileNotFoundError, ValueError) as error:
        raise click.ClickException(str(error)) from None
    click.echo(f"wrote the capture {path} and {path / SPLIT}")


@import_.command("diligent")
@click.argument("object_dir", type=click.Path(exists=True, file_okay=False))
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--force", is_flag=True, help="Write over an existing import at OUT.")
def diligent(object_dir: str, out: str, force: bool) -> None:
    """Write the DiLiGenT object in OBJECT_DIR as OUT/diligent.npz (images per unit light intensity, lights, mask;
    x right, y up, z towards the camera) and OUT/split.json (the fixed training and held-out halves of the lights)."""
    path = import_diligent(object_dir, out, force=force)
    click.echo(f"wrote {path / DILIGENT_ARCHIVE} and {path / DILIGENT_SPLIT}")


def _calibration_options(command):
    """The options of the imports of calibrations (:func:`~mifaces.importers.calibration_io.import_calibration`'s)."""
    options = [
        click.option("--force", is_flag=True, help="Write over an existing capture at OUT."),
        click.option("--diffuse", default=None, help="The image (its name in the calibration) that is every "
                     "measurement's diffuse companion, for the landmark detector (default: the first)."),
        click.option("--transfer", default=default(import_calibration, "transfer"), show_default=True,
                     type=click.Choice(TRANSFERS), help="How the images' codes decode to linear values."),
        click.option("--scale", default=default(import_calibration, "scale"), show_default=True,
                     type=click.FloatRange(min=0, min_open=True),
                     help="Millimetres per unit of the calibration's world frame."),
    ]
    for option in reversed(options):
        command = option(command)
    return command


@import_.command("colmap")
@click.argument("sparse_dir", type=click.Path(exists=True, file_okay=False))
@click.argument("image_dir", type=click.Path(exists=True, file_okay=False))
@click.argument("out", type=click.Path(file_okay=False))
@_calibration_options
def colmap(sparse_dir: str, image_dir: str, out: str, force: bool, diffuse: str | None, transfer: str,
           scale: float) -> None:
    """Write the images of the COLMAP sparse model SPARSE_DIR (text or binary), found in IMAGE_DIR, as a
    capture at OUT: its cameras, one unknown light per image (docs/capture.md)."""
    path = import_colmap(sparse_dir, image_dir, out, force=force, diffuse=diffuse, transfer=transfer, scale=scale)
    click.echo(f"wrote the capture {path}")


@import_.command("transforms")
@click.argument("transforms_json", type=click.Path(exists=True, dir_okay=False))
@click.argument("out", type=click.Path(file_okay=False))
@_calibration_options
def transforms(transforms_json: str, out: str, force: bool, diffuse: str | None, transfer: str, scale: float) -> None:
    """Write the frames of a Nerfstudio / instant-ngp TRANSFORMS_JSON (images relative to its folder) as a
    capture at OUT: its cameras, one unknown light per image (docs/capture.md)."""
    path = import_transforms(transforms_json, out, force=force, diffuse=diffuse, transfer=transfer, scale=scale)
    click.echo(f"wrote the capture {path}")


@import_.command("photos")
@click.argument("photo_dir", type=click.Path(exists=True, file_okay=False))
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--focal-35mm", type=click.FloatRange(min=0, min_open=True), default=None,
              help="The lens's focal length in 35 mm terms (default: from the pictures' EXIF, else "
                   f"{DEFAULT_FOCAL_35MM:g} mm).")
@click.option("--force", is_flag=True, help="Write over an existing capture at OUT.")
def photos(photo_dir: str, out: str, focal_35mm: float | None, force: bool) -> None:
    """Write the JPEG and PNG photographs of one face in PHOTO_DIR as a capture at OUT: one uncalibrated camera
    (focal length from EXIF), each photograph its own unknown light and pose, feature points detected
    (docs/capture.md)."""
    try:
        result = import_photos(photo_dir, out, force=force, focal_35mm=focal_35mm,
                               progress=lambda name: click.echo(f"  {name}: face found"))
    except (FileExistsError, ValueError) as error:
        raise click.ClickException(str(error)) from None
    for name, why in result.skipped.items():
        click.echo(f"  {name}: left out, {why}")
    click.echo(f"wrote the capture {result.path}: {result.measurements} photographs, focal length guess "
               f"{result.focal_px:.0f} px ({result.focal_from})")


@click.command("export-calibration")
@click.argument("capture", type=click.Path(exists=True))
@click.argument("out", type=click.Path(file_okay=False))
def export_calibration_command(capture: str, out: str) -> None:
    """Write the camera of CAPTURE for other tools: a COLMAP sparse model OUT/sparse/0/ (text) and a
    Nerfstudio / instant-ngp OUT/transforms.json, one entry per picture."""
    path = export_calibration(capture, out)
    click.echo(f"wrote {path / SPARSE} and {path / TRANSFORMS}")
