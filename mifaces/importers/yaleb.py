"""The Extended Yale Face Database B (cropped): one face under 64 directional lights.

Georghiades, Belhumeur, Kriegman, "From few to many", PAMI 23(6), 2001;
Lee, Ho, Kriegman, "Acquiring linear subspaces for face recognition under
variable lighting", PAMI 27(5), 2005. A subject's folder holds
``yaleBxx_P00A{az}E{el}.pgm`` (8-bit greyscale, one strobe each, ambient
light included) and ``yaleBxx_P00_Ambient.pgm``.

Light directions: ``az`` and ``el`` are degrees from the camera axis;
positive azimuth lights the subject's right side (the image's left),
positive elevation is above. This module gives them as unit vectors from
the face towards the light in the camera frame of :mod:`mifaces.capture`
(OpenCV: x right, y down, z forward, away from the camera)::

    d = (-cos(el) sin(az), -sin(el), -cos(el) cos(az))

so the light at the camera, ``A+000E+00``, is ``(0, 0, -1)``, a light
above has negative y and one on the subject's right negative x.

:func:`import_subject` (``mifaces import yaleb``) writes a subject's
training photographs as a capture (:mod:`mifaces.capture`) whose world
frame is that camera frame, with the held-out lights named in ``split.json``.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model.geometry import camera_frame_direction
from ..io.image_files import read_codes
from ..capture.types import FORMAT, MANIFEST, VERSION
from ..io.atomic import atomic_write, write_json

#: ``yaleBxx_P00A+035E-20``: azimuth and elevation in degrees.
_LIGHT = re.compile(r"_P00A([+-]\d+)E([+-]\d+)$")
#: File of an imported capture naming its training and held-out photographs.
SPLIT = "split.json"
#: Focal length guess of :func:`import_subject`, in image heights (a long lens; see there).
FOCAL_GUESS = 4.0
#: Label of the one pose of every Yale photograph.
POSE = "frontal"
#: Training lights of :func:`default_split`: elevation and azimuth limits (degrees), so each lights most of the face.
MAX_ELEVATION = 60.0
MAX_AZIMUTH = 90.0
#: The imported capture says ``"ambient": "none"`` (no light but the strobe's) where the subject's
#: ambient-only frame is this dark against the training photographs (mean over mean); the three
#: subjects here read 0.013-0.015.
AMBIENT_NEGLIGIBLE = 0.05


@dataclass(frozen=True, eq=False)
class YaleImage:
    """One photograph of a subject under one light.

    Attributes
    ----------
    stem : str
        File name without suffix, e.g. ``yaleB01_P00A+035E-20``.
    pixels : (H, W) float32
        The 8-bit codes divided by 255 (the camera's response is unknown).
    azimuth, elevation : float
        The light's angles in degrees (see the module's conventions).
    direction : (3,) float64
        Unit vector towards the light in the camera frame (x right, y down, z forward).
    """

    stem: str
    pixels: np.ndarray
    azimuth: float
    elevation: float
    direction: np.ndarray

    @property
    def light(self) -> str:
        """The light's tag in the file name, e.g. ``A+035E-20``."""
        return self.stem.rsplit("_P00", 1)[-1]


def light_direction(azimuth: float, elevation: float) -> np.ndarray:
    """Unit vector towards a Yale light in the camera frame (x right, y down, z forward)."""
    return camera_frame_direction(azimuth, elevation)


def _pixels(path: Path) -> np.ndarray:
    codes = read_codes(path)
    if codes.dtype != np.uint8 or codes.ndim != 2:
        raise ValueError(f"{path.name}: expected an 8-bit greyscale image, got {codes.dtype} {codes.shape}")
    return codes.astype(np.float32) / np.float32(255.0)


def read_subject(subject_dir: str | os.PathLike) -> list[YaleImage]:
    """The light images of one subject's folder, sorted by file name (the ambient image is left out).

    Raises
    ------
    FileNotFoundError
        For a folder without Yale light images.
    """
    folder = Path(subject_dir)
    images = []
    for path in sorted(folder.glob("*_P00A*E*.pgm")):
        match = _LIGHT.search(path.stem)
        if match is None:
            continue
        azimuth, elevation = float(match.group(1)), float(match.group(2))
        images.append(YaleImage(path.stem, _pixels(path), azimuth, elevation, light_direction(azimuth, elevation)))
    if not images:
        raise FileNotFoundError(f"no Yale light images (*_P00A*E*.pgm) in {folder}")
    return images


