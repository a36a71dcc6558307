"""Shape estimation: fitting the morphable model to each photograph (paper sec. 4.2).

For every measurement of a capture, :func:`fit_shape` finds the model
coefficients and rendering parameters whose synthesis matches the photograph,
independently per image and starting from the average face, by minimising ::

    E = E_I + E_F + E_P

* ``E_I`` -- the image term: squared RGB differences between the photograph
  and a Phong rendering of the model, **in the model's domain**: a subset of
  model vertices is projected into the image, the (blurred, coarse to fine)
  image is sampled bilinearly at the projections, and compared with the Phong
  colour of the vertex (ambient + directed light with cast shadows + a
  specular lobe, then colour contrast, per-channel gain and offset; Blanz and
  Vetter 1999, sec. 4). Only vertices seen by the camera count; visibility and
  cast shadows come from Mitsuba ray casting (``Scene.ray_test``) on the
  current full mesh, recomputed every ``visibility_interval`` iterations
  rather than every step (the paper re-computes its shadow map every 1000
  iterations). The companion diffuse-light photograph, where the capture has
  one, is a second image term with its own lighting and colour parameters
  and the same geometry and texture: it pins texture and outline where the
  point light leaves the face dark (paper sec. 5, Figure 3, views 16/17).
* ``E_F`` -- squared image-plane distances (px) between the model's feature
  points (:data:`mifaces.model.landmarks.FEATURE_POINTS` -> iBUG index ->
  model vertex) and the capture's clicked ones; strong in the first
  iterations, then faded.
* ``E_P`` -- the Mahalanobis distance of the coefficients from the average
  face (``sum alpha^2 + sum delta^2 + sum beta^2``, coefficients in standard
  deviations; Blanz and Vetter 1999, eq. 3), plus a weak prior keeping the
  focal length near the calibrated one, plus the capture's metric distances
  between feature points (``Capture.distances``, measured on the face at
  rest, compared with the identity shape without expression): images fix
  a face's size only relative to its distance, these fix the scale.

The directed light of the point-light image is, as in the paper, given by two
angles; where the capture's light calibration gives the lamp's position, it
sits at the calibrated distance from the face in the fitted direction, so
that the direction and the inverse-square falloff vary over the face as they
do in the studio (a directional light otherwise).

Gradients come from Dr.Jit's reverse-mode AD through the whole synthesis;
the optimiser is Adam (Kingma and Ba 2015) on parameters scaled to natural
units (:class:`_Layout`), the learning rate decaying geometrically over the
image levels, in place of the paper's stochastic Newton method;
``validation/shape_estimation.py`` measures error against iterations (the
default schedule is at its plateau; on measurement m00 of the default capture
a quarter of it gives the same normal and landmark errors). Kernels are cached across
iterations (parameters enter as one opaque array; the fading weights are
opaque too).

Parameters optimised (paper sec. 4.2): rotation (3 angles), translation (3),
focal length (1), per image the direction of the directed light (2 angles),
its colour (3), the ambient colour (3), colour contrast (1), gain (3) and
offset (3) per channel, and a specular strength; shape coefficients alpha,
expression coefficients delta (for models with an expression basis) and
texture coefficients beta -- or, for a model without a colour model, a
per-vertex albedo regularised towards its mean.

Frames and units
----------------
* Model space: the model's own frame (mm, y up, face along +z).
* Camera space: OpenCV (x right, y down, z forward), mm;
  ``x_camera = R0 R(yaw, pitch, roll) (x_model - c) + t`` with ``R0 = diag(1, -1, -1)``
  (a frontal view), ``c`` the centre of the mean shape's bounding box and
  ``R(yaw, pitch, roll) = R_y R_x R_z`` (the simulator's convention).
* World space: the capture's frame, ``x_world = R_cam^T (x_camera - t_cam)``.
* Pixels: OpenCV, centre of the top-left pixel at (0, 0).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model import load_model
from ..status import CONVERGED, DIVERGED, NOT_CONVERGED
from ..model.geometry import rotation_matrix

#: Statuses a fit may end with.
#: Name of the index file :func:`fit_shape` writes beside the per-measurement files.
INDEX = "shapes.json"
#: Phong exponent of the specular lobe (fixed; its strength is fitted).
PHONG_EXPONENT = 16.0
#: Model -> camera rotation of a frontal view (model y up, face along +z; camera y down, z forward).
FRONTAL = np.diag([1.0, -1.0, -1.0])
#: Sample vertices are kept this far (mm) from the mesh's open border.
BORDER_MARGIN = 6.0
#: Start the per-vertex albedo of a model without colour model from the photograph
#: (:meth:`_Fitter.extract_albedo`). Off: on the simulated Surrey capture it made the normals
#: worse (4.3 vs 4.1 deg on m00-m01) than starting from a uniform skin colour.
EXTRACT_ALBEDO = False
#: Rec. 601 luminance weights of the colour-contrast operator (Blanz and Vetter 1999).
LUMINANCE = (0.3, 0.59, 0.11)


class ShapeFitError(ValueError):
    """A measurement that cannot be fitted (missing or misnamed feature points, ...)."""


# --------------------------------------------------------------------------------------------
# Values
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Schedule:
    """The coarse-to-fine schedule of one fit.

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
        return self.pose_iterations + sum(int(level[0]) for level in self.levels)

    @classmethod
    def scaled(cls, factor: float) -> Schedule:
        """The default schedule with every iteration count multiplied by ``factor``."""
        d = cls()
        return cls(tuple((max(1, int(round(i * factor))), s, b) for i, s, b in d.levels),
                   max(1, int(round(d.pose_iterations * factor))))


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
    around the calibrated value; ``distance_sigma``: the error (mm) of a metric
    distance between feature points that costs 1 (part of E_P: it fixes the
    scale, hence the depth, that images alone leave open).
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
    distance_sigma: float = 1.0


@dataclass
class ShapeFit:
    """The fitted shape and rendering parameters of one measurement.

    Attributes
    ----------
    measurement : str
    status : str
        ``'converged'``; ``'diverged'`` (non-finite loss, or feature points
        ending farther from their targets than they started, or more than 4x
        the limit); ``'not_converged'`` (feature points still above the limit
        but closer than at the start: more iterations may help); ``message``
        says why. Only converged fits are written as shapes.
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
                "history": self.history}


# --------------------------------------------------------------------------------------------
# Geometry helpers (numpy)
# --------------------------------------------------------------------------------------------
def light_direction(elevation: float, azimuth: float) -> np.ndarray:
    """Unit direction towards the light in camera space for two angles (radians):
    (0, 0) points at the camera, positive elevation up, positive azimuth to the image's right."""
    return np.array([math.cos(elevation) * math.sin(azimuth), -math.sin(elevation),
                     -math.cos(elevation) * math.cos(azimuth)])


def rotation_centre(model) -> np.ndarray:
    """The point ``c`` of the model the fitted rotation turns about: the centre of the
    mean shape's bounding box (model space, mm)."""
    return 0.5 * (model.shape_mean.min(axis=0) + model.shape_mean.max(axis=0)).astype(np.float64)


