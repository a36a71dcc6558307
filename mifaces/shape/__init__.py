"""Shape estimation: the morphable model fitted to each photograph (paper sec. 4.2).

:mod:`.result` (what a fit is asked for and returns), :mod:`.targets` (feature
points, metric distances, the start), :mod:`.energy` (E = E_I + E_F + E_P, of
:mod:`.sampled_model`'s rows of the model, :mod:`.shading`'s illumination model and
:mod:`.projection`'s camera), :mod:`.fitter` (the optimiser), :mod:`.poses` (measurements grouped by pose,
the fits a pose's measurements share), :mod:`.io` (hand-off to the next stage,
in memory or on disk), :mod:`.fit` (:func:`fit_measurement`, :func:`fit_shape`).
"""

from .fit import feature_limit, fit_measurement, fit_shape
from .io import INDEX, load_fitted_shapes, load_geometry, shapes_in_world, write_fit, write_index
from .result import ShapeFit, ShapeFitError, ShapeOptions, ShapeSchedule, Weights
from .targets import feature_targets, light_direction, metric_distances, rotation_centre

__all__ = ["ShapeFit", "ShapeFitError", "ShapeOptions", "ShapeSchedule", "Weights", "feature_limit",
           "fit_measurement", "fit_shape", "shapes_in_world", "load_fitted_shapes", "load_geometry", "write_fit", "write_index",
           "INDEX", "feature_targets", "light_direction", "metric_distances", "rotation_centre"]
