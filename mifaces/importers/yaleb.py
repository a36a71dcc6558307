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
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..capture.images import read_codes

#: ``yaleBxx_P00A+035E-20``: azimuth and elevation in degrees.
_LIGHT = re.compile(r"_P00A([+-]\d+)E([+-]\d+)$")
#: Training lights of :func:`default_split`: elevation and azimuth limits (degrees), so each lights most of the face.
MAX_ELEVATION = 60.0
MAX_AZIMUTH = 90.0


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
    az, el = np.radians(azimuth), np.radians(elevation)
    return np.array([-np.cos(el) * np.sin(az), -np.sin(el), -np.cos(el) * np.cos(az)])


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