def _distance_from_border(model) -> np.ndarray:
    """Distance (mm, on the mean shape) of every vertex from the nearest vertex on an open
    border of the mesh (an edge used by one triangle); inf for a closed mesh."""
    from scipy.spatial import cKDTree

    t = np.asarray(model.triangles, np.int64)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    border = np.unique(unique[counts == 1])
    if len(border) == 0:
        return np.full(model.vertex_count, np.inf)
    return cKDTree(model.shape_mean[border]).query(model.shape_mean)[0]


def metric_distances(distances, model) -> list[tuple[int, int, float]]:
    """The capture's metric distances as ``(vertex, vertex, mm)`` on ``model``.

    ``distances`` holds :class:`mifaces.capture.Distance` values (or ``(start, end, mm)``
    tuples) between named feature points; those whose points the model lacks are skipped.
    """
    from ..model.landmarks import FEATURE_POINTS

    ibug = model.ibug_landmarks
    out = []
    for d in distances or ():
        start, end, mm = (d.start, d.end, d.mm) if hasattr(d, "mm") else d
        for name in (start, end):
            if name not in FEATURE_POINTS:
                raise ShapeFitError(f"metric distance names unknown feature point {name!r}; "
                                    f"known names: {sorted(FEATURE_POINTS)}")
        if FEATURE_POINTS[start] in ibug and FEATURE_POINTS[end] in ibug and mm > 0:
            out.append((ibug[FEATURE_POINTS[start]], ibug[FEATURE_POINTS[end]], float(mm)))
    return out


def _adjacency(triangles: np.ndarray, vertex_count: int) -> np.ndarray:
    """(N, D) triangle indices adjacent to each vertex, padded with -1."""
    t = np.asarray(triangles, np.int64)
    corner_vertex = t.ravel()
    corner_triangle = np.repeat(np.arange(len(t)), 3)
    order = np.argsort(corner_vertex, kind="stable")
    cv, ct = corner_vertex[order], corner_triangle[order]
    counts = np.bincount(cv, minlength=vertex_count)
    d = max(int(counts.max()), 1)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(len(cv)) - starts[cv]
    out = np.full((vertex_count, d), -1, np.int64)
    out[cv, slot] = ct
    return out


