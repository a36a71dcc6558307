"""From photographs on fitted shapes to BRDFs (paper sec. 4.3-5.3): reflectance
samples in texture space, per-region fits by Levenberg-Marquardt, per-texel
diffuse refinement, the estimate they make together, its files, and renders
of it in novel poses and lights or on another face."""

from .maps.diffuse import DiffuseMap, refine_diffuse
from .estimate import fit_brdf
from .result import BRDFEstimate
from .options import FitOptions
from .fit.region_fit import RegionFit, RegionFitOptions, RegionSamples, Uncertainty, fit_region
from .fit.regions import fit_regions
from .io import load_estimate, write_estimate
from .render import RenderOptions, render_estimate, render_fitted
from .resampling import capture_samples
from .samples import ReflectanceSamples

__all__ = ["ReflectanceSamples", "capture_samples", "RegionSamples", "RegionFitOptions", "Uncertainty", "RegionFit",
           "fit_region", "fit_regions", "DiffuseMap", "refine_diffuse", "BRDFEstimate", "FitOptions", "fit_brdf",
           "write_estimate", "load_estimate", "render_estimate", "RenderOptions", "render_fitted"]
