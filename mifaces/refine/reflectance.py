"""Analysis by synthesis through Mitsuba: the texture-space fit refined by
differentiating renders of the fitted face against the photographs.

The texture-space fit (:func:`mifaces.reflectance.estimate.fit_brdf`, the
paper's method, sec. 4.3-5.3) reads each texel as if it were lit by the
light alone and seen through an ideal pixel: interreflection (eye sockets,
nostrils, under the lips), a lamp of finite size, and the resampling and
pixel footprint that blur thin curved regions (lips, eyebrows, hair) are not
modelled, so small regions' highlights read too weak. :func:`refine_estimate`
starts from that fit and minimises the difference between Mitsuba renders of
the fitted face and the photographs themselves:

    E(θ, ρ_d, g) = Σ_k 1/|M_k| Σ_{p ∈ M_k} Σ_c ψ_ε((e^{g_l(k) - ḡ} I_k(θ, ρ_d)[p, c] - s J_k[p, c]) / μ_k),

where I_k is the path-traced render of measurement k (its face mesh, its
camera, its light, the per-region plugins with parameters θ over the albedo
texture ρ_d), g_l the log gain of light l, the light of measurement k (ḡ
their mean: the overall scale belongs to the albedo and the white target; a
calibrated lamp is off in distance by about a percent, its irradiance by
twice that, which with the lights held the glossy parameters absorb), J_k
the photograph (s = s_white/π puts it in the renderer's
units, eq. 4 with the white target's scale), M_k the pixels the face covers
(eroded by one pixel at silhouettes, saturated pixels left out), μ_k the
photograph's mean over M_k and ψ_ε(r) = sqrt(r² + ε²) - ε the Charbonnier
penalty (quadratic below ε, linear above: misregistered pixels cannot
dominate). Gradients come from Dr.Jit's reverse mode through Mitsuba's path
replay backpropagation (``prb``; Vicini et al., "Path Replay
Backpropagation", SIGGRAPH 2021); the steps are Adam's, one photograph per
step in turn, and the result is the mean of the last iterates
(Polyak-Ruppert averaging, :class:`~mifaces.refine.schedule.IterateAverage`).
Parameters stay inside their ranges (``Parameter.lower`` and
``upper``) by the reparameterisation of the texture-space fit
(:class:`~mifaces.reflectance.fit.parameters.ParameterSpace`, a sigmoid or its
logarithmic form); the albedo, optionally a variable too, by a smooth
multiplicative correction (:class:`~mifaces.refine.albedo_correction.AlbedoCorrection`).

Each photograph's scene is the one face-scene builder's
(:meth:`mifaces.render.FaceScene.scene`) with the differentiable integrator,
a film cropped to the face, and the light of the capture: a point light, a
directional light, or, where the capture states ``lamp_radius_mm`` (in its
``metadata``) or the caller gives ``lamp_radius``, a spherical area light of
that radius and the same radiant intensity; or an environment map (Mitsuba's
``envmap``). An estimated map (:attr:`mifaces.capture.Light.estimated`) is a
variable too: its log radiance per texel, the mean held, with a smoothness
prior (:attr:`RefineSchedule.environment_learning_rate`); under a map the
glossy parameters start at the model's start values
(:attr:`RefineSchedule.restart_under_maps`). No other geometry. The scenes
are built once; each step writes the parameters (opaque, so the kernels
compiled on the first pass over the photographs are reused) and renders.

The pieces: each photograph against its render, the image loss and its pixels in
:mod:`~mifaces.refine.photograph`; the variables and the loss over all photographs in
:mod:`~mifaces.refine.problem` (:class:`~mifaces.refine.problem.RefineProblem`); an estimated
map as a variable in :mod:`~mifaces.refine.environment`; the driver, :func:`refine_estimate`, here.

The refined estimate is returned only if it lowers the loss on pixels the
refinement did not fit: blocks of each photograph's face pixels held out of E
(:attr:`RefineSchedule.holdout`), rendered before and after with the same
seed; otherwise the texture-space fit comes back, and ``refinement`` says why.
"""