# --------------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------------
def feature_targets(measurement, model) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The measurement's feature points that the fit uses: ``(names, vertices, pixels)``.

    Raises
    ------
    ShapeFitError
        If the measurement has fewer than 6 feature points, names one outside
        :data:`~mifaces.model.landmarks.FEATURE_POINTS`, or one the model does not define.
    """
    from ..model.landmarks import FEATURE_POINTS

    points = dict(getattr(measurement, "feature_points", None) or {})
    name = getattr(measurement, "name", "?")
    unknown = [n for n in points if n not in FEATURE_POINTS]
    if unknown:
        raise ShapeFitError(f"measurement {name!r}: unknown feature point name(s) {sorted(unknown)}; "
                            f"known names: {sorted(FEATURE_POINTS)}")
    ibug = model.ibug_landmarks
    missing_on_model = [n for n in points if FEATURE_POINTS[n] not in ibug]
    usable = [n for n in points if FEATURE_POINTS[n] in ibug]
    if len(usable) < 6:
        raise ShapeFitError(
            f"measurement {name!r}: {len(usable)} usable feature point(s) {sorted(usable)}, the fit needs at "
            f"least 6 (paper sec. 4.2: 7-20)" + (f"; not defined on model {model.name!r}: "
                                                f"{sorted(missing_on_model)}" if missing_on_model else ""))
    pixels = np.array([np.asarray(points[n], np.float64).reshape(2) for n in usable])
    if not np.all(np.isfinite(pixels)):
        raise ShapeFitError(f"measurement {name!r}: non-finite feature point position(s)")
    vertices = np.array([ibug[FEATURE_POINTS[n]] for n in usable], np.int64)
    return usable, vertices, pixels


def _normalised(pixels: np.ndarray) -> tuple[np.ndarray, float]:
    """Image divided by its 99th percentile (so E_I's sigma means the same for every image)."""
    p = np.asarray(pixels, np.float32)
    scale = float(np.percentile(p, 99.0))
    scale = scale if scale > 0 and np.isfinite(scale) else 1.0
    return np.nan_to_num(p / scale), scale


def _blurred(image: np.ndarray, sigma: float) -> np.ndarray:
    import scipy.ndimage as ndi

    if sigma <= 0.05:
        return image
    return ndi.gaussian_filter(image, (sigma, sigma, 0), mode="nearest")


# --------------------------------------------------------------------------------------------
# The fitter
# --------------------------------------------------------------------------------------------
class _Layout:
    """Named blocks of the parameter vector and their natural units (Adam works on theta / unit)."""

    IMAGE_BLOCK = (("light_angles", 2, 0.15), ("light_color", 3, 0.15), ("ambient", 3, 0.1),
                   ("specular", 1, 0.05), ("contrast", 1, 0.1), ("gain", 3, 0.1), ("offset", 3, 0.03))

    def __init__(self, model, images: list[str], fit_albedo: bool):
        self.slices, units = {}, []

        def add(name, n, unit):
            self.slices[name] = slice(len(units), len(units) + n)
            units.extend([unit] * n)

        add("rotation", 3, 0.05)
        add("translation", 3, 5.0)
        add("log_focal", 1, 0.02)
        for image in images:
            for name, n, unit in self.IMAGE_BLOCK:
                add(f"{image}.{name}", n, unit)
        add("shape", model.shape_dim, 1.0)
        add("expression", model.expression_dim, 1.0)
        if model.has_texture:
            add("color", model.color_dim, 0.3)
        elif fit_albedo:
            add("albedo", 3 * model.vertex_count, 0.03)
        self.units = np.array(units, np.float64)
        self.size = len(units)

    def __getitem__(self, name):
        return self.slices[name]


class _Fitter:
    """One fit: the model restricted to the sampled vertices, on the Dr.Jit side."""

    def __init__(self, model, camera, images: dict, targets, weights: Weights, schedule: Schedule, rng,
                 light_world=None, fit_focal=True, initial_color=None, initial=None, fixed=(), distances=()):
        import mitsuba as mi

        self.mi = mi
        self.model = model
        self.camera = camera
        self.weights = weights
        self.schedule = schedule
        self.rng = rng
        self.fit_focal = fit_focal
        self.names, self.feature_vertices, self.feature_pixels = targets
        self.distances = metric_distances(distances, model)
        self.distance_vertices = (np.array([[a, b] for a, b, _ in self.distances], np.int64).reshape(-1, 2))
        self.scale_px = camera.height / 512.0  # px per "512-px pixel"
        self.images = {}
        self.image_scale = {}
        for key, pixels in images.items():
            self.images[key], self.image_scale[key] = _normalised(pixels)
        self.image_names = list(self.images)
        self.layout = _Layout(model, self.image_names, fit_albedo=True)
        self.centre = rotation_centre(model)
        self.initial_blocks = dict(initial or {})
        unknown = [k for k in list(self.initial_blocks) + list(fixed) if k not in self.layout.slices]
        if unknown:
            raise ValueError(f"unknown parameter block(s) {unknown}; blocks: {list(self.layout.slices)}")
        self.fixed = tuple(fixed)
        self.adjacency = _adjacency(model.triangles, model.vertex_count)
        regions = model.vertex_regions()
        used = np.zeros(model.vertex_count, bool)
        used[model.triangles.ravel()] = True
        # samples keep away from the mesh's open border, whose pixels mix face and background
        inner = _distance_from_border(model) > BORDER_MARGIN
        self.candidates = np.flatnonzero(used & (regions != 0) & inner)
        if len(self.candidates) < 100:
            self.candidates = np.flatnonzero(used)
        self.light_world = None if light_world is None else np.asarray(light_world, np.float64)
        #: distance (mm) of the directed light from the face centre: infinite (a directional light)
        #: unless the capture's calibration gives the light's position
        self.light_distance = math.inf
        self.initial_color = initial_color
        self._shadow_scene_vertices = None

    # ---- parameter vector --------------------------------------------------------------------
    def initial(self) -> np.ndarray:
        """Frontal view of the mean face placed on the feature points (paper: 'default values
        defining a frontal view and frontal illumination'), lights from the calibration."""
        L, cam, m = self.layout, self.camera, self.model
        theta = np.zeros(L.size)
        # translation: depth from the spread of the feature points, x/y from their centroid
        lm = m.shape_mean[self.feature_vertices].astype(np.float64)
        lm_c = (lm - self.centre) @ FRONTAL.T
        px = self.feature_pixels
        spread_px = np.sqrt(np.mean(np.sum((px - px.mean(0)) ** 2, axis=1)))
        spread_mm = np.sqrt(np.mean(np.sum((lm_c[:, :2] - lm_c[:, :2].mean(0)) ** 2, axis=1)))
        z = cam.fy * spread_mm / max(spread_px, 1e-6)
        rays = cam.undistort(np.stack([(px[:, 0] - cam.cx) / cam.fx, (px[:, 1] - cam.cy) / cam.fy], -1))
        xy = rays.mean(0) * (z + lm_c[:, 2].mean()) - lm_c[:, :2].mean(0)
        theta[L["translation"]] = [xy[0], xy[1], z]
        for image in self.image_names:
            el, az = 0.0, 0.0
            if image == "point" and self.light_world is not None:
                head = cam.to_world(theta[L["translation"]])
                d = cam.rotation @ (self.light_world - head)
                self.light_distance = float(np.linalg.norm(d))
                d /= np.linalg.norm(d)
                el, az = math.asin(float(np.clip(-d[1], -1, 1))), math.atan2(d[0], -d[2])
            theta[L[f"{image}.light_angles"]] = [el, az]
            theta[L[f"{image}.light_color"]] = 0.8 if image == "point" else 0.0
            theta[L[f"{image}.ambient"]] = 0.1 if image == "point" else 1.0
            theta[L[f"{image}.specular"]] = 0.05 if image == "point" else 0.0
            theta[L[f"{image}.contrast"]] = 1.0
            theta[L[f"{image}.gain"]] = 1.0
        if m.has_texture and self.initial_color is not None:
            theta[L["color"]] = np.asarray(self.initial_color, np.float64)[: m.color_dim]
        if not m.has_texture:
            theta[L["albedo"]] = np.tile([0.55, 0.42, 0.36], m.vertex_count)
        for name, value in self.initial_blocks.items():
            theta[L[name]] = np.broadcast_to(np.asarray(value, np.float64), (L[name].stop - L[name].start,))
        return theta

    # ---- the sample set --------------------------------------------------------------------
    def set_samples(self, count: int):
        """Choose ``count`` sample vertices (plus the feature vertices) and move the model rows
        they and their one-rings need to the Dr.Jit side."""
        mi, m = self.mi, self.model
        count = min(count, len(self.candidates))
        samples = np.sort(self.rng.choice(self.candidates, count, replace=False))
        adj = self.adjacency[samples]  # (S, D)
        valid = adj >= 0
        ring_tris = m.triangles[np.where(valid, adj, 0)]  # (S, D, 3)
        needed = np.unique(np.concatenate([samples, ring_tris[valid].ravel(), self.feature_vertices,
                                           self.distance_vertices.ravel()]))
        local = np.full(m.vertex_count, -1, np.int64)
        local[needed] = np.arange(len(needed))
        self.samples, self.needed = samples, needed
        self.n_samples, self.n_needed, self.degree = len(samples), len(needed), adj.shape[1]
        rows = (3 * needed[:, None] + np.arange(3)).ravel()
        sigma = np.sqrt(m.shape_variance).astype(np.float64)
        columns = [m.shape_basis[rows] * sigma]
        if m.has_expressions:
            columns.append(m.expression_basis[rows] * np.sqrt(m.expression_variance))
        basis = np.concatenate(columns, axis=1).astype(np.float32)
        self.n_modes = basis.shape[1]
        self.dr_mean = mi.Float(m.shape_mean[needed].astype(np.float32).ravel())
        self.dr_basis = [mi.Float(np.ascontiguousarray(basis[:, k])) for k in range(self.n_modes)]
        self.dr_sample_local = mi.UInt32(local[samples].astype(np.uint32))
        self.dr_feature_local = mi.UInt32(local[self.feature_vertices].astype(np.uint32))
        if len(self.distances):
            self.dr_distance_local = [mi.UInt32(local[self.distance_vertices[:, k]].astype(np.uint32))
                                      for k in range(2)]
            self.dr_distance_mm = mi.Float(np.array([d for _, _, d in self.distances], np.float32))
        corners = local[ring_tris]  # (S, D, 3)
        corners = np.where(valid[..., None], corners, 0).astype(np.uint32)
        self.dr_corners = [mi.UInt32(np.ascontiguousarray(corners[..., c].ravel())) for c in range(3)]
        self.dr_slot_valid = mi.Float(valid.astype(np.float32).ravel())
        if m.has_texture:
            crow = (3 * samples[:, None] + np.arange(3)).ravel()
            cbasis = m.color_basis[crow] * np.sqrt(m.color_variance)
            self.dr_color_mean = mi.Float(m.color_mean[samples].astype(np.float32).ravel())
            self.dr_color_basis = [mi.Float(np.ascontiguousarray(cbasis[:, k].astype(np.float32)))
                                   for k in range(m.color_dim)]
        self.dr_sample_vertex = mi.UInt32(samples.astype(np.uint32))
        self.visible = {k: np.ones(count, np.float32) for k in self.image_names}
        self.shadow = np.ones(count, np.float32)
        self.dr_visible = {k: mi.Float(v) for k, v in self.visible.items()}
        self.dr_shadow = mi.Float(self.shadow)

    def set_level(self, blur: float):
        mi = self.mi
        self.dr_images = {}
        for key, image in self.images.items():
            b = _blurred(image, blur * self.scale_px)
            self.dr_images[key] = mi.Float(np.ascontiguousarray(b, np.float32).ravel())

    # ---- synthesis (Dr.Jit, differentiable) ----------------------------------------------------
    def _scalar(self, theta, i: int):
        import drjit as dr

        return dr.gather(self.mi.Float, theta, self.mi.UInt32(i))

    def _block(self, theta, name: str):
        s = self.layout[name]
        return [self._scalar(theta, i) for i in range(s.start, s.stop)]

    def _rotation(self, theta):
        """Rows of ``R0 R_y R_x R_z`` as Dr.Jit scalars (row-major 3x3 list)."""
        import drjit as dr

        yaw, pitch, roll = self._block(theta, "rotation")
        cy, sy, cp, sp, cr, sr = dr.cos(yaw), dr.sin(yaw), dr.cos(pitch), dr.sin(pitch), dr.cos(roll), dr.sin(roll)
        # R_y R_x R_z, expanded
        r = [[cy * cr + sy * sp * sr, -cy * sr + sy * sp * cr, sy * cp],
             [cp * sr, cp * cr, -sp],
             [-sy * cr + cy * sp * sr, sy * sr + cy * sp * cr, cy * cp]]
        return [[float(FRONTAL[i, i]) * r[i][j] for j in range(3)] for i in range(3)]

    def positions(self, theta):
        """Model-space positions of the needed vertices (flat Floats ``x0, y0, z0, ...``):
        ``(with expression, identity only)``. The expression block follows the shape block
        in the parameter vector, and its columns follow the shape columns in the basis."""
        p = self.dr_mean
        s = self.layout["shape"].start
        identity = p
        for k in range(self.n_modes):
            p = p + self.dr_basis[k] * self._scalar(theta, s + k)
            if k == self.model.shape_dim - 1:
                identity = p
        return p, identity

    def _project(self, pc, focal):
        """Pixel coordinates of camera-space points (OpenCV model with distortion)."""
        import drjit as dr

        cam = self.camera
        z = dr.maximum(pc[2], 1.0)
        x, y = pc[0] / z, pc[1] / z
        if np.any(cam.distortion):
            d = np.zeros(8)
            d[:len(cam.distortion)] = cam.distortion
            k1, k2, p1, p2, k3, k4, k5, k6 = (float(v) for v in d)
            r2 = x * x + y * y
            radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            x, y = (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                    y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
        return focal * cam.fx * x + cam.cx, focal * cam.fy * y + cam.cy

    def _bilinear(self, image, u, v):
        """Image (flat RGB Float) at pixel coordinates (u, v), bilinear; returns (rgb, inside)."""
        import drjit as dr

        mi, cam = self.mi, self.camera
        w, h = cam.width, cam.height
        inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
        uc, vc = dr.clip(u, 0, w - 1.001), dr.clip(v, 0, h - 1.001)
        x0, y0 = dr.floor(uc), dr.floor(vc)
        fx, fy = uc - x0, vc - y0
        i0 = mi.UInt32(y0) * w + mi.UInt32(x0)

        def at(i):
            return dr.gather(mi.Vector3f, image, i)

        top = at(i0) * (1 - fx) + at(i0 + 1) * fx
        bottom = at(i0 + w) * (1 - fx) + at(i0 + w + 1) * fx
        return top * (1 - fy) + bottom * fy, inside

    def evaluate(self, theta_np: np.ndarray, feature_weight: float, image_weight: float, grad: bool = True):
        """E and its terms for parameters ``theta_np``; with ``grad``, also dE/dtheta (numpy)."""
        import drjit as dr

        mi, L, w = self.mi, self.layout, self.weights
        theta = mi.Float(theta_np.astype(np.float32))
        if grad:
            dr.enable_grad(theta)
        R = self._rotation(theta)
        t = self._block(theta, "translation")
        focal = dr.exp(self._scalar(theta, L["log_focal"].start))
        pos, neutral = self.positions(theta)
        c = [float(x) for x in self.centre]

        def to_camera(p):
            q = [p[0] - c[0], p[1] - c[1], p[2] - c[2]]
            return [R[i][0] * q[0] + R[i][1] * q[1] + R[i][2] * q[2] + t[i] for i in range(3)]

        def rotate(n):
            return [R[i][0] * n[0] + R[i][1] * n[1] + R[i][2] * n[2] for i in range(3)]

        # feature term (E_F), px at 512 px height
        fp = dr.gather(mi.Vector3f, pos, self.dr_feature_local)
        fu, fv = self._project(to_camera(fp), focal)
        tu = mi.Float(self.feature_pixels[:, 0].astype(np.float32))
        tv = mi.Float(self.feature_pixels[:, 1].astype(np.float32))
        f_sq = (dr.square(fu - tu) + dr.square(fv - tv)) / (self.scale_px ** 2)
        e_f = dr.sum(f_sq) / len(self.names) / w.feature_sigma ** 2

        # prior (E_P)
        e_p = mi.Float(0.0)
        for name, weight in (("shape", w.shape), ("expression", w.expression), ("color", w.texture)):
            if name in L.slices and L[name].stop > L[name].start:
                s = L[name]
                vals = dr.gather(mi.Float, theta, dr.arange(mi.UInt32, s.start, s.stop))
                e_p = e_p + weight * dr.sum(dr.square(vals))
        log_f = self._scalar(theta, L["log_focal"].start)
        e_p = e_p + dr.square(log_f / w.focal)

        # metric distances between feature points (the capture's tape measurements), mm
        e_d = mi.Float(0.0)
        if len(self.distances):
            # measured on the face at rest: the identity shape, without expression
            length = dr.norm(dr.gather(mi.Vector3f, neutral, self.dr_distance_local[0]) -
                             dr.gather(mi.Vector3f, neutral, self.dr_distance_local[1]))
            e_d = dr.sum(dr.square((length - self.dr_distance_mm) / w.distance_sigma)) / len(self.distances)
            e_p = e_p + e_d

        e_i = mi.Float(0.0)
        stats = {}
        if image_weight > 0:
            sp = dr.gather(mi.Vector3f, pos, self.dr_sample_local)
            # vertex normals from the one-ring (area weighted), model space -> camera space
            a = dr.gather(mi.Vector3f, pos, self.dr_corners[0])
            b = dr.gather(mi.Vector3f, pos, self.dr_corners[1])
            cc = dr.gather(mi.Vector3f, pos, self.dr_corners[2])
            fn = dr.cross(b - a, cc - a) * self.dr_slot_valid
            n = dr.normalize(mi.Vector3f(dr.block_sum(fn.x, self.degree), dr.block_sum(fn.y, self.degree),
                                         dr.block_sum(fn.z, self.degree)))
            pc = to_camera(sp)
            nc = mi.Vector3f(*rotate(n))
            pcv = mi.Vector3f(*pc)
            view = dr.normalize(-pcv)
            u, v = self._project(pc, focal)
            facing = dr.maximum(dr.dot(nc, view), 0.0)
            if self.model.has_texture:
                alb = self.dr_color_mean
                s = L["color"].start
                for k in range(self.model.color_dim):
                    alb = alb + self.dr_color_basis[k] * self._scalar(theta, s + k)
                albedo = dr.gather(mi.Vector3f, alb, dr.arange(mi.UInt32, self.n_samples))
                albedo_prior = None
            else:
                s = L["albedo"].start
                albedo = mi.Vector3f(*[dr.gather(mi.Float, theta, 3 * self.dr_sample_vertex + (s + k))
                                       for k in range(3)])
                mean_albedo = mi.Vector3f(*[dr.sum(albedo[k]) / self.n_samples for k in range(3)])
                albedo_prior = w.albedo * dr.sum(dr.squared_norm(albedo - mean_albedo)) / self.n_samples
                e_p = e_p + albedo_prior
            total = mi.Float(0.0)
            for key in self.image_names:
                el, az = self._block(theta, f"{key}.light_angles")
                ld = mi.Vector3f(dr.cos(el) * dr.sin(az), -dr.sin(el), -dr.cos(el) * dr.cos(az))
                lc = mi.Color3f(*self._block(theta, f"{key}.light_color"))
                if key == "point" and math.isfinite(self.light_distance):
                    # the lamp at its calibrated distance in the fitted direction: per-point
                    # direction and inverse-square falloff (relative to the face centre)
                    to_light = mi.Vector3f(*t) + self.light_distance * ld - pcv
                    dist2 = dr.squared_norm(to_light)
                    ld = to_light / dr.sqrt(dist2)
                    lc = lc * (self.light_distance ** 2 / dist2)
                amb = mi.Color3f(*self._block(theta, f"{key}.ambient"))
                ks = self._scalar(theta, L[f"{key}.specular"].start)
                contrast = self._scalar(theta, L[f"{key}.contrast"].start)
                gain = mi.Color3f(*self._block(theta, f"{key}.gain"))
                offset = mi.Color3f(*self._block(theta, f"{key}.offset"))
                shadow = self.dr_shadow if key == "point" else 1.0
                ndl = dr.dot(nc, ld)
                refl = 2 * ndl * nc - ld
                spec = ks * dr.power(dr.maximum(dr.dot(refl, view), 0.0), PHONG_EXPONENT)
                lit = shadow * dr.select(ndl > 0, 1.0, 0.0)
                colour = albedo * (amb + lc * dr.maximum(ndl, 0.0) * shadow) + lc * spec * lit
                lum = LUMINANCE[0] * colour.x + LUMINANCE[1] * colour.y + LUMINANCE[2] * colour.z
                colour = lum + contrast * (colour - lum)
                colour = gain * colour + offset
                observed, inside = self._bilinear(self.dr_images[key], u, v)
                weight = self.dr_visible[key] * dr.select(inside, 1.0, 0.0) * dr.clip((facing - 0.1) * 5.0, 0.0, 1.0)
                residual = dr.squared_norm(colour - observed)
                wsum = dr.maximum(dr.sum(weight), 1.0)
                total = total + dr.sum(weight * residual) / wsum / w.image_sigma ** 2
                stats[key] = (residual, weight)
            e_i = total / len(self.image_names)

        # the weights change every iteration while E_F fades: opaque, so kernels stay cached
        energy = (dr.opaque(mi.Float, image_weight) * e_i +
                  dr.opaque(mi.Float, feature_weight * w.feature) * e_f + e_p)
        if grad:
            dr.backward(energy)
            g = np.asarray(dr.grad(theta), np.float64)
        else:
            g = None
        frms = math.sqrt(float(dr.sum(f_sq)[0]) / len(self.names)) * self.scale_px
        terms = {"E": float(energy[0]), "E_I": float(e_i[0]), "E_F": float(e_f[0]), "E_P": float(e_p[0]),
                 "E_D": float(e_d[0]),
                 "feature_rms_px": frms}
        if stats:
            num = sum(float(dr.sum(r * wt)[0]) for r, wt in stats.values())
            den = sum(float(dr.sum(wt)[0]) for r, wt in stats.values())
            terms["image_rms"] = math.sqrt(num / max(den, 1.0) / 3.0)
        return terms, g

    # ---- full mesh, visibility and cast shadows (Mitsuba ray casting) -------------------------
    def vertices_camera(self, theta: np.ndarray) -> np.ndarray:
        """All model vertices in camera space (numpy float64, mm)."""
        m, L = self.model, self.layout
        alpha = theta[L["shape"]]
        delta = theta[L["expression"]] if m.has_expressions else None
        local = m.shape(alpha, delta).astype(np.float64)
        return (local - self.centre) @ self.rotation(theta).T + theta[L["translation"]]

    def rotation(self, theta: np.ndarray) -> np.ndarray:
        return FRONTAL @ rotation_matrix(*np.degrees(theta[self.layout["rotation"]]))

    def update_visibility(self, theta: np.ndarray):
        """Camera visibility of the samples and cast shadows of the directed light, by ray casting
        against the current full mesh (``Scene.ray_test``)."""
        import drjit as dr

        from ..model.geometry import vertex_normals
        from ..model.mesh import mitsuba_mesh

        mi, L = self.mi, self.layout
        verts = self.vertices_camera(theta)
        scene = mi.load_dict({"type": "scene", "face": mitsuba_mesh(verts, self.model.triangles)})
        p = verts[self.samples]
        n = vertex_normals(verts, self.model.triangles)[self.samples].astype(np.float64)
        eps = 0.3
        dist = np.linalg.norm(p, axis=1)
        d = -p / dist[:, None]  # towards the camera
        origin = p + eps * n

        def occluded(o, direction, maxt):
            ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, k].astype(np.float32)) for k in range(3)]),
                           mi.Vector3f(*[mi.Float(direction[:, k].astype(np.float32)) for k in range(3)]))
            ray.maxt = mi.Float(np.asarray(maxt, np.float32))
            return np.asarray(scene.ray_test(ray), bool)

        seen = ~occluded(origin, d, np.maximum(dist - 2 * eps, eps))
        seen &= np.sum(n * d, axis=1) > 0
        for key in self.image_names:
            self.visible[key] = seen.astype(np.float32)
            self.dr_visible[key] = mi.Float(self.visible[key])
        if "point" in self.image_names:
            el, az = theta[L["point.light_angles"]]
            ld = np.broadcast_to(light_direction(el, az), p.shape)
            maxt = np.full(len(p), 1e5)
            if math.isfinite(self.light_distance):
                to_light = theta[L["translation"]] + self.light_distance * ld - origin
                maxt = np.linalg.norm(to_light, axis=1)
                ld = to_light / maxt[:, None]
            lit = ~occluded(origin, np.ascontiguousarray(ld), maxt)
            self.shadow = lit.astype(np.float32)
            self.dr_shadow = mi.Float(self.shadow)
        dr.eval()

    def extract_albedo(self, theta: np.ndarray) -> np.ndarray:
        """Start the per-vertex albedo (models without a colour model) from the photograph at the
        landmark-fitted pose, as the paper extracts the texture of a view [Blanz and Vetter 1999]:
        the diffuse-light image (else the point-light image divided by its Lambert shading) sampled
        at every front-facing vertex, over the start's ambient and gain; the rest take their mean."""
        import scipy.ndimage as ndi

        from ..model.geometry import vertex_normals

        L, cam = self.layout, self.camera
        verts = self.vertices_camera(theta)
        n = vertex_normals(verts, self.model.triangles).astype(np.float64)
        view = -verts / np.linalg.norm(verts, axis=1, keepdims=True)
        px = cam.project(cam.to_world(verts))
        key = "diffuse" if "diffuse" in self.images else self.image_names[0]
        img = _blurred(self.images[key], 1.0 * self.scale_px)
        colour = np.stack([ndi.map_coordinates(img[..., c], [px[:, 1], px[:, 0]], order=1, mode="nearest")
                           for c in range(3)], axis=-1)
        shade = theta[L[f"{key}.ambient"]] * np.ones((len(verts), 3))
        if key == "point":
            el, az = theta[L["point.light_angles"]]
            shade = shade + theta[L["point.light_color"]] * np.maximum(n @ light_direction(el, az), 0.0)[:, None]
        shade = shade * theta[L[f"{key}.gain"]]
        inside = (px[:, 0] >= 0) & (px[:, 0] <= cam.width - 1) & (px[:, 1] >= 0) & (px[:, 1] <= cam.height - 1)
        ok = inside & (np.sum(n * view, axis=1) > 0.3) & np.all(shade > 0.05, axis=1)
        if ok.sum() < 10:
            return theta
        albedo = np.clip(colour / np.maximum(shade, 1e-3), 0.0, 1.0)
        albedo[~ok] = np.median(albedo[ok], axis=0)
        theta = theta.copy()
        theta[L["albedo"]] = albedo.ravel()
        return theta

    # ---- optimisation ------------------------------------------------------------------------
    def run(self, progress_bar=None, lr=(0.1, 0.01), visibility_interval: int = 50):
        """Adam on ``theta / unit``: landmark-only steps, then the coarse-to-fine image levels."""
        L, sched, w = self.layout, self.schedule, self.weights
        theta = self.initial()
        units = self.layout.units.copy()
        if not self.fit_focal:
            units[L["log_focal"]] = 0.0
        for name in self.fixed:
            units[L[name]] = 0.0
        nonnegative = np.zeros(L.size, bool)
        for key in self.image_names:
            for name in ("light_color", "ambient", "specular", "contrast", "gain"):
                nonnegative[L[f"{key}.{name}"]] = True
        history = []
        use_image = len(self.image_names) > 0
        # frozen blocks during the landmark-only stage: lighting, colour and texture
        pose_mask = np.zeros(L.size, bool)
        for name in ("rotation", "translation", "log_focal", "shape", "expression"):
            pose_mask[L[name]] = True
        stages = [("pose", sched.pose_iterations, None, None, pose_mask)]
        for i, (iters, samples, blur) in enumerate(sched.levels):
            if use_image:
                stages.append((f"level{i}", int(iters), int(samples), float(blur), np.ones(L.size, bool)))
        image_total = sum(s[1] for s in stages[1:])
        image_done = 0
        beta1, beta2, eps = 0.9, 0.999, 1e-8
        terms = {}
        it_total = 0
        for name, iters, samples, blur, mask in stages:
            m1 = np.zeros(L.size)
            m2 = np.zeros(L.size)
            self.set_samples(100 if samples is None else samples)
            if samples is not None:
                if name == "level0" and "albedo" in L.slices and EXTRACT_ALBEDO:
                    theta = self.extract_albedo(theta)
                self.set_level(blur)
                self.update_visibility(theta)
            for it in range(iters):
                if samples is None:
                    fw, iw = 1.0, 0.0
                    rate = lr[0]
                else:
                    frac = image_done / max(image_total, 1)
                    fade = min(frac / max(w.feature_fade, 1e-9), 1.0)
                    fw = (1 - fade) * 1.0 + fade * (w.feature_final / max(w.feature, 1e-12))
                    iw = 1.0
                    rate = lr[0] * (lr[1] / lr[0]) ** frac
                    if it > 0 and it % visibility_interval == 0:
                        self.update_visibility(theta)
                terms, g = self.evaluate(theta, fw, iw)
                if not (np.isfinite(terms["E"]) and np.all(np.isfinite(g))):
                    return theta, terms, history, it_total, DIVERGED, f"non-finite energy or gradient in {name}"
                gu = g * units * mask
                m1 = beta1 * m1 + (1 - beta1) * gu
                m2 = beta2 * m2 + (1 - beta2) * gu * gu
                k = it + 1
                step = rate * (m1 / (1 - beta1 ** k)) / (np.sqrt(m2 / (1 - beta2 ** k)) + eps)
                theta = theta - step * units * mask
                theta[nonnegative] = np.maximum(theta[nonnegative], 0.0)
                it_total += 1
                if samples is not None:
                    image_done += 1
                if it % 10 == 0 or it == iters - 1:
                    history.append({"iteration": it_total, "stage": name, **{k_: float(v) for k_, v in terms.items()}})
                if progress_bar is not None:
                    progress_bar.update(1)
                    progress_bar.set_postfix(stage=name, E=f"{terms['E']:.3g}",
                                             lm=f"{terms['feature_rms_px']:.2f}px")
        if use_image and sched.levels:
            self.update_visibility(theta)
        terms, _ = self.evaluate(theta, w.feature_final / max(w.feature, 1e-12), 1.0 if use_image and sched.levels else 0.0,
                                 grad=False)
        return theta, terms, history, it_total, None, ""


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------
def _load(capture):
    from ..capture import Capture, load_capture

    return capture if isinstance(capture, Capture) else load_capture(capture)


