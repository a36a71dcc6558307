"""Per-texel normals of a face from its reflectance samples (beyond the paper).

A morphable model's smooth shape, fitted to photographs, has normals a few
degrees off, and the region BRDF fit reads those errors as a wrong gloss
(issue 13: on the simulated Surrey capture with fitted shapes, skin ρ_s off
by a third). With every light and pose, each texel has several samples, and
they hold its normal: the non-Lambertian photometric stereo of
:mod:`mifaces.photometric_stereo.nonlambertian`, run in texture space.

**Frame.** A sample's l̂ and v̂ are in its measurement's local shading frame at
the texel (:func:`mifaces.reflectance.resampling.measurement_samples`: tangent
along +u, normal the model's). The face moves rigidly between poses, so one
texel's frames differ between measurements only by the shape fit's errors,
and a normal given in that frame, n = (a, b, c) with (0, 0, 1) the model's,
is one unknown shared by all of the texel's samples: a tangent-space normal
map.

**Normal step.** Per region, with the region's glossy parameters θ fixed, the
texel's normal n_p and albedo ρ_p minimise
E = Σ_k w_kp |I_kp - (ρ_p + π f_s(l̂', v̂'; θ)) max(0, n_p·l_kp)|² + λ |n_p - ẑ|²
(:func:`mifaces.reflectance.maps.normal_fit.refine_normals`), with I = r cos θ_l the
sample's reflectance times its cosine at the model's normal (radiance per unit
irradiance, up to π), l̂', v̂' the directions in the frame of n_p, and w the
image-space weight of eq. 10's σ, w = 1 / (σ cos θ_l)² (the BRDF fit's residual
(r - π f)/σ is the image residual times √w), scaled to mean 1 over the
samples. The prior (λ = ``prior_weight`` · mean I², in observations) keeps a
texel with few or poor samples at the model's normal; a texel with fewer
than :data:`MIN_OBSERVATIONS` samples keeps it exactly. Cast shadows, grazing
angles and saturated pixels are already out of the samples.

**Alternation** (:func:`refine_texel_normals`): each round takes the normal
step (optionally averaging the normals over the texture afterwards,
:func:`smooth_normals`), re-expresses every sample in the frame of its
texel's new normal (:func:`rotate_samples`: l̂, v̂ rotated, r = I / cos θ_l',
σ rescaled by eq. 9's l_z² v_z) and refits the region BRDFs on them (the
caller's fit, the same as without normals), until E improves by less than
``tol`` (relative). Two choices make the refit see the gloss rather than the
albedo's texture: each sample's r has its texel's albedo offset ρ_p - ρ̄
subtracted (ρ_p the normal step's closed form, ρ̄ the region's mean), as
:func:`mifaces.photometric_stereo.nonlambertian.brdf_samples` does per pixel, and a region
with refined texels is fitted on their samples only (elsewhere neither the
normal nor the albedo offset is known). On the simulated Surrey capture with
fitted shapes (``validation/normals_faces.py``) the offsets alone take skin
ρ_s from 34 % to 26 % off, the normals with them to 7.5 %.

**Output.** The normals are written for Mitsuba's ``normalmap`` BSDF
(:func:`mitsuba_tangent_normals`): relative to its shading frame, whose
normal is the interpolated vertex normal and whose tangent is the triangle's
∂p/∂u made orthogonal to it (Mitsuba's ``SurfaceInteraction.initialize_sh_frame``),
encoded (x + 1) / 2 per channel (:func:`encode`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.ndimage

from ...model.texture_space import rasterize, texel_geometry
from ...options.fields import check, option
from .diffuse import albedo_offsets
from .normal_fit import LitPixels, NormalFit, NormalStepOptions, refine_normals
from ..samples import MIN_COSINE, ReflectanceSamples

#: Default weight of the model's normal in a texel's normal step, in observations of mean weight.
PRIOR_WEIGHT = 0.5
#: Texels with fewer samples keep the model's normal.
MIN_OBSERVATIONS = 3
#: The start search of the normal step (radius, step, levels in degrees; see
#: :func:`mifaces.reflectance.maps.normal_fit.search_start`): fitted shapes are off by a few degrees.
SEARCH = (9.0, 3.0, 3)
#: Most rounds of normal step and region fit. Chosen on development data in scratch runs (2026-12-06, not
#: kept in validation/results/), before the glossy refit after the rounds was added: on Yale B01 most of the
#: loss fell in the first round (311.8, then 295.6, 291.5, and 287.9 after eight); on the simulated default
#: capture (which bench_pipeline.json also reports) three rounds came within 1 % of eight in Cook-Torrance's
#: held-out relative RMSE, at about half the fit's time.
NORMAL_ROUNDS = 3
#: Each normal step's Gauss-Newton iterations stop when one lowers the step's E by less than this
#: fraction of it (:class:`~mifaces.reflectance.maps.normal_fit.NormalStepOptions`' ``tol``, whose
#: default, 1e-7, photometric stereo keeps). Chosen on development captures
#: (``validation/normal_step_tol.py``, ``normal_step_tol.json``: seeds 101 and 102, fitted shapes):
#: against 1e-7 it takes about a quarter off the fits' time and moves no model's held-out error by more
#: than the renders' noise.
STEP_TOL = 1e-5


@dataclass(frozen=True)
class NormalOptions:
    """How :func:`refine_texel_normals` alternates (module docstring): ``FitOptions.normal_options``'
    fields. Validated on construction: a number out of its range raises a ``ValueError`` naming the field.

    Attributes
    ----------
    prior_weight : float
        Weight of the model's normal in each normal step, in observations.
    rounds : int
        Most rounds of normal step + BRDF fit.
    tol : float
        Stop when a round lowers E by less than ``tol`` · E.
    step_tol : float
        Each normal step's tolerance (:data:`STEP_TOL`): its iterations stop when one lowers the
        step's E by less than ``step_tol`` times it.
    search : (radius, step, levels) or None
        The normal step's start search (:func:`~mifaces.reflectance.maps.normal_fit.search_start`; None:
        none).
    smooth : float
        After each normal step, average the normals over the texture with a Gaussian of this many
        texels (:func:`smooth_normals`; 0: not at all).
    """

    prior_weight: float = option(PRIOR_WEIGHT, bounds=(0.0, None))
    rounds: int = option(NORMAL_ROUNDS, bounds=(0, None))
    tol: float = option(1e-3, bounds=(0.0, None))
    step_tol: float = option(STEP_TOL, bounds=(0.0, None))
    search: tuple | None = SEARCH
    smooth: float = option(0.0, bounds=(0.0, None))

    def __post_init__(self):
        check(self)


@dataclass
class TexelNormals:
    """Outcome of :func:`refine_texel_normals`.

    Attributes
    ----------
    normals : ndarray (R, R, 3)
        Unit normals in the samples' local frame (tangent along +u, z the
        model's normal); (0, 0, 1) where not refined.
    refined : ndarray (R, R) of bool
        Texels whose normal was estimated (at least :data:`MIN_OBSERVATIONS` samples).
    fits : dict
        Region name -> RegionFit, fitted on the samples in the refined frames.
    samples : ReflectanceSamples
        The samples in the refined frames (:func:`rotate_samples`): those of the input
        still seen and lit above the grazing limit in them.
    loss : float
        E (module docstring) of the returned state, all regions.
    history : list of dict
        Per round: ``{"round", "loss", "seconds", "texels", "mean_tilt_deg"}``; round 0 is the model's normals.
    """

    normals: np.ndarray
    refined: np.ndarray
    fits: dict
    samples: ReflectanceSamples
    loss: float
    history: list = field(default_factory=list)

    def summary(self) -> dict:
        """The refinement's record for ``brdf.json``: rounds, texels refined, tilts."""
        tilt = np.degrees(np.arccos(np.clip(self.normals[..., 2][self.refined], -1.0, 1.0)))
        return {"texels": int(self.refined.sum()), "loss": self.loss, "history": self.history,
                "mean_tilt_deg": float(tilt.mean()) if tilt.size else 0.0,
                "median_tilt_deg": float(np.median(tilt)) if tilt.size else 0.0}