from __future__ import annotations

import dataclasses
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from ..runtime.progress import progress as progress_bar
from ..reflectance.result import BRDFEstimate
from .kernels import kernel_counts, kernel_history
from .photograph import LAMP_RADIUS_KEY
from .problem import RefineProblem
from .schedule import ALBEDO, LIGHT_GAIN, IterateAverage, RefineSchedule


def _rates(problem: RefineProblem, schedule: RefineSchedule, iteration: int) -> dict:
    """Each variable's learning rate at ``iteration`` (:meth:`RefineSchedule.rate`)."""
    return {name: schedule.rate(name, iteration, problem.pixels.get(name.rsplit(".", 1)[0]))
            for name in problem.variables}


def _optimizer(problem: RefineProblem, schedule: RefineSchedule):
    opt = mi.ad.Adam(lr=schedule.learning_rate)
    for name, value in problem.variables.items():
        if name == ALBEDO or np.ndim(value) == 3:  # the albedo correction, an environment map
            opt[name] = mi.TensorXf(np.ascontiguousarray(value, np.float32))
        elif name == LIGHT_GAIN:
            opt[name] = mi.Float(np.asarray(value, np.float32))
        else:
            opt[name] = mi.Float(value)
    opt.set_learning_rate(_rates(problem, schedule, 0))
    return opt


def _iterate(problem: RefineProblem, opt, schedule: RefineSchedule, seed: int, progress: bool, callback,
             t0: float) -> tuple[list, IterateAverage]:
    """Adam's steps, one photograph per step in turn: each step's record (seconds, photograph, loss,
    kernel launches: :func:`~mifaces.refine.kernels.kernel_counts`) and the average of the last
    iterates. ``callback`` as :func:`refine_estimate` calls it (``t0`` its start)."""
    history, average = [], IterateAverage(problem.variables, schedule)
    bar = progress_bar(range(schedule.iterations), desc="refining", unit="it", enabled=progress)
    with kernel_history():
        for it in bar:
            t = time.perf_counter()
            photo = problem.photographs[it % len(problem.photographs)]
            loss = problem.loss(photo, opt, schedule.spp, seed=seed * 7919 + 2 * it)
            dr.backward(loss)
            opt.step()
            opt.set_learning_rate(_rates(problem, schedule, it + 1))
            dr.eval()
            average.add(it, opt)
            history.append([round(time.perf_counter() - t, 4), photo.name, float(loss[0]), *kernel_counts()])
            bar.set_postfix_str(f"loss {float(loss[0]):.4g}")
            if callback is not None:
                callback(it + 1, time.perf_counter() - t0, lambda: problem.estimate_of(average.mean(opt), None))
    return history, average


