"""What a shape fit is asked for and what it returns (paper sec. 4.2): the
coarse-to-fine schedule, the weights of the energy's terms, the options and
convergence limits of a fit, and the fitted shape and rendering parameters of
one measurement."""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field

import numpy as np

from ..options.fields import check, option
from ..runtime.status import CONVERGED

#: Default convergence limit of the feature points: RMS distance from their targets as a fraction of
#: the face's eye distance (outer corners) in the image, on top of :data:`FEATURE_NOISE`; with it,
#: the limit is 4 px on the simulator's 512 x 512 captures (eye distance about 152 px), as before.
MAX_FEATURE_ERROR = 0.02
#: Default expected RMS error (px) of the feature points themselves: whole-pixel positions, as a
#: detector (:mod:`mifaces.capture.detector`) or a careful click gives them.
FEATURE_NOISE = 1.0
#: Default convergence limit of the photometric residual: the RMS difference per channel between the
#: fitted rendering and the photograph over the face's samples, in units of the photograph's 99th
#: percentile (``ShapeFit.loss['image_rms']``). A fit is converged only when the feature points and
#: this both meet their limits: feature points alone can fit a face that is far off (issue 22). Good
#: fits of simulated training captures (seeds 11 and 12, not reported on) end at 0.031-0.053.
MAX_IMAGE_RMS = 0.1


class ShapeFitError(ValueError):
    """A measurement that cannot be fitted (missing or misnamed feature points, ...)."""


@dataclass(frozen=True)
class ShapeSchedule:
    """The coarse-to-fine schedule of one shape fit.

    Each level is ``(iterations, samples, blur)``: Adam steps, number of model
    vertices sampled for the image term, and the standard deviation (px at
    512 px image height; scaled with the image) of the Gaussian the image is
    blurred with. ``pose_iterations`` landmark-only steps (pose, focal length,
    shape) come first.
    """

    levels: tuple = ((150, 1000, 4.0), (150, 2500, 2.0), (200, 5000, 1.0))
    pose_iterations: int = 150

    @property
    def iterations(self) -> int:
        """All steps: the landmark-only ones and those of every image level."""
        return self.pose_iterations + sum(int(level[0]) for level in self.levels)

    @classmethod
    def scaled(cls, factor: float) -> ShapeSchedule:
        """The default schedule with every iteration count multiplied by ``factor``."""
        return cls().scaled_by(factor)

    def scaled_by(self, factor: float) -> ShapeSchedule:
        """This schedule with every iteration count multiplied by ``factor``."""
        return type(self)(tuple((max(1, int(round(i * factor))), s, b) for i, s, b in self.levels),
                          max(1, int(round(self.pose_iterations * factor))))


@dataclass(frozen=True)
class Weights:
    """Weights of the terms of E (paper sec. 4.2).

    ``image_sigma``: the RGB residual (in units of the normalised image, whose
    99th percentile is 1) that costs 1; ``feature_sigma``: the feature-point
    residual (px at 512 px image height) that costs 1; the feature term's
    weight fades linearly from ``feature`` to ``feature_final`` over the first
    ``feature_fade`` of the image iterations. ``shape``, ``expression``,
    ``texture``: weights of the squared Mahalanobis norms; ``albedo``: of the
    per-vertex albedo's squared deviation from its mean (models without a
    colour model), per vertex; ``focal``: standard deviation of log focal length
    around the calibrated value, and ``focal_uncalibrated`` around the guess of
    an uncalibrated camera (``Camera.calibrated`` False); ``distance_sigma``:
    the error (mm) of a metric distance between feature points that costs 1
    (part of E_P: it fixes the scale, hence the depth, that images alone leave
    open).
    """

    image_sigma: float = 0.05
    feature_sigma: float = 1.0
    feature: float = 1.0
    feature_final: float = 0.5
    feature_fade: float = 0.5
    shape: float = 0.1
    expression: float = 0.1
    texture: float = 0.1
    albedo: float = 2.0
    focal: float = 0.01
    focal_uncalibrated: float = 0.3
    distance_sigma: float = 1.0