def texel_table(texel, measurement, select):
    """The samples ``select`` (bool (N,)) laid out as (K, P): P distinct texels, K slots, one per measurement.

    Returns ``texels`` (P,) flat texel indices, ``index`` (K, P) sample index or -1."""
    chosen = np.flatnonzero(select)
    texels, column = np.unique(texel[chosen], return_inverse=True)
    slots = np.unique(measurement[chosen], return_inverse=True)
    row = slots[1]
    index = np.full((len(slots[0]), len(texels)), -1, np.int64)
    index[row, column] = chosen
    return texels, index


def _observations(light, view, reflectance, sigma, index):
    """(K, P) arrays of the normal step from sample ``index`` (-1: none): l, v, I = r l_z, w."""
    have = index >= 0
    i = np.where(have, index, 0)
    l, v = np.asarray(light, np.float64)[i], np.asarray(view, np.float64)[i]
    l[~have], v[~have] = (0.0, 0.0, 1.0), (0.0, 0.0, 1.0)
    lz = l[..., 2]
    values = np.asarray(reflectance, np.float64)[i] * lz[..., None] * have[..., None]
    w = np.where(have, 1.0 / np.square(np.asarray(sigma, np.float64)[i] * np.maximum(lz, 1e-6)), 0.0)
    w /= max(w[have].mean(), 1e-30) if have.any() else 1.0
    return l, v, values, w