def fit_measurement(measurement, camera, model="builtin", light_position=None, schedule: Schedule | None = None,
                    weights: Weights | None = None, use_diffuse: bool = True, use_point: bool = True,
                    fit_focal: bool = True, initial_color=None, seed: int = 0, max_feature_error: float = 4.0,
                    progress=True, lr=(0.1, 0.01), visibility_interval: int = 50, initial: dict | None = None,
                    fixed=(), distances=()) -> ShapeFit:
    """Fit the morphable model to one measurement (paper sec. 4.2), from the mean face.

    Parameters
    ----------
    measurement : mifaces.capture.Measurement
    camera : mifaces.capture.Camera
        The calibrated camera (its focal length is the start and prior of the fitted one).
    model : str, path or MorphableModel
    light_position : (3,) array, optional
        World position of the point light (mm): starts the directed light's direction.
    schedule, weights : optional
        :class:`Schedule` and :class:`Weights`; defaults as documented there.
    use_diffuse, use_point : bool
        Use the companion diffuse-light image / the point-light image in E_I.
    fit_focal : bool
        Optimise the focal length (paper sec. 4.2) under a weak prior around the calibration.
    initial_color : (C,) array, optional
        Texture coefficients to start from (the paper starts every fit from the
        texture of a frontal, frontally lit view).
    max_feature_error : float
        A fit whose feature points end farther than this RMS (px at 512 px image
        height) from their targets is not a success: ``'diverged'`` or
        ``'not_converged'`` (see :attr:`ShapeFit.status`).
    seed : int
        Seeds the choice of sample vertices.
    progress : bool or tqdm
        Show a progress bar (or update the one given).
    lr : (float, float)
        Adam's step (in natural units of each parameter) at the start and the end of the image levels.
    visibility_interval : int
        Iterations between re-computations of visibility and cast shadows by ray casting.
    initial : dict, optional
        Start values of parameter blocks by name, overriding the defaults:
        ``'rotation'`` (yaw, pitch, roll in radians), ``'translation'`` (camera-space
        position of :func:`rotation_centre`, mm), ``'log_focal'``, ``'shape'``,
        ``'expression'``, ``'color'``, and per image (``'point.'``/``'diffuse.'``)
        ``light_angles``, ``light_color``, ``ambient``, ``specular``, ``contrast``, ``gain``, ``offset``.
    fixed : iterable of str
        Parameter blocks held at their start values.
    distances : iterable of mifaces.capture.Distance
        Metric distances between feature points (mm) that fix the face's scale
        (``Capture.distances``); a term of E_P with :attr:`Weights.distance_sigma`.

    Returns
    -------
    ShapeFit
    """
    from tqdm import tqdm

    t0 = time.perf_counter()
    model = load_model(model)
    schedule = schedule or Schedule()
    weights = weights or Weights()
    targets = feature_targets(measurement, model)
    images = {}
    if use_point:
        images["point"] = measurement.image.pixels
    if use_diffuse and measurement.diffuse is not None:
        images["diffuse"] = measurement.diffuse.pixels
    for key, img in images.items():
        if img.shape[:2] != (camera.height, camera.width):
            raise ShapeFitError(f"measurement {measurement.name!r}: {key} image is {img.shape[1]}x{img.shape[0]}, "
                                f"the camera {camera.width}x{camera.height}")
    fitter = _Fitter(model, camera, images, targets, weights, schedule, np.random.default_rng(seed),
                     light_world=light_position, fit_focal=fit_focal, initial_color=initial_color,
                     initial=initial, fixed=fixed, distances=distances)
    own_bar = progress is True
    bar = tqdm(total=schedule.pose_iterations + (sum(int(l[0]) for l in schedule.levels) if images else 0),
               desc=f"fit {measurement.name}", unit="it", leave=False) if own_bar else (progress or None)
    try:
        theta, terms, history, iterations, status, message = fitter.run(bar, lr=lr,
                                                                       visibility_interval=visibility_interval)
    finally:
        if own_bar:
            bar.close()
    L = fitter.layout
    if status is None:
        if not all(np.isfinite(v) for v in terms.values()) or not np.all(np.isfinite(theta)):
            status, message = DIVERGED, "non-finite parameters or loss"
        elif terms["feature_rms_px"] > max_feature_error * fitter.scale_px:
            start = history[0]["feature_rms_px"] if history else math.inf
            # feature points that end farther than they started, or far off: the fit ran away;
            # still approaching them: it needs more iterations
            ran_away = terms["feature_rms_px"] > min(start, 4 * max_feature_error * fitter.scale_px)
            status = DIVERGED if ran_away else NOT_CONVERGED
            message = (f"feature points end {terms['feature_rms_px']:.1f} px RMS from their targets "
                       f"(limit {max_feature_error * fitter.scale_px:.1f} px; {start:.1f} px at the start)"
                       + ("" if ran_away else ": more iterations may help"))
        else:
            status, message = CONVERGED, ""
    finite = np.all(np.isfinite(theta))
    verts_c = fitter.vertices_camera(theta) if finite else np.full((model.vertex_count, 3), np.nan)
    light = {}
    for key in fitter.image_names:
        el, az = theta[L[f"{key}.light_angles"]]
        scale = fitter.image_scale[key]
        light[key] = {"direction": light_direction(el, az), "color": theta[L[f"{key}.light_color"]],
                      "ambient": theta[L[f"{key}.ambient"]], "specular": float(theta[L[f"{key}.specular"]][0]),
                      "contrast": float(theta[L[f"{key}.contrast"]][0]),
                      "gain": theta[L[f"{key}.gain"]] * scale, "offset": theta[L[f"{key}.offset"]] * scale}
    rot = fitter.rotation(theta)
    focal = math.exp(theta[L["log_focal"]][0]) * np.array([camera.fx, camera.fy])
    return ShapeFit(
        measurement=measurement.name, status=status,
        vertices_world=camera.to_world(verts_c).astype(np.float32), vertices_camera=verts_c.astype(np.float32),
        coefficients=theta[L["shape"]].copy(),
        expression=theta[L["expression"]].copy(),
        color=theta[L["color"]].copy() if model.has_texture else None,
        albedo=theta[L["albedo"]].reshape(-1, 3).astype(np.float32) if "albedo" in L.slices else None,
        rotation=rot, translation=theta[L["translation"]] - rot @ fitter.centre,
        yaw_pitch_roll=np.degrees(theta[L["rotation"]]), focal_length=focal, light=light, loss=terms,
        iterations=iterations, seconds=time.perf_counter() - t0, message=message, history=history)


