"""The 68 iBUG facial landmarks of a photograph, found automatically.

The detector is dlib's (King, "Dlib-ml: A machine learning toolkit", JMLR
10, 2009): a HOG face detector for the face box, then the ensemble of
regression trees of Kazemi and Sullivan ("One millisecond face alignment
with an ensemble of regression trees", CVPR 2014) trained on iBUG 300-W
(Sagonas et al., 2013), the ``shape_predictor_68_face_landmarks.dat`` that
the ``face-recognition-models`` package ships. Both work offline; they are
the optional extra ``pip install "mifaces[landmarks]"``.

Pixel coordinates: x right, y down, the centre of the top-left pixel at
(0, 0), as :class:`mifaces.capture.Camera`. dlib indexes ``image[y][x]`` at
the point ``(x, y)``, so its points are in this convention already; they
are whole pixels (dlib rounds its estimate to the nearest pixel centre).
Face boxes are dlib's rectangles, ``(x0, y0, x1, y1)`` with ``x1, y1`` the
last pixel inside: the whole image is ``(0, 0, W - 1, H - 1)``.

The indices are iBUG's in 0-based order here (row ``i`` is iBUG point
``i + 1``, the 1-based index of :data:`mifaces.model.landmarks.FEATURE_POINTS`); rows 0-16 are
the jaw contour, 17-67 the inner points.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.image_files import read_codes, read_exr

#: Number of landmarks (iBUG 300-W).
COUNT = 68
#: Rows of the jaw contour, whose points slide along the outline and are least reliable.
CONTOUR = slice(0, 17)
#: Rows of the inner points: eyebrows, nose, eyes, mouth.
INNER = slice(17, 68)
#: Times the detector upsamples the image to find small faces (dlib's usual choice).
UPSAMPLE = 1


class NoFaceError(ValueError):
    """The detector found no face in an image."""


@dataclass(frozen=True, eq=False)
class Landmarks:
    """The 68 landmarks of one face.

    Attributes
    ----------
    points : (68, 2) float64
        Pixel coordinates (x, y) in iBUG order, the top-left pixel's centre at (0, 0).
    box : (x0, y0, x1, y1) tuple of int
        The face box the points were predicted in (``x1, y1`` inside it).
    """

    points: np.ndarray
    box: tuple[int, int, int, int]


@functools.lru_cache(maxsize=1)
def _models():
    """dlib's face detector and the 68-point shape predictor, loaded once per process (about 1 s)."""
    try:
        import dlib
        import face_recognition_models
    except ImportError as error:
        raise ImportError(f'landmark detection needs dlib and its models: pip install "mifaces[landmarks]" '
                          f"({error})") from error
    predictor = dlib.shape_predictor(face_recognition_models.pose_predictor_model_location())
    return dlib, dlib.get_frontal_face_detector(), predictor


def _as_uint8(image) -> np.ndarray:
    """An image path or array as the 8-bit grey (H, W) or RGB (H, W, 3) array dlib takes.

    Integer codes keep their top 8 bits; floats are display values in [0, 1] (clipped).
    """
    if isinstance(image, (str, os.PathLike)):
        path = Path(image)
        if not path.is_file():
            raise FileNotFoundError(f"image not found: {path}")
        if path.suffix.lower() == ".exr":
            image = read_exr(path)
        else:
            image = read_codes(path)
    data = np.asarray(image)
    if data.ndim == 3 and data.shape[2] in (1, 3, 4):
        data = data[:, :, 0] if data.shape[2] == 1 else data[:, :, :3]
    if data.ndim not in (2, 3):
        raise ValueError(f"image must be (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), got shape {data.shape}")
    if data.dtype == np.uint8:
        out = data
    elif np.issubdtype(data.dtype, np.integer):
        out = np.clip(np.round(data * (255.0 / np.iinfo(data.dtype).max)), 0, 255).astype(np.uint8)
    elif np.issubdtype(data.dtype, np.floating):
        out = np.round(np.clip(np.nan_to_num(data), 0.0, 1.0) * 255.0).astype(np.uint8)
    else:
        raise ValueError(f"image must hold integers or floats, got {data.dtype}")
    return np.ascontiguousarray(out)


def detect_landmarks(image, box=None, name: str | None = None) -> Landmarks:
    """The 68 iBUG landmarks of the face in an image (the largest where there are several).

    Parameters
    ----------
    image : path or array
        A photograph (any format :func:`mifaces.io.image_files.read_codes` or
        EXR reads), or an array (H, W) or (H, W, C), integer codes or floats in [0, 1].
    box : (x0, y0, x1, y1), optional
        The face box, skipping the detector: needed for tight crops, whose
        face the detector may miss (for the Yale crops, the whole image).
    name : str, optional
        The image's name in errors (default: the path, or 'image').

    Returns
    -------
    Landmarks

    Raises
    ------
    NoFaceError
        Where the detector finds no face.
    ImportError
        Without the ``landmarks`` extra.
    """
    name = name or (str(image) if isinstance(image, (str, os.PathLike)) else "image")
    pixels = _as_uint8(image)
    dlib, detector, predictor = _models()
    if box is None:
        faces = list(detector(pixels, UPSAMPLE))
        if not faces:
            raise NoFaceError(f"no face found in {name}")
        rect = max(faces, key=lambda r: r.width() * r.height())
    else:
        if len(box) != 4:
            raise ValueError(f"box must be (x0, y0, x1, y1), got {box!r}")
        x0, y0, x1, y1 = (int(round(v)) for v in box)
        if x1 <= x0 or y1 <= y0:
            raise ValueError(f"box must have x1 > x0 and y1 > y0, got {box!r}")
        rect = dlib.rectangle(x0, y0, x1, y1)
    shape = predictor(pixels, rect)
    points = np.array([(shape.part(i).x, shape.part(i).y) for i in range(COUNT)], np.float64)
    return Landmarks(points, (rect.left(), rect.top(), rect.right(), rect.bottom()))