def frames_of(normals) -> np.ndarray:
    """(M, 3, 3) rows (t₁, t₂, n) of the frame of each unit normal (M, 3) of a local frame: t₁ the
    local x axis (the u direction) made orthogonal to n, so the model's normal ẑ gives the identity."""
    n = np.asarray(normals, np.float64)
    t1 = np.zeros_like(n)
    t1[:, 0] = 1.0
    t1 -= n * n[:, :1]
    t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-30)
    return np.stack([t1, np.cross(n, t1), n], axis=1)


def rotate_samples(light, view, reflectance, sigma, normals, min_cosine: float = MIN_COSINE):
    """Samples re-expressed in the frame of their texel's normal ``normals`` (N, 3) (module docstring).

    r' = r l_z / l_z' keeps the observed radiance; σ' = σ l_z² v_z / (l_z'² v_z') keeps eq. 10's
    distance factor. Samples seen or lit below ``min_cosine`` in the new frame are dropped.

    Returns
    -------
    light, view, reflectance, sigma, keep
        The kept samples, and ``keep`` (N,) bool.
    """
    frame = frames_of(normals)
    light, view = np.asarray(light, np.float64), np.asarray(view, np.float64)
    l2, v2 = np.einsum("nij,nj->ni", frame, light), np.einsum("nij,nj->ni", frame, view)
    keep = (l2[:, 2] >= min_cosine) & (v2[:, 2] >= min_cosine)
    lz, vz, lz2, vz2 = light[keep, 2], view[keep, 2], l2[keep, 2], v2[keep, 2]
    r = np.asarray(reflectance, np.float64)[keep] * (lz / lz2)[:, None]
    s = np.asarray(sigma, np.float64)[keep] * (lz * lz * vz) / (lz2 * lz2 * vz2)
    return (l2[keep].astype(np.float32), v2[keep].astype(np.float32), r.astype(np.float32), s.astype(np.float32),
            keep)


class _Region:
    """One region's texels with enough samples, as the normal step's (K, P) observations."""

    def __init__(self, samples: ReflectanceSamples, select):
        self.texels, index = texel_table(samples.texel, samples.measurement, select)
        count = (index >= 0).sum(axis=0)
        enough = count >= MIN_OBSERVATIONS
        self.texels, index = self.texels[enough], index[:, enough]
        light, view, values, weights = _observations(samples.light, samples.view, samples.reflectance, samples.sigma,
                                                     index)
        footprint = None  # each observation's footprint (K, P, 3), where the samples have one
        if samples.footprint is not None:
            footprint = np.where((index >= 0)[..., None], np.asarray(samples.footprint)[np.maximum(index, 0)], 0.0)
        self.pixels = LitPixels(values, light, weights, view=view, footprint=footprint)

    def step(self, model, params, normals, options: NormalStepOptions):
        """The normal step from ``normals`` (P, 3), a NormalFit; with ``iterations=0`` and no search,
        E and the closed-form albedo at them."""
        if len(self.texels) == 0:
            return NormalFit(normals, np.zeros_like(normals), 0.0, 0)
        prior = np.tile([0.0, 0.0, 1.0], (len(self.texels), 1))  # the model's normal
        return refine_normals(model, params, self.pixels, normals, prior=prior, options=options)