def _reference_measurement(capture) -> str:
    """The measurement to take the starting texture from: the one whose light is closest to the
    camera's viewing axis and whose feature points are most left-right symmetric (a frontal view
    at frontal illumination, paper sec. 4.2)."""
    cam = capture.camera
    best, best_score = capture.measurements[0].name, np.inf
    for m in capture.measurements:
        light = capture.light(m.light).position if m.light else None
        angle = 0.0
        if light is not None:
            fp = np.array(list(m.feature_points.values()))
            centre = cam.to_world(cam.pixel_rays(fp.mean(0)) * np.linalg.norm(cam.translation))
            d1 = (light - centre) / np.linalg.norm(light - centre)
            d2 = (cam.position - centre) / np.linalg.norm(cam.position - centre)
            angle = math.degrees(math.acos(float(np.clip(d1 @ d2, -1, 1))))
        pts = m.feature_points
        asym = 0.0
        if "nose_tip" in pts and "right_eye_outer" in pts and "left_eye_outer" in pts:
            a = np.linalg.norm(np.asarray(pts["right_eye_outer"]) - pts["nose_tip"])
            b = np.linalg.norm(np.asarray(pts["left_eye_outer"]) - pts["nose_tip"])
            asym = abs(math.log(max(a, 1e-6) / max(b, 1e-6))) * 100.0
        score = angle + asym
        if score < best_score:
            best, best_score = m.name, score
    return best


