"""Shape estimation (paper sec. 4.2): the morphable model fitted to each
photograph of a capture, independently and from the average face, by
minimising ``E = E_I + E_F + E_P`` (:mod:`mifaces.shape.energy`) with the
optimiser of :mod:`mifaces.shape.fitter`. The method, its frames and how well
it works: ``docs/shape_estimation.md``."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..model import MorphableModel, load_model
from ..progress import progress as progress_bar
from ..status import CONVERGED, DIVERGED, NOT_CONVERGED
from .fitter import Fitter
from .io import as_capture, write_fit, write_index
from .result import ShapeFit, ShapeFitError, ShapeSchedule, Weights
from .targets import feature_targets, light_direction, reference_measurement


def fit_measurement(measurement, camera, model="builtin", light_position=None, schedule: ShapeSchedule | None = None,
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
        :class:`ShapeSchedule` and :class:`Weights`; defaults as documented there.
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
    progress : bool or progress bar
        Show a progress bar (or update the one given).
    lr : (float, float)
        Adam's step (in natural units of each parameter) at the start and the end of the image levels.
    visibility_interval : int
        Iterations between re-computations of visibility and cast shadows by ray casting.
    initial : dict, optional
        Start values of parameter blocks by name, overriding the defaults:
        ``'rotation'`` (yaw, pitch, roll in radians), ``'translation'`` (camera-space
        position of :func:`~mifaces.shape.targets.rotation_centre`, mm), ``'log_focal'``,
        ``'shape'``, ``'expression'``, ``'color'``, and per image (``'point.'``/``'diffuse.'``)
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
    t0 = time.perf_counter()
    model = load_model(model)
    schedule = schedule or ShapeSchedule()
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
    fitter = Fitter(model, camera, images, targets, weights or Weights(), schedule, np.random.default_rng(seed),
                     light_world=light_position, fit_focal=fit_focal, initial_color=initial_color,
                     initial=initial, fixed=fixed, distances=distances)
    own_bar = progress is True
    bar = progress_bar(total=schedule.pose_iterations + (sum(int(l[0]) for l in schedule.levels) if images else 0),
                       desc=f"fit {measurement.name}", unit="it", leave=False, detail=True) if own_bar else (progress or None)
    try:
        theta, terms, history, iterations, status, message = fitter.run(bar, lr=lr,
                                                                       visibility_interval=visibility_interval)
    finally:
        if own_bar:
            bar.close()
    if status is None:
        status, message = _status(theta, terms, history, max_feature_error * fitter.scale_px)
    return _result(fitter, theta, measurement.name, status, message, terms, history, iterations,
                   time.perf_counter() - t0)


def _status(theta, terms: dict, history: list, limit_px: float) -> tuple[str, str]:
    """How a fit that ran all its iterations ended, and why, for a feature-point limit in px."""
    if not all(np.isfinite(v) for v in terms.values()) or not np.all(np.isfinite(theta)):
        return DIVERGED, "non-finite parameters or loss"
    if terms["feature_rms_px"] <= limit_px:
        return CONVERGED, ""
    start = history[0]["feature_rms_px"] if history else math.inf
    # feature points that end farther than they started, or far off: the fit ran away;
    # still approaching them: it needs more iterations
    ran_away = terms["feature_rms_px"] > min(start, 4 * limit_px)
    return (DIVERGED if ran_away else NOT_CONVERGED,
            f"feature points end {terms['feature_rms_px']:.1f} px RMS from their targets "
            f"(limit {limit_px:.1f} px; {start:.1f} px at the start)" + ("" if ran_away else ": more iterations may help"))


def _result(fitter, theta, name, status, message, terms, history, iterations, seconds) -> ShapeFit:
    """The :class:`ShapeFit` of parameters ``theta``: vertices, pose and per-image lighting, with the
    gain and offset back in the photograph's units."""
    L, model, camera = fitter.layout, fitter.model, fitter.camera
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
        measurement=name, status=status,
        vertices_world=camera.to_world(verts_c).astype(np.float32), vertices_camera=verts_c.astype(np.float32),
        coefficients=theta[L["shape"]].copy(),
        expression=theta[L["expression"]].copy(),
        color=theta[L["color"]].copy() if model.has_texture else None,
        albedo=theta[L["albedo"]].reshape(-1, 3).astype(np.float32) if "albedo" in L.slices else None,
        rotation=rot, translation=theta[L["translation"]] - rot @ fitter.centre,
        yaw_pitch_roll=np.degrees(theta[L["rotation"]]), focal_length=focal, light=light, loss=terms,
        iterations=iterations, seconds=seconds, message=message, history=history)


def _model_source(model) -> str:
    """What :func:`mifaces.load_model` loads ``model`` (a name, a path or a loaded model) from."""
    if not isinstance(model, MorphableModel):
        return str(model)
    source = Path(str(model.metadata.get("source", "")))
    return str(model.metadata["source"]) if source.is_file() else model.name


def fit_shape(capture, model="builtin", measurements=None, out=None,
              iterations: float | ShapeSchedule | None = None, progress: bool = True, weights: Weights | None = None,
              use_diffuse: bool = True, fit_focal: bool = True, seed: int = 0, max_feature_error: float = 4.0,
              fixed=()) -> list[ShapeFit]:
    """Fit the morphable model to every measurement of a capture, independently (paper sec. 4.2).

    Each measurement is fitted from the average face; the texture of a
    frontal, frontally lit measurement (fitted first) starts the others, as
    in the paper. :func:`~mifaces.shape.io.shapes_in_world` turns the result
    into the next stage's input without the round trip through ``out``.

    Parameters
    ----------
    capture : Capture or path
        A loaded capture or its folder.
    model : str, path or MorphableModel
        ``'builtin'``, a model file for :func:`mifaces.load_model`, or a loaded model.
    measurements : list of str, optional
        Names to fit (default: all).
    out : path, optional
        Folder to write, per measurement, ``<name>.json`` (parameters, loss
        terms, iterations, seconds, status) and, for a converged fit,
        ``<name>.npy`` (fitted vertices (N, 3) float32 in **camera space**,
        mm); and ``shapes.json``, the index. All written atomically.
    iterations : float or ShapeSchedule, optional
        A :class:`ShapeSchedule`, or a factor on the default schedule's iteration counts.
    progress : bool
        Show progress (:func:`mifaces.progress.progress`).
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
    capture = as_capture(capture)
    source = _model_source(model)
    model = load_model(model)
    if isinstance(iterations, ShapeSchedule):
        schedule = iterations
    else:
        schedule = ShapeSchedule() if iterations is None else ShapeSchedule.scaled(float(iterations))
    todo = _measurements(capture, measurements, model)
    reference = reference_measurement(capture) if model.has_texture else None
    fits, initial_color = {}, None
    bar = progress_bar(total=len(todo), desc="fit-shape", unit="image", enabled=bool(progress))
    for m in sorted(todo, key=lambda m: m.name != reference):
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
        write_index(out, capture, model, result, reference, model_source=source)
    return result


def _measurements(capture, names, model) -> list:
    """The capture's measurements named ``names`` (all for None), in the capture's order, each
    checked to have usable feature points on ``model`` before any work."""
    known = [m.name for m in capture.measurements]
    wanted = known if names is None else list(names)
    unknown = [n for n in wanted if n not in known]
    if unknown:
        raise ShapeFitError(f"no measurement(s) {unknown} in {capture.path}; measurements: {known}")
    todo = [m for m in capture.measurements if m.name in wanted]
    for m in todo:
        feature_targets(m, model)
    return todo
