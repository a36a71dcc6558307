"""A fit's parameters and albedo against a simulated capture's ground truth: :func:`ground_truth_errors`."""

from __future__ import annotations

import numpy as np
from skimage.transform import resize

from ..capture import read_ground_truth
from ..model.regions import REGIONS
from ..runtime.status import NOT_FITTED


def ground_truth_errors(estimate, capture, ground_truth=None, albedo_scale: float = 1.0) -> dict | None:
    """How far a fit is from a simulated capture's ground truth (``ground_truth/``).

    Returns None for a capture without ground truth, else ``{"truth_model",
    "regions": {region: {parameter: relative error, mean over channels}},
    "albedo": {...}}``. Parameter errors are given where the truth is the
    same model, for the regions fitted on their own samples (η, held at its
    published value, is left out); the albedo errors, RMSE and mean error of
    the refined map against the truth's (downsampled to the fit's
    resolution), on texels with samples and on all face texels, always.
    ``ground_truth`` (the capture's, already read) saves reading it again. ``albedo_scale``
    multiplies the fitted albedo first (a relative estimate's, in the truth's units:
    :meth:`mifaces.validation.validator.Validator.reflectance_scale`); the parameter errors are as fitted.
    """
    ground_truth = read_ground_truth(capture) if ground_truth is None else ground_truth
    if ground_truth is None:
        return None
    truth = ground_truth.brdf
    regions = {}
    if truth["model"] == estimate.model:
        for name, fit in estimate.fits.items():
            if fit.status in NOT_FITTED or name not in truth["regions"]:
                continue
            regions[name] = {key: float(np.mean(np.abs(np.asarray(fit.params[key], float) - np.asarray(value, float))
                                                / np.abs(np.asarray(value, float))))
                             for key, value in truth["regions"][name].items() if key != "eta"}
    r = estimate.resolution
    error = albedo_scale * estimate.albedo.albedo - resize(ground_truth.albedo, (r, r, 3), anti_aliasing=True, order=1)
    seen = estimate.albedo.samples > 0
    face = estimate.region_map > 0
    skin = seen & (estimate.region_map == REGIONS["skin"])
    albedo = {"rmse_sampled": float(np.sqrt(np.mean(error[seen] ** 2))),
              "rmse_face": float(np.sqrt(np.mean(error[face] ** 2))),
              "skin_rmse_sampled": float(np.sqrt(np.mean(error[skin] ** 2))),
              "bias_sampled": float(error[seen].mean()), "texels_sampled": int(seen.sum()),
              "texels_face": int(face.sum())}
    return {"truth_model": truth["model"], "regions": regions, "albedo": albedo}


__all__ = ["ground_truth_errors"]
