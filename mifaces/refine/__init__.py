"""Refinement by differentiable rendering, the stage after the BRDF fit: the fitted
reflectance against the photographs (:mod:`.reflectance`, :func:`refine_estimate`), and the
face's shape beyond the model (:mod:`.shape`, :func:`refine_shape`); their schedules
(:mod:`.schedule`). See ``docs/refine.md`` and ``docs/refine_shape.md``."""

from .reflectance import refine_estimate
from .schedule import RefineSchedule
from .shape import ShapeRefineSchedule, ShapeRefinement, refine_shape

__all__ = ["RefineSchedule", "ShapeRefineSchedule", "ShapeRefinement", "refine_estimate", "refine_shape"]