def refine_texel_normals(model, fit, fits: dict, samples: ReflectanceSamples, names: dict, *,
                         options: NormalOptions | None = None, progress=None) -> TexelNormals:
    """Alternate the per-texel normal step with the region BRDF fit (module docstring).

    Parameters
    ----------
    model : BRDFModel
    fit : callable
        ``fit(samples) -> {region name: RegionFit}``: the region fit of
        :func:`mifaces.reflectance.estimate.fit_brdf`, called on the samples in the refined frames.
    fits : dict
        Region name -> RegionFit at the model's normals (the fit without refinement).
    samples : ReflectanceSamples
        The face's samples, with their region labels (``label``).
    names : dict
        Region label -> name, of the regions fitted.
    options : NormalOptions, optional
        The prior's weight, the most rounds and their tolerance, the start search, the smoothing
        (default ``NormalOptions()``).
    progress : callable, optional
        Called with each round's history entry.

    Returns
    -------
    TexelNormals
        The best round's state (lowest E).
    """
    t0 = time.perf_counter()
    options = options or NormalOptions()
    step = NormalStepOptions(prior_weight=options.prior_weight, search=options.search, tol=options.step_tol)
    measure = NormalStepOptions(prior_weight=options.prior_weight, iterations=0, search=None)  # E where they are
    texel, label, resolution = np.asarray(samples.texel), samples.labels(), samples.resolution
    regions = {lab: _Region(samples, label == lab) for lab in names}
    size = resolution * resolution
    normals = np.zeros((size, 3))
    normals[:, 2] = 1.0
    refined = np.zeros(size, bool)
    for region in regions.values():
        refined[region.texels] = True
    loss, albedo = _evaluate(model, regions, fits, names, normals, measure)
    history = [{"round": 0, "loss": loss, "seconds": time.perf_counter() - t0, "texels": 0, "mean_tilt_deg": 0.0}]
    if progress is not None:
        progress(history[-1])
    best = (loss, normals.copy(), fits, samples)
    for round_ in range(1, options.rounds + 1):
        t0 = time.perf_counter()
        for lab, region in regions.items():
            normals[region.texels] = region.step(model, fits[names[lab]].params, normals[region.texels], step).normals
        if options.smooth:
            normals = smooth_normals(normals.reshape(resolution, resolution, 3),
                                     refined.reshape(resolution, resolution), options.smooth).reshape(-1, 3)
        loss, albedo = _evaluate(model, regions, fits, names, normals, measure)
        rotated = _rotated(samples, normals[texel])
        use = _fitted_samples(refined, rotated.texel, rotated.label)
        offsets = albedo_offsets(albedo, rotated.texel, rotated.label, where=refined[rotated.texel])
        fits = fit(replace(rotated, reflectance=rotated.reflectance - offsets).select(use))
        tilt = np.degrees(np.arccos(np.clip(normals[refined, 2], -1.0, 1.0)))
        history.append({"round": round_, "loss": loss, "seconds": time.perf_counter() - t0,
                        "texels": int(refined.sum()), "mean_tilt_deg": float(tilt.mean()) if tilt.size else 0.0})
        if progress is not None:
            progress(history[-1])
        improved = loss < best[0] * (1 - options.tol)
        if loss < best[0]:
            best = (loss, normals.copy(), fits, rotated)
        if not improved:
            break
    loss, normals, fits, rotated = best
    return TexelNormals(normals=normals.reshape(resolution, resolution, 3),
                        refined=refined.reshape(resolution, resolution), fits=fits, samples=rotated, loss=loss,
                        history=history)


def _rotated(samples: ReflectanceSamples, normals) -> ReflectanceSamples:
    """``samples`` in the frames of their texel's normal ``normals`` (N, 3): :func:`rotate_samples`,
    the samples it keeps with their texel, measurement and label."""
    light, view, reflectance, sigma, keep = rotate_samples(samples.light, samples.view, samples.reflectance,
                                                           samples.sigma, normals)
    return replace(samples.select(keep), light=light, view=view, reflectance=reflectance, sigma=sigma)


def _evaluate(model, regions, fits, names, normals, measure: NormalStepOptions):
    """E at ``normals`` (all texels, (R², 3)) and each refined texel's closed-form albedo (R², 3), by the
    normal step ``measure`` (no iterations, no search)."""
    loss, albedo = 0.0, np.zeros_like(normals)
    for lab, region in regions.items():
        if len(region.texels):
            state = region.step(model, fits[names[lab]].params, normals[region.texels], measure)
            loss += state.loss
            albedo[region.texels] = state.albedo
    return loss, albedo


def _fitted_samples(refined, texel, label) -> np.ndarray:
    """The samples of the region fit: in a region with refined texels, theirs (a texel's normal and
    albedo are known only there); in the others, all."""
    on = refined[texel]
    with_normals = np.unique(label[on])
    return on | ~np.isin(label, with_normals)


