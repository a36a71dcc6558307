"""Shape estimation (paper sec. 4.2): the morphable model fitted to each
pose of a capture (the measurements sharing a ``pose`` label share one fit),
independently and from the average face, by minimising ``E = E_I + E_F + E_P``
(:mod:`mifaces.shape.energy`) with the optimiser of :mod:`mifaces.shape.fitter`.
The method, its frames and how well it works: ``docs/shape_estimation.md``."""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..capture import load_capture
from ..environment import dominant_direction
from ..model import MorphableModel, load_model
from ..progress import progress as progress_bar
from ..status import CONVERGED, DIVERGED, NOT_CONVERGED
from .energy import DIFFUSE, POINT, lit_key
from .fitter import Fitter
from .io import write_fit, write_index
from .result import ShapeFit, ShapeFitError, ShapeSchedule, Weights
from .targets import (eye_distance_px, feature_targets, light_angles, light_direction, normalised,
                      reference_measurement, rotation_centre, start_light_angles)

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
#: Feature points of measurements labelled with one pose that differ from the pose's fitted
#: measurement's by more than this fraction of their spread (RMS) are not one pose: fitted apart.
POSE_AGREEMENT = 0.25
#: Parameter blocks of a fit's geometry and texture: held where only a photograph's lighting is fitted
#: on a pose's shared face (:func:`fit_light`).
GEOMETRY_BLOCKS = ("rotation", "translation", "log_focal", "shape", "expression", "color", "albedo")
#: The second pass of a fit of one face to several poses (``fit_shape(one_identity=True)``): this
#: fraction of the schedule's iterations, from each pose's first fit with the shared identity held.
SECOND_PASS = 0.35


#: The most photographs of one pose fitted jointly (the leader and its companions,
#: :func:`fit_measurement`'s ``companions``): each adds its own light, and its share of E_I's cost.
JOINT_PHOTOGRAPHS = 8


def feature_limit(vertices_camera, model, focal_px: float, max_feature_error: float = MAX_FEATURE_ERROR,
                  feature_noise: float = FEATURE_NOISE) -> float:
    """The RMS feature-point error (px) within which a fit has converged:
    ``max_feature_error * d_eyes + feature_noise``, with ``d_eyes`` the fitted face's eye distance in
    the image (:func:`~mifaces.shape.targets.eye_distance_px`), so the limit follows the face's size
    in the image, not the image's size, and the points' own noise."""
    return max_feature_error * eye_distance_px(vertices_camera, model, focal_px) + feature_noise


def estimated_quantities(camera, distances, fit_focal: bool = True) -> tuple[str, ...]:
    """What a fit estimates that the capture does not give (:attr:`ShapeFit.estimated`)."""
    return (("scale",) if not len(distances or ()) else ()) + \
        (("focal_length",) if fit_focal and not getattr(camera, "calibrated", True) else ())