@dataclass(frozen=True)
class ShapeOptions:
    """How one shape fit runs and when it has converged (paper sec. 4.2), the choices that travel
    unchanged from :func:`~mifaces.shape.fit.fit_shape` to every
    :func:`~mifaces.shape.fit.fit_measurement`. Validated on construction: a number out of its
    range raises a ``ValueError`` naming the field.

    Attributes
    ----------
    weights : Weights
        The weights of E's terms (:class:`Weights`). A fit on an uncalibrated camera
        (``Camera.calibrated`` False) puts :attr:`Weights.focal_uncalibrated` in place of
        :attr:`Weights.focal`.
    fixed : tuple of str
        Parameter blocks held at their start values (:func:`~mifaces.shape.fit.fit_measurement`'s
        ``initial``, or the defaults): ``'rotation'``, ``'translation'``, ``'log_focal'``,
        ``'shape'``, ``'expression'``, ``'color'`` or ``'albedo'``, and per photograph
        ``'<key>.<block>'`` (``'point.ambient'``); an unknown name raises a ``ValueError`` when the
        fit starts. A list is taken as a tuple.
    use_diffuse, use_point : bool
        Use the companion diffuse-light image / the point-light image in E_I.
    fit_focal : bool
        Optimise the focal length (paper sec. 4.2) under a prior around the camera's.
    seed : int
        Seeds the choice of sample vertices.
    max_feature_error, feature_noise : float
        A fit whose feature points end farther than :func:`~mifaces.shape.fit.feature_limit` (px
        RMS: ``max_feature_error`` times the face's eye distance in the image, plus the points'
        expected noise ``feature_noise`` in px) from their targets is not a success:
        ``'diverged'`` or ``'not_converged'`` (see :attr:`ShapeFit.status`).
    max_image_rms : float
        The convergence limit of the photometric residual ``loss['image_rms']``
        (:data:`MAX_IMAGE_RMS`), where the photographs are used: a fit whose feature points fit
        but whose rendering does not match is ``'not_converged'``. With companions the limit
        applies to the measurement's own photographs (``loss['image_rms_measurement']``);
        ``loss['image_rms.<key>']`` gives each photograph's.
    lr : (float, float)
        Adam's step (in natural units of each parameter) at the start and the end of the image levels.
    visibility_interval : int
        Iterations between re-computations of visibility and cast shadows by ray casting.
    ambient : bool
        Fit an ambient term with each photograph lit by a directed light. False holds it at zero:
        the capture says no other light reaches the face (``Capture.ambient_light``), and an
        ambient term would only trade against the light's frontal part (``docs/unknown_lights.md``).
        The diffuse-light companion keeps its ambient: that is its light.
    facing_min : float
        E_I counts a sample only where the cosine between its normal and the direction to the
        camera exceeds this. 0 (the default) counts every sample the camera sees; 0.5 (within 60°)
        leaves out those near the silhouette, whose pixels the blur mixes with the background: it
        removes a pull towards a smaller, farther face, but fits the face's outline worse
        (``docs/shape_estimation.md``, "What limits the depth").
    """

    use_diffuse: bool = True
    use_point: bool = True
    fit_focal: bool = True
    seed: int = option(0, bounds=(0, None))
    max_feature_error: float = option(MAX_FEATURE_ERROR, bounds=(0.0, None))
    feature_noise: float = option(FEATURE_NOISE, bounds=(0.0, None))
    max_image_rms: float = option(MAX_IMAGE_RMS, bounds=(0.0, None))
    lr: tuple = (0.1, 0.01)
    visibility_interval: int = option(50, bounds=(1, None))
    ambient: bool = True
    facing_min: float = option(0.0, bounds=(-1.0, 1.0))
    weights: Weights = field(default_factory=Weights)
    fixed: tuple = ()

    def __post_init__(self):
        check(self)
        if not isinstance(self.weights, Weights):
            raise ValueError(f"ShapeOptions.weights must be a Weights, got {self.weights!r}")
        if (len(self.lr) != 2 or not all(isinstance(v, numbers.Real) and not isinstance(v, bool) and v > 0
                                         for v in self.lr)):
            raise ValueError(f"ShapeOptions.lr must be two numbers > 0 (start, end), got {self.lr!r}")
        if isinstance(self.fixed, str) or not all(isinstance(name, str) for name in self.fixed):
            raise ValueError(f"ShapeOptions.fixed must be parameter block names, got {self.fixed!r}")
        object.__setattr__(self, "fixed", tuple(self.fixed))