def refine_estimate(estimate: BRDFEstimate, capture, shapes, face_model, schedule: RefineSchedule | None = None, *,
                    lamp_radius: float | None = None, measurements=None, seed: int = 0, progress: bool = True,
                    callback=None) -> BRDFEstimate:
    """Refine a texture-space fit by differentiable rendering against the photographs.

    Parameters
    ----------
    estimate : BRDFEstimate
        The fit of :func:`mifaces.reflectance.estimate.fit_brdf` to start from.
    capture : Capture
    shapes : mapping
        Measurement name -> (V, 3) world vertices (mm) of ``face_model``.
    face_model : MorphableModel
    schedule : RefineSchedule, optional
    lamp_radius : float, optional
        Radius (mm) of the lamp, a sphere of that size in place of each point
        light; default the capture's ``metadata["lamp_radius_mm"]``, else a
        point light.
    measurements : sequence of str, optional
        Photographs to refine on (default: those the estimate was fitted to).
    seed : int
        Monte Carlo seeds derive from it.
    progress : bool
    callback : callable, optional
        Called after each step as ``callback(iteration, seconds, estimate)``,
        ``seconds`` since the start, ``estimate()`` giving the estimate at
        that step (the running average of the iterates once ``schedule.average``
        starts; for error-against-time curves).

    Returns
    -------
    BRDFEstimate
        With the refined glossy parameters per region seen by enough pixels
        (and the albedo with ``schedule.albedo_learning_rate``), the average
        of the last iterates (``schedule.average``), if that lowers the loss
        on the held-out pixels (:attr:`RefineSchedule.holdout`); otherwise
        ``estimate`` unchanged. Either way ``refinement``: ``accepted`` and
        ``reason``, the schedule, the loss on the fitted and on the held-out
        pixels before and after, the loss per iteration, the regions refined,
        times and kernel launches.
    """
    schedule = schedule or RefineSchedule()
    if lamp_radius is None:
        lamp_radius = capture.metadata.get(LAMP_RADIUS_KEY)
    t0 = time.perf_counter()
    problem = RefineProblem(estimate, capture, shapes, face_model, schedule, lamp_radius, measurements, seed)
    opt = _optimizer(problem, schedule)
    t_build = time.perf_counter()
    with dr.suspend_grad():
        start = {k: mi.TensorXf(opt[k]) if isinstance(opt[k], mi.TensorXf) else mi.Float(opt[k])
                 for k in problem.variables}
    # the texture-space fit's loss, which the result must beat on held-out pixels (also where it restarted)
    before = problem.total_loss({**start, **{k: mi.Float(v) for k, v in problem.fitted.items()}},
                                schedule.evaluation_spp, seed=seed * 7919 + (1 << 20))
    t_before = time.perf_counter()
    history, average = _iterate(problem, opt, schedule, seed, progress, callback, t0)
    t_iterate = time.perf_counter()
    result = average.mean(opt)
    after = problem.total_loss(result, schedule.evaluation_spp, seed=seed * 7919 + (1 << 20))
    accepted = after["heldout"] < before["heldout"]
    reason = (f"held-out loss {before['heldout']:.5g} -> {after['heldout']:.5g}: "
              + ("fell, the refined estimate is kept" if accepted else "did not fall, the texture-space fit is kept"))
    t_end = time.perf_counter()
    first = len(problem.photographs)  # the first pass over the photographs compiles the kernels
    refinement = {
        "method": "prb",
        "schedule": dataclasses.asdict(schedule),
        "lamp_radius_mm": float(lamp_radius) if lamp_radius else None, "lights": sorted(problem.light_kinds),
        "photographs": [p.name for p in problem.photographs],
        "regions": sorted(problem.spaces), "region_pixels": problem.pixels,
        "restarted": bool(problem.restarted),
        "light_gains": problem.light_gains(result if accepted else start),
        # the refined maps, where the refinement is kept (else the capture's estimates stand)
        "environment_maps": {light: m.tolist() for light, m in problem.environment_maps(result).items()}
        if accepted else {},
        "accepted": bool(accepted), "reason": reason,
        "loss_before": before["fit"], "loss_after": after["fit"],
        "heldout_loss_before": before["heldout"], "heldout_loss_after": after["heldout"],
        "iterates_averaged": average.count,
        "history_keys": ["seconds", "photograph", "loss", "launches", "compiled", "compile_seconds"],
        "history": history,
        "launches_per_iteration": float(np.mean([h[3] for h in history])),
        "kernels_compiled": {"first_pass": int(sum(h[4] for h in history[:first])),
                             "later": int(sum(h[4] for h in history[first:]))},
        "seconds": {"build": t_build - t0, "loss_before": t_before - t_build, "iterations": t_iterate - t_before,
                    "compile": float(sum(h[5] for h in history)),
                    "first_pass": float(sum(h[0] for h in history[:first])),
                    "per_iteration_after_first_pass": float(np.mean([h[0] for h in history[first:]]))
                    if len(history) > first else None,
                    "loss_after": t_end - t_iterate, "total": t_end - t0},
    }
    refined = (dataclasses.replace(estimate, refinement=refinement) if not accepted
               else problem.estimate_of(result, refinement))
    # the fit's time with its refinement's, as the estimate's total
    refined.seconds = {**estimate.seconds, "total": estimate.seconds.get("total", 0.0) + t_end - t0}
    return refined


__all__ = ["refine_estimate"]
