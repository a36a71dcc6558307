"""Photometric stereo: normals per pixel from photographs under known directional lights.

:mod:`.lambertian` (re-exported here) is Woodham's Lambertian photometric stereo, the
baseline real photographs are judged against; :mod:`.nonlambertian` alternates the normals
with a fitted analytic BRDF (DiLiGenT, ``validation/real_diligent.py``). It is imported on its
own (``from mifaces.photometric_stereo import nonlambertian``): it uses the region fit of
:mod:`mifaces.reflectance`, which the Lambertian baseline does not need.
"""

from .lambertian import MIN_SPREAD, SHADOW_FRACTION, angular_error, fit, observation_weights, predict

__all__ = ["MIN_SPREAD", "SHADOW_FRACTION", "angular_error", "fit", "observation_weights", "predict"]