def fit_shape(capture, model="builtin", measurements=None, out=None, iterations: float | Schedule | None = None,
              progress: bool = True, weights: Weights | None = None, use_diffuse: bool = True,
              fit_focal: bool = True, seed: int = 0, max_feature_error: float = 4.0, fixed=()) -> list[ShapeFit]:
    """Fit the morphable model to every measurement of a capture, independently (paper sec. 4.2).

    Each measurement is fitted from the average face; the texture of a
    frontal, frontally lit measurement (fitted first) starts the others, as
    in the paper.

    Parameters
    ----------
    capture : Capture or path
        A loaded capture or its folder.
    model : str, path or MorphableModel
        ``'builtin'`` or a model file for :func:`mifaces.load_model`.
    measurements : list of str, optional
        Names to fit (default: all).
    out : path, optional
        Folder to write, per measurement, ``<name>.json`` (parameters, loss
        terms, iterations, seconds, status) and, for a converged fit,
        ``<name>.npy`` (fitted vertices (N, 3) float32 in **camera space**,
        mm); and ``shapes.json``, the index. All written atomically.
    iterations : float or Schedule, optional
        A :class:`Schedule`, or a factor on the default schedule's iteration counts.
    progress : bool
        Show progress bars (tqdm).
    weights : Weights, optional
    use_diffuse : bool
        Use the companion diffuse-light image where present.
    fit_focal : bool
        Optimise the focal length.
    seed : int
    max_feature_error : float
        RMS feature-point error (px at 512 px) above which a fit is not a success
        (``'diverged'`` or ``'not_converged'``, see :attr:`ShapeFit.status`).
    fixed : iterable of str
        Parameter blocks held at their start values (see :func:`fit_measurement`).

    Returns
    -------
    list of ShapeFit
        In the order of the capture's measurements.

    Raises
    ------
    ShapeFitError
        For an unknown measurement name, or missing or misnamed feature points
        (checked for all measurements before any fitting).
    """
    from tqdm import tqdm

    capture = _load(capture)
    source = model if not hasattr(model, "shape_mean") else (
        model.metadata["source"] if Path(str(model.metadata.get("source", ""))).is_file() else model.name)
    model = load_model(model)
    if isinstance(iterations, Schedule):
        schedule = iterations
    else:
        schedule = Schedule() if iterations is None else Schedule.scaled(float(iterations))
    names = [m.name for m in capture.measurements]
    wanted = names if measurements is None else list(measurements)
    unknown = [n for n in wanted if n not in names]
    if unknown:
        raise ShapeFitError(f"no measurement(s) {unknown} in {capture.path}; measurements: {names}")
    todo = [m for m in capture.measurements if m.name in wanted]
    for m in todo:
        feature_targets(m, model)  # fail before any work
    reference = _reference_measurement(capture) if model.has_texture else None
    order = sorted(todo, key=lambda m: m.name != reference)
    fits, initial_color = {}, None
    bar = tqdm(total=len(order), desc="fit-shape", unit="image", disable=not progress)
    for m in order:
        light = capture.light(m.light).position if m.light else None
        fit = fit_measurement(m, capture.camera, model, light_position=light, schedule=schedule, weights=weights,
                              use_diffuse=use_diffuse, fit_focal=fit_focal, initial_color=initial_color,
                              seed=seed, max_feature_error=max_feature_error, progress=progress, fixed=fixed,
                              distances=capture.distances)
        if m.name == reference and fit.converged:
            initial_color = fit.color
        fits[m.name] = fit
        if out is not None:
            write_fit(out, fit, model)
        bar.update(1)
        bar.set_postfix(last=m.name, status=fit.status)
    bar.close()
    result = [fits[m.name] for m in todo]
    if out is not None:
        write_index(out, capture, model, result, reference, model_source=str(source))
    return result