def smooth_normals(normals, mask, sigma: float) -> np.ndarray:
    """Normals (R, R, 3) averaged over ``mask`` with a Gaussian of ``sigma`` texels (normalised
    convolution: texels outside ``mask`` neither give nor take), renormalised; outside unchanged."""
    mask = np.asarray(mask, np.float64)
    weight = scipy.ndimage.gaussian_filter(mask, sigma)
    out = np.array(normals, np.float64)
    for c in range(3):
        out[..., c] = np.where(mask > 0, scipy.ndimage.gaussian_filter(out[..., c] * mask, sigma) /
                               np.maximum(weight, 1e-12), out[..., c])
    inside = mask > 0
    out[inside] /= np.maximum(np.linalg.norm(out[inside], axis=-1, keepdims=True), 1e-30)
    return out


def mitsuba_frames(face_model, vertices, resolution: int):
    """Mitsuba's shading frame and the samples' frame at every covered texel of the face ``vertices``.

    Mitsuba (``Mesh.compute_surface_interaction``, ``SurfaceInteraction.initialize_sh_frame``): n the
    interpolated vertex normal, s = normalise(∂p/∂u - n (n·∂p/∂u)) with the triangle's ∂p/∂u, t = n × s.
    The samples (:func:`~mifaces.model.texture_space.texel_geometry`): the same n, the tangent
    interpolated from the vertices' accumulated ∂p/∂u.

    Returns
    -------
    texel : ndarray (M,)
        Flat indices of the covered texels.
    mitsuba, samples : ndarray (M, 3, 3)
        Rows (s, t, n) and (tangent, bitangent, normal), world frame.
    """
    raster = rasterize(face_model.uv, face_model.triangles, (resolution, resolution))
    vertices = np.asarray(vertices, np.float64)
    geo = texel_geometry(vertices, face_model.triangles, face_model.uv, raster)
    tri = np.asarray(face_model.triangles, np.int64)[raster.triangle.ravel()[geo.texel]]
    p, uv = vertices[tri], np.asarray(face_model.uv, np.float64)[tri]
    e1, e2, d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    dpdu = (d2[:, 1:2] * e1 - d1[:, 1:2] * e2) / np.where(det == 0, 1.0, det)[:, None]
    n = geo.normal
    s = dpdu - n * np.sum(n * dpdu, axis=1, keepdims=True)
    s /= np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-30)
    mitsuba = np.stack([s, np.cross(n, s), n], axis=1)
    samples = np.stack([geo.tangent, geo.bitangent, n], axis=1)
    return geo.texel, mitsuba, samples


def mitsuba_tangent_normals(normals, face_model, vertices) -> np.ndarray:
    """Normals (R, R, 3) in the samples' local frame as Mitsuba ``normalmap`` normals: the same world
    directions on the face ``vertices`` relative to Mitsuba's shading frame (:func:`mitsuba_frames`).
    Rigid motions of the face leave them unchanged. Uncovered texels get (0, 0, 1)."""
    normals = np.asarray(normals, np.float64)
    resolution = normals.shape[0]
    texel, mitsuba, samples = mitsuba_frames(face_model, vertices, resolution)
    world = np.einsum("mij,mi->mj", samples, normals.reshape(-1, 3)[texel])
    local = np.einsum("mij,mj->mi", mitsuba, world)
    out = np.zeros((resolution * resolution, 3))
    out[:, 2] = 1.0
    out[texel] = local / np.maximum(np.linalg.norm(local, axis=1, keepdims=True), 1e-30)
    return out.reshape(resolution, resolution, 3)


def encode(normals) -> np.ndarray:
    """Unit normals (..., 3) as a ``normalmap`` texture: (n + 1) / 2, float32."""
    return ((np.asarray(normals, np.float64) + 1.0) / 2.0).astype(np.float32)


def decode(texture) -> np.ndarray:
    """A ``normalmap`` texture back to unit normals, as Mitsuba reads it: normalise(2 x - 1)."""
    n = 2.0 * np.asarray(texture, np.float64) - 1.0
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)


__all__ = ["PRIOR_WEIGHT", "MIN_OBSERVATIONS", "STEP_TOL", "NormalOptions", "TexelNormals", "texel_table", "frames_of",
           "rotate_samples", "refine_texel_normals", "mitsuba_frames", "mitsuba_tangent_normals", "encode", "decode"]
