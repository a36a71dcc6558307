"""From photographs on fitted shapes to BRDFs (paper sec. 4.3-5.3): reflectance
samples in texture space, per-region fits by Levenberg-Marquardt, per-texel
diffuse refinement, and the estimate they make together."""

from .diffuse import DiffuseMap, refine_diffuse
from .estimate import BRDFEstimate, fit_brdf, load_estimate, render_estimate, render_fitted
from .fitting import RegionFit, fit_region, fit_regions
from .samples import ReflectanceSamples, capture_samples

__all__ = ["ReflectanceSamples", "capture_samples", "RegionFit", "fit_region", "fit_regions", "DiffuseMap",
           "refine_diffuse", "BRDFEstimate", "fit_brdf", "load_estimate", "render_estimate",
           "render_fitted"]
