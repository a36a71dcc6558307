"""The lights' relative intensities checked against the face's one albedo.

A texel's reflectance ``r = pixel / (E cos)`` is the same under every light where each light's
irradiance ``E`` is right, and ``1 / s`` of it where ``E`` is ``s`` times too large. The reflectance
samples of a capture's photographs therefore measure each light's intensity error relative to the
others (:func:`log_light_errors`). :func:`mifaces.light_estimation.unknown.balance_intensities` uses that to set
estimated lights' intensities; :func:`balance_given_lights` corrects calibrated ones (a lamp the
steel spheres place a percent too far gives 2 % too little light, which skin's ρs absorbs many
times over: ``docs/refine.md``).

The glossy lobe's tails reach the samples read (a rough skin's lobe is wide), and they differ from
light to light. :func:`balance_given_lights` therefore takes the glossy part a fit predicts for each
sample and reads the albedo of what is left; the sample stage
(:func:`mifaces.reflectance.sample_stage.with_balanced_lights`) alternates it with a quick fit,
:data:`BALANCE_FIT_ROUNDS` times (``docs/reflectance.md``, "Where skin's bias comes from").
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

#: Samples that compare the photographs' albedos (:func:`log_light_errors`): light and view at
#: least this cosine from grazing, and texels seen under at least two lights.
BALANCE_MIN_COSINE = 0.3
#: Rounds of the alternating robust fit of :func:`log_light_errors`.
BALANCE_ROUNDS = 20
#: :func:`balance_given_lights` reads only samples whose half vector lies at least this far from the
#: normal (cosine at most this): highlights pull the estimate towards equal lights, and a calibrated
#: lamp is off by a percent or two. Chosen on the uncertainty validation's tuning captures, seeds
#: 100-104 (``validation/light_calibration_bias.py``: ``balance_sweep``; docs/uncertainty.md).
GIVEN_MAX_HALF_COSINE = 0.8
#: Rounds of quick fit and balance (:func:`mifaces.reflectance.sample_stage.with_balanced_lights`): the
#: first fit's lobe has absorbed part of the lights' errors, so one round finds most of them, not all.
#: Chosen on development seed 100 (its ideal capture of ``validation/reflectance_bias.py``, the steel
#: spheres' lamps; a look, not kept): the factors stopped moving (to 0.01 %) after the third round.
BALANCE_FIT_ROUNDS = 3
#: A light whose factor lies this many times or more from the median light's, either way, has failed
#: (a strobe that did not fire, a photograph under another lamp), not drifted: a calibrated lamp is off
#: by percents. :func:`balance_given_lights` leaves its photographs' samples out of the fit. Chosen on the
#: development Yale subjects (``validation/light_balance_limit.py``: their sound photographs' factors lie
#: within a third of the median; yaleB10's strobe that did not fire gives about 54 times).
FAILED_LIGHT_FACTOR = 2.0
#: The balance corrects a calibration, which is off by a percent or two. Where the lights' factors (the
#: failed ones left out) spread farther than this from the median light's, either way, they measure how
#: far the face's model misses the photographs (shadows, shape), not the lamps: :func:`balance_given_lights`
#: leaves the lights as given, with a warning. Chosen on development data (``validation/light_balance_limit.py``):
#: simulated captures' calibrated lamps spread by about a percent, the development Yale subjects' lights by
#: 17 % to 33 %, where balancing them anyway raised the held-out error on six subjects of seven
#: (``validation/results/real_yaleb_balance_lights.json``).
BALANCE_LIMIT = 1.1


def log_light_errors(capture, samples, lights, anchors=(), max_half_cosine: float | None = None) -> dict | None:
    """How far off each light's intensity is, by the face's one albedo: ``log s`` per light of
    ``lights`` (names) such that its irradiance is ``s`` times too large, from the reflectance
    samples (:func:`mifaces.reflectance.capture_samples`) taken under ``capture``'s lights.

    The log reflectance is fitted as ``a_texel - log s_light`` by alternating a texel's mean and
    a light's median (robust against highlights and shadows), over the samples of light and view
    at least :data:`BALANCE_MIN_COSINE` from grazing and the texels seen under two or more of the
    lights; with ``max_half_cosine``, only samples whose half vector's cosine to the normal is at
    most that (away from the highlights). The mean ``log s`` of the ``anchors`` present (of all the
    lights present without anchors) is 0. None where fewer than two of the lights have such
    samples; a light without any is left out."""
    names = list(samples.measurement_names)
    light_of = {m.name: m.light for m in capture.measurements}
    keep = ((samples.light[:, 2] >= BALANCE_MIN_COSINE) & (samples.view[:, 2] >= BALANCE_MIN_COSINE)
            & np.all(samples.reflectance > 0, axis=1))
    if max_half_cosine is not None:
        half = samples.light + samples.view
        keep &= half[:, 2] <= max_half_cosine * np.linalg.norm(half, axis=1)
    which = np.array([light_of[name] for name in names])[samples.measurement[keep]]
    index = {name: k for k, name in enumerate(lights)}
    on = np.array([name in index for name in which], bool)
    if not on.any():
        return None
    light = np.array([index[name] for name in which[on]], np.int64)
    texels = samples.texel[keep][on]
    log_r = np.log(np.mean(samples.reflectance[keep][on], axis=1))
    pairs = np.unique(texels * len(index) + light)  # (texel, light) seen
    shared = np.bincount(pairs // len(index), minlength=int(texels.max(initial=-1)) + 1)[texels] >= 2
    light, texels, log_r = light[shared], texels[shared], log_r[shared]
    present = sorted(set(np.unique(light).tolist()))
    if len(present) < 2:
        return None
    held = [index[name] for name in anchors if index[name] in present] or present
    log_s = np.zeros(len(index))
    per_texel = np.bincount(texels)
    for _ in range(BALANCE_ROUNDS):
        a = np.bincount(texels, weights=log_r + log_s[light]) / np.maximum(per_texel, 1)
        log_s = np.array([np.median(a[texels[light == k]] - log_r[light == k]) if k in present else 0.0
                          for k in range(len(index))])
        log_s -= log_s[held].mean()
    return {name: float(log_s[k]) for name, k in index.items() if k in present}


def failed_lights(log_s: dict) -> dict:
    """The lights of ``log_s`` (:func:`log_light_errors`) whose factor lies at least
    :data:`FAILED_LIGHT_FACTOR` times from the median light's, either way: each one's factor against
    that median."""
    if len(log_s) < 3:  # two lights: no median to tell which one failed
        return {}
    middle = float(np.median(list(log_s.values())))
    return {name: float(np.exp(value - middle)) for name, value in log_s.items()
            if abs(value - middle) >= np.log(FAILED_LIGHT_FACTOR)}


def spread(log_s: dict) -> float:
    """How far the lights of ``log_s`` (:func:`log_light_errors`) lie from the median light's, either
    way: the largest factor against it (1: all equal)."""
    middle = float(np.median(list(log_s.values())))
    return float(np.exp(max(abs(value - middle) for value in log_s.values())))


def balance_given_lights(capture, samples, glossy=None):
    """``capture`` and its reflectance ``samples`` with each given light's intensity corrected by
    the face's one albedo (:func:`log_light_errors`), their mean log intensity kept (the overall
    scale is the white target's). A calibrated lamp is off in distance by about a percent, its
    irradiance by twice that, which the glossy parameters otherwise absorb
    (``docs/uncertainty.md``). Captures of fewer than two given point or directional lights come
    back unchanged.

    A light whose factor says it failed (:func:`failed_lights`: a strobe that did not fire) is not
    balanced: its photographs' samples are left out, with a warning that names them, the others
    balanced without them, and ``capture.metadata['failed_lights']`` has its factor against the
    median light's. Where the other lights' factors spread farther than :data:`BALANCE_LIMIT` (:func:`spread`),
    the lights are left as given, with a warning, and ``capture.metadata['light_balance_refused']`` is
    that spread.

    ``glossy`` (N, 3), the glossy part a fit of these samples predicts for each (π f_s), is taken
    out of them before their albedos are read. A capture balanced before is balanced again from
    where it stands: its ``metadata['light_balance']`` becomes the product of the factors.

    Returns
    -------
    (Capture, ReflectanceSamples)
        The lights' intensities divided by their ``s``, each sample's reflectance times its light's
        ``s``, and ``capture.metadata['light_balance']`` the factors ``s``.
    """
    names = [light.name for light in capture.lights if light.intensity_given]
    read = samples
    if glossy is not None:
        read = replace(samples, reflectance=(samples.reflectance - glossy).astype(samples.reflectance.dtype))
    log_s = log_light_errors(capture, read, names, max_half_cosine=GIVEN_MAX_HALF_COSINE) if len(names) >= 2 else None
    if not log_s:
        return capture, samples
    failed = failed_lights(log_s)
    if failed:
        capture, samples = _without_failed(capture, samples, failed)
        return balance_given_lights(capture, samples, None if glossy is None else glossy[_kept(capture, read)])
    spread_of_lights = spread(log_s)
    if spread_of_lights > BALANCE_LIMIT:
        warnings.warn(f"the given lights' balance factors spread {spread_of_lights:.3g} times from the median "
                      f"light's, more than a calibration is off ({BALANCE_LIMIT}): they measure how far the face's "
                      "model misses the photographs, not the lamps; the lights are left as given", stacklevel=2)
        return replace(capture, metadata=dict(capture.metadata, light_balance_refused=spread_of_lights)), samples
    factor = {name: float(np.exp(value)) for name, value in log_s.items()}
    light_of = {m.name: m.light for m in capture.measurements}
    per_measurement = np.array([factor.get(light_of[name], 1.0) for name in samples.measurement_names])
    balanced = replace(samples, reflectance=(samples.reflectance * per_measurement[samples.measurement][:, None])
                       .astype(samples.reflectance.dtype))
    lights = tuple(light.with_intensity(np.asarray(light.intensity, np.float64) / factor[light.name])
                   if light.name in factor else light for light in capture.lights)
    before = capture.metadata.get("light_balance") or {}
    total = {light.name: before.get(light.name, 1.0) * factor.get(light.name, 1.0) for light in capture.lights
             if light.name in before or light.name in factor}
    return replace(capture, lights=lights, metadata=dict(capture.metadata, light_balance=total)), balanced


def _kept(capture, samples) -> np.ndarray:
    """Which of ``samples`` were taken under a light that has not failed (``capture.metadata['failed_lights']``)."""
    failed = capture.metadata.get("failed_lights") or {}
    light_of = {m.name: m.light for m in capture.measurements}
    ok = np.array([light_of[name] not in failed for name in samples.measurement_names], bool)
    return ok[samples.measurement]


def _without_failed(capture, samples, failed: dict):
    """``capture`` with ``failed`` (light name: factor) added to its ``metadata['failed_lights']``,
    and ``samples`` without those lights' photographs; a warning names them."""
    light_of = {m.name: m.light for m in capture.measurements}
    for name, factor in failed.items():
        photographs = [m for m in samples.measurement_names if light_of[m] == name]
        warnings.warn(f"light {name!r}: its photographs ({', '.join(photographs)}) read the face {1 / factor:.3g} "
                      "times as bright as the other lights' do (the median light's); a lamp that failed, not one a "
                      "calibration puts a few percent off: left out of the fit", stacklevel=3)
    before = capture.metadata.get("failed_lights") or {}
    capture = replace(capture, metadata=dict(capture.metadata, failed_lights={**before, **failed}))
    return capture, samples.select(_kept(capture, samples))


__all__ = ["BALANCE_FIT_ROUNDS", "BALANCE_LIMIT", "BALANCE_MIN_COSINE", "BALANCE_ROUNDS", "FAILED_LIGHT_FACTOR",
           "GIVEN_MAX_HALF_COSINE", "balance_given_lights", "failed_lights", "log_light_errors", "spread"]
