"""Shape estimation: the morphable model fitted to each photograph (paper sec. 4.2)."""

from .fit import ShapeFit, ShapeFitError, fit_measurement, fit_shape, load_fitted_shapes

__all__ = ["ShapeFit", "ShapeFitError", "fit_measurement", "fit_shape", "load_fitted_shapes"]
