"""The photo studio simulated with Mitsuba: a capture of a morphable-model
face with known shapes, BRDFs and albedo (the ground truth), written in the
capture format of :mod:`mifaces.capture`."""

from .options import SimulationOptions
from .simulate import SimulationResult, simulate
from .truth import brdf_with_overrides, default_brdf

__all__ = ["simulate", "SimulationOptions", "SimulationResult", "default_brdf", "brdf_with_overrides"]
