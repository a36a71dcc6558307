"""BRDF estimation from a capture: the stage from photographs and face
geometry to fitted BRDFs (paper sec. 4.3-5.3).

:func:`fit_brdf` chains the steps:

1. per measurement, the photograph resampled into the model's common texture
   parameterization and turned into weighted reflectance samples
   (:func:`mifaces.reflectance.samples.capture_samples`: eq. 4, 9, 10, shadow
   and grazing-angle masks);
2. each sample labelled with the a-priori material region of its texel, as
   the triangle covering it is labelled
   (:func:`mifaces.model.regions.texel_regions_of_mesh`);
3. one BRDF model fitted per region by hierarchical Levenberg-Marquardt
   (:func:`mifaces.reflectance.fit.regions.fit_regions`; a region with too few samples
   borrows a neighbour's fit, a region with none is not evaluated);
4. optionally (``normals=True``, beyond the paper), a normal per texel
   alternated with step 3 (:func:`mifaces.reflectance.maps.normals.refine_texel_normals`);
5. the diffuse albedo refitted per texel with the glossy part fixed
   (:func:`mifaces.reflectance.maps.diffuse.refine_diffuse`).

With ``out``, :func:`mifaces.reflectance.io.write_estimate` writes the
result: ``brdf.json``, the albedo map and ``scene.xml``.

The face geometry per measurement is an input: the simulator's ground truth
(``geometry="ground-truth"``), the shapes written by ``mifaces fit-shape``,
or any mapping from measurement name to world-space vertices.
"""

from __future__ import annotations

import dataclasses
import time
import warnings

import numpy as np

from .. import brdf as brdf_models
from ..capture import load_capture
from ..shape.io import load_geometry
from ..model.regions import REGIONS, regions_present, texel_regions_of_mesh
from ..status import AT_BOUND, CONVERGED
from .maps.diffuse import AlbedoOffsets, refine_diffuse
from .fit.regions import fit_regions
from .interreflection import INDIRECT_DEPTH, INDIRECT_SPP, INDIRECT_WIDTH, bounced_light
from .io import write_fitted
from .options import FitOptions, fit_options
from .result import BRDFEstimate
from .light_balance import balance_given_lights
from .samples import ReflectanceSamples, capture_samples
from .maps.specular import refine_specular
from .fit.uncertainty import TEXEL_TILE_AT_128, tile_clusters
from .maps.normals import MIN_OBSERVATIONS, mitsuba_tangent_normals, refine_texel_normals



