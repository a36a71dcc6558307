"""Captures: the photographs of one measurement session and their calibration.

A capture is a folder with a JSON manifest, ``capture.json``, and the images it
names (paper sec. 3; the format is documented in ``docs/capture.md``). It
holds the camera (calibrated, or only a guess of its intrinsics), the light
conditions (a point light's position and intensity, the two steel-sphere
pictures to compute the position from, or a directional light's direction,
possibly of unknown absolute intensity), and per measurement the
point-light image (colour or greyscale), its companion diffuse-light image
or exposure series, and named feature points (detected automatically where
the capture gives none, :mod:`mifaces.capture.feature_points`); optionally
metric distances on the face and the value of the white calibration target.

:func:`load_capture` reads and validates a capture and returns a
:class:`Capture`, a plain dataclass of arrays. Every problem found is named
in one :class:`CaptureError`. A ``ground_truth/`` subfolder (written by the
simulator) is never read by it: :func:`read_ground_truth` reads it, as a
:class:`GroundTruth`.

Conventions
-----------
* Lengths in millimetres, in the capture's **world frame**.
* The camera follows OpenCV: pixel ``(x, y)`` = (column, row) with the
  centre of the top-left pixel at ``(0, 0)``; camera axes x right, y down,
  z forward; intrinsics ``fx, fy, cx, cy``; distortion coefficients
  ``k1, k2, p1, p2[, k3[, k4, k5, k6]]``; pose as ``rotation`` R and
  ``translation`` t with ``x_camera = R x_world + t``.
* Images are returned as float32 (H, W, 3) **linear** values divided by
  their exposure, so images taken with different exposures compare directly.
"""


from .camera import Camera
from .ground_truth import (GroundTruth, TrueLight, TrueMeasurement, read_ground_truth, with_true_lights,
                           write_ground_truth)
from .images import decode, read_image
from .loader import load_capture
from .types import (FEATURE_POINT_RANGE, FORMAT, GROUND_TRUTH, IMAGE_SUFFIXES, MANIFEST, TRANSFERS, VERSION,
                    Capture, CaptureError, Distance, Image, Light, Measurement, SpherePictures, WhiteTarget)

__all__ = ["Camera", "Capture", "CaptureError", "Distance", "Image", "Light", "Measurement", "SpherePictures",
           "WhiteTarget", "decode", "read_image", "load_capture", "MANIFEST", "FORMAT", "VERSION", "GROUND_TRUTH",
           "FEATURE_POINT_RANGE", "TRANSFERS", "IMAGE_SUFFIXES", "GroundTruth", "TrueLight", "TrueMeasurement",
           "read_ground_truth", "with_true_lights", "write_ground_truth"]