def fit_measurement(measurement, camera, model="builtin", light_position=None, schedule: ShapeSchedule | None = None,
                    weights: Weights | None = None, use_diffuse: bool = True, use_point: bool = True,
                    fit_focal: bool = True, initial_color=None, seed: int = 0,
                    max_feature_error: float = MAX_FEATURE_ERROR, progress=True, lr=(0.1, 0.01),
                    visibility_interval: int = 50, initial: dict | None = None, fixed=(), distances=(),
                    light=None, feature_noise: float = FEATURE_NOISE,
                    max_image_rms: float = MAX_IMAGE_RMS, companions=()) -> ShapeFit:
    """Fit the morphable model to one measurement (paper sec. 4.2), from the mean face.

    Parameters
    ----------
    measurement : mifaces.capture.Measurement
        Greyscale photographs (``Image.greyscale``) are compared grey with grey: the
        rendering's luminance against the photograph's value, with one light colour,
        ambient, gain and offset (no tint), the model's albedo still coloured.
    camera : mifaces.capture.Camera
        The camera; its focal length is the start and prior of the fitted one, with
        :attr:`Weights.focal` for a calibrated camera and :attr:`Weights.focal_uncalibrated`
        where ``camera.calibrated`` is False (the principal point stays where it is: one
        view cannot tell it from the face's position).
    model : str, path or MorphableModel
        Fitted on its leading :attr:`~mifaces.model.MorphableModel.fit_shape_modes` identity modes.
    light_position : (3,) array, optional
        World position of the point light (mm): starts the directed light's direction.
    light : mifaces.capture.Light, optional
        The point image's light: a directional light's direction (camera frame) or a point
        light's position starts the directed light (supersedes ``light_position``).
    schedule, weights : optional
        :class:`ShapeSchedule` and :class:`Weights`; defaults as documented there.
    use_diffuse, use_point : bool
        Use the companion diffuse-light image / the point-light image in E_I.
    fit_focal : bool
        Optimise the focal length (paper sec. 4.2) under a prior around the camera's.
    initial_color : (C,) array, optional
        Texture coefficients to start from (the paper starts every fit from the
        texture of a frontal, frontally lit view).
    max_feature_error, feature_noise : float
        A fit whose feature points end farther than :func:`feature_limit` (px RMS:
        ``max_feature_error`` times the face's eye distance in the image, plus the
        points' expected noise ``feature_noise`` in px) from their targets is not a
        success: ``'diverged'`` or ``'not_converged'`` (see :attr:`ShapeFit.status`).
    max_image_rms : float
        The convergence limit of the photometric residual ``loss['image_rms']``
        (:data:`MAX_IMAGE_RMS`), where the photographs are used: a fit whose feature
        points fit but whose rendering does not match is ``'not_converged'``. With
        ``companions`` the limit applies to the measurement's own photographs
        (``loss['image_rms_measurement']``); ``loss['image_rms.<key>']`` gives each
        photograph's.
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
        Without them the scale comes from the prior (the mean face's size).
    companions : sequence of (Measurement, Light or None)
        Other photographs of the same pose under other directed lights, fitted jointly: one
        geometry, each photograph with its own light, ambient, gain and offset (and cast
        shadow), as image ``point_1``, ``point_2``, ... (:func:`~mifaces.shape.energy.lit_key`).
        Their lights start from their calibration where the capture has one.

    Returns
    -------
    ShapeFit
    """
    t0 = time.perf_counter()
    model = load_model(model)
    model = model.truncated(model.fit_shape_modes)
    schedule = schedule or ShapeSchedule()
    weights = weights or Weights()
    if not getattr(camera, "calibrated", True):
        weights = replace(weights, focal=weights.focal_uncalibrated)
    targets = feature_targets(measurement, model)
    used, lights = {}, {}
    if use_point:
        used[POINT], lights[POINT] = measurement.image, light
    if use_diffuse and measurement.diffuse is not None:
        used[DIFFUSE] = measurement.diffuse
    for index, (companion, companion_light) in enumerate(companions, start=1):
        used[lit_key(index)], lights[lit_key(index)] = companion.image, companion_light
    images = {key: image.pixels for key, image in used.items()}
    for key, img in images.items():
        if img.shape[:2] != (camera.height, camera.width):
            raise ShapeFitError(f"measurement {measurement.name!r}: {key} image is {img.shape[1]}x{img.shape[0]}, "
                                f"the camera {camera.width}x{camera.height}")
    initial = dict(initial or {})
    positions = {POINT: light_position} if light_position is not None else {}
    for key, source in lights.items():
        if source is None:
            continue
        if source.unknown or source.environment:  # a free directed light: from its guess, else frontal
            if source.guess is not None:
                initial.setdefault(f"{key}.light_angles", light_angles(camera.rotation @ source.guess))
            elif source.envmap is not None:  # a given map: from where most of its light comes
                initial.setdefault(f"{key}.light_angles",
                                   light_angles(camera.rotation @ dominant_direction(source.envmap, camera)))
        elif source.directional:
            initial.setdefault(f"{key}.light_angles", start_light_angles(source, camera, camera.position))
        else:
            positions[key] = source.position
    fitter = Fitter(model, camera, images, targets, weights, schedule, np.random.default_rng(seed),
                    light_world=positions, fit_focal=fit_focal, initial_color=initial_color,
                    initial=initial, fixed=fixed, distances=distances)
    greyscale = bool(used) and all(getattr(image, "greyscale", False) for image in used.values())
    fitter.energy.greyscale = greyscale  # read by Energy._shade
    own_bar = progress is True
    bar = progress_bar(total=schedule.pose_iterations + (sum(int(l[0]) for l in schedule.levels) if images else 0),
                       desc=f"fit {measurement.name}", unit="it", leave=False, detail=True) if own_bar else (progress or None)
    try:
        theta, terms, history, iterations, status, message = fitter.run(bar, lr=lr,
                                                                       visibility_interval=visibility_interval)
    finally:
        if own_bar:
            bar.close()
    if companions and "image_rms" in terms and np.all(np.isfinite(theta)):
        sums = fitter.energy.image_sums(theta)
        terms.update({f"image_rms.{key}": _rms(*sums[key]) for key in sums})
        own = [sums[key] for key in (POINT, DIFFUSE) if key in sums]
        terms["image_rms_measurement"] = _rms(sum(n for n, _ in own), sum(d for _, d in own))
    fit = _result(fitter, theta, measurement.name, terms, history, iterations, greyscale)
    if status is None:
        limit = (feature_limit(fit.vertices_camera, model, float(fit.focal_length[1]), max_feature_error,
                               feature_noise) if np.all(np.isfinite(theta)) else math.inf)
        status, message = _status(theta, terms, history, limit, max_image_rms)
    return replace(fit, status=status, message=message, seconds=time.perf_counter() - t0,
                   estimated=estimated_quantities(camera, distances, fit_focal))


