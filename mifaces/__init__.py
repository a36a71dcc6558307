"""mifaces: reflectance of human faces from photographs by analysis-by-synthesis.

Importing mifaces points Dr.Jit at a working libLLVM (see :mod:`mifaces.llvm`),
sets the default Mitsuba variant (``cuda_ad_rgb`` with a GPU, else
``llvm_ad_rgb``; ``$MIFACES_VARIANT`` overrides) and registers the BSDF plugins
``phong``, ``cooktorrance``, ``ward`` and ``lafortune`` in it.
"""

import sys as _sys

from . import llvm as _llvm

_drjit_came_first = "drjit" in _sys.modules
_llvm.configure()
if _drjit_came_first:
    _llvm.check_loaded()

from .model import MorphableModel, load_model  # noqa: E402
from .variant import default_variant, set_variant  # noqa: E402

__version__ = "0.1.0"

set_variant()

#: The pipeline's stages, importable from the package (loaded on first use).
_STAGES = {"load_capture": "capture", "simulate": "simulate", "fit_shape": "shape_estimation",
           "load_fitted_shapes": "shape_estimation", "capture_samples": "reflectance_samples",
           "fit_brdf": "brdf_estimation", "render_fitted": "brdf_estimation", "measure": "pipeline"}


def __getattr__(name):
    if name in _STAGES:
        import importlib

        return getattr(importlib.import_module(f".{_STAGES[name]}", __name__), name)
    raise AttributeError(f"module 'mifaces' has no attribute {name!r}")
