"""Empirical-Bayes shrinkage of per-texel estimates towards their region's value (beyond the paper).

A region's texels each have an estimate x̂_t (a diffuse albedo per channel,
:mod:`mifaces.reflectance.maps.diffuse`; a specular scale,
:mod:`mifaces.reflectance.maps.specular`) with information I_t: x̂_t is the texel's value plus
noise of variance s₀²/I_t. Taking the texels' values as drawn around the region's x_R with
variance τ², a texel's posterior mean is

    (I_t x̂_t + λ x_R) / (I_t + λ),   λ = s₀² / τ²,

and its posterior variance s₀² / (I_t + λ). Both variances are estimated from the region's
samples (empirical Bayes): s₀² as the weighted squared residuals of the samples about their
texels' fits over their degrees of freedom, τ² as the variance of the estimates beyond that
noise,

    τ² = max(Var_t x̂_t - s₀² mean_t(1/I_t), floor),

floored so that a region whose texels scatter no more than the noise shrinks them all the way
to its value rather than dividing by zero.
"""

from __future__ import annotations

import numpy as np


def empirical_bayes(squares, dof: int, estimates, information, floor) -> tuple:
    """λ = s₀²/τ², s₀² and τ² of one region (module docstring).

    Parameters
    ----------
    squares : float or ndarray (C,)
        Σ_s w_s e_s²: the weighted squared residuals of the region's samples about their texels'
        fits (per channel, or summed over the channels for one estimate per texel).
    dof : int
        Their degrees of freedom (the samples' residuals less the parameters fitted per texel).
    estimates : ndarray (T,) or (T, C)
        x̂_t of the texels that have one.
    information : ndarray (T,)
        I_t of those texels.
    floor : float or ndarray (C,)
        Least τ².

    Returns
    -------
    lam, noise, spread : float or ndarray (C,)
        λ, s₀² and τ².
    """
    noise = squares / dof
    spread = np.maximum(np.var(estimates, axis=0) - noise * np.mean(1.0 / information), floor)
    return noise / spread, noise, spread


__all__ = ["empirical_bayes"]