def _rms(num: float, den: float) -> float:
    """The RMS RGB residual of E_I's sums (as :meth:`~mifaces.shape.energy.Energy.terms`' ``image_rms``)."""
    return math.sqrt(num / max(den, 1.0) / 3.0)


def _status(theta, terms: dict, history: list, limit_px: float, max_image_rms: float = MAX_IMAGE_RMS
            ) -> tuple[str, str]:
    """How a fit that ran all its iterations ended, and why, for a feature-point limit in px and the
    photometric limit :data:`MAX_IMAGE_RMS` (where the fit used the photographs)."""
    if not all(np.isfinite(v) for v in terms.values()) or not np.all(np.isfinite(theta)):
        return DIVERGED, "non-finite parameters or loss"
    # a joint fit is judged on the measurement's own photographs, those the limit was set on
    image_rms = terms.get("image_rms_measurement", terms.get("image_rms"))
    if terms["feature_rms_px"] <= limit_px and (image_rms is None or image_rms <= max_image_rms):
        return CONVERGED, ""
    if terms["feature_rms_px"] <= limit_px:  # the points fit, the face's shading does not
        return NOT_CONVERGED, (f"the feature points fit ({terms['feature_rms_px']:.1f} px RMS, limit {limit_px:.1f} px) "
                               f"but the rendered face does not match the photograph: image residual {image_rms:.3f} "
                               f"RMS, limit {max_image_rms:g} (of the photograph's 99th percentile)")
    start = history[0]["feature_rms_px"] if history else math.inf
    # feature points that end farther than they started, or far off: the fit ran away;
    # still approaching them: it needs more iterations
    ran_away = terms["feature_rms_px"] > min(start, 4 * limit_px)
    return (DIVERGED if ran_away else NOT_CONVERGED,
            f"feature points end {terms['feature_rms_px']:.1f} px RMS from their targets "
            f"(limit {limit_px:.1f} px; {start:.1f} px at the start)" + ("" if ran_away else ": more iterations may help"))