def read_ambient(subject_dir: str | os.PathLike) -> np.ndarray:
    """The subject's ambient-only image (H, W) float32, codes / 255 (already in every light image)."""
    paths = sorted(Path(subject_dir).glob("*_P00_Ambient.pgm"))
    if not paths:
        raise FileNotFoundError(f"no ambient image (*_P00_Ambient.pgm) in {subject_dir}")
    return _pixels(paths[0])


def default_split(images: list[YaleImage], train: int | list[str] = 8) -> tuple[list[YaleImage], list[YaleImage]]:
    """Training lights spread over the sphere of directions, the others held out.

    With a count, the training lights are chosen greedily: first the one
    nearest the camera (``A+000E+00``), then each time the light farthest
    (largest smallest angle) from those chosen, among the lights with
    elevation <= :data:`MAX_ELEVATION` and ``|azimuth| <=`` :data:`MAX_AZIMUTH`
    so that each training photograph lights most of the face; ties go to the
    earlier image. The choice depends only on the directions present, so it
    is the same for every subject with the full set of 64.

    Parameters
    ----------
    images : list of YaleImage
        As from :func:`read_subject`.
    train : int or list of str
        How many training lights, or their stems or light tags (``'A+035E-20'``).

    Returns
    -------
    train, held_out : lists of YaleImage
        Disjoint; ``train`` in the order chosen, ``held_out`` in the order of ``images``.
    """
    if isinstance(train, int):
        chosen = _farthest_points(images, train)
    else:
        index = {key: i for i, image in enumerate(images) for key in (image.stem, image.light)}
        unknown = [s for s in train if s not in index]
        if unknown:
            raise ValueError(f"unknown training lights {unknown}")
        chosen = list(dict.fromkeys(index[s] for s in train))
    taken = set(chosen)
    held_out = [image for i, image in enumerate(images) if i not in taken]
    return [images[i] for i in chosen], held_out


def _farthest_points(images: list[YaleImage], count: int) -> list[int]:
    """Greedy farthest-point choice of ``count`` lights, from the one nearest the camera."""
    candidates = [i for i, image in enumerate(images)
                  if image.elevation <= MAX_ELEVATION and abs(image.azimuth) <= MAX_AZIMUTH]
    if not 1 <= count <= len(candidates):
        raise ValueError(f"train must be between 1 and {len(candidates)} (the candidate lights), got {count}")
    directions = np.stack([images[i].direction for i in candidates])
    chosen = [int(np.argmax(directions @ light_direction(0.0, 0.0)))]
    nearest = directions @ directions[chosen[0]]  # cosine to the nearest chosen light
    while len(chosen) < count:
        best = int(np.argmin(nearest))  # the first of equals
        chosen.append(best)
        nearest = np.maximum(nearest, directions @ directions[best])
    return [candidates[i] for i in chosen]


