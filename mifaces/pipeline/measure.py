"""The whole pipeline, end to end: photographs → fitted shapes → reflectance
samples → fitted BRDFs → renders and a report.

:func:`measure` is the main job of ``mifaces measure``: given a capture (or,
without one, a capture it simulates from the built-in face with ground
truth), it fits the face model to every photograph (or takes the
simulator's ground-truth shapes), fits each BRDF model per region, and
writes a report: ``report.md`` and ``report.json`` with every region's
parameters, losses, sample counts and times, each model's relative RMSE on
the first photograph (``training_rmse``: a photograph the fit saw), and
``report.png``, per model the first photograph, the fitted face rendered in
its place, their difference, and the fitted face under a novel light;
``report_uncertainty.png``, every region's parameters with their 95 %
intervals (``models.<model>.uncertainty``, docs/uncertainty.md).

For a simulated capture (with ground truth) the report also separates the
models by what the fit never saw (:mod:`mifaces.validation.validator`):
``models.<model>.validation`` holds ``brdf_rmse`` per region,
``albedo_rmse``, ``heldout_rmse`` and ``environment_rmse``, ``ranking``
orders the models by the last two, ``report.png`` shows the true face and
the fits side by side in a novel pose under the held-out lights and the
environments, and the training panels move to ``report_training.png``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..brdf import NAMES
from ..capture import Capture, load_capture, read_ground_truth
from ..export import export_face
from ..io.atomic import write_json
from ..render.face_pixels import face_pixels
from ..shape.io import load_geometry
from ..light_estimation.unknown import (LIGHTS_PICTURE, RELATIVE_NOTE, as_given, balance_intensities, check_estimable,
                                        estimate_environments, estimate_lights, lights_document, refit_lights,
                                        write_lights, write_lights_picture)
from ..model import load_model
from ..options.measure import GEOMETRIES, MeasureOptions
from .. import brdf as brdf_models
from ..reflectance import BRDFEstimate, FitOptions, capture_samples, write_estimate
from ..reflectance.fitting import fit_samples
from ..reflectance.sample_stage import SampleSet, take_samples, with_balanced_lights, without_bounced_light
from ..refine import refine_estimate
from ..refine.shape import ShapeRefineSchedule
from ..refine.shape_lit import refine_lit, refined_fits
from ..lights.emitters import light_record
from ..lights.light import estimated_lights
from ..render import FaceScene
from ..report.measurement import (ranking, ties, write_fit_picture, write_markdown, write_uncertainty_picture,
                                  write_validation_picture)
from ..report.html import write_html
from ..shape import fit_shape, shapes_in_world
from ..shape.io import model_source, write_fit, write_index
from ..shape.views import depth_uncertainty, reprojection_errors
from ..validation.shape_errors import capture_shape_errors
from ..studio import simulate
from ..validation.truth_errors import ground_truth_errors
from ..validation.held_out import novel_light
from ..validation.validator import Validator, relative_rmse

#: Models ``measure`` fits unless told otherwise.
MODELS = NAMES
#: The fitted face the report shows in 3D (the best model's, or the first's, as glTF).
FACE_GLB = "face.glb"
#: Folders of the result: the fitted faces, and those refined by ``refine_shape`` (same layout).
SHAPES, REFINED_SHAPES = "shapes", "shapes_refined"


#: Said where a capture lit by an environment map is measured without the refinement.
MAP_WITHOUT_REFINE = ("photographs lit by an environment map are read as lit from one direction per texel: right for "
                      "the albedo, biased for the glossy parameters (skin's specular far too weak); measure with "
                      "refine=True (--refine), which renders the map itself (docs/unknown_lights.md)")


class NoUsableShapeError(ValueError):
    """No photograph of a capture got a shape fit that the next stages can use."""


@dataclass(frozen=True)
class FittedModel:
    """One BRDF model fitted by :func:`measure`: its estimate and its row of
    the report's picture (:func:`mifaces.report.measurement.write_fit_picture`).

    Attributes
    ----------
    model : str
        The BRDF model's name.
    photo : (H, W, 3) array
        The first photograph, linear.
    rendered : (H, W, 3) array
        The fitted face rendered in its place, under its light.
    relit : (H, W, 3) array
        The fitted face under the novel light (:func:`novel_light`).
    estimate : BRDFEstimate
        The fit (refined where asked), which the validation measures.
    """

    model: str
    photo: np.ndarray
    rendered: np.ndarray
    relit: np.ndarray
    estimate: BRDFEstimate


def measure(out, capture=None, options: MeasureOptions | FitOptions | None = None, *, progress: bool = True,
            **keywords) -> dict:
    """Measure the reflectance of the face in ``capture``, writing everything to ``out``.

    The stages hand their results to each other in memory: the face model is
    loaded once, the fitted shapes go straight to the reflectance samples, the
    samples (with their region labels) to every BRDF model's fit. Files are
    written for the user, never read back.

    Parameters
    ----------
    out : path
        Output folder: ``capture/`` (when simulated), ``shapes/``,
        ``brdf/<model>/``, ``report.{md,json,png}`` (and
        ``report_training.png`` for a capture with ground truth),
        ``report.html`` (:mod:`mifaces.report.html`) with ``face.glb``: the
        face of the model best under the held-out lights (else the first model),
        in the shape fitted to the first photograph (the mean shape with
        ``geometry='ground-truth'``). For a capture with unknown lights, also
        ``lights.json`` and ``report_lights.png`` (:mod:`mifaces.light_estimation.unknown`).
    capture : path or Capture, optional
        A capture folder; without one, the default capture of
        :func:`mifaces.studio.simulate` (built-in face, Cook-Torrance
        ground truth) is simulated first into ``out/capture``.
    options : MeasureOptions or FitOptions, optional
        How to measure (:class:`mifaces.options.measure.MeasureOptions`: the BRDF models, the
        geometry, the face model, the fit's :class:`~mifaces.reflectance.FitOptions`, the
        refinements, the renders' spp); a :class:`~mifaces.reflectance.FitOptions` is the fit's,
        the rest as default. Recorded whole in ``report.json``'s ``options``: ``requested``, and
        ``effective`` as the fits' plan resolved them (:meth:`MeasureOptions.resolved
        <mifaces.options.measure.MeasureOptions.resolved>`; each model's in its entry's
        ``fit_options``).
    progress : bool
        Progress bars and lines.
    **keywords
        Fields of :class:`~mifaces.options.measure.MeasureOptions` as keywords, applied over
        ``options`` (``models=("phong",)``, ``geometry=``, ``refine=``, ``refine_shape=True`` or a
        :class:`~mifaces.refine.shape.ShapeRefineSchedule`, ``shape_iterations=``, ``spp=``,
        ``face_model=``), as this function took them before the options value; and, deprecated
        with a :class:`DeprecationWarning`, :class:`~mifaces.reflectance.FitOptions`' fields
        (``resolution=``, ``normals=``, ...). :meth:`MeasureOptions.of
        <mifaces.options.measure.MeasureOptions.of>` makes the one value.

    Returns
    -------
    dict
        The report (also written as ``report.json``).

    Notes
    -----
    Lights the capture does not know (``"unknown": true``) are estimated with the faces: the shape
    fit fits each photograph's light (:func:`mifaces.shape.fit.fit_light`),
    :func:`mifaces.light_estimation.unknown.estimate_lights` makes them the capture's directional lights and
    :func:`~mifaces.light_estimation.unknown.balance_intensities` sets their intensities from the reflectance
    samples; every later stage reads them as given (``docs/unknown_lights.md``). Reflectance is
    then relative (``brdf.json``'s ``lighting``).

    Raises
    ------
    NoUsableShapeError
        No shape fit converged, so there is no geometry to sample reflectance on.
    UnknownLightError
        For an unknown light of a kind not estimated (an environment map), before any fitting,
        or one none of whose photographs got a converged shape fit.
    ValueError
        For unknown lights with ``geometry='ground-truth'`` (they are estimated on fitted faces).

    Examples
    --------
    The main job on a small capture (``capture_folder``, one :func:`mifaces.simulate` wrote here),
    one BRDF model on the simulator's true shapes, into ``out / "measure"``:

    >>> from mifaces import MeasureOptions, measure
    >>> from mifaces.reflectance import FitOptions
    >>> options = MeasureOptions(models=("phong",), geometry="ground-truth", spp=2, fit=FitOptions(resolution=32))
    >>> report = measure(out / "measure", capture_folder, options, progress=False)
    >>> list(report["models"]), sorted(p.name for p in (out / "measure").glob("report.*"))
    (['phong'], ['report.html', 'report.json', 'report.md', 'report.png'])
    >>> sorted(report["models"]["phong"]["validation"])[:3]  # a simulated capture is judged against its truth
    ['albedo_rmse', 'brdf_rmse', 'environment_rmse']
    >>> MeasureOptions.from_record(report["options"]["requested"]) == options  # recorded whole
    True
    """
    t0 = time.perf_counter()
    out = Path(out)
    options = MeasureOptions.of(options, keywords)
    resolution, geometry, models = options.fit.resolution, options.geometry, options.models
    timings = {}
    capture = _capture(out, capture, timings, progress)
    report = {"capture": str(capture.path), "measurements": len(capture.measurements), "geometry": geometry,
              "resolution": resolution,
              "options": {"requested": options.to_record(), "effective": options.resolved().to_record()},
              "models": {}}
    unknown = bool(capture.unknown_lights)
    if unknown:
        check_estimable(capture)
        if geometry != "fitted":
            raise ValueError(f"lights {[l.name for l in capture.unknown_lights]} are unknown: they are estimated with "
                             "the fitted faces, so geometry must be 'fitted'")
    face, shapes, fits = _geometry(out, capture, options, options.face_model, report, timings, progress)
    if unknown:  # every later stage reads the estimated lights as given ones
        t = time.perf_counter()
        estimated = estimate_lights(capture, fits)
        if any(light.fitted_on_face for light in capture.lights):
            # one round of alternation: each pose's face fitted to all its photographs under the first
            # estimates, then each light fitted again on that face
            first = timings["fit_shape"]
            face, shapes, fits = _geometry(out, as_given(estimated), options, face, report, timings, progress)
            timings["fit_shape"], timings["fit_shape_alternation"] = first, timings["fit_shape"]
            estimated = estimate_lights(capture, refit_lights(capture, fits, face))
        capture = estimate_environments(estimated, shapes, face, progress=progress)
        timings["estimate_lights"] = time.perf_counter() - t
    t = time.perf_counter()
    samples = None
    if unknown:  # the intensities that give the face one albedo under every estimated light
        samples = capture_samples(capture, shapes, face, resolution, progress=progress)
        balanced = balance_intensities(capture, samples)
        if balanced is not capture:
            capture, samples = balanced, None
    taken = take_samples(capture, shapes, face, options.fit, samples=samples, progress=progress)
    timings["reflectance_samples"] = time.perf_counter() - t
    if not options.refine and any(light.radiance_map is not None for light in capture.lights):
        report["environment_note"] = MAP_WITHOUT_REFINE
        warnings.warn(MAP_WITHOUT_REFINE, stacklevel=2)
    if unknown:
        report["lights"] = {"file": write_lights(out, capture).name, "picture": LIGHTS_PICTURE, "note": RELATIVE_NOTE,
                            "estimates": [e for e in lights_document(capture)["lights"] if e["estimated"]]}
        write_lights_picture(out / LIGHTS_PICTURE, capture)
    if options.refine_shape is not None:
        taken = _refine_shapes(out, taken, fits, models[0], report, timings, progress, options.refine_shape)
        shapes = taken.shapes
    first = next(m for m in capture.measurements if m.name in shapes)
    novel = novel_light(capture, np.asarray(shapes[first.name]).mean(axis=0))
    scene = FaceScene(face, shapes[first.name])  # the first photograph's face, built once for every model
    validator = None
    if read_ground_truth(capture) is not None:
        t = time.perf_counter()
        validator = Validator(capture, face, shapes[first.name], first.name)
        timings["validation_truth"] = time.perf_counter() - t
        report["validation"] = validator.summary
    fitted, validation_images = [], {}
    if options.fit.interreflection:  # the bounced light, rendered once with the first model's fit, for every model
        t = time.perf_counter()
        taken = without_bounced_light(taken, brdf_models.model(models[0], **options.fit.brdf_options()), options.fit,
                                      progress=progress)
        timings["interreflection"] = time.perf_counter() - t
    if options.fit.balance_lights:  # the given lights' balance, found once with the first model's fit, for every model
        t = time.perf_counter()
        taken = with_balanced_lights(taken, brdf_models.model(models[0], **options.fit.brdf_options()), options.fit)
        report["light_balance"] = taken.light_balance
        for key in ("failed_lights", "light_balance_refused"):  # lamps that did not fire; a balance not applied
            if taken.capture.metadata.get(key):
                report[key] = taken.capture.metadata[key]
        timings["light_balance"] = time.perf_counter() - t
    for model in models:
        entry, result = _fit_model(out, taken, model, scene, first, novel, timings, progress, options)
        if validator is not None:
            t = time.perf_counter()
            entry["validation"], validation_images[model] = validator.validate(result.estimate)
            timings[f"validation_{model}"] = time.perf_counter() - t
        report["models"][model] = entry
        fitted.append(result)
    timings["total"] = time.perf_counter() - t0
    report["seconds"] = timings
    report["novel_light"] = light_record(novel)
    if validator is not None:
        report["ranking"] = ranking(report["models"])
        report["ties"] = ties(report["models"], report["ranking"])
    write_json(out / "report.json", report)
    if validator is not None:
        write_validation_picture(out / "report.png", validator.truth, validation_images, report)
    write_fit_picture(out / ("report.png" if validator is None else "report_training.png"), fitted, first.name)
    write_uncertainty_picture(out / "report_uncertainty.png", report)
    write_markdown(out / "report.md", report, first.name)
    best = report.get("ranking", {}).get("heldout_rmse", list(models))[0]
    estimate = next(f.estimate for f in fitted if f.model == best)  # exported from memory, not read back
    glb = export_face(estimate, out / FACE_GLB, measurement=first.name if geometry == "fitted" else None,
                      shapes=fits, face_model=face, source=str(out / "brdf" / best))[-1]
    write_html(out / "report.html", report, glb, best)
    return report


def _capture(out: Path, capture, timings: dict, progress: bool) -> Capture:
    """The capture to measure: loaded, or simulated into ``out/capture`` when none is given."""
    if capture is None:
        simulated = simulate(out / "capture", progress=progress, force=True, cache=True)  # measure's own folder
        timings["simulate"] = simulated.seconds
        capture = out / "capture"
    return load_capture(capture)


def _geometry(out: Path, capture: Capture, options: MeasureOptions, face_model, report: dict, timings: dict,
              progress: bool):
    """The face model, per-measurement world vertices and the shape fits: fitted (and written to
    ``out/shapes`` for the user) or the simulator's ground truth (no fits: None)."""
    if options.geometry == "ground-truth":
        return (*load_geometry(capture, "ground-truth"), None)
    face = load_model(face_model)  # a loaded model is taken as it is
    t = time.perf_counter()
    fits = fit_shape(capture, face, out=out / SHAPES, iterations=options.shape_iterations, progress=progress)
    timings["fit_shape"] = time.perf_counter() - t
    report["shapes"] = {f.measurement: {"status": f.status, "seconds": f.seconds,
                                        "feature_rms_px": f.loss.get("feature_rms_px"),
                                        "image_rms": f.loss.get("image_rms"),
                                        "image_rms_measurement": f.loss.get("image_rms_measurement"),
                                        "shape_modes": len(f.coefficients)} for f in fits}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the failed fits are named below
        shapes = shapes_in_world(fits, capture)
    views = reprojection_errors(capture, shapes, face)
    for name, error in views["photographs"].items():
        report["shapes"][name]["reprojection_px"] = error
    report["cameras"] = views["cameras"]
    report["depth"] = depth_uncertainty(capture, shapes, face)
    fitted_modes = max((len(f.coefficients) for f in fits), default=0)
    report["face_model"] = {"name": face.name, "model_shape_modes": face.shape_dim, "fit_shape_modes": fitted_modes}
    truth = read_ground_truth(capture)
    if truth is not None:
        report["face_model"]["truth_shape_modes"] = len(truth.coefficients.get("shape", ()))
        report["face_model"]["truth_detail"] = bool(truth.description.get("detail", False))
    if shapes and truth is not None:  # a simulated capture: how far off each fit lies
        _, true_shapes = load_geometry(capture, "ground-truth")
        errors = capture_shape_errors(face, shapes, true_shapes, capture.camera)
        for name, entry in report["shapes"].items():
            if name in errors:
                entry["errors"] = errors[name]
        report["shape_errors"] = errors.get("summary")
    if not shapes:
        detail = "; ".join(f"{f.measurement}: {f.status}" + (f" ({f.message})" if f.message else "")
                           for f in fits)
        raise NoUsableShapeError(f"no shape fit converged, so there is no face geometry to measure reflectance on: "
                                 f"{detail}. The fits are in {out / SHAPES}.")
    return face, shapes, fits


def _refine_shapes(out: Path, taken: SampleSet, fits, model: str, report: dict, timings: dict, progress: bool,
                   schedule: ShapeRefineSchedule | None = None) -> SampleSet:
    """The samples ``taken`` on the faces refined by differentiable rendering (kept only where the held-out
    losses fall); ``report['shape_refinement']`` says what happened, and on a simulated capture
    ``report['shape_errors_refined']`` how far the refined faces lie from the truth. Refined fitted
    faces are written to ``out/shapes_refined`` (:data:`REFINED_SHAPES`, the layout of
    ``out/shapes``), the geometry the BRDFs are then fitted on."""
    t = time.perf_counter()
    capture, face = taken.capture, taken.face
    result = refine_lit(capture, taken.shapes, face, taken.samples, model, taken.resolution, schedule=schedule,
                        progress=progress)
    report["shape_refinement"] = {"accepted": result.accepted, "reason": result.reason, "model": model,
                                  "seconds": time.perf_counter() - t,
                                  **{k: v for k, v in result.record.items() if k not in ("loss_per_iteration",)}}
    timings["refine_shape"] = time.perf_counter() - t
    if not result.accepted:
        return taken
    if read_ground_truth(capture) is not None:
        _, true_shapes = load_geometry(capture, "ground-truth")
        report["shape_errors_refined"] = capture_shape_errors(face, result.shapes, true_shapes,
                                                              capture.camera).get("summary")
    if fits is not None:
        refined = refined_fits(fits, result, capture)
        for fit in refined:
            write_fit(out / REFINED_SHAPES, fit, face)
        write_index(out / REFINED_SHAPES, capture, face, refined, model_source=model_source(face))
        report["shape_refinement"]["shapes"] = REFINED_SHAPES
    taken = taken.on_shapes(result.shapes, progress=progress)
    timings["reflectance_samples"] += taken.seconds
    return taken


def _fit_model(out: Path, taken: SampleSet, model: str, scene: FaceScene, first, novel, timings: dict, progress: bool,
               options: MeasureOptions) -> tuple[dict, FittedModel]:
    """Fit one BRDF model, write it, render it in the first photograph's place
    and under the novel light; the report's entry, and the fitted model."""
    t = time.perf_counter()
    capture, shapes, face = taken.capture, taken.shapes, taken.face
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        brdf = brdf_models.model(model, **options.fit.brdf_options())
        estimate = fit_samples(with_balanced_lights(without_bounced_light(taken, brdf, options.fit, progress=progress),
                                                    brdf, options.fit), brdf, options.fit,
                               progress=progress)
        if options.refine:
            estimate = refine_estimate(estimate, capture, shapes, face, seed=options.fit.seed, progress=progress)
    if estimated_lights(capture.lights):
        estimate = replace(estimate, lighting={"lights": "estimated", "reflectance": "relative", "note": RELATIVE_NOTE})
    light = capture.light(first.light)
    camera = capture.camera_of(first)
    write_estimate(estimate, out / "brdf" / model, scene, camera, light, force=True)  # measure's own folder
    lamp = estimate.fitted_light(light)
    timings[f"fit_brdf_{model}"] = time.perf_counter() - t
    entry = estimate.to_json()
    entry["warnings"] = [str(w.message) for w in caught]
    entry["ground_truth"] = ground_truth_errors(estimate, capture)
    brdf, albedo = estimate.to_json(), estimate.albedo.albedo
    maps = {"normals": estimate.normal_texture(), "specular": estimate.specular_texture()}
    rendered = scene.render(brdf, albedo, camera, lamp, spp=options.spp, **maps)
    relit = scene.render(brdf, albedo, camera, novel, spp=options.spp, **maps)
    photo = first.image.pixels
    on_face = face_pixels(scene, camera)  # the fitted face's pixels, whatever the background shows
    entry["training_rmse"] = relative_rmse(rendered, photo, on_face)
    return entry, FittedModel(model, photo, rendered, relit, estimate)
