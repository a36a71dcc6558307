"""The shape refinement as ``mifaces measure`` and ``mifaces fit-shape`` run it
(``--refine-shape``): the fitted faces lit by a quick per-region fit of a BRDF
made for the purpose, refined by :func:`~mifaces.refine.shape.refine_shape`, and
the shape fits given the refined vertices where the refinement was kept."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from ..reflectance import FitOptions
from ..reflectance.estimate import fit_brdf
from ..reflectance.resampling import capture_samples
from ..shape import shapes_in_world
from .shape import ShapeRefinement, ShapeRefineSchedule, refine_shape
from .shape_choice import judged_photographs


#: The BRDF model that lights the faces when shapes are refined without a fitted reflectance
#: (``mifaces fit-shape --refine-shape``): the cheapest of the four to fit.
FIT_SHAPE_BRDF = "phong"


def refine_lit(capture, shapes: dict, face_model, samples, brdf: str = FIT_SHAPE_BRDF, resolution: int = 256,
               schedule: ShapeRefineSchedule | None = None, progress: bool = True) -> ShapeRefinement:
    """:func:`refine_shape` of ``shapes``, lit by a per-region fit of ``brdf`` (texture resolution
    ``resolution``): the refinement when no fitted reflectance is at hand yet (``measure`` and
    ``fit-shape`` with ``--refine-shape``). ``samples``: the reflectance samples on ``shapes``. The
    judged photographs (:func:`judged_photographs`) stay out of that fit, and the refined faces are
    judged lit by the same fit made again on them (``refit``): as the pipeline goes on to use them."""
    schedule = schedule or ShapeRefineSchedule()
    names = [m.name for m in capture.measurements if m.name in shapes]
    judged = judged_photographs(names, schedule.judged)
    fitted = {name: shapes[name] for name in names if name not in judged}

    def lit(faces, given=None):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the quick fit's warnings are the final fits' too
            if given is None:
                given = capture_samples(capture, faces, face_model, resolution, progress=False)
            return fit_brdf(capture, brdf, faces, face_model=face_model, samples=given, progress=False,
                            options=FitOptions(resolution=resolution, uncertainty=None))  # lights, not reports

    estimate = lit(fitted, None if judged else samples)
    return refine_shape(capture, shapes, face_model, estimate, schedule, refit=lit, progress=progress)


def refine_fits(capture, fits: list, face_model, resolution: int = 256, brdf: str = FIT_SHAPE_BRDF,
                schedule: ShapeRefineSchedule | None = None, progress: bool = True) -> tuple[list, ShapeRefinement]:
    """Shape fits (:func:`mifaces.shape.fit.fit_shape`) refined by :func:`refine_shape`, for
    ``mifaces fit-shape --refine-shape``: a quick per-region fit of ``brdf`` on the fitted faces
    (texture resolution ``resolution``) lights them; the converged fits get the refined vertices where
    the refinement was accepted (else they come back unchanged). Returns the fits and the refinement."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        shapes = shapes_in_world(fits, capture)
    samples = capture_samples(capture, shapes, face_model, resolution, progress=False)
    result = refine_lit(capture, shapes, face_model, samples, brdf, resolution, schedule, progress=progress)
    return refined_fits(fits, result, capture), result


def refined_fits(fits: list, result: ShapeRefinement, capture) -> list:
    """``fits`` with the refined vertices of ``result`` where it was accepted (converged fits only;
    the others, and all of them for a refinement not accepted, come back unchanged), each in the frame
    of its photograph's camera (``capture.camera_of``)."""
    if not result.accepted:
        return list(fits)
    out = []
    for fit in fits:
        world = result.shapes.get(fit.measurement)
        if world is None or not fit.converged:
            out.append(fit)
            continue
        out.append(replace(fit, vertices_world=np.asarray(world, np.float32),
                           vertices_camera=capture.camera_of(fit.measurement).to_camera(
                               np.asarray(world, np.float64)).astype(np.float32),
                           message=(fit.message + "; " if fit.message else "") + "refined by differentiable rendering"))
    return out


__all__ = ["FIT_SHAPE_BRDF", "refine_lit", "refine_fits", "refined_fits"]
