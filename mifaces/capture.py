"""Captures: the photographs of one measurement session and their calibration.

A capture is a folder with a JSON manifest, ``capture.json``, and the images it
names (paper sec. 3; the format is documented in ``docs/capture.md``). It
holds the calibrated camera, the light conditions (a light position and
intensity, or the two steel-sphere pictures to compute the position from),
and per measurement the point-light image, its companion diffuse-light image
or exposure series, and named feature points; plus three metric distances on
the face and the value of the white calibration target.

:func:`load_capture` reads and validates a capture and returns a
:class:`Capture`, a plain dataclass of arrays. Every problem found is named
in one :class:`CaptureError`. A ``ground_truth/`` subfolder (written by the
simulator) is never read.

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

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .model.landmarks import FEATURE_POINTS

#: File name of the manifest inside a capture folder.
MANIFEST = "capture.json"
#: Value of the manifest's ``format`` field, and the version this module reads.
FORMAT = "mifaces-capture"
VERSION = 1
#: Subfolder of a capture that loading ignores (the simulator's ground truth).
GROUND_TRUTH = "ground_truth"
#: Number of named feature points a measurement must have (paper sec. 4.2).
FEATURE_POINT_RANGE = (7, 20)
#: Transfer curves of integer images.
TRANSFERS = ("linear", "srgb", "gamma")
IMAGE_SUFFIXES = (".exr", ".png", ".tif", ".tiff", ".jpg", ".jpeg")


class CaptureError(ValueError):
    """A capture that cannot be loaded; the message lists every problem found."""

    def __init__(self, path, problems: list[str]):
        self.path = Path(path)
        self.problems = list(problems)
        lines = "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(f"invalid capture {self.path}: {len(self.problems)} problem(s)\n{lines}")


# --------------------------------------------------------------------------------------------
# Camera
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated pinhole camera with lens distortion, in OpenCV conventions.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point in pixels (pixel centres at integers).
    distortion : (D,) float64
        OpenCV coefficients ``k1, k2, p1, p2[, k3[, k4, k5, k6]]`` (D = 0, 4, 5 or 8).
    rotation : (3, 3) float64
        R of ``x_camera = R x_world + t``.
    translation : (3,) float64
        t of that relation, in mm.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 intrinsic matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def position(self) -> np.ndarray:
        """Centre of projection in world coordinates, ``-R^T t``."""
        return -self.rotation.T @ self.translation

    def to_camera(self, points) -> np.ndarray:
        """World points (..., 3) to camera coordinates."""
        return np.asarray(points, np.float64) @ self.rotation.T + self.translation

    def to_world(self, points) -> np.ndarray:
        """Camera points (..., 3) to world coordinates."""
        return (np.asarray(points, np.float64) - self.translation) @ self.rotation

    def _coefficients(self) -> np.ndarray:
        d = np.zeros(8)
        d[:len(self.distortion)] = self.distortion
        return d

    def distort(self, xy) -> np.ndarray:
        """Apply lens distortion to normalised image coordinates (..., 2) (OpenCV's model)."""
        k1, k2, p1, p2, k3, k4, k5, k6 = self._coefficients()
        xy = np.asarray(xy, np.float64)
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def undistort(self, xy, iterations: int = 20) -> np.ndarray:
        """Invert :meth:`distort` by fixed-point iteration (as OpenCV's ``undistortPoints``)."""
        xy = np.asarray(xy, np.float64)
        if not np.any(self.distortion):
            return xy
        k1, k2, p1, p2, k3, k4, k5, k6 = self._coefficients()
        x, y = xy[..., 0].copy(), xy[..., 1].copy()
        for _ in range(iterations):
            r2 = x * x + y * y
            inv_radial = (1 + r2 * (k4 + r2 * (k5 + r2 * k6))) / (1 + r2 * (k1 + r2 * (k2 + r2 * k3)))
            dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
            x = (xy[..., 0] - dx) * inv_radial
            y = (xy[..., 1] - dy) * inv_radial
        return np.stack([x, y], axis=-1)

    def project(self, points) -> np.ndarray:
        """Pixel coordinates (..., 2) of world points (..., 3)."""
        pc = self.to_camera(points)
        xy = self.distort(pc[..., :2] / pc[..., 2:3])
        return np.stack([self.fx * xy[..., 0] + self.cx, self.fy * xy[..., 1] + self.cy], axis=-1)

    def pixel_rays(self, pixels) -> np.ndarray:
        """Unit ray directions (..., 3) in **camera** coordinates through pixels (..., 2)."""
        p = np.asarray(pixels, np.float64)
        xy = self.undistort(np.stack([(p[..., 0] - self.cx) / self.fx, (p[..., 1] - self.cy) / self.fy], -1))
        d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def to_json(self) -> dict:
        """The manifest's ``camera`` entry."""
        return {"width": int(self.width), "height": int(self.height), "fx": float(self.fx), "fy": float(self.fy),
                "cx": float(self.cx), "cy": float(self.cy), "distortion": [float(d) for d in self.distortion],
                "rotation": np.asarray(self.rotation, float).tolist(),
                "translation": [float(t) for t in self.translation]}


# --------------------------------------------------------------------------------------------
# Capture values
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Image:
    """One photograph, decoded.

    Attributes
    ----------
    pixels : (H, W, 3) float32
        Linear values divided by ``exposure``.
    saturated : (H, W) bool
        Pixels where a channel reached the sensor's clipping level.
    exposure : float
        Relative exposure (time x gain) the picture was taken with.
    path : Path
    """

    pixels: np.ndarray
    saturated: np.ndarray
    exposure: float
    path: Path


@dataclass(frozen=True, eq=False)
class SpherePictures:
    """The two steel-sphere pictures of one light condition (paper sec. 3).

    ``highlight`` is taken under the point light (the spheres show its
    reflection), ``outline`` under the diffuse light (the spheres show their
    outline against the background). ``radius`` is the spheres' radius in mm.
    """

    radius: float
    highlight: Image
    outline: Image


@dataclass(frozen=True, eq=False)
class Light:
    """One light condition.

    Attributes
    ----------
    name : str
    position : (3,) float64 or None
        World position in mm, as given or as calibrated from ``spheres``.
    intensity : (3,) float64
        Radiant intensity of the point light per RGB channel, in the units of
        the white target's calibration.
    spheres : SpherePictures or None
    calibration : object or None
        The :class:`mifaces.calibration.LightCalibration` the position came from.
    """

    name: str
    position: np.ndarray | None
    intensity: np.ndarray
    spheres: SpherePictures | None = None
    calibration: object | None = None


@dataclass(frozen=True, eq=False)
class Measurement:
    """One measurement: a point-light photograph and its companions at one pose.

    Attributes
    ----------
    name : str
    light : str
        Name of the :class:`Light` condition.
    pose : str or None
        Label shared by the measurements taken at one pose of the subject.
    image : Image
        The point-light photograph the BRDF is fitted to.
    diffuse : Image or None
        Companion picture under diffuse light.
    exposures : tuple of Image
        Companion exposure series (may be empty).
    feature_points : dict
        Feature point name (see :data:`mifaces.model.landmarks.FEATURE_POINTS`)
        -> pixel position (2,) float64.
    """

    name: str
    light: str
    pose: str | None
    image: Image
    diffuse: Image | None
    exposures: tuple[Image, ...]
    feature_points: dict[str, np.ndarray]


@dataclass(frozen=True)
class Distance:
    """A metric distance on the face between two named feature points, in mm."""

    start: str
    end: str
    mm: float


@dataclass(frozen=True, eq=False)
class WhiteTarget:
    """The white calibration target.

    ``value`` is the linear RGB pixel value (per unit exposure) that a
    Lambertian target of reflectance ``reflectance`` shows when lit by a
    point light of intensity ``intensity`` at ``distance`` mm with incidence
    cosine ``cos_incidence``.
    """

    value: np.ndarray
    reflectance: float
    distance: float
    intensity: np.ndarray
    cos_incidence: float = 1.0

    def reflectance_scale(self) -> np.ndarray:
        """The scale s (RGB) of ``r = s R d² / (I cos θ)`` that gives the target
        its reflectance (the physical reading of the paper's eq. 4; see
        :func:`mifaces.reflectance_samples.reflectance`): with that s, a white
        target of reflectance 1 has r = 1."""
        return self.reflectance * self.intensity * self.cos_incidence / (self.value * self.distance ** 2)


@dataclass(frozen=True, eq=False)
class Capture:
    """A loaded, validated capture (see the module docstring)."""

    path: Path
    camera: Camera
    lights: tuple[Light, ...]
    measurements: tuple[Measurement, ...]
    distances: tuple[Distance, ...]
    white_target: WhiteTarget
    metadata: dict = field(default_factory=dict)

    def light(self, name: str) -> Light:
        """The light condition called ``name``."""
        for light in self.lights:
            if light.name == name:
                return light
        raise KeyError(f"no light {name!r} in {self.path}; lights: {[l.name for l in self.lights]}")

    def __repr__(self) -> str:
        return (f"Capture({str(self.path)!r}: {self.camera.width}x{self.camera.height}, "
                f"{len(self.lights)} lights, {len(self.measurements)} measurements)")


# --------------------------------------------------------------------------------------------
# Reading images
# --------------------------------------------------------------------------------------------
def decode(data: np.ndarray, transfer: str = "linear", gamma: float = 2.2) -> np.ndarray:
    """Integer or float pixel data to linear float values in [0, 1] (floats unchanged by ``'linear'``).

    Parameters
    ----------
    data : array
        ``uint8``/``uint16`` codes (divided by the largest code) or floats.
    transfer : {'linear', 'srgb', 'gamma'}
        The encoding curve: ``'srgb'`` is IEC 61966-2-1, inverted with
        colour-science's ``cctf_decoding``; ``'gamma'`` is ``v ** gamma``.
    """
    if transfer == "srgb":
        from .hdr import decode_srgb

        return decode_srgb(data)
    if np.issubdtype(data.dtype, np.integer):
        values = data.astype(np.float64) / np.iinfo(data.dtype).max
    else:
        values = data.astype(np.float64)
    if transfer == "linear":
        out = values
    elif transfer == "gamma":
        out = np.clip(values, 0.0, None) ** gamma
    else:
        raise ValueError(f"transfer must be one of {TRANSFERS}, got {transfer!r}")
    return np.asarray(out, np.float32)


def read_image(path: str | os.PathLike, transfer: str = "linear", gamma: float = 2.2, exposure: float = 1.0,
               saturation: float | None = None) -> Image:
    """Read a photograph as an :class:`Image` (linear RGB per unit exposure).

    EXR files must be linear. Integer images (PNG, TIFF, JPEG; 8 or 16 bit)
    are decoded with ``transfer``; their saturated pixels are those at the
    largest code. ``saturation`` (linear value, before dividing by the
    exposure) marks saturated pixels of float images.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"image not found: {path}")
    if path.suffix.lower() == ".exr":
        from .files import read_exr

        if transfer != "linear":
            raise ValueError(f"{path.name}: EXR images are linear, not {transfer!r}")
        data = read_exr(path)
        top = None
    else:
        import skimage.io

        data = skimage.io.imread(path)
        if data.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"{path.name}: integer images must be 8 or 16 bit, got {data.dtype}")
        top = np.iinfo(data.dtype).max
    if data.ndim == 2:
        data = data[:, :, None]
    if data.ndim != 3 or data.shape[2] not in (1, 3, 4):
        raise ValueError(f"{path.name}: expected 1, 3 or 4 channels, got shape {data.shape}")
    data = data[:, :, :3] if data.shape[2] >= 3 else np.repeat(data, 3, axis=2)
    if top is not None:
        saturated = np.any(data >= top, axis=2)
    elif saturation is not None:
        saturated = np.any(data >= saturation, axis=2)
    else:
        saturated = np.zeros(data.shape[:2], bool)
    pixels = decode(data, transfer, gamma) / np.float32(exposure)
    return Image(pixels=pixels, saturated=saturated, exposure=float(exposure), path=path)


# --------------------------------------------------------------------------------------------
# Loading and validating
# --------------------------------------------------------------------------------------------
class _Problems(list):
    """Collects validation messages; each names where in the manifest it is."""

    def objects(self, data, key: str, what: str):
        """Yield ``(index, entry, where)`` for the objects of the non-empty list
        ``data[key]``, recording a problem for a missing list or a non-object."""
        entries = data.get(key)
        if not isinstance(entries, list) or not entries:
            self.append(f"{key}: need a non-empty list{what}")
            return
        for i, entry in enumerate(entries):
            where = f"{key}[{i}]"
            if not isinstance(entry, dict):
                self.append(f"{where}: must be an object")
                continue
            yield i, entry, where

    def need(self, obj, key, where, kind=None):
        if not isinstance(obj, dict) or key not in obj:
            self.append(f"{where}: missing '{key}'")
            return None
        value = obj[key]
        if kind is not None and not isinstance(value, kind):
            names = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
            self.append(f"{where}.{key}: must be {names}, got {type(value).__name__} {value!r}"[:300])
            return None
        return value

    def number(self, obj, key, where, positive=False, default=None, required=True):
        if isinstance(obj, dict) and key not in obj and not required:
            return default
        value = self.need(obj, key, where, (int, float))
        if value is None or isinstance(value, bool):
            if isinstance(value, bool):
                self.append(f"{where}.{key}: must be a number, got {value!r}")
            return None
        if not math.isfinite(value) or (positive and value <= 0):
            self.append(f"{where}.{key}: must be a finite{' positive' if positive else ''} number, got {value!r}")
            return None
        return float(value)

    def vector(self, obj, key, where, length, required=True, default=None, positive=False, scalar_ok=False):
        if isinstance(obj, dict) and key not in obj and not required:
            return default
        value = self.need(obj, key, where)
        if value is None:
            return None
        if scalar_ok and isinstance(value, (int, float)) and not isinstance(value, bool):
            value = [value] * length
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            self.append(f"{where}.{key}: must be a list of {length} numbers, got {value!r}"[:300])
            return None
        if a.shape != (length,) if isinstance(length, int) else a.shape != length:
            self.append(f"{where}.{key}: must have shape {length}, got {a.shape}")
            return None
        if not np.all(np.isfinite(a)) or (positive and np.any(a <= 0)):
            self.append(f"{where}.{key}: must be finite{' and positive' if positive else ''}, got {value!r}")
            return None
        return a


def _camera(entry, problems: _Problems) -> Camera | None:
    where = "camera"
    if not isinstance(entry, dict):
        problems.append("camera: missing or not an object")
        return None
    n = len(problems)
    width = problems.need(entry, "width", where, int)
    height = problems.need(entry, "height", where, int)
    for name, v in (("width", width), ("height", height)):
        if v is not None and v <= 0:
            problems.append(f"camera.{name}: must be positive, got {v}")
    fx = problems.number(entry, "fx", where, positive=True)
    fy = problems.number(entry, "fy", where, positive=True)
    cx = problems.number(entry, "cx", where)
    cy = problems.number(entry, "cy", where)
    distortion = entry.get("distortion", [])
    try:
        distortion = np.asarray(distortion, np.float64).ravel()
        if len(distortion) not in (0, 4, 5, 8) or not np.all(np.isfinite(distortion)):
            problems.append(f"camera.distortion: must be 0, 4, 5 or 8 finite OpenCV coefficients "
                            f"(k1, k2, p1, p2[, k3[, k4, k5, k6]]), got {entry.get('distortion')!r}")
    except (TypeError, ValueError):
        problems.append(f"camera.distortion: must be a list of numbers, got {entry.get('distortion')!r}")
    rotation = problems.vector(entry, "rotation", where, (3, 3), required=False, default=np.eye(3))
    if rotation is not None and not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-4):
        problems.append("camera.rotation: must be a rotation matrix (orthonormal rows)")
    elif rotation is not None and np.linalg.det(rotation) < 0:
        problems.append("camera.rotation: has determinant -1 (a reflection, not a rotation)")
    translation = problems.vector(entry, "translation", where, 3, required=False, default=np.zeros(3))
    if len(problems) > n:
        return None
    return Camera(width, height, fx, fy, cx, cy, distortion, rotation, translation)


def _image(entry, where: str, root: Path, camera: Camera | None, problems: _Problems) -> Image | None:
    """Read and check one image entry ``{"path", "transfer", "gamma", "exposure", "saturation"}``."""
    if isinstance(entry, str):
        entry = {"path": entry}
    if not isinstance(entry, dict):
        problems.append(f"{where}: must be an image entry (a path or an object with 'path'), got {entry!r}"[:300])
        return None
    rel = problems.need(entry, "path", where, str)
    if rel is None:
        return None
    n = len(problems)
    transfer = entry.get("transfer", "linear")
    if transfer not in TRANSFERS:
        problems.append(f"{where}.transfer: must be one of {TRANSFERS}, got {transfer!r}")
    gamma = problems.number(entry, "gamma", where, positive=True, default=2.2, required=False)
    exposure = problems.number(entry, "exposure", where, positive=True, default=1.0, required=False)
    saturation = problems.number(entry, "saturation", where, positive=True, default=None, required=False)
    path = root / rel
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        problems.append(f"{where}.path: {rel!r} is not an image file we read ({', '.join(IMAGE_SUFFIXES)})")
    elif not path.is_file():
        problems.append(f"{where}: image file missing: {rel}")
    if len(problems) > n:
        return None
    try:
        image = read_image(path, transfer, gamma, exposure, saturation)
    except Exception as e:  # noqa: BLE001 - any reader failure is a problem of this capture
        problems.append(f"{where}: cannot read {rel}: {e}")
        return None
    h, w = image.pixels.shape[:2]
    if camera is not None and (w, h) != (camera.width, camera.height):
        problems.append(f"{where}: {rel} is {w}x{h} pixels, the camera's images are "
                        f"{camera.width}x{camera.height}")
        return None
    bad = ~np.isfinite(image.pixels)
    if bad.any():
        rows, cols = np.nonzero(bad.any(axis=2))
        problems.append(f"{where}: {rel} has {int(bad.any(axis=2).sum())} pixels with NaN or infinite values "
                        f"(first at x={cols[0]}, y={rows[0]})")
        return None
    return image


def _feature_points(entry, where: str, camera: Camera | None, problems: _Problems) -> dict[str, np.ndarray]:
    if not isinstance(entry, dict):
        problems.append(f"{where}: must be an object mapping feature point names to [x, y] pixels")
        return {}
    out = {}
    lo, hi = FEATURE_POINT_RANGE
    if not lo <= len(entry) <= hi:
        problems.append(f"{where}: has {len(entry)} feature points, a measurement needs {lo} to {hi}")
    for name, xy in entry.items():
        if name not in FEATURE_POINTS:
            problems.append(f"{where}: unknown feature point {name!r}; known: {', '.join(sorted(FEATURE_POINTS))}")
            continue
        p = problems.vector(entry, name, where, 2)
        if p is None:
            continue
        if camera is not None and not (-0.5 <= p[0] <= camera.width - 0.5 and -0.5 <= p[1] <= camera.height - 0.5):
            problems.append(f"{where}.{name}: {p.tolist()} lies outside the {camera.width}x{camera.height} image")
            continue
        out[name] = p
    return out


def load_capture(path: str | os.PathLike, calibrate: bool = True) -> Capture:
    """Load and validate the capture in folder ``path`` (or its ``capture.json``).

    Parameters
    ----------
    path : path
        The capture folder, or its manifest file.
    calibrate : bool
        Compute the position of lights given by steel-sphere pictures
        (:func:`mifaces.calibration.calibrate_light`). Without it such lights
        have ``position=None``.

    Returns
    -------
    Capture

    Raises
    ------
    CaptureError
        Naming every problem: a corrupted or incomplete manifest, missing or
        unreadable images, images of the wrong size, NaN or infinite pixels,
        malformed calibration, unknown feature points, lights that cannot be
        calibrated.
    """
    path = Path(path)
    manifest = path if path.is_file() else path / MANIFEST
    root = manifest.parent
    if not manifest.is_file():
        raise CaptureError(root, [f"no manifest: {manifest} does not exist"])
    try:
        data = json.loads(manifest.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CaptureError(root, [f"{MANIFEST} is not valid JSON: {e}"]) from None
    problems = _Problems()
    if not isinstance(data, dict):
        raise CaptureError(root, [f"{MANIFEST}: must hold a JSON object, got {type(data).__name__}"])
    if data.get("format") != FORMAT:
        problems.append(f"format: must be {FORMAT!r}, got {data.get('format')!r}")
    if data.get("version") != VERSION:
        problems.append(f"version: this mifaces reads version {VERSION}, got {data.get('version')!r}")

    camera = _camera(data.get("camera"), problems)

    # white target
    wt = data.get("white_target")
    white = None
    if not isinstance(wt, dict):
        problems.append("white_target: missing or not an object")
    else:
        n = len(problems)
        value = problems.vector(wt, "value", "white_target", 3, positive=True, scalar_ok=True)
        refl = problems.number(wt, "reflectance", "white_target", positive=True, default=1.0, required=False)
        dist = problems.number(wt, "distance_mm", "white_target", positive=True)
        inten = problems.vector(wt, "intensity", "white_target", 3, positive=True, scalar_ok=True)
        cos_i = problems.number(wt, "cos_incidence", "white_target", positive=True, default=1.0, required=False)
        if cos_i is not None and cos_i > 1:
            problems.append(f"white_target.cos_incidence: must be in (0, 1], got {cos_i}")
        if len(problems) == n:
            white = WhiteTarget(value, refl, dist, inten, cos_i)

    # distances
    distances = []
    entries = data.get("distances")
    if not isinstance(entries, list) or len(entries) < 3:
        problems.append(f"distances: need a list of at least three metric distances on the face, got {entries!r}"[:300])
        entries = entries if isinstance(entries, list) else []
    for i, d in enumerate(entries):
        where = f"distances[{i}]"
        a, b = problems.need(d, "from", where, str), problems.need(d, "to", where, str)
        mm = problems.number(d, "mm", where, positive=True)
        for name in (a, b):
            if name is not None and name not in FEATURE_POINTS:
                problems.append(f"{where}: unknown feature point {name!r}")
        if a is not None and b is not None and mm is not None:
            distances.append(Distance(a, b, mm))

    # lights
    lights = []
    for i, e, where in problems.objects(data, "lights", " of light conditions"):
        name = problems.need(e, "name", where, str)
        where = f"lights[{i}] ({name})" if name else where
        intensity = problems.vector(e, "intensity", where, 3, positive=True, scalar_ok=True)
        position = problems.vector(e, "position_mm", where, 3, required=False)
        spheres = None
        if "spheres" in e:
            s = e["spheres"]
            sw = f"{where}.spheres"
            radius = problems.number(s, "radius_mm", sw, positive=True)
            hl = _image(s.get("highlight") if isinstance(s, dict) else None, f"{sw}.highlight", root, camera, problems)
            ol = _image(s.get("outline") if isinstance(s, dict) else None, f"{sw}.outline", root, camera, problems)
            if radius is not None and hl is not None and ol is not None:
                spheres = SpherePictures(radius, hl, ol)
        elif position is None and "position_mm" not in e:
            problems.append(f"{where}: needs 'position_mm' or 'spheres' (the steel-sphere pictures)")
        if name is not None and intensity is not None:
            lights.append(Light(name, position, intensity, spheres))
    names = [l.name for l in lights]
    for name in {n for n in names if names.count(n) > 1}:
        problems.append(f"lights: name {name!r} used more than once")

    # measurements
    measurements = []
    for i, e, where in problems.objects(data, "measurements", ""):
        name = problems.need(e, "name", where, str) or f"#{i}"
        where = f"measurements[{i}] ({name})"
        light = problems.need(e, "light", where, str)
        if light is not None and light not in names:
            problems.append(f"{where}.light: no light condition named {light!r} (lights: {names})")
        pose = e.get("pose")
        image = _image(e.get("image"), f"{where}.image", root, camera, problems) if "image" in e else \
            problems.need(e, "image", where)
        diffuse = _image(e["diffuse"], f"{where}.diffuse", root, camera, problems) if "diffuse" in e else None
        series = e.get("exposures", [])
        if not isinstance(series, list):
            problems.append(f"{where}.exposures: must be a list of image entries")
            series = []
        exposures = [_image(x, f"{where}.exposures[{j}]", root, camera, problems) for j, x in enumerate(series)]
        if "diffuse" not in e and not series:
            problems.append(f"{where}: needs a companion picture: 'diffuse' (diffuse light) or 'exposures' "
                            "(an exposure series)")
        if len(series) == 1:
            problems.append(f"{where}.exposures: an exposure series needs at least two pictures")
        points = _feature_points(e.get("feature_points"), f"{where}.feature_points", camera, problems)
        if isinstance(image, Image) and light is not None and None not in exposures:
            measurements.append(Measurement(name, light, None if pose is None else str(pose), image, diffuse,
                                            tuple(exposures), points))
    mnames = [m.name for m in measurements]
    for name in {n for n in mnames if mnames.count(n) > 1}:
        problems.append(f"measurements: name {name!r} used more than once")

    if problems:
        raise CaptureError(root, problems)

    if calibrate:
        from .calibration import CalibrationError, calibrate_light

        calibrated = []
        for light in lights:
            if light.position is None and light.spheres is not None:
                try:
                    cal = calibrate_light(light.spheres, camera)
                except CalibrationError as e:
                    problems.append(f"light {light.name!r}: steel-sphere calibration failed: {e}")
                    calibrated.append(light)
                    continue
                light = Light(light.name, cal.position, light.intensity, light.spheres, cal)
            calibrated.append(light)
        lights = calibrated
        if problems:
            raise CaptureError(root, problems)

    return Capture(root, camera, tuple(lights), tuple(measurements), tuple(distances), white,
                   dict(data.get("metadata", {})) if isinstance(data.get("metadata", {}), dict) else {})