def import_subject(subject_dir: str | os.PathLike, out: str | os.PathLike, train: int | list[str] = 8,
                   force: bool = False, unknown_lights: bool = False) -> Path:
    """Write one subject's training photographs as a capture, the held-out ones named in ``split.json``.

    The capture at ``out`` (``capture.json``, ``images/``, ``split.json``):

    * **World frame** = the camera frame (camera at the origin, identity
      rotation, OpenCV axes: x right, y down, z forward).
    * **Camera**: uncalibrated (``"calibrated": false``), the shape fit
      estimates it. The crops are 168 x 192 pixels of a larger frame taken by
      an unknown lens at an unknown offset, so the guess is a long lens,
      ``focal_guess_px`` = :data:`FOCAL_GUESS` x the image height (a field
      of view of 14 degrees over the crop: the face about four face heights
      away, nearly orthographic, which a face filling a crop of a distant
      camera's frame is), and the principal point at the crop's centre (the
      crop is centred on the face; with a long lens an offset principal point
      trades against the face's position).
    * **Lights**: one directional light per training photograph, named by its
      tag (``A+035E-20``), ``direction`` from the file name
      (:func:`light_direction`), no intensity, so ``relative`` at
      :data:`~mifaces.capture.types.RELATIVE_IRRADIANCE` (the database's
      strobes are equal, their absolute power unknown). With
      ``unknown_lights``, the same names without directions
      (``"unknown": true``): lights to estimate with the face
      (``docs/unknown_lights.md``).
    * **Measurements**: one per training photograph, named by its stem, the
      PGM file copied into ``images/`` as is (``transfer`` linear: the
      codes are taken as proportional to radiance, the camera's response being
      unknown); all of pose :data:`POSE`; their ``diffuse`` companion is the
      training photograph whose light is nearest the camera axis (evenly lit
      for the landmark detector; never a held-out one).
    * ``"ambient": "none"`` where the subject's ambient-only frame
      (:func:`read_ambient`) is darker than :data:`AMBIENT_NEGLIGIBLE` of
      the training photographs (their means): no light but the strobe's, so
      the shape fit holds its ambient term at zero (``Capture.ambient_light``);
      the ratio is in ``metadata.ambient_fraction``. Without an ambient frame,
      or a brighter one, the capture leaves ``ambient`` out (fitted).
    * No white target and no distances (reflectance only up to a factor, and
      no absolute scale); no feature points: :func:`mifaces.capture.load_capture`
      detects them in the companion, inside the capture-level ``face_box``
      of the whole image (the detector misses faces on these tight crops).
    * ``split.json``: ``{"train": [stems], "heldout": [stems]}``, the held-out
      photographs for relighting to be compared with (they stay in ``subject_dir``).

    Parameters
    ----------
    subject_dir : path
        A subject's folder (``yaleBxx_P00A{az}E{el}.pgm``).
    out : path
        The capture folder to write.
    train : int or list of str
        The training lights: a count for :func:`default_split`, or stems or light tags.
    force : bool
        Write over an existing capture at ``out``.
    unknown_lights : bool
        Hide the light directions: every light ``{"name": tag, "unknown": true}``
        (the companion stays the photograph nearest the camera axis, an evenly lit
        picture as one would take for the landmark detector).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    FileExistsError
        Where ``out`` holds a capture already and ``force`` is False.
    FileNotFoundError, ValueError
        From :func:`read_subject` and :func:`default_split`.
    """
    folder, out = Path(subject_dir), Path(out)
    if (out / MANIFEST).exists() and not force:
        raise FileExistsError(f"{out} holds a capture already ({MANIFEST}); use force=True (--force) to replace it")
    images = read_subject(folder)
    training, held_out = default_split(images, train)
    companion = max(training, key=lambda image: -image.direction[2])  # nearest the camera axis, (0, 0, -1)
    height, width = images[0].pixels.shape
    for image in training:
        with atomic_write(out / "images" / f"{image.stem}.pgm") as f:
            f.write((folder / f"{image.stem}.pgm").read_bytes())
    write_json(out / SPLIT, {"train": [i.stem for i in training], "heldout": [i.stem for i in held_out]})
    fraction = ambient_fraction(folder, training)
    manifest = {
        "format": FORMAT, "version": VERSION,
        "camera": {"width": width, "height": height, "calibrated": False, "focal_guess_px": FOCAL_GUESS * height},
        "face_box": [0, 0, width - 1, height - 1],
        "lights": [{"name": i.light, "unknown": True} if unknown_lights else
                   {"name": i.light, "direction": (i.direction + 0.0).tolist(), "relative": True} for i in training],
        "measurements": [{"name": i.stem, "light": i.light, "pose": POSE,
                          "image": {"path": f"images/{i.stem}.pgm", "transfer": "linear"},
                          "diffuse": {"path": f"images/{companion.stem}.pgm", "transfer": "linear"}}
                         for i in training],
        "metadata": {"source": "Extended Yale Face Database B, cropped (Georghiades et al. 2001; Lee et al. 2005)",
                     "subject": folder.name, "subject_dir": str(folder.resolve()), "split": SPLIT,
                     "ambient_fraction": fraction},
    }
    if fraction is not None and fraction < AMBIENT_NEGLIGIBLE:
        manifest["ambient"] = "none"
    write_json(out / MANIFEST, manifest)
    return out


def ambient_fraction(subject_dir: str | os.PathLike, training: list[YaleImage]) -> float | None:
    """How bright the subject's ambient-only frame is against the training photographs (mean over
    their mean), or None where the folder has no ambient frame."""
    try:
        ambient = read_ambient(subject_dir)
    except FileNotFoundError:
        return None
    return float(ambient.mean() / np.mean([image.pixels.mean() for image in training]))
