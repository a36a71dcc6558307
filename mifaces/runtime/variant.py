"""Choosing the Mitsuba variant and registering the mifaces plugins in it.

Mitsuba's Python plugins are registered per variant: a plugin registered in
``llvm_ad_rgb`` does not exist in ``scalar_rgb``. :func:`set_variant` switches
variant and registers the BSDFs of :mod:`mifaces.plugins` there, once.
"""

from __future__ import annotations

import os

import drjit as dr
import mitsuba as mi

from .. import plugins
from . import llvm

_registered: set[str] = set()


def default_variant() -> str:
    """``$MIFACES_VARIANT`` if set, else ``cuda_ad_rgb`` where a CUDA GPU is
    present, else ``llvm_ad_rgb``."""
    if os.environ.get("MIFACES_VARIANT"):
        return os.environ["MIFACES_VARIANT"]
    try:
        if dr.has_backend(dr.JitBackend.CUDA):
            return "cuda_ad_rgb"
    except Exception:  # no driver: Dr.Jit may raise instead of answering False
        pass
    return "llvm_ad_rgb"


def set_variant(variant: str | None = None) -> str:
    """Set the Mitsuba variant and register the mifaces plugins in it.

    Parameters
    ----------
    variant : str, optional
        A Mitsuba variant name (``'llvm_ad_rgb'``, ``'cuda_ad_rgb'``,
        ``'scalar_rgb'``, ...). By default :func:`default_variant`.

    Returns
    -------
    str
        The variant now active.
    """
    variant = variant or default_variant()
    if variant not in mi.variants():
        raise ValueError(f"variant {variant!r} is not one of Mitsuba's: {mi.variants()}")
    if variant.startswith("llvm") and not dr.has_backend(dr.JitBackend.LLVM):
        raise RuntimeError(llvm.INSTALL_HINT)
    mi.set_variant(variant)
    if variant not in _registered:
        plugins.register()
        _registered.add(variant)
    return variant
