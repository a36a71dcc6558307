"""Feature points of a photograph found by the 68-point landmark detector (:mod:`mifaces.capture.detector`),
for captures whose manifest marks none (:func:`mifaces.capture.load_capture` calls it)."""

from __future__ import annotations

import numpy as np

from .detector import CONTOUR, detect_landmarks
from ..model.landmarks import FEATURE_POINTS
from .types import Image

#: The named feature points detection gives: the jaw contour slides along the face's outline and
#: is cut off on tight crops, so of it only the chin is kept.
DETECTED_POINTS = {name: index for name, index in FEATURE_POINTS.items()
                   if not CONTOUR.start < index <= CONTOUR.stop or name == "chin"}
#: Percentile of a photograph's linear values shown as white to the detector.
DISPLAY_PERCENTILE = 99.5


def display_values(image: Image) -> np.ndarray:
    """A photograph as a viewer shows it, for the detector: the linear values exposed so that their
    :data:`DISPLAY_PERCENTILE` is white, sRGB-encoded (IEC 61966-2-1, colour-science)."""
    import colour  # colour-science takes most of a second to import: only where faces are detected

    pixels = image.pixels[..., 0] if image.greyscale else image.pixels
    top = float(np.percentile(pixels, DISPLAY_PERCENTILE))
    exposed = np.clip(pixels / top if top > 0 else pixels, 0.0, 1.0)
    return np.asarray(colour.cctf_encoding(exposed, function="sRGB"), np.float32)


def detect_feature_points(image: Image, box=None, name: str | None = None) -> dict[str, np.ndarray]:
    """The named feature points of the face in a photograph, by the 68-point landmark detector.

    The points of :data:`DETECTED_POINTS` (iBUG index i is the detector's row i - 1) that fall inside
    the image. Detection works on the photograph as a viewer shows it (:func:`display_values`).

    Parameters
    ----------
    image : Image
        Best an evenly lit one (a measurement's diffuse companion).
    box : (x0, y0, x1, y1), optional
        The face box, pixels (see :func:`mifaces.capture.detector.detect_landmarks`); None: the detector finds it.
    name : str, optional
        The image's name in errors.

    Raises
    ------
    mifaces.capture.detector.NoFaceError
        Where no face is found.
    """
    points = detect_landmarks(display_values(image), box=box, name=name or str(image.path)).points
    height, width = image.pixels.shape[:2]
    inside = (points[:, 0] >= -0.5) & (points[:, 0] <= width - 0.5) & (points[:, 1] >= -0.5) & \
        (points[:, 1] <= height - 0.5)
    return {point: points[index - 1].copy() for point, index in DETECTED_POINTS.items() if inside[index - 1]}