def _result(fitter, theta, name, terms, history, iterations, greyscale=False) -> ShapeFit:
    """The :class:`ShapeFit` of parameters ``theta`` (status still open): vertices, pose and
    per-image lighting, with the gain and offset back in the photograph's units; for greyscale
    photographs the tied colour blocks' one value (channel 0) in every channel."""
    L, model, camera = fitter.layout, fitter.model, fitter.camera
    finite = np.all(np.isfinite(theta))
    verts_c = fitter.vertices_camera(theta) if finite else np.full((model.vertex_count, 3), np.nan)

    def block(key, name):
        value = theta[L[f"{key}.{name}"]]
        return np.full_like(value, value[0]) if greyscale and len(value) == 3 else value.copy()

    light = {}
    for key in fitter.image_names:
        el, az = theta[L[f"{key}.light_angles"]]
        scale = fitter.image_scale[key]
        light[key] = {"direction": light_direction(el, az), "color": block(key, "light_color"),
                      "ambient": block(key, "ambient"), "specular": float(theta[L[f"{key}.specular"]][0]),
                      "contrast": 1.0 if greyscale else float(theta[L[f"{key}.contrast"]][0]),
                      "gain": block(key, "gain") * scale, "offset": block(key, "offset") * scale}
    rot = fitter.rotation(theta)
    focal = math.exp(theta[L["log_focal"]][0]) * np.array([camera.fx, camera.fy])
    return ShapeFit(
        measurement=name, status=NOT_CONVERGED,
        vertices_world=camera.to_world(verts_c).astype(np.float32), vertices_camera=verts_c.astype(np.float32),
        coefficients=theta[L["shape"]].copy(),
        expression=theta[L["expression"]].copy(),
        color=theta[L["color"]].copy() if model.has_texture else None,
        albedo=theta[L["albedo"]].reshape(-1, 3).astype(np.float32) if "albedo" in L.slices else None,
        rotation=rot, translation=theta[L["translation"]] - rot @ fitter.centre,
        yaw_pitch_roll=np.degrees(theta[L["rotation"]]), focal_length=focal, light=light, loss=terms,
        iterations=iterations, seconds=0.0, history=history)


def model_source(model) -> str:
    """What :func:`mifaces.load_model` loads ``model`` (a name, a path or a loaded model) from."""
    if not isinstance(model, MorphableModel):
        return str(model)
    source = Path(str(model.metadata.get("source", "")))
    return str(model.metadata["source"]) if source.is_file() else model.name


