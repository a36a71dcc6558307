"""Dr.Jit's kernel launches during a refinement: how many, how many compiled (not found in
the cache), and the compile time, per step (the ``history`` of :func:`~mifaces.refine.refine_estimate`
and :func:`~mifaces.refine.refine_shape`). A step after the first pass over the photographs should
compile nothing: its scenes' parameters are opaque, so the kernels are reused."""

from __future__ import annotations

import drjit as dr


class kernel_history:
    """Record Dr.Jit's kernel launches inside the ``with`` block (read them with :func:`kernel_counts`)."""

    def __enter__(self):
        self.was = dr.flag(dr.JitFlag.KernelHistory)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()  # clears it
        return self

    def __exit__(self, *exc):
        dr.set_flag(dr.JitFlag.KernelHistory, self.was)


def kernel_counts() -> tuple[int, int, float]:
    """Kernels launched since the last call: count, how many were compiled
    (not found in the cache), and their compile time in seconds."""
    kernels = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
    compiled = [k for k in kernels if not k.get("cache_hit", False) and not k.get("cache_disk", False)]
    seconds = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in compiled) / 1000.0
    return len(kernels), len(compiled), round(seconds, 4)


__all__ = ["kernel_counts", "kernel_history"]