def write_fit(out, fit: ShapeFit, model) -> None:
    """Write ``<name>.json`` and, if converged, ``<name>.npy`` (camera-space vertices) atomically.
    A diverged fit's stale ``.npy`` from an earlier run is removed, so it is never read as a success."""
    from ..files import atomic_write, write_json

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    npy = out / f"{fit.measurement}.npy"
    if fit.converged:
        with atomic_write(npy) as f:
            np.save(f, fit.vertices_camera.astype(np.float32))
    elif npy.exists():
        npy.unlink()
    data = fit.to_json()
    data["model"] = model.name
    data["vertices"] = npy.name if fit.converged else None
    if fit.albedo is not None and fit.converged:
        alb = out / f"{fit.measurement}_albedo.npy"
        with atomic_write(alb) as f:
            np.save(f, fit.albedo)
        data["albedo"] = alb.name
    write_json(out / f"{fit.measurement}.json", data)


def write_index(out, capture, model, fits: list[ShapeFit], reference=None, model_source=None) -> None:
    """Write ``shapes.json``: the capture, the model (``model_source``: what
    :func:`mifaces.load_model` loads it from), the camera and per measurement its status."""
    from ..files import write_json

    out = Path(out)
    index = {"format": "mifaces-shapes", "version": 1, "capture": str(capture.path), "model": model.name,
             "model_source": str(model_source if model_source is not None else model.name),
             "vertex_count": model.vertex_count, "frame": "camera (OpenCV), mm",
             "camera": capture.camera.to_json(), "texture_reference": reference, "measurements": {}}
    old = out / INDEX
    if old.is_file():
        import json

        try:
            index["measurements"].update(json.loads(old.read_text()).get("measurements", {}))
        except (ValueError, OSError):
            pass
    for fit in fits:
        index["measurements"][fit.measurement] = {
            "status": fit.status, "vertices": f"{fit.measurement}.npy" if fit.converged else None,
            "parameters": f"{fit.measurement}.json", "seconds": round(fit.seconds, 3),
            "feature_rms_px": fit.loss.get("feature_rms_px"), "message": fit.message}
    write_json(out / INDEX, index)