def fit_brdf(capture, model: str = "cooktorrance", geometry="ground-truth", *, face_model=None,
             options: FitOptions | None = None, samples: ReflectanceSamples | None = None, measurements=None,
             out=None, progress: bool = True, force: bool = False, **deprecated) -> BRDFEstimate:
    """Fit a BRDF model per region to the photographs of a capture.

    Parameters
    ----------
    capture : Capture or path
    model : str
        ``phong``, ``cooktorrance``, ``ward`` or ``lafortune``.
    geometry : ``'ground-truth'``, path or mapping
        Per-measurement face geometry (see :func:`load_geometry`).
    face_model : MorphableModel or path, optional
    options : FitOptions, optional
        How to fit (resolution, per-texel maps, uncertainty, ...; :class:`FitOptions`).
    samples : ReflectanceSamples, optional
        Samples computed before (skips step 1; must match ``options.resolution``).
    measurements : sequence of str, optional
        Fit to these measurements only (default: all with geometry).
    out : path, optional
        Write the result there (:func:`mifaces.reflectance.io.write_estimate`).
    force : bool
        Replace a fitted BRDF that ``out`` holds.
    **deprecated
        The fit options as separate keywords (``resolution=``, ``normals=``, ...), as before
        :class:`FitOptions`: still accepted, with a :class:`DeprecationWarning`.

    Returns
    -------
    BRDFEstimate
        Refine it by differentiable rendering with
        :func:`mifaces.refine.refine_estimate`, the next stage.

    Examples
    --------
    Phong fitted per region on a simulated capture's true shapes (``capture_folder``, one
    :func:`mifaces.simulate` wrote here), in a 32 × 32 texture space, written to ``out``:

    >>> from mifaces.reflectance import FitOptions, fit_brdf
    >>> estimate = fit_brdf(capture_folder, "phong", "ground-truth", options=FitOptions(resolution=32),
    ...                     out=out / "phong", progress=False)
    >>> sorted(estimate.fits["skin"].params)
    ['diffuse_reflectance', 'exponent', 'specular_reflectance']
    >>> estimate.resolution, (out / "phong" / "brdf.json").is_file()
    (32, True)

    Refining it by differentiable rendering is the next stage's call:
    ``mifaces.refine.refine_estimate(estimate, capture, shapes, face)``.
    """
    t0 = time.perf_counter()
    options = fit_options(options, deprecated, "fit_brdf")
    resolution, fixed, schedule, seed = options.resolution, options.fixed, options.schedule, options.seed
    normals = options.normals
    capture = load_capture(capture)
    brdf = brdf_models.model(model, **options.brdf_options())
    face, shapes = load_geometry(capture, geometry, face_model)
    interreflection = None
    if options.interreflection:  # a first fit, its bounced light rendered, then the fit on samples without it
        first = fit_brdf(capture, model, shapes, face_model=face, samples=samples, measurements=measurements,
                         progress=progress, options=dataclasses.replace(
                             options, interreflection=False, uncertainty=None, normals=False, specular_maps=False))
        bounced = bounced_light(capture, shapes, face, first, measurements=first.measurements, progress=progress)
        samples = capture_samples(capture, shapes, face, resolution, measurements=first.measurements,
                                  progress=progress, indirect=bounced)
        interreflection = {"depth": INDIRECT_DEPTH, "width": INDIRECT_WIDTH, "spp": INDIRECT_SPP,
                           "seconds": time.perf_counter() - t0}
    if samples is None:
        samples = capture_samples(capture, shapes, face, resolution, measurements=measurements, progress=progress)
    elif samples.resolution != resolution:
        raise ValueError(f"the samples are at resolution {samples.resolution}, not {resolution}")
    if len(samples) == 0:
        raise ValueError("no valid reflectance samples: every texel is hidden, shadowed, grazing or saturated")
    light_balance = None
    if options.balance_lights:
        capture, samples = balance_given_lights(capture, samples)
        light_balance = capture.metadata.get("light_balance")
    t_samples = time.perf_counter()
    region_map = (samples.region_map if samples.region_map is not None
                  else texel_regions_of_mesh(face.region_map, face.uv, face.triangles, resolution))
    label = samples.label if samples.label is not None else samples.region(region_map)
    names = {REGIONS[n]: n for n in regions_present(face.region_map)}
    on_face = dataclasses.replace(samples, label=label).select(np.isin(label, list(names)))
    # parameters with a published value per region (Cook-Torrance's η) are fixed at it unless given
    per_region = {name: {k: v for k, v in brdf.fixed_in_region(name).items() if fixed is None or k not in fixed}
                  for name in names.values()}
    plan = options.resolved()  # which of the albedo's fits, and whether intervals, with normals
    rounds, texel_albedo, uncertainty = int(plan.albedo_rounds), plan.texel_albedo, plan.uncertainty
    region_fit = dict(progress=progress, fixed=fixed, fixed_by_region=per_region, schedule=schedule, seed=seed,
                      cluster=tile_clusters(on_face.texel, resolution, label=on_face.label))
    fits = fit_regions(brdf, on_face, names, **region_fit,
                       uncertainty=None if rounds or texel_albedo else uncertainty)
    if texel_albedo:  # the glossy parts with an albedo per texel, and their intervals over larger tiles
        region_fit["cluster"] = tile_clusters(on_face.texel, resolution, label=on_face.label,
                                              tile=max(1, round(TEXEL_TILE_AT_128 * resolution / 128)))
        refits = uncertainty == "bootstrap"  # which does not refit albedos per texel: a last round does
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the first fit has warned already
            per_texel = fit_regions(brdf, on_face, names, **region_fit, uncertainty=None if refits else uncertainty,
                                    texel_albedo=True, starts=_measured(fits))
        rounds = 1 if refits else 0
        lost = _lost_skin(fits, per_texel)
        if lost:  # too few photographs per texel to see the lobe (two, say): the region fit, with its intervals
            warnings.warn(f"the glossy fit with an albedo per texel measured no lobe on skin ({lost}): every region "
                          "keeps the region fit, one albedo per region", stacklevel=2)
            texel_albedo, rounds = False, 0
            region_fit["cluster"] = tile_clusters(on_face.texel, resolution, label=on_face.label)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the first fit has warned already
                fits = fit_regions(brdf, on_face, names, **region_fit, uncertainty=uncertainty, starts=_measured(fits))
        else:
            fits = per_texel
    for round_ in range(rounds):
        by_label = {REGIONS[name]: fit.params for name, fit in fits.items()}
        # unshrunk: the texel means (a texel effect per texel, consistent for the glossy part); shrunk
        # towards the region's albedo they leave part of the texture in, and bias skin's lobe
        offsets = AlbedoOffsets.of(refine_diffuse(brdf, by_label, on_face, region_map, shrinkage=False),
                                   on_face.texel, on_face.label)
        corrected = dataclasses.replace(on_face, reflectance=on_face.reflectance - offsets.offsets)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the first fit has warned already
            last = round_ == rounds - 1  # its intervals re-estimate the offsets per replicate
            fits = fit_regions(brdf, corrected, names, **region_fit, uncertainty=uncertainty if last else None,
                               offsets=offsets if last else None,
                               starts=_measured(fits) if texel_albedo else None)
    texel_normals = None
    if normals:
        texel_normals = _refine_normals(brdf, fits, on_face, names, options.normal_options, progress,
                                        dict(fixed=fixed, fixed_by_region=per_region, schedule=schedule, seed=seed,
                                             uncertainty=None))
        if texel_normals is not None:
            on_face, fits = texel_normals.samples, texel_normals.fits
    t_fit = time.perf_counter()
    by_label = {REGIONS[name]: fit.params for name, fit in fits.items()}
    albedo = refine_diffuse(brdf, by_label, on_face, region_map)
    specular = None
    if options.specular_maps:
        if any(p.name == "specular_reflectance" for p in brdf.specular_parameters()):
            specular = refine_specular(brdf, by_label, on_face, region_map)
        else:
            warnings.warn(f"specular maps left out: {brdf.name} has no specular_reflectance", stacklevel=2)
    t_end = time.perf_counter()
    estimate = BRDFEstimate(model=brdf.name, options=options.brdf_options(), fits=fits, albedo=albedo,
                            region_map=region_map, samples=len(on_face), specular=specular,
                            measurements=tuple(samples.measurement_names),
                            seconds={"samples": t_samples - t0, "fit": t_fit - t_samples, "refine": t_end - t_fit,
                                     "total": t_end - t0}, light_balance=light_balance,
                            interreflection=interreflection, texel_albedo=texel_albedo, fit_options=options)
    if texel_normals is not None:
        first = next(name for name in estimate.measurements if name in shapes)
        estimate.normals = mitsuba_tangent_normals(texel_normals.normals, face, shapes[first]).astype(np.float32)
        estimate.normal_refinement = texel_normals.summary()
    if out is not None:
        write_fitted(estimate, out, capture, face, shapes, force=force)
    return estimate


