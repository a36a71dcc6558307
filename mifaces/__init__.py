"""mifaces: reflectance of human faces from photographs by analysis-by-synthesis.

Importing mifaces points Dr.Jit at a working libLLVM (see :mod:`mifaces.runtime.llvm`),
sets the default Mitsuba variant (``cuda_ad_rgb`` with a GPU, else
``llvm_ad_rgb``; ``$MIFACES_VARIANT`` overrides) and registers the BSDF plugins
``phong``, ``cooktorrance``, ``ward`` and ``lafortune`` in it.
"""

import sys as _sys

from .runtime import llvm as _llvm

_drjit_came_first = "drjit" in _sys.modules
_llvm.configure()
if _drjit_came_first:
    _llvm.check_loaded()

from .model import MorphableModel, load_model  # noqa: E402
from .runtime.variant import default_variant, set_variant  # noqa: E402

from .version import VERSION as __version__  # noqa: E402,F401

set_variant()

from .capture import load_capture  # noqa: E402
from .options.measure import MeasureOptions  # noqa: E402
from .pipeline.measure import measure  # noqa: E402
from .reflectance import RenderOptions, capture_samples, fit_brdf, render_fitted  # noqa: E402
from .shape import fit_shape, load_fitted_shapes  # noqa: E402
from .studio import SimulationOptions, simulate  # noqa: E402

__all__ = ["__version__", "MorphableModel", "load_model", "default_variant", "set_variant", "load_capture", "simulate",
           "SimulationOptions", "fit_shape", "load_fitted_shapes", "capture_samples", "fit_brdf", "render_fitted",
           "RenderOptions", "measure", "MeasureOptions"]
