"""Adam (Kingma and Ba 2015, Algorithm 1) on the Dr.Jit side: the shape fit's steps
without a round trip to the host per iteration.

One step -- E and dE/dtheta (:meth:`mifaces.shape.energy.Energy.energy`), Adam's moments,
the update of ``theta`` on ``theta / unit``, the clamp of the non-negative blocks -- is one
frozen function (``dr.freeze``), replayed step after step on arrays that stay on the device;
the host reads the steps' terms and whether a step failed every few steps
(:data:`mifaces.shape.fitter.CHUNK`), not every step. Parameters and moments are float64, as
the host-side optimiser they replace kept them; E is evaluated in float32 as before.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..runtime.arrays import device_array

#: Packed values per step (see :meth:`Energy.energy`).
PACKED = 8
#: Columns of the per-step table: feature weight, image weight, step size, 1 - beta1^k, 1 - beta2^k.
COLUMNS = 5


class DeviceAdam:
    """Adam's state for one stage of a shape fit, on the Dr.Jit side.

    A step whose E or gradient is not finite leaves theta and the moments as they were and
    records its number (1-based within the stage) in ``failed``; the steps after it change
    nothing.
    """

    beta1, beta2, eps = 0.9, 0.999, 1e-8

    def __init__(self, energy, freeze: bool = True):
        self.energy = energy
        self._frozen = dr.freeze(self._step, enabled=freeze, warn_after=20,
                                 state_fn=lambda arrays, state, use_image: (
                                     *energy.widths(arrays), dr.width(state["table"]), dr.width(state["theta"])))

    def start(self, theta: np.ndarray, scale: np.ndarray, nonnegative: np.ndarray, table: np.ndarray):
        """A new stage from ``theta``: moments zero; ``scale`` (units times the stage's mask),
        ``nonnegative`` (bool per parameter), and the per-step ``table`` (steps, :data:`COLUMNS`)."""
        zero = np.zeros(len(theta))
        self.steps = len(table)
        self.state = {"theta": device_array(np.float64, theta), "m1": device_array(np.float64, zero),
                      "m2": device_array(np.float64, zero), "scale": device_array(np.float64, scale),
                      "nonnegative": device_array(np.float64, nonnegative),
                      "table": device_array(np.float64, np.asarray(table, np.float64)),
                      "terms": device_array(np.float64, np.zeros(len(table) * PACKED)),
                      "it": device_array(np.uint32, [0]), "failed": device_array(np.uint32, [0])}

    def step(self, use_image: bool):
        """One step (queued on the device; nothing is read back)."""
        self.state = self._frozen(self.energy.arrays(), self.state, use_image)

    def read(self):
        """``(theta, terms, failed)``: theta (numpy float64), the packed values of every step of
        the stage so far ((steps, :data:`PACKED`)), and the 1-based number of the first failed
        step (0: none)."""
        s = self.state
        return (np.asarray(s["theta"], np.float64), np.asarray(s["terms"], np.float64).reshape(-1, PACKED),
                int(np.asarray(s["failed"])[0]))

    def _step(self, arrays: dict, state: dict, use_image: bool) -> dict:
        energy_of = self.energy.bound(arrays)
        it, table = state["it"], state["table"]

        def column(c):
            return dr.gather(mi.Float64, table, it * COLUMNS + c)

        theta64 = state["theta"]
        theta = mi.Float(theta64)
        dr.enable_grad(theta)
        energy, packed = energy_of.energy(theta, [mi.Float(column(0)), mi.Float(column(1))], use_image)
        dr.backward(energy)
        g = mi.Float64(dr.grad(theta))
        finite = dr.isfinite(dr.gather(mi.Float, packed, dr.zeros(mi.UInt32, 1))) & dr.all(dr.isfinite(g))
        ok = finite & (state["failed"] == 0)
        b1, b2, scale = self.beta1, self.beta2, state["scale"]
        gu = g * scale
        m1 = b1 * state["m1"] + (1 - b1) * gu
        m2 = b2 * state["m2"] + (1 - b2) * gu * gu
        step = column(2) * (m1 / column(3)) / (dr.sqrt(m2 / column(4)) + self.eps)
        new = theta64 - step * scale
        new = dr.select(state["nonnegative"] > 0, dr.maximum(new, 0.0), new)
        terms = mi.Float64(state["terms"])
        dr.scatter(terms, mi.Float64(packed), it * PACKED + dr.arange(mi.UInt32, PACKED))
        out = {**state, "theta": dr.select(ok, new, theta64), "m1": dr.select(ok, m1, state["m1"]),
               "m2": dr.select(ok, m2, state["m2"]), "terms": terms, "it": it + 1,
               "failed": dr.select(~finite & (state["failed"] == 0), it + 1, state["failed"])}
        dr.eval(out)
        return out