def _lost_skin(region: dict, per_texel: dict) -> str | None:
    """The texel fit's status and reason where its skin measured no lobe (no converged fit, none kept at a
    bound) and the region fit's skin did; None otherwise."""
    skin = per_texel.get("skin")
    if skin is None or "skin" not in _measured(region) or skin.status in (CONVERGED, AT_BOUND):
        return None
    return f"{skin.status}: {skin.reason.split('; ')[-1]}"


def _measured(fits: dict) -> dict:
    """The parameters of the region fits that measured their glossy part (converged, or kept at a bound):
    the next fit's start values, which it may keep (a region that borrowed its lobe starts afresh)."""
    return {name: fit.params for name, fit in fits.items() if fit.status in (CONVERGED, AT_BOUND)}


def _refine_normals(brdf, fits, samples, names, options, progress, region_fit):
    """:func:`refine_texel_normals` on the face's ``samples``, the region fit as :func:`fit_brdf`'s
    (``region_fit``: keyword arguments of :func:`fit_regions`), or None (with a warning) where no texel has
    :data:`MIN_OBSERVATIONS` samples (one light per texel: nothing to tell a normal from)."""
    def fit(rotated):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the fit at the model's normals has warned already
            return fit_regions(brdf, rotated, names, **region_fit)

    if not np.any(np.bincount(samples.texel) >= MIN_OBSERVATIONS):
        warnings.warn(f"per-texel normals left out: no texel has the {MIN_OBSERVATIONS} samples (lights and "
                      "poses) a normal needs", stacklevel=3)
        return None
    report = (lambda e: print(f"normals round {e['round']}: E {e['loss']:.6g}, {e['texels']} texels, "
                              f"mean tilt {e['mean_tilt_deg']:.2f} deg", flush=True)) if progress else None
    return refine_texel_normals(brdf, fit, fits, samples, names, progress=report, **(options or {}))


__all__ = ["fit_brdf"]