def fit_shape(capture, model="builtin", measurements=None, out=None,
              iterations: float | ShapeSchedule | None = None, progress: bool = True, weights: Weights | None = None,
              use_diffuse: bool = True, fit_focal: bool = True, seed: int = 0,
              max_feature_error: float = MAX_FEATURE_ERROR, fixed=(), feature_noise: float = FEATURE_NOISE,
              shape_modes: int | None = None, one_identity: bool = True,
              max_image_rms: float = MAX_IMAGE_RMS) -> list[ShapeFit]:
    """Fit the morphable model to every pose of a capture, independently (paper sec. 4.2).

    Measurements sharing a ``pose`` label (one pose of the subject photographed
    under several lights) share one fit: the pose is fitted once, with the feature
    points of its measurement whose light is nearest the camera's axis (with its
    diffuse companion where present), on that photograph and the pose's others
    whose lights the capture gives, together (:func:`fit_measurement`'s
    ``companions``, :data:`JOINT_PHOTOGRAPHS` at most), each with its own light;
    the others get that fit's geometry and the light fitted for them
    (:attr:`ShapeFit.shared_with`), a photograph under an unknown light its light
    fitted on that face (:func:`fit_light`); a labelled measurement whose feature points
    disagree with that one's (by more than :data:`POSE_AGREEMENT` of their
    spread) is fitted on its own, with a warning. Each fit starts from the
    average face; the texture of a frontal, frontally lit measurement (fitted
    first) starts the others, as in the paper.
    :func:`~mifaces.shape.io.shapes_in_world` turns the result into the next
    stage's input without the round trip through ``out``.

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
    max_feature_error, feature_noise : float
        The convergence limit of the feature points (see :func:`feature_limit`).
    max_image_rms : float
        The convergence limit of the photometric residual (:func:`fit_measurement`).
    fixed : iterable of str
        Parameter blocks held at their start values (see :func:`fit_measurement`).
    shape_modes : int, optional
        Identity modes fitted, the leading ones (default: the model's
        :attr:`~mifaces.model.MorphableModel.fit_shape_modes`, 50 of the built-in's 100).
        ``shapes.json`` records the number.
    one_identity : bool
        One face for all photographs: after each pose is fitted on its own, the identity
        coefficients of the converged fits are averaged (:func:`one_face`) and every pose is fitted
        again, briefly (:data:`SECOND_PASS` of the schedule), from its first fit with that identity
        held: its own pose, expression and lighting. Without it, each pose keeps its own identity.

    Returns
    -------
    list of ShapeFit
        One per measurement, in the order of the capture's measurements.

    Raises
    ------
    ShapeFitError
        For an unknown measurement name, or missing or misnamed feature points
        (checked for all measurements before any fitting).
    """
    capture = load_capture(capture)
    source = model_source(model)
    model = load_model(model)
    model = model.truncated(model.fit_shape_modes if shape_modes is None else shape_modes)
    if isinstance(iterations, ShapeSchedule):
        schedule = iterations
    else:
        schedule = ShapeSchedule() if iterations is None else ShapeSchedule.scaled(float(iterations))
    todo = _measurements(capture, measurements, model)
    reference = reference_measurement(capture) if model.has_texture else None
    groups = sorted(pose_groups(capture, todo), key=lambda g: g[0].name != reference)
    fits, leaders, initial_color = {}, {}, None
    joint = one_identity and len(groups) > 1
    bar = progress_bar(total=len(todo) + (len(groups) if joint else 0), desc="fit-shape", unit="image",
                       enabled=bool(progress))
    options = dict(weights=weights, use_diffuse=use_diffuse, fit_focal=fit_focal, seed=seed,
                   max_feature_error=max_feature_error, progress=progress, distances=capture.distances,
                   feature_noise=feature_noise, max_image_rms=max_image_rms)
    for leader, *others in groups:
        light = capture.light(leader.light) if leader.light else None
        fit = fit_measurement(leader, capture.camera, model, light=light, schedule=schedule,
                              initial_color=initial_color, fixed=fixed,
                              companions=_companions(capture, others), **options)
        if leader.name == reference and fit.converged:
            initial_color = fit.color
        leaders[leader.name] = fit
        bar.update(1 + len(others))
        bar.set_postfix(last=leader.name, status=fit.status)
    identity = one_face(list(leaders.values())) if joint else None
    if identity is not None:  # every photograph again, its pose, expression and lighting on the one face
        second = schedule.scaled_by(SECOND_PASS)
        for leader, *others in groups:
            first = leaders[leader.name]
            light = capture.light(leader.light) if leader.light else None
            companions = _companions(capture, others)
            fit = fit_measurement(leader, capture.camera, model, light=light, schedule=second,
                                  initial_color=initial_color, fixed=tuple(fixed) + ("shape",),
                                  initial=dict(_start_from(first, model, leader, companions), shape=identity),
                                  companions=companions, **options)
            leaders[leader.name] = replace(fit, seconds=fit.seconds + first.seconds,
                                           message=(fit.message + "; " if fit.message else "")
                                           + f"identity shared by {len(groups)} poses")
            bar.update(1)
            bar.set_postfix(last=leader.name, status=fit.status)
    for leader, *others in groups:
        fit = leaders[leader.name]
        keys = {m.name: lit_key(i) for i, (m, _) in enumerate(_companions(capture, others), start=1)}
        for fit_m in [_own_lights(fit)] + [_member_fit(fit, m, capture, model, schedule, options, keys.get(m.name))
                                           for m in others]:
            fits[fit_m.measurement] = fit_m
            if out is not None:
                write_fit(out, fit_m, model)
    bar.close()
    result = [fits[m.name] for m in todo]
    if out is not None:
        write_index(out, capture, model, result, reference, model_source=source)
    return result


def _member_fit(fit: ShapeFit, measurement, capture, model, schedule: ShapeSchedule, options: dict,
                key: str | None = None) -> ShapeFit:
    """The fit of a pose group's ``measurement`` on its leader's ``fit``: with the light fitted for it
    where it was the joint fit's photograph ``key``; its own light fitted on the shared face where the
    capture does not know it (:func:`fit_light`); else :func:`shared_fit`."""
    light = capture.light(measurement.light) if measurement.light else None
    if key is not None or light is None or not light.unknown or light.environment or not fit.converged:
        return shared_fit(fit, measurement, capture, key)
    options = {k: v for k, v in options.items() if k != "use_diffuse"}
    return fit_light(fit, measurement, capture.camera, model, light, schedule, **options)


