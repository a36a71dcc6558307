"""mifaces: reflectance of human faces from photographs by analysis-by-synthesis.

Importing mifaces points Dr.Jit at a working libLLVM (see :mod:`mifaces.llvm`),
sets the default Mitsuba variant (``cuda_ad_rgb`` with a GPU, else
``llvm_ad_rgb``; ``$MIFACES_VARIANT`` overrides) and registers the BSDF plugins
``phong``, ``cooktorrance``, ``ward`` and ``lafortune`` in it.
"""

from . import llvm as _llvm

_llvm.configure()

from .variant import default_variant, set_variant  # noqa: E402

__version__ = "0.1.0"

set_variant()
