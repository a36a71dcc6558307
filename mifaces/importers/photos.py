"""A folder of ordinary photographs of one face as a capture: :func:`import_photos`
(``mifaces import photos DIR OUT``).

Phone or camera pictures come without a calibration, a manifest or clicked points. This writes all of
them:

* **Camera**: one uncalibrated camera (``"calibrated": false``) of the photographs' size, its focal
  length a guess the shape fit refines: from the EXIF focal length in 35 mm terms where a picture
  has one (``FocalLengthIn35mmFilm``, or ``FocalLength`` with the focal plane's resolution), else
  :data:`DEFAULT_FOCAL_35MM`; the median over the pictures. A focal length in 35 mm terms ``F`` is
  ``F / 36`` of the picture's longer side in pixels (the 36 mm width of the 35 mm frame).
* **Orientation**: a picture that EXIF says is turned (``Orientation``) is written upright (PNG).
* **Lights and poses**: each photograph its own unknown directional light (``"unknown": true``:
  estimated with the face) and its own head pose; pictures taken at one instant (the same EXIF
  ``DateTimeOriginal`` with its sub-seconds) share one.
* **Feature points**: detected here (:func:`mifaces.capture.feature_points.detect_feature_points`),
  written into the manifest for a person to check and correct. A picture where no face is found is
  left out, and said so: it does not take the others down.

The photographs must all be of one size (one camera). Written atomically, as one manifest.
"""

from __future__ import annotations

import os
import statistics
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import ExifTags, Image as PillowImage, ImageOps

from ..capture.detector import NoFaceError
from ..capture.feature_points import detect_feature_points
from ..capture.images import read_image
from ..capture.types import FEATURE_POINT_RANGE, FORMAT, MANIFEST, VERSION
from ..io.atomic import atomic_write, write_json
from ..io.paths import check_name

#: The pictures read: JPEG and PNG, as phones and cameras write them (8-bit sRGB).
SUFFIXES = (".jpg", ".jpeg", ".png")
#: Focal length (mm, 35 mm terms) guessed for a picture without EXIF: a phone's main camera (26-28 mm).
DEFAULT_FOCAL_35MM = 28.0
#: Width (mm) of the 35 mm frame, to which focal lengths "in 35 mm terms" refer.
FRAME_35MM = 36.0
#: EXIF's units of the focal plane resolution: inches, centimetres, millimetres (mm per unit).
_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0}


@dataclass
class PhotoImport:
    """What :func:`import_photos` wrote: the capture folder, the focal length guess (px) and where it
    came from, and the pictures left out (name -> why)."""

    path: Path
    focal_px: float
    focal_from: str
    skipped: dict = field(default_factory=dict)
    measurements: int = 0


def exif_focal_35mm(exif) -> float | None:
    """A picture's focal length in 35 mm terms from its EXIF (Pillow's ``getexif()``), or None."""
    tags = exif.get_ifd(ExifTags.IFD.Exif) if exif else {}
    value = tags.get(ExifTags.Base.FocalLengthIn35mmFilm)
    if value:
        return float(value)
    focal, resolution = tags.get(ExifTags.Base.FocalLength), tags.get(ExifTags.Base.FocalPlaneXResolution)
    unit = _UNIT_MM.get(int(tags.get(ExifTags.Base.FocalPlaneResolutionUnit, 2)))
    width = tags.get(ExifTags.Base.ExifImageWidth)
    if focal and resolution and unit and width:
        sensor_mm = float(width) / float(resolution) * unit  # the sensor's width
        return float(focal) * FRAME_35MM / sensor_mm
    return None


def _shot(exif) -> str | None:
    """When a picture was taken (EXIF ``DateTimeOriginal`` and its sub-seconds), or None."""
    tags = exif.get_ifd(ExifTags.IFD.Exif) if exif else {}
    when = tags.get(ExifTags.Base.DateTimeOriginal)
    return None if not when else f"{when}.{tags.get(ExifTags.Base.SubsecTimeOriginal, '')}"