@dataclass
class ShapeFit:
    """The fitted shape and rendering parameters of one measurement.

    Attributes
    ----------
    measurement : str
    status : str
        ``'converged'`` (feature points end within the limit of
        :func:`~mifaces.shape.fit.feature_limit`, and the photometric residual
        ``loss['image_rms']`` within :data:`MAX_IMAGE_RMS`
        where the photographs were used); ``'diverged'`` (non-finite
        loss, or feature points ending farther from their targets than they
        started, or more than 4x the limit); ``'not_converged'`` (feature
        points still above the limit but closer than at the start: more
        iterations may help); ``message`` says why. Only converged fits are
        written as shapes.
    vertices_world, vertices_camera : (N, 3) float32
        Fitted vertices in the capture's world frame and in camera space, mm.
    coefficients : (K,) float64
        Shape coefficients alpha (standard deviations).
    expression : (E,) float64
        Expression coefficients delta (empty for models without expressions).
    color : (C,) float64 or None
        Texture coefficients beta (None for models without a colour model).
    albedo : (N, 3) float32 or None
        Per-vertex albedo (models without a colour model).
    rotation : (3, 3) float64
        Model -> camera rotation ``R0 R(yaw, pitch, roll)``.
    translation : (3,) float64
        Model -> camera translation: ``x_camera = rotation x_model + translation``.
    yaw_pitch_roll : (3,) float64
        Degrees.
    focal_length : (2,) float64
        ``fx, fy`` in px.
    light : dict
        Per image (``'point'``, ``'diffuse'``): ``direction`` (unit, camera
        space, towards the light), ``color``, ``ambient``, ``specular``,
        ``contrast``, ``gain``, ``offset``.
    loss : dict
        Final terms ``E``, ``E_I``, ``E_F``, ``E_P`` and the diagnostics
        ``feature_rms_px`` and ``image_rms``.
    iterations : int
    seconds : float
    message : str
    shared_with : str or None
        The measurement whose fit this one shares (same ``pose`` label: one
        fit per pose, see :func:`~mifaces.shape.fit.fit_shape`); None for a
        fit of its own. A shared fit has the geometry, pose and texture of
        that fit, no fitted lighting, 0 iterations and 0 seconds.
    estimated : tuple of str
        What the capture did not give and the fit estimated: ``'scale'`` (no
        metric distances: the face's size, hence its depth, comes from the
        model's prior, the mean face's size), ``'focal_length'`` (an
        uncalibrated camera: the focal length fitted from the guess; the
        principal point stays at the guess).
    """

    measurement: str
    status: str
    vertices_world: np.ndarray
    vertices_camera: np.ndarray
    coefficients: np.ndarray
    expression: np.ndarray
    color: np.ndarray | None
    albedo: np.ndarray | None
    rotation: np.ndarray
    translation: np.ndarray
    yaw_pitch_roll: np.ndarray
    focal_length: np.ndarray
    light: dict
    loss: dict
    iterations: int
    seconds: float
    message: str = ""
    history: list = field(default_factory=list)
    shared_with: str | None = None
    estimated: tuple = ()

    @property
    def converged(self) -> bool:
        return self.status == CONVERGED

    def to_json(self) -> dict:
        """Everything but the vertices, as JSON-ready values."""
        def f(a):
            return None if a is None else np.asarray(a, np.float64).tolist()

        return {"measurement": self.measurement, "status": self.status, "message": self.message,
                "coefficients": f(self.coefficients), "expression": f(self.expression), "color": f(self.color),
                "rotation": f(self.rotation), "translation_mm": f(self.translation),
                "yaw_pitch_roll_deg": f(self.yaw_pitch_roll), "focal_length_px": f(self.focal_length),
                "light": {k: {kk: (f(vv) if not isinstance(vv, float) else vv) for kk, vv in v.items()}
                          for k, v in self.light.items()},
                "loss": {k: float(v) for k, v in self.loss.items()}, "iterations": int(self.iterations),
                "seconds": float(self.seconds), "frame": "vertices in camera space (OpenCV), mm",
                "shared_with": self.shared_with, "estimated": list(self.estimated), "history": self.history}
