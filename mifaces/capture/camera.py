"""The calibrated camera of a capture, in OpenCV conventions (see
:mod:`mifaces.capture` for the frames and units)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..model.geometry import camera_frame_direction


def distorted(x, y, coefficients):
    """OpenCV's lens distortion of normalised image coordinates ``x``, ``y``: the one formula of
    the distortion, written with arithmetic only, so that numpy arrays (:meth:`Camera.distort`) and
    Dr.Jit Floats (the shape fit's energy, :func:`mifaces.shape.projection.project`) go through it
    alike.

    Parameters
    ----------
    x, y : arrays (numpy or Dr.Jit)
    coefficients : sequence of 8 float
        ``k1, k2, p1, p2, k3, k4, k5, k6`` (:attr:`Camera.distortion_coefficients`: Python floats,
        which a Dr.Jit expression takes as literals).

    Returns
    -------
    (xd, yd)
        The distorted coordinates.
    """
    k1, k2, p1, p2, k3, k4, k5, k6 = coefficients
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return xd, yd


#: The optics' blur: a photograph's pixel is the image under a Gaussian point spread function of
#: this standard deviation (pixels). The simulator renders with it; the reflectance fit takes it
#: for a pixel's footprint (:mod:`mifaces.reflectance.footprint`).
PIXEL_BLUR_STD = 0.5


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
    calibrated : bool
        False where the intrinsics (``fx, fy, cx, cy``) are only a starting
        guess (an unknown camera): the shape fit then estimates them.
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
    calibrated: bool = True

    def scaled(self, factor: float) -> Camera:
        """This camera with its image ``factor`` times as many pixels along each side (the same field
        of view and frame; pixel centres stay at integers, so pixel ``u`` here is ``(u + 0.5) factor
        - 0.5`` there)."""
        return replace(self, width=max(1, int(round(self.width * factor))),
                       height=max(1, int(round(self.height * factor))), fx=self.fx * factor, fy=self.fy * factor,
                       cx=(self.cx + 0.5) * factor - 0.5, cy=(self.cy + 0.5) * factor - 0.5)

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 intrinsic matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def direction(self, azimuth: float, elevation: float) -> np.ndarray:
        """The world-frame unit vector from the subject towards a light at
        ``azimuth`` and ``elevation`` (degrees) about the camera's optical
        axis, as the Yale face database names its lights: (0, 0) points at
        the camera, positive azimuth towards the image's left (a frontal
        subject's right), positive elevation above."""
        return self.rotation.T @ camera_frame_direction(azimuth, elevation)

    @property
    def frame(self) -> np.ndarray:
        """The camera's frame in the world (3x3, columns): its right (+x of the image), its up
        (-y of the image), and the direction from the scene towards the camera (-z)."""
        rotation = np.asarray(self.rotation, np.float64)
        return np.stack([rotation[0], -rotation[1], -rotation[2]], axis=1)

    @property
    def up(self) -> np.ndarray:
        """The camera's up direction in the world frame (unit): the second column of :attr:`frame`."""
        return self.frame[:, 1]

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

    @property
    def distortion_coefficients(self) -> tuple[float, ...]:
        """The eight OpenCV coefficients ``k1, k2, p1, p2, k3, k4, k5, k6`` (zeros for those
        :attr:`distortion` leaves out), as Python floats: what :func:`distorted` takes."""
        return tuple(float(v) for v in self._coefficients())

    def distort(self, xy) -> np.ndarray:
        """Apply lens distortion to normalised image coordinates (..., 2) (OpenCV's model, :func:`distorted`)."""
        xy = np.asarray(xy, np.float64)
        return np.stack(distorted(xy[..., 0], xy[..., 1], self.distortion_coefficients), axis=-1)

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

    @classmethod
    def from_json(cls, entry: dict) -> Camera:
        """The camera of a manifest's ``camera`` entry, trusted as written by :meth:`to_json`
        (:func:`mifaces.capture.load_capture` validates a manifest's own)."""
        return cls(int(entry["width"]), int(entry["height"]), float(entry["fx"]), float(entry["fy"]),
                   float(entry["cx"]), float(entry["cy"]), np.asarray(entry.get("distortion", []), np.float64),
                   np.asarray(entry.get("rotation", np.eye(3)), np.float64),
                   np.asarray(entry.get("translation", np.zeros(3)), np.float64),
                   bool(entry.get("calibrated", True)))

    def to_json(self) -> dict:
        """The manifest's ``camera`` entry."""
        return {"width": int(self.width), "height": int(self.height), "fx": float(self.fx), "fy": float(self.fy),
                "cx": float(self.cx), "cy": float(self.cy), "distortion": [float(d) for d in self.distortion],
                "rotation": np.asarray(self.rotation, float).tolist(),
                "translation": [float(t) for t in self.translation],
                **({} if self.calibrated else {"calibrated": False})}


def relative_pose(source: Camera, target: Camera) -> tuple[np.ndarray, np.ndarray]:
    """``(A, b)`` of ``x_target = A x_source + b``: camera ``source``'s frame to camera ``target``'s."""
    A = np.asarray(target.rotation, np.float64) @ np.asarray(source.rotation, np.float64).T
    return A, np.asarray(target.translation, np.float64) - A @ np.asarray(source.translation, np.float64)
