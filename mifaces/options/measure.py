"""How :func:`mifaces.measure` runs: :class:`MeasureOptions`, one value from the command line (or
a script) to the pipeline and to :mod:`mifaces.pipeline.batch`'s workers, recorded whole in
``report.json``."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

from ..brdf import MODELS as BRDF_CLASSES, NAMES
from ..refine.shape_schedule import ShapeRefineSchedule
from ..reflectance.options import FitOptions, fit_options
from .fields import check, from_record, option, record

#: Where the face geometry comes from.
GEOMETRIES = ("fitted", "ground-truth")


@dataclass(frozen=True)
class MeasureOptions:
    """Options of :func:`mifaces.measure` (and of every capture of :func:`mifaces.pipeline.batch.measure_batch`).

    Validated on construction: an unknown model or geometry, a number out of its range, or
    settings that contradict each other raise a ``ValueError`` naming the field.

    Attributes
    ----------
    models : tuple of str
        BRDF models to fit (:data:`mifaces.brdf.NAMES`; a list is taken as a tuple).
    geometry : {'fitted', 'ground-truth'}
        Fit the face model to every photograph (``mifaces fit-shape``), or use a simulated
        capture's true shapes.
    face_model : str or MorphableModel
        The face model fitted to the photographs (``geometry='fitted'``): ``'builtin'`` or a model
        file (:func:`mifaces.load_model`; a path is taken as its string), or a loaded model.
    shape_iterations : float or None
        Scale of the shape fitter's iteration schedule (None: the schedule as it is).
    fit : FitOptions
        How every BRDF model is fitted (:class:`mifaces.reflectance.FitOptions`).
    refine : bool
        Refine each fit by differentiable rendering (:func:`mifaces.refine.refine_estimate`).
    refine_shape : ShapeRefineSchedule or None
        Refine the fitted faces beyond the model's span by differentiable rendering
        (:func:`mifaces.refine.shape.refine_shape`) with this schedule (True: the default one; None
        or False: not): a first fit of the first of ``models`` on the model-fitted shapes lights the
        faces, one displacement along the normals is fitted against the photographs, and it is kept
        only if it lowers the loss on pixels it did not fit (and, with
        :attr:`~mifaces.refine.shape.ShapeRefineSchedule.judged`, on photographs it left out); the
        samples are then taken on the kept faces. Off by default: it costs minutes, and on the
        default capture the faces it keeps relight worse (``docs/refine_shape.md``).
    spp : int
        Samples per pixel of the report's renders.
    """

    models: tuple = option(NAMES, choices=NAMES, flag="brdf",
                           help="BRDF model(s) to fit, repeatable (default: all four).")
    geometry: str = option("fitted", choices=GEOMETRIES,
                           help="Fit the face model to each photograph, or use a simulated capture's true shapes.")
    face_model: str = option("builtin", help="Face model fitted to the photographs: 'builtin' or a model file "
                                             "(see mifaces.load_model).")
    shape_iterations: float | None = option(None, bounds=(0.01, None), help="Scale of the shape fit's iteration "
                                                                            "schedule (e.g. 0.25 for a quick fit).")
    fit: FitOptions = option(factory=FitOptions, nested=FitOptions, help="How each BRDF model is fitted.")
    refine: bool = option(False, help="Refine each fit by differentiable rendering against the photographs.")
    refine_shape: ShapeRefineSchedule | None = option(
        None, nested=ShapeRefineSchedule, switch=True,
        help="Refine the fitted faces beyond the model by differentiable rendering, lit by a quick Phong fit "
             "(minutes; kept only if it lowers the loss on pixels it did not fit: docs/refine_shape.md).")
    spp: int = option(64, bounds=(1, None), help="Samples per pixel of the report's renders.")

    def __post_init__(self):
        if isinstance(self.models, (list, str)):
            object.__setattr__(self, "models", tuple(self.models) if isinstance(self.models, list) else (self.models,))
        if isinstance(self.face_model, os.PathLike):
            object.__setattr__(self, "face_model", os.fspath(self.face_model))
        if isinstance(self.refine_shape, bool):  # measure(refine_shape=True) as before the schedule
            object.__setattr__(self, "refine_shape", ShapeRefineSchedule() if self.refine_shape else None)
        check(self)
        if not isinstance(self.fit, FitOptions):
            raise ValueError(f"MeasureOptions.fit must be a FitOptions, got {self.fit!r}"[:300])
        if not (self.refine_shape is None or isinstance(self.refine_shape, ShapeRefineSchedule)):
            raise ValueError(f"MeasureOptions.refine_shape must be a ShapeRefineSchedule, True, False or None, got "
                             f"{self.refine_shape!r}"[:300])
        one_lobe = [m for m in self.models if not BRDF_CLASSES[m].SEVERAL_LOBES]
        if self.fit.lobes != 1 and one_lobe:
            several = [m for m in NAMES if BRDF_CLASSES[m].SEVERAL_LOBES]
            raise ValueError(f"MeasureOptions.fit.lobes is {self.fit.lobes}, but {', '.join(one_lobe)} "
                             f"{'has' if len(one_lobe) == 1 else 'have'} one lobe: fit {' or '.join(several)} "
                             "alone (models) with several lobes")

    @classmethod
    def of(cls, options=None, keywords: dict | None = None, caller: str = "measure") -> MeasureOptions:
        """The options a call of ``caller`` asked for: ``options`` (a :class:`MeasureOptions`, a
        :class:`FitOptions` for the fit, or None for the defaults) with ``keywords`` applied, each a
        field of :class:`MeasureOptions` (``models=``, ``spp=``, ``refine_shape=True``, ...) or,
        deprecated with a :class:`DeprecationWarning`, of :class:`FitOptions` (``resolution=``:
        :func:`~mifaces.reflectance.options.fit_options`). The one place the keywords become options.

        Raises
        ------
        TypeError
            For a keyword neither class has a field for.
        """
        if not isinstance(options, cls):
            options = cls(fit=fit_options(options, {}, caller))
        keywords = dict(keywords or {})
        own = {name: keywords.pop(name) for name in [f.name for f in dataclasses.fields(cls)] if name in keywords}
        if "fit" in own:
            raise TypeError(f"{caller}() takes the fit options as options=FitOptions(...) or MeasureOptions(fit=...)")
        if keywords:
            own["fit"] = fit_options(options.fit, keywords, caller)
        return dataclasses.replace(options, **own) if own else options

    def to_record(self) -> dict:
        """Every option, as a JSON object (``report.json``'s ``options``); :meth:`from_record`
        reads it back, equal (a loaded face model is recorded by its name)."""
        data = record(self)
        if not isinstance(self.face_model, str):
            data["face_model"] = getattr(self.face_model, "name", str(self.face_model))
        return data

    @classmethod
    def from_record(cls, data: dict) -> MeasureOptions:
        """The options :meth:`to_record` wrote.

        Raises
        ------
        ValueError
            For a record of options this version does not have, or values it refuses.
        """
        return from_record(cls, data)

    def resolved(self) -> MeasureOptions:
        """These options as the fits plan to run them (:meth:`FitOptions.resolved
        <mifaces.reflectance.options.FitOptions.resolved>`)."""
        return dataclasses.replace(self, fit=self.fit.resolved())


__all__ = ["GEOMETRIES", "MeasureOptions"]
