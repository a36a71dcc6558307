"""The values a loaded capture is made of: images, lights, measurements,
distances, the white target, and the capture itself."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..lights.light import Light, any_relative, unknown_lights
from .camera import Camera

#: File name of the manifest inside a capture folder.
MANIFEST = "capture.json"
#: Value of the manifest's ``format`` field, and the version this module reads.
FORMAT = "mifaces-capture"
VERSION = 1
#: Subfolder of a capture that loading ignores (the simulator's ground truth).
GROUND_TRUTH = "ground_truth"
#: Number of named feature points a measurement must have (paper sec. 4.2).
FEATURE_POINT_RANGE = (7, 20)
#: Irradiance of a directional light whose absolute intensity is unknown: the one that brings a white
#: Lambertian surface facing the light to pixel value 1 (radiance E/π), so reflectance reads as
#: pixel value / cos θ and the fitted albedos fall in the range the BRDF models' parameters allow.
RELATIVE_IRRADIANCE = float(np.pi)
#: Kinds of a light whose lighting is unknown (``"unknown": true`` in the manifest): a distant light
#: plus ambient, or a low-resolution environment map (``docs/unknown_lights.md``).
LIGHT_KINDS = ("directional", "environment")
#: The capture-level ``ambient``: ``"unknown"`` (default; the shape fit fits an ambient term with each
#: photograph's light) or ``"none"`` (no light reaches the face but each photograph's own: a dark
#: room, a light stage, a strobe dome whose ambient-only frame is dark; the shape fit holds its ambient
#: term at zero, as the reflectance stage has none).
AMBIENT_KINDS = ("unknown", "none")
#: Environment map of an unknown ``"environment"`` light: default size (width, height) in texels of the
#: latitude-longitude map, and the allowed heights (the width is twice the height).
ENVMAP_SIZE = (32, 16)
ENVMAP_HEIGHTS = (4, 128)
#: Heights (pixels) a given environment map may have (the width is twice the height).
GIVEN_ENVMAP_HEIGHTS = (4, 4096)
#: Id of the camera of a capture whose manifest gives one ``camera`` (not a ``cameras`` list).
DEFAULT_CAMERA = "camera"
#: Cameras of one capture whose centres are closer than this (mm) are one camera listed twice.
MIN_CAMERA_SEPARATION = 1.0
#: Transfer curves of integer images.
TRANSFERS = ("linear", "srgb", "gamma")
IMAGE_SUFFIXES = (".exr", ".png", ".tif", ".tiff", ".jpg", ".jpeg", ".pgm", ".ppm", ".pnm")


class CaptureError(ValueError):
    """A capture that cannot be loaded; the message lists every problem found."""

    def __init__(self, path, problems: list[str]):
        self.path = Path(path)
        self.problems = list(problems)
        lines = "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(f"invalid capture {self.path}: {len(self.problems)} problem(s)\n{lines}")


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
    channels : int
        Channels of the file: 1 for a greyscale photograph (its value is
        repeated in the three channels of ``pixels``), else 3.
    """

    pixels: np.ndarray
    saturated: np.ndarray
    exposure: float
    path: Path
    channels: int = 3

    @property
    def greyscale(self) -> bool:
        return self.channels == 1


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
class Measurement:
    """One measurement: a point-light photograph and its companions at one pose.

    Attributes
    ----------
    name : str
    light : str
        Name of the :class:`Light` condition.
    pose : str or None
        Label shared by the measurements taken at one pose of the subject: the manifest's
        ``pose``, or its ``shot`` (the photographs several cameras took of the unmoved head).
    image : Image
        The point-light photograph the BRDF is fitted to.
    diffuse : Image or None
        Companion picture under diffuse light.
    exposures : tuple of Image
        Companion exposure series (may be empty).
    feature_points : dict
        Feature point name (see :data:`mifaces.model.landmarks.FEATURE_POINTS`)
        -> pixel position (2,) float64. Where the capture gives none,
        :func:`mifaces.capture.load_capture` detects them
        (:mod:`mifaces.capture.detector`); empty only when loaded with ``detect=False``.
    face_box : (x0, y0, x1, y1) or None
        Where the face is in the photograph (pixels), for the landmark
        detector on tight crops; None: the detector finds it.
    camera : str
        Id of the camera that took the pictures (:attr:`Capture.cameras`).
    """

    name: str
    light: str
    pose: str | None
    image: Image
    diffuse: Image | None
    exposures: tuple[Image, ...]
    feature_points: dict[str, np.ndarray]
    face_box: tuple[float, float, float, float] | None = None
    camera: str = DEFAULT_CAMERA


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
        :func:`mifaces.reflectance.samples.reflectance`): with that s, a white
        target of reflectance 1 has r = 1."""
        return self.reflectance * self.intensity * self.cos_incidence / (self.value * self.distance ** 2)


@dataclass(frozen=True, eq=False)
class Capture:
    """A loaded, validated capture (see the module docstring).

    ``camera`` is the capture's first camera, whose frame the lights' calibration uses;
    ``cameras`` every camera by id (:data:`DEFAULT_CAMERA` alone for a one-camera manifest), each
    measurement naming its own (:meth:`camera_of`).
    """

    path: Path
    camera: Camera
    lights: tuple[Light, ...]
    measurements: tuple[Measurement, ...]
    distances: tuple[Distance, ...]
    white_target: WhiteTarget | None
    metadata: dict = field(default_factory=dict)
    ambient: str = AMBIENT_KINDS[0]
    cameras: dict = field(default_factory=dict)

    def camera_of(self, measurement) -> Camera:
        """The camera that took ``measurement`` (a :class:`Measurement` or its name)."""
        if isinstance(measurement, str):
            name, measurement = measurement, next((m for m in self.measurements if m.name == measurement), None)
            if measurement is None:
                raise KeyError(f"no measurement {name!r} in {self.path}")
        if not self.several_cameras:  # the one camera is `camera` (a replaced one included)
            return self.camera
        return self.cameras[measurement.camera]

    @property
    def several_cameras(self) -> bool:
        """The photographs come from more than one camera."""
        return len(self.cameras) > 1

    @property
    def ambient_light(self) -> bool:
        """Light other than each photograph's own may reach the face (:data:`AMBIENT_KINDS`): the
        shape fit fits an ambient term where it does, and holds it at zero where the capture says
        ``"ambient": "none"``."""
        return self.ambient != "none"

    @property
    def greyscale(self) -> bool:
        """Every point-light photograph is greyscale."""
        return all(m.image.greyscale for m in self.measurements)

    @property
    def unknown_lights(self) -> tuple[Light, ...]:
        """The lights nobody measured, to estimate with the face (:attr:`Light.unknown`)."""
        return unknown_lights(self.lights)

    @property
    def relative_reflectance(self) -> bool:
        """Reflectance is known only up to a factor: no white target, or
        lights of unknown absolute intensity."""
        return self.white_target is None or any_relative(self.lights)

    def reflectance_scale(self) -> np.ndarray:
        """The scale s of eq. 4 the reflectance samples take (RGB): the white target's
        (:meth:`WhiteTarget.reflectance_scale`), π without one (reflectance relative to the
        lights' stated intensities)."""
        return (self.white_target.reflectance_scale() if self.white_target is not None
                else np.full(3, np.pi))

    def light(self, name: str) -> Light:
        """The light condition called ``name``."""
        for light in self.lights:
            if light.name == name:
                return light
        raise KeyError(f"no light {name!r} in {self.path}; lights: {[l.name for l in self.lights]}")

    def __repr__(self) -> str:
        cameras = f"{len(self.cameras)} cameras, " if self.several_cameras else ""
        return (f"Capture({str(self.path)!r}: {cameras}{self.camera.width}x{self.camera.height}, "
                f"{len(self.lights)} lights, {len(self.measurements)} measurements)")


# --------------------------------------------------------------------------------------------
# Reading images