def import_photos(photo_dir: str | os.PathLike, out: str | os.PathLike, force: bool = False,
                  focal_35mm: float | None = None, progress=None) -> PhotoImport:
    """Write the JPEG and PNG pictures of one face in ``photo_dir`` as a capture at ``out`` (module
    docstring). ``focal_35mm``: the lens's focal length in 35 mm terms, over EXIF and the default.
    ``progress``: a callable told each picture's name as it is done.

    Raises
    ------
    FileExistsError
        Where ``out`` holds a capture already and ``force`` is False.
    ValueError
        For a folder without pictures, pictures of different sizes, a picture name that cannot name a
        measurement, or no picture in which a face is found.
    """
    photo_dir, out = Path(photo_dir), Path(out)
    if (out / MANIFEST).exists() and not force:
        raise FileExistsError(f"{out} holds a capture already ({MANIFEST}); use force=True (--force) to replace it")
    if focal_35mm is not None and not (np.isfinite(focal_35mm) and focal_35mm > 0):
        raise ValueError(f"focal_35mm: must be a positive focal length in mm, got {focal_35mm!r}")
    files = sorted(p for p in photo_dir.iterdir() if p.suffix.lower() in SUFFIXES and p.is_file())
    if not files:
        raise ValueError(f"{photo_dir}: no photographs ({', '.join(SUFFIXES)})")
    pictures, sizes, focals, skipped = [], {}, [], {}
    for path in files:
        name = check_name(path.stem.replace(" ", "_"), f"the measurement name of {path.name!r}")
        with PillowImage.open(path) as opened:
            exif = opened.getexif()
            turned = ImageOps.exif_transpose(opened) if exif.get(ExifTags.Base.Orientation, 1) != 1 else None
            sizes.setdefault((turned or opened).size, []).append(path.name)
            focal = exif_focal_35mm(exif)
            if focal is not None:
                focals.append(focal)
            pictures.append((name, path, turned, _shot(exif)))
    if len(sizes) > 1:
        listed = "; ".join(f"{w}x{h}: {', '.join(names[:3])}" for (w, h), names in sizes.items())
        raise ValueError(f"{photo_dir}: the photographs are of {len(sizes)} sizes ({listed}); one camera takes "
                         "one size: import each size apart")
    (width, height), = sizes
    focal_mm, focal_from = ((focal_35mm, "given") if focal_35mm is not None else
                            (statistics.median(focals), f"EXIF of {len(focals)} of {len(files)} photographs") if focals
                            else (DEFAULT_FOCAL_35MM, "default: no EXIF focal length"))
    focal_px = focal_mm / FRAME_35MM * max(width, height)
    images = out / "images"
    measurements, lights, shots = [], [], {}
    for name, path, turned, when in pictures:
        target = images / (f"{name}.png" if turned is not None else path.name)
        with atomic_write(target) as f:
            if turned is not None:
                turned.save(f, format="PNG")
            else:
                f.write(path.read_bytes())
        relative = f"images/{target.name}"
        try:
            points = detect_feature_points(read_image(target, "srgb"), name=relative)
        except NoFaceError as error:
            skipped[path.name] = f"no face found ({error})"
            continue
        if len(points) < FEATURE_POINT_RANGE[0]:
            skipped[path.name] = f"only {len(points)} feature points found, a measurement needs {FEATURE_POINT_RANGE[0]}"
            continue
        pose = shots.setdefault(when, f"P{len(shots):02d}") if when is not None else f"P_{name}"
        picture = {"path": relative, "transfer": "srgb"}
        lights.append({"name": name, "unknown": True})
        measurements.append({"name": name, "light": name, "pose": pose, "image": picture, "diffuse": picture,
                             "feature_points": {k: [round(float(v), 2) for v in xy] for k, xy in points.items()}})
        if progress is not None:
            progress(path.name)
    if not measurements:
        raise ValueError(f"{photo_dir}: no face found in any photograph: " + "; ".join(
            f"{k}: {v}" for k, v in skipped.items()))
    write_json(out / MANIFEST, {
        "format": FORMAT, "version": VERSION,
        "camera": {"width": width, "height": height, "calibrated": False, "focal_guess_px": round(focal_px, 2)},
        "lights": lights, "measurements": measurements,
        "metadata": {"source": f"photographs in {photo_dir.resolve()}", "focal_35mm": focal_mm,
                     "focal_from": focal_from, "skipped": skipped}})
    return PhotoImport(out, focal_px, focal_from, skipped, len(measurements))
