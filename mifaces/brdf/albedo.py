"""Hemispherical albedo of a BRDF model's glossy part, by importance sampling.

    a(wi) = ∫ f_s(wi, wo) cos θo dωo ≈ (1/N) Σ f_s(wi, wo_k) cos θo_k / p(wo_k),

with wo_k drawn by the model's own sampler (its density checked by the
chi-square tests). Used to check energy conservation (a <= 1 for the
normalised models) and to report by how much the others exceed it.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .model import BRDFModel, mean


def glossy_albedo(model: BRDFModel, cases: list[tuple[float, dict]], samples: int = 1 << 16):
    """Albedo of the glossy part for each (cos θi, parameters) case.

    Parameters
    ----------
    model : BRDFModel
    cases : list of (cos θi, dict)
        Incidence cosine and grey parameter values (floats) of each case.
    samples : int
        Importance samples per case.

    Returns
    -------
    (estimate, standard_error) : two ndarrays of shape (len(cases),)
        Channel-mean albedo and the Monte Carlo standard error.
    """
    k = len(cases)
    n = k * samples
    case = dr.arange(mi.UInt32, n) // samples
    rng = mi.PCG32(size=n, initstate=dr.arange(mi.UInt64, n))
    u1, u2 = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
    cos_i = dr.gather(mi.Float, mi.Float([float(c) for c, _ in cases]), case)
    wi = mi.Vector3f(dr.safe_sqrt(1 - cos_i * cos_i), 0, cos_i)
    params = {p.name: dr.gather(mi.Float, mi.Float([float(c[1][p.name]) for c in cases]), case)
              for p in model.specular_parameters()}
    wo = model.sample_specular(wi, u1, u2, params)
    pdf = model.pdf_specular(wi, wo, params)
    f = model.eval(wi, wo, params, diffuse=False)
    value = dr.select((pdf > 0) & (wo.z > 0), mean(f) * wo.z / dr.maximum(pdf, 1e-30), 0.0)
    v = np.array(value).reshape(k, samples)
    return v.mean(axis=1), v.std(axis=1) / np.sqrt(samples)
