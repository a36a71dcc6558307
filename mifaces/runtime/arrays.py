"""Arrays from NumPy into Dr.Jit's own memory, for kernels that are compiled once."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

#: An opaque zero per array type (see :func:`device_array`).
_ZERO = {}


def device_array(dtype, values):
    """``values`` as a flat Dr.Jit array (``mi.Float`` for float32, ``mi.Float64`` for float64,
    ``mi.UInt32`` for uint32) in memory Dr.Jit owns, evaluated.

    Dr.Jit's LLVM backend maps a NumPy array's memory instead of copying it, and writes whether
    it is aligned into the code of the kernels that load from it: by chance, so the same kernel
    of a second photograph would differ and be compiled again; and releasing mapped memory
    cannot happen while a frozen function records. So the values are copied into a 64-byte
    aligned buffer, and from there by a kernel (always the same) into Dr.Jit's own memory.
    """
    values = np.ascontiguousarray(values, dtype).ravel()
    buffer = np.empty(values.size + 64 // values.itemsize, dtype)
    start = (-buffer.ctypes.data % 64) // values.itemsize
    aligned = buffer[start:start + values.size]
    aligned[:] = values
    array_type = {np.dtype(np.float32): mi.Float, np.dtype(np.float64): mi.Float64}.get(np.dtype(dtype), mi.UInt32)
    if array_type not in _ZERO:  # made once: an opaque value is a launch
        _ZERO[array_type] = dr.opaque(array_type, 0)
    owned = array_type(aligned) + _ZERO[array_type]
    dr.eval(owned)
    return owned


__all__ = ["device_array"]