def fit_light(fit: ShapeFit, measurement, camera, model, light, schedule: ShapeSchedule | None = None,
              **options) -> ShapeFit:
    """The lighting of ``measurement``'s photograph on the face of ``fit`` (same pose): the
    directed light's angles, colour, ambient, specular strength, gain and offset of the
    photograph fitted by the shape fit's energy and optimiser (:func:`fit_measurement`), with
    every block of the geometry and texture held (:data:`GEOMETRY_BLOCKS`) at ``fit``'s values,
    the photograph alone (not its companion). The light starts from ``light.guess`` (world frame)
    where stated, else frontal; the cast shadows follow the light as it moves (ray cast on the
    held face every ``visibility_interval`` steps).

    Returns
    -------
    ShapeFit
        ``fit`` (its geometry and status: the face is the leader's) for ``measurement``, with this
        photograph's fitted ``light['point']``, the light fit's loss, iterations and seconds,
        :attr:`ShapeFit.shared_with` the leader, and the light fit's own status in ``message``.
    """
    model = load_model(model)
    model = model.truncated(len(fit.coefficients))
    start = {k: v for k, v in _start_from(fit, model, measurement).items() if "." not in k}
    start["shape"] = fit.coefficients
    start["log_focal"] = math.log(float(fit.focal_length[1]) / camera.fy)
    schedule = schedule or ShapeSchedule()
    schedule = replace(schedule, pose_iterations=1)  # the feature points do not move: the face is held
    fixed = tuple(b for b in GEOMETRY_BLOCKS if b != ("albedo" if model.has_texture else "color"))
    result = fit_measurement(measurement, camera, model, light=light, schedule=schedule, use_diffuse=False,
                             initial=start, fixed=fixed, **options)
    light_fit = f"light fitted on the face of {fit.measurement!r} (same pose): {result.status}" + \
        (f" ({result.message})" if result.message else "")
    return replace(fit, measurement=measurement.name, light=result.light, loss=result.loss,
                   iterations=result.iterations, seconds=result.seconds, history=result.history,
                   shared_with=fit.measurement, message=light_fit + (f"; {fit.message}" if fit.message else ""))


def one_face(fits: list[ShapeFit]) -> np.ndarray | None:
    """The identity of the face all ``fits`` show: the mean of the converged fits' shape
    coefficients (each photograph's fit is an estimate of the same face), None without two
    converged fits."""
    done = [f.coefficients for f in fits if f.converged]
    return np.mean(done, axis=0) if len(done) >= 2 else None


def _start_from(fit: ShapeFit, model, measurement, companions=()) -> dict:
    """Start values (:func:`fit_measurement`'s ``initial``) that continue ``fit`` of ``measurement``
    (and its ``companions``): its pose, expression, albedo or colour, lighting (gain and offset back
    in the normalised photograph's units the fit works in: :func:`~mifaces.shape.targets.normalised`)."""
    photographs = {POINT: measurement.image, DIFFUSE: measurement.diffuse}
    photographs.update({lit_key(i): m.image for i, (m, _) in enumerate(companions, start=1)})
    start = {"rotation": np.radians(fit.yaw_pitch_roll),
             "translation": fit.translation + fit.rotation @ rotation_centre(model)}
    if len(fit.expression):
        start["expression"] = fit.expression
    if fit.albedo is not None and not model.has_texture:
        start["albedo"] = np.asarray(fit.albedo, np.float64).ravel()
    if fit.color is not None:
        start["color"] = fit.color
    for image, light in (fit.light or {}).items():
        if image not in photographs:
            continue
        scale = normalised(photographs[image].pixels)[1] if photographs.get(image) is not None else 1.0
        for name in ("color", "ambient", "specular", "contrast", "gain", "offset"):
            if name in light:
                value = np.asarray(light[name], np.float64) / (scale if name in ("gain", "offset") else 1.0)
                start[f"{image}.{'light_color' if name == 'color' else name}"] = value
        if "direction" in light:
            start[f"{image}.light_angles"] = light_angles(light["direction"])
    return start


