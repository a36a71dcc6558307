"""The glossy lobes of a fit the samples do not support: lobes that explain no sample (pruned),
lobes fitted into spikes no photograph showed (:data:`SPIKE`, :func:`glossy_peak`), and the
lobe-less parameters of a region nothing can lend a glossy part to (:func:`no_lobe`)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ...brdf.model import BRDFModel
from .parameters import ParameterSpace
from .problem import Problem


def prune_lobes(model: BRDFModel, space: ParameterSpace, problem: Problem, params: dict, loss: float,
                rtol: float = 1e-4) -> tuple[dict, float, list[int]]:
    """Zero the lobes the samples do not need, of a model with several.

    A lobe whose removal raises the loss by less than ``rtol`` (relative)
    explains no sample: typically it has drifted to a sharp spike where no
    sample lies, where it would only add a highlight no photograph showed.
    Such lobes get their scales (:meth:`~mifaces.brdf.model.BRDFModel.lobe_scales`,
    a Lafortune lobe's C_xy and C_z) set to 0; the plugin then leaves them
    out. Returns the parameters, their loss and the numbers of the lobes
    removed.
    """
    pruned = []
    for j, scales in model.lobe_scales().items():
        if any(name in space.fixed for name in scales):
            continue
        trial = {**params, **{name: [0.0] * 3 if model.parameter(name).kind == "rgb" else 0.0 for name in scales}}
        trial_loss = problem.loss(space.vector(trial))
        if np.isfinite(trial_loss) and trial_loss <= loss * (1 + rtol):
            params, loss = space.values(space.vector(trial)), min(loss, trial_loss)
            pruned.append(j)
    return params, loss, pruned


#: Why a fit whose lobe width ended at its sharp end is not trusted.
SPIKE = "the lobe became a spike at the sharp end of its width range"
#: A fitted glossy lobe whose peak reflectance (π f at the mirror direction, the brightest incidence
#: of a grid) exceeds this many times the region's brightest sample is a spike no photograph showed
#: (a narrow, strong lobe fitted to a few samples' noise; under a light the photographs did not cover
#: it would blow up): it is handled as one (:data:`SPIKE`).
PEAK_FACTOR = 5.0
#: Incidence angles (degrees) at which :func:`glossy_peak` evaluates the lobe at its mirror direction:
#: up to 40°, where photographs see highlights; towards grazing a true microfacet lobe rises far above
#: any sample (1 / (4 cos cos) and Fresnel), which says nothing about noise.
PEAK_ANGLES = (0.0, 20.0, 40.0)


def no_lobe(model: BRDFModel) -> dict:
    """The model's default parameters with every glossy lobe's scales at zero: what a region renders
    when nothing measured its glossy part and no region can lend one (status ``'defaults'``): no
    highlight rather than an invented one."""
    params = {**model.defaults(), **model.fixed_defaults()}
    for scales in model.lobe_scales().values():
        for name in scales:
            if name in params:
                params[name] = (np.zeros_like(np.asarray(params[name], np.float64)).tolist()
                                if np.ndim(params[name]) else 0.0)
    return params


def glossy_peak(model: BRDFModel, params: dict) -> float:
    """The largest π f_s(wi, mirror(wi)) of the glossy part over :data:`PEAK_ANGLES`, all
    channels: the brightest highlight the fitted lobe predicts, in the units of reflectance samples."""
    theta = np.radians(np.asarray(PEAK_ANGLES))
    wi = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)])
    wo = wi * np.array([[-1.0], [-1.0], [1.0]])
    # opaque: one kernel for every fit's parameters (literals would compile one per value)
    values = {k: (mi.Color3f(*(dr.opaque(mi.Float, float(c)) for c in np.broadcast_to(np.asarray(v, np.float64), 3)))
                  if np.ndim(v) else dr.opaque(mi.Float, float(v)))
              for k, v in params.items()}
    f = np.array(model.eval(mi.Vector3f(wi.astype(np.float32)), mi.Vector3f(wo.astype(np.float32)), values,
                            diffuse=False))
    return float(np.pi * np.nanmax(f)) if f.size else 0.0


__all__ = ["SPIKE", "PEAK_FACTOR", "PEAK_ANGLES", "prune_lobes", "no_lobe", "glossy_peak"]
