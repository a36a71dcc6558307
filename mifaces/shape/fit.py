"""Shape estimation (paper sec. 4.2): the morphable model fitted to each
pose of a capture (the measurements sharing a ``pose`` label share one fit),
independently and from the average face, by minimising ``E = E_I + E_F + E_P``
(:mod:`mifaces.shape.energy`) with the optimiser of :mod:`mifaces.shape.fitter`.
The method, its frames and how well it works: ``docs/shape_estimation.md``."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from ..capture import load_capture
from ..model import load_model
from ..runtime.progress import progress as progress_bar
from ..runtime.status import CONVERGED, DIVERGED, NOT_CONVERGED
from .shading import DIFFUSE, POINT, directed, lit_key
from .fitter import Fitter
from .io import model_source, write_fit, write_index
from .poses import companions, one_face, own_lights, pose_groups, seen_by, shared_fit
from .result import (FEATURE_NOISE, MAX_FEATURE_ERROR, MAX_IMAGE_RMS, ShapeFit, ShapeFitError, ShapeOptions,
                     ShapeSchedule)
from .targets import (eye_distance_px, feature_targets, light_angles, normalised, reference_measurement,
                      rotation_centre)

#: Parameter blocks of a fit's geometry and texture: held where only a photograph's lighting is fitted
#: on a pose's shared face (:func:`fit_light`).
GEOMETRY_BLOCKS = ("rotation", "translation", "log_focal", "shape", "expression", "color", "albedo")
#: The second pass of a fit of one face to several poses (``fit_shape(one_identity=True)``): this
#: fraction of the schedule's iterations, from each pose's first fit with the shared identity held.
SECOND_PASS = 0.35


def feature_limit(vertices_camera, model, focal_px: float, max_feature_error: float = MAX_FEATURE_ERROR,
                  feature_noise: float = FEATURE_NOISE) -> float:
    """The RMS feature-point error (px) within which a fit has converged:
    ``max_feature_error * d_eyes + feature_noise``, with ``d_eyes`` the fitted face's eye distance in
    the image (:func:`~mifaces.shape.targets.eye_distance_px`), so the limit follows the face's size
    in the image, not the image's size, and the points' own noise."""
    return max_feature_error * eye_distance_px(vertices_camera, model, focal_px) + feature_noise


def estimated_quantities(camera, distances, fit_focal: bool = True, views: int = 1) -> tuple[str, ...]:
    """What a fit estimates that the capture does not give (:attr:`ShapeFit.estimated`): the scale
    where neither metric distances nor a second calibrated camera (``views``) fix it."""
    return (("scale",) if not len(distances or ()) and views < 2 else ()) + \
        (("focal_length",) if fit_focal and not getattr(camera, "calibrated", True) else ())


def fit_measurement(measurement, camera, model="builtin", light=None, *, schedule: ShapeSchedule | None = None,
                    options: ShapeOptions | None = None, initial: dict | None = None, distances=(), companions=(),
                    progress=True) -> ShapeFit:
    """Fit the morphable model to one measurement (paper sec. 4.2), from the mean face.

    Parameters
    ----------
    measurement : mifaces.capture.Measurement
        Greyscale photographs (``Image.greyscale``) are compared grey with grey: the
        rendering's luminance against the photograph's value, with one light colour,
        ambient, gain and offset (no tint), the model's albedo still coloured.
    camera : mifaces.capture.Camera
        The camera; its focal length is the start and prior of the fitted one, with the options'
        :attr:`Weights.focal` for a calibrated camera and :attr:`Weights.focal_uncalibrated`
        where ``camera.calibrated`` is False (the principal point stays where it is: one
        view cannot tell it from the face's position).
    model : str, path or MorphableModel
        Fitted on its leading :attr:`~mifaces.model.MorphableModel.fit_shape_modes` identity modes.
    light : mifaces.capture.Light, optional
        The point image's light: a directional light's direction (camera frame) or a point
        light's position starts the directed light.
    schedule, options : optional
        :class:`ShapeSchedule` and :class:`ShapeOptions` (the images used, the focal length fitted
        or not, the seed, the convergence limits, Adam's steps, the :class:`Weights` of E's terms,
        the parameter blocks held); defaults as documented there.
    initial : dict, optional
        Start values of parameter blocks by name, overriding the defaults:
        ``'rotation'`` (yaw, pitch, roll in radians), ``'translation'`` (camera-space
        position of :func:`~mifaces.shape.targets.rotation_centre`, mm), ``'log_focal'``,
        ``'shape'``, ``'expression'``, ``'color'`` (texture coefficients: the paper starts every fit
        from the texture of a frontal, frontally lit view), and per image (``'point.'``/``'diffuse.'``)
        ``light_angles``, ``light_color``, ``ambient``, ``specular``, ``contrast``, ``gain``, ``offset``.
        The blocks :attr:`ShapeOptions.fixed` names are held at these start values.
    distances : iterable of mifaces.capture.Distance
        Metric distances between feature points (mm) that fix the face's scale
        (``Capture.distances``); a term of E_P with :attr:`Weights.distance_sigma`.
        Without them the scale comes from the prior (the mean face's size).
    companions : sequence of (Measurement, Light or None, Camera)
        Other photographs of the same pose under other directed lights, fitted jointly: one
        geometry, each photograph with its own light, ambient, gain and offset (and cast
        shadow), as image ``point_1``, ``point_2``, ... (:func:`~mifaces.shape.shading.lit_key`).
        Their lights start from their calibration where the capture has one. Each comes with the
        camera that took it (:meth:`~mifaces.capture.Capture.camera_of`;
        :func:`~mifaces.shape.poses.companions` gives them so): a companion taken by another
        calibrated camera of the shot than ``camera`` is compared with the face seen through that
        camera, and its feature points join E_F in its pixels, which fixes the face's depth.
    progress : bool or progress bar
        Show a progress bar (or update the one given).

    Returns
    -------
    ShapeFit
    """
    t0 = time.perf_counter()
    model = load_model(model)
    model = model.truncated(model.fit_shape_modes)
    schedule = schedule or ShapeSchedule()
    options = options or ShapeOptions()
    weights = options.weights
    if not getattr(camera, "calibrated", True):
        weights = replace(weights, focal=weights.focal_uncalibrated)
    targets = feature_targets(measurement, model)
    used, lights = {}, {}
    if options.use_point:
        used[POINT], lights[POINT] = measurement.image, light
    if options.use_diffuse and measurement.diffuse is not None:
        used[DIFFUSE] = measurement.diffuse
    views = {}
    for index, (companion, companion_light, view) in enumerate(companions, start=1):
        used[lit_key(index)], lights[lit_key(index)] = companion.image, companion_light
        if view is not camera:
            views[lit_key(index)] = (view, *feature_targets(companion, model)[1:])
    images = {key: image.pixels for key, image in used.items()}
    for key, img in images.items():
        view = views.get(key, (camera,))[0]
        if img.shape[:2] != (view.height, view.width):
            raise ShapeFitError(f"measurement {measurement.name!r}: {key} image is {img.shape[1]}x{img.shape[0]}, "
                                f"the camera {view.width}x{view.height}")
    initial = dict(initial or {})
    positions = {}
    for key, source in lights.items():
        if source is None:
            continue
        start = source.start_direction(camera)  # None: frontal, or a point light's held position
        if start is not None:
            initial.setdefault(f"{key}.light_angles", light_angles(camera.rotation @ start))
        elif source.held_position is not None:
            positions[key] = source.held_position
    fixed = options.fixed
    if not options.ambient:  # no light but the photographs' own: each directed light's ambient held at zero
        held = [f"{key}.ambient" for key in images if directed(key)]
        initial.update(dict.fromkeys(held, 0.0))
        fixed = fixed + tuple(held)
    fitter = Fitter(model, camera, images, targets, weights, schedule, np.random.default_rng(options.seed),
                    light_world=positions, fit_focal=options.fit_focal and not views,
                    initial=initial, fixed=fixed, distances=distances,
                    facing_min=options.facing_min, views=views)
    greyscale = bool(used) and all(getattr(image, "greyscale", False) for image in used.values())
    fitter.energy.greyscale = greyscale  # read by Energy._shade
    own_bar = progress is True
    total = schedule.pose_iterations + (sum(int(level[0]) for level in schedule.levels) if images else 0)
    bar = (progress_bar(total=total, desc=f"fit {measurement.name}", unit="it", leave=False, detail=True)
           if own_bar else (progress or None))
    try:
        theta, terms, history, iterations, status, message = fitter.run(
            bar, lr=options.lr, visibility_interval=options.visibility_interval)
    finally:
        if own_bar:
            bar.close()
    if companions and "image_rms" in terms and np.all(np.isfinite(theta)):
        sums = fitter.energy.image_sums(theta)
        terms.update({f"image_rms.{key}": _rms(*sums[key]) for key in sums})
        own = [sums[key] for key in (POINT, DIFFUSE) if key in sums]
        terms["image_rms_measurement"] = _rms(sum(n for n, _ in own), sum(d for _, d in own))
    fit = fitter.result(theta, measurement.name, terms, history, iterations, greyscale)
    if status is None:
        limit = (feature_limit(fit.vertices_camera, model, float(fit.focal_length[1]), options.max_feature_error,
                               options.feature_noise) if np.all(np.isfinite(theta)) else math.inf)
        status, message = _status(theta, terms, history, limit, options.max_image_rms)
    return replace(fit, status=status, message=message, seconds=time.perf_counter() - t0,
                   estimated=estimated_quantities(camera, distances, options.fit_focal,
                                                  1 + len({id(view[0]) for view in views.values()})))


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
        return NOT_CONVERGED, (f"the feature points fit ({terms['feature_rms_px']:.1f} px RMS, "
                               f"limit {limit_px:.1f} px) "
                               f"but the rendered face does not match the photograph: image residual {image_rms:.3f} "
                               f"RMS, limit {max_image_rms:g} (of the photograph's 99th percentile)")
    start = history[0]["feature_rms_px"] if history else math.inf
    # feature points that end farther than they started, or far off: the fit ran away;
    # still approaching them: it needs more iterations
    ran_away = terms["feature_rms_px"] > min(start, 4 * limit_px)
    return (DIVERGED if ran_away else NOT_CONVERGED,
            f"feature points end {terms['feature_rms_px']:.1f} px RMS from their targets "
            f"(limit {limit_px:.1f} px; {start:.1f} px at the start)"
            + ("" if ran_away else ": more iterations may help"))


def fit_shape(capture, model="builtin", measurements=None, out=None,
              iterations: float | ShapeSchedule | None = None, progress: bool = True, *,
              options: ShapeOptions | None = None, shape_modes: int | None = None,
              one_identity: bool = True) -> list[ShapeFit]:
    """Fit the morphable model to every pose of a capture, independently (paper sec. 4.2).

    Measurements sharing a ``pose`` label (one pose of the subject photographed
    under several lights) share one fit: the pose is fitted once, with the feature
    points of its measurement whose light is nearest the camera's axis (with its
    diffuse companion where present), on that photograph and the pose's others
    whose lights the capture gives, together (:func:`fit_measurement`'s
    ``companions``, :data:`~mifaces.shape.poses.JOINT_PHOTOGRAPHS` at most), each with its own light;
    the others get that fit's geometry and the light fitted for them
    (:attr:`ShapeFit.shared_with`), a photograph under an unknown light its light
    fitted on that face (:func:`fit_light`); a labelled measurement whose feature points
    disagree with that one's (by more than :data:`~mifaces.shape.poses.POSE_AGREEMENT` of their
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
        Show progress (:func:`mifaces.runtime.progress.progress`).
    options : ShapeOptions, optional
        How every fit runs and when it has converged, as :func:`fit_measurement` takes them: the
        diffuse-light image used or not (``use_diffuse``), the focal length fitted or not
        (``fit_focal``), the seed, the convergence limits of the feature points (``max_feature_error``,
        ``feature_noise``: :func:`feature_limit`) and of the photometric residual
        (``max_image_rms``), the cut of E_I (``facing_min``), the :class:`Weights` and the parameter
        blocks held (``fixed``). Default ``ShapeOptions()``. Its ``ambient`` is the capture's
        (``Capture.ambient_light``), whatever it says.
    shape_modes : int, optional
        Identity modes fitted, the leading ones (default: the model's
        :attr:`~mifaces.model.MorphableModel.fit_shape_modes`, 50 of the built-in's 100).
        ``shapes.json`` records the number.
    one_identity : bool
        One face for all photographs: after each pose is fitted on its own, the identity
        coefficients of the converged fits are averaged (:func:`~mifaces.shape.poses.one_face`) and
        every pose is fitted again, briefly (:data:`SECOND_PASS` of the schedule), from its first fit
        with that identity held: its own pose, expression and lighting. Without it, each pose keeps its own identity.

    Returns
    -------
    list of ShapeFit
        One per measurement, in the order of the capture's measurements.

    Raises
    ------
    ShapeFitError
        For an unknown measurement name, or missing or misnamed feature points
        (checked for all measurements before any fitting).

    Examples
    --------
    The built-in face fitted to each photograph of a capture (``capture_folder``, one
    :func:`mifaces.simulate` wrote here), on a short schedule:

    >>> from mifaces.shape import fit_shape, shapes_in_world
    >>> fits = fit_shape(capture_folder, iterations=0.2, progress=False)
    >>> [fit.measurement for fit in fits]
    ['m00', 'm01']
    >>> fits[0].vertices_camera.shape[1], fits[0].status in ("converged", "not_converged")
    (3, True)
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
    options = replace(options or ShapeOptions(), ambient=capture.ambient_light)
    for leader, *others in groups:
        light = capture.light(leader.light) if leader.light else None
        fit = fit_measurement(leader, capture.camera_of(leader), model, light=light, schedule=schedule,
                              options=options, initial=None if initial_color is None else {"color": initial_color},
                              distances=capture.distances, companions=companions(capture, others, leader),
                              progress=progress)
        if leader.name == reference and fit.converged:
            initial_color = fit.color
        leaders[leader.name] = fit
        bar.update(1 + len(others))
        bar.set_postfix(last=leader.name, status=fit.status)
    identity = one_face(list(leaders.values())) if joint else None
    if identity is not None:  # every photograph again, its pose, expression and lighting on the one face
        second, held = schedule.scaled_by(SECOND_PASS), replace(options, fixed=options.fixed + ("shape",))
        for leader, *others in groups:
            first = leaders[leader.name]
            light = capture.light(leader.light) if leader.light else None
            together = companions(capture, others, leader)
            fit = fit_measurement(leader, capture.camera_of(leader), model, light=light, schedule=second,
                                  options=held,
                                  initial=dict(_start_from(first, model, leader, together), shape=identity),
                                  distances=capture.distances, companions=together, progress=progress)
            leaders[leader.name] = replace(fit, seconds=fit.seconds + first.seconds,
                                           message=(fit.message + "; " if fit.message else "")
                                           + f"identity shared by {len(groups)} poses")
            bar.update(1)
            bar.set_postfix(last=leader.name, status=fit.status)
    for leader, *others in groups:
        fit = leaders[leader.name]
        keys = {m.name: lit_key(i) for i, (m, *_) in enumerate(companions(capture, others, leader), start=1)}
        for fit_m in [own_lights(fit)] + [_member_fit(fit, m, capture, model, schedule, options, progress,
                                                      keys.get(m.name)) for m in others]:
            fits[fit_m.measurement] = fit_m
            if out is not None:
                write_fit(out, fit_m, model)
    bar.close()
    result = [fits[m.name] for m in todo]
    if out is not None:
        write_index(out, capture, model, result, reference, model_source=source)
    return result


def _member_fit(fit: ShapeFit, measurement, capture, model, schedule: ShapeSchedule, options: ShapeOptions,
                progress, key: str | None = None) -> ShapeFit:
    """The fit of a pose group's ``measurement`` on its leader's ``fit``: with the light fitted for it
    where it was the joint fit's photograph ``key``; its own light fitted on the shared face where the
    capture does not know it (:func:`fit_light`, with ``options`` and ``progress``); else
    :func:`~mifaces.shape.poses.shared_fit`."""
    light = capture.light(measurement.light) if measurement.light else None
    leader, own = capture.camera_of(fit.measurement), capture.camera_of(measurement)
    if own is not leader:  # another camera of the shot: the face seen from there
        return seen_by(shared_fit(fit, measurement, capture, key), leader, own)
    if key is not None or light is None or not light.fitted_on_face or not fit.converged:
        return shared_fit(fit, measurement, capture, key)
    return fit_light(fit, measurement, own, model, light, schedule, options=options, distances=capture.distances,
                     progress=progress)


def fit_light(fit: ShapeFit, measurement, camera, model, light, schedule: ShapeSchedule | None = None, *,
              options: ShapeOptions | None = None, distances=(), progress=True) -> ShapeFit:
    """The lighting of ``measurement``'s photograph on the face of ``fit`` (same pose): the
    directed light's angles, colour, ambient, specular strength, gain and offset of the
    photograph fitted by the shape fit's energy and optimiser (:func:`fit_measurement`), with
    every block of the geometry and texture held (:data:`GEOMETRY_BLOCKS`) at ``fit``'s values,
    the photograph alone (not its companion). The light starts from ``light.guess`` (world frame)
    where stated, else frontal; the cast shadows follow the light as it moves (ray cast on the
    held face every ``visibility_interval`` steps). ``options`` (but its ``use_diffuse`` and
    ``fixed``), ``distances`` and ``progress`` as :func:`fit_measurement` takes them.

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
    result = fit_measurement(measurement, camera, model, light, schedule=schedule,
                             options=replace(options or ShapeOptions(), use_diffuse=False, fixed=fixed),
                             initial=start, distances=distances, progress=progress)
    light_fit = f"light fitted on the face of {fit.measurement!r} (same pose): {result.status}" + \
        (f" ({result.message})" if result.message else "")
    return replace(fit, measurement=measurement.name, light=result.light, loss=result.loss,
                   iterations=result.iterations, seconds=result.seconds, history=result.history,
                   shared_with=fit.measurement, message=light_fit + (f"; {fit.message}" if fit.message else ""))


def _start_from(fit: ShapeFit, model, measurement, companions=()) -> dict:
    """Start values (:func:`fit_measurement`'s ``initial``) that continue ``fit`` of ``measurement``
    (and its ``companions``): its pose, expression, albedo or colour, lighting (gain and offset back
    in the normalised photograph's units the fit works in: :func:`~mifaces.shape.targets.normalised`)."""
    photographs = {POINT: measurement.image, DIFFUSE: measurement.diffuse}
    photographs.update({lit_key(i): m.image for i, (m, *_) in enumerate(companions, start=1)})
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