def load_fitted_shapes(path, capture=None) -> dict[str, np.ndarray]:
    """Fitted shapes written by :func:`fit_shape`, in the capture's **world** frame.

    Parameters
    ----------
    path : path
        The ``out`` folder of :func:`fit_shape` (holding ``shapes.json``).
    capture : Capture or path, optional
        The capture whose camera maps camera space to world space (default:
        the camera stored in ``shapes.json``).

    Returns
    -------
    dict
        Measurement name -> (N, 3) float32 vertices, world frame, mm -- the
        same quantity as the simulator's ``ground_truth/shapes/<name>.npy``.
        Measurements whose fit diverged are left out, with a warning.
    """
    import json

    from ..capture import Camera

    path = Path(path)
    index_path = path / INDEX
    if not index_path.is_file():
        raise FileNotFoundError(f"no {INDEX} in {path}: not a fit-shape output folder")
    index = json.loads(index_path.read_text())
    if capture is not None:
        camera = _load(capture).camera
    else:
        c = index["camera"]
        camera = Camera(c["width"], c["height"], c["fx"], c["fy"], c["cx"], c["cy"], np.asarray(c["distortion"]),
                        np.asarray(c["rotation"]), np.asarray(c["translation"]))
    out = {}
    skipped = []
    for name, entry in index["measurements"].items():
        if entry.get("status") != CONVERGED or not entry.get("vertices"):
            skipped.append(f"{name} ({entry.get('status')})")
            continue
        verts = np.load(path / entry["vertices"])
        out[name] = camera.to_world(verts).astype(np.float32)
    if skipped:
        warnings.warn(f"fitted shapes not converged, left out: {', '.join(skipped)}", stacklevel=2)
    return out


__all__ = ["metric_distances", "rotation_centre", "ShapeFit", "ShapeFitError", "Schedule", "Weights", "fit_shape",
           "fit_measurement", "load_fitted_shapes", "feature_targets", "write_fit", "write_index", "CONVERGED",
           "DIVERGED", "NOT_CONVERGED"]