def pose_groups(capture, measurements) -> list[list]:
    """``measurements`` grouped by their ``pose`` label, each group led by the measurement its
    shared fit is made on (:func:`~mifaces.shape.targets.reference_measurement` among them);
    unlabelled measurements, and labelled ones whose feature points disagree with the leader's
    (:data:`POSE_AGREEMENT`), are groups of their own."""
    labelled: dict[str, list] = {}
    groups = []
    for m in measurements:
        if m.pose is None:
            groups.append([m])
        else:
            labelled.setdefault(m.pose, []).append(m)
    for pose, members in labelled.items():
        leader = next(m for m in members if m.name == reference_measurement(capture, members))
        group = [leader]
        for m in members:
            if m is leader:
                continue
            if _points_agree(leader.feature_points, m.feature_points):
                group.append(m)
            else:
                warnings.warn(f"measurement {m.name!r} is labelled pose {pose!r} but its feature points differ "
                              f"from {leader.name!r}'s: fitted on its own", stacklevel=3)
                groups.append([m])
        groups.append(group)
    order = {m.name: i for i, m in enumerate(measurements)}
    return sorted(groups, key=lambda g: min(order[m.name] for m in g))


def _points_agree(a: dict, b: dict) -> bool:
    """Feature points ``b`` within :data:`POSE_AGREEMENT` of the spread of ``a`` (RMS over the names
    both have); too few shared names do not agree."""
    names = [n for n in a if n in b]
    if len(names) < 3:
        return False
    pa = np.array([np.asarray(a[n], np.float64) for n in names])
    pb = np.array([np.asarray(b[n], np.float64) for n in names])
    spread = np.sqrt(np.mean(np.sum((pa - pa.mean(0)) ** 2, axis=1)))
    return float(np.sqrt(np.mean(np.sum((pa - pb) ** 2, axis=1)))) <= POSE_AGREEMENT * spread


def _companions(capture, others) -> list:
    """The photographs of a pose fitted with its leader: those whose light the capture gives
    (an unknown light is fitted afterwards on the pose's face, :func:`fit_light`),
    :data:`JOINT_PHOTOGRAPHS` at most with the leader, in the capture's order, each with its light."""
    given = [(m, capture.light(m.light) if m.light else None) for m in others]
    return [(m, light) for m, light in given
            if light is None or not (light.unknown or light.environment)][:JOINT_PHOTOGRAPHS - 1]


def _own_lights(fit: ShapeFit) -> ShapeFit:
    """``fit`` with only its own photographs' lights (a joint fit also holds its companions')."""
    own = {key: light for key, light in (fit.light or {}).items() if key in (POINT, DIFFUSE)}
    return replace(fit, light=own)


def shared_fit(fit: ShapeFit, measurement, capture, key: str | None = None) -> ShapeFit:
    """The fit of ``measurement`` that shares ``fit``'s geometry, pose and texture (same pose),
    0 iterations, 0 seconds. Its light is the one fitted for it where ``measurement`` was the
    joint fit's photograph ``key`` (:func:`~mifaces.shape.energy.lit_key`); otherwise only the
    capture's light direction, in camera space, where known."""
    light = {}
    fitted = (fit.light or {}).get(key) if key else None
    if fitted is not None:
        light[POINT] = fitted
    else:
        source = capture.light(measurement.light) if measurement.light else None
        head = fit.vertices_world.mean(axis=0)
        angles = start_light_angles(source, capture.camera, head) if np.all(np.isfinite(head)) else None
        if angles is not None:
            light[POINT] = {"direction": light_direction(*angles)}
    joint = f"fitted jointly with {fit.measurement!r}" if fitted is not None else f"geometry of {fit.measurement!r}"
    return replace(fit, measurement=measurement.name, light=light, iterations=0, seconds=0.0, history=[],
                   shared_with=fit.measurement,
                   message=f"{joint} (same pose)" + (f"; {fit.message}" if fit.message else ""))


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
