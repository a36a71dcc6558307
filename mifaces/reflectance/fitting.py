"""The BRDF fit on samples taken: :func:`fit_samples`, a short sequence of named stages.

1. The plan: the options as the fit runs them (:meth:`FitOptions.resolved`), resolved once.
2. The face's regions: each sample labelled with the region of its texel, the samples off the face
   left out, the arguments every region fit shares (:class:`FaceRegions`).
3. With ``normals`` (the default), a normal per texel alternated with a fit of one albedo per region
   with its per-texel offsets taken out (:func:`~mifaces.reflectance.maps.normals.refine_texel_normals`),
   the samples then turned into the normals' frames: as photometric stereo solves a normal with each
   pixel's albedo, the shading the fitted shape gets wrong is not read as albedo or gloss. The glossy
   fit is then the last round's, refitted ``albedo_rounds`` times (at least once) with its intervals.
4. Otherwise (``--no-normals``, or no texel with the samples a normal needs) the glossy fit, by the
   plan's strategy from :data:`GLOSSY_FITS`, with its intervals: one albedo per region
   (``region``), refitted with the albedo's per-texel offsets taken out (``albedo_rounds``), or an
   albedo per texel (``texel_albedo``).
5. The maps: the diffuse albedo per texel with the glossy part fixed, and with ``specular_maps`` the
   specular reflectance per texel.

Only the first region fit warns: every later fit is of the same samples (:func:`_refit`).
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass

import numpy as np

from ..model.regions import REGIONS, regions_present, texel_regions_of_mesh
from ..runtime.status import AT_BOUND, CONVERGED
from .fit.region_fit import RegionFitOptions, Uncertainty
from .fit.regions import fit_regions
from .fit.uncertainty import TEXEL_TILE_AT_128, tile_clusters
from .maps.diffuse import AlbedoOffsets, refine_diffuse
from .maps.normals import MIN_OBSERVATIONS, NormalOptions, mitsuba_tangent_normals, refine_texel_normals
from .maps.specular import refine_specular
from .options import FitOptions
from .result import BRDFEstimate


@dataclass(frozen=True)
class FaceRegions:
    """The samples on the face, labelled by region, and what every region fit of them shares.

    Attributes
    ----------
    samples : ReflectanceSamples
        The samples of texels in a region of the face, each labelled with it.
    region_map : (R, R) uint8
    names : dict
        Region label -> region name, for the regions the face has.
    options : RegionFitOptions
        How every region fit of these samples runs: the fixed parameters, the subset schedule, the seed.
    fixed_by_region : dict
        Region name -> parameters fixed there on top (:func:`fit_regions`).
    cluster : ndarray (N,)
        Each sample's cluster for the intervals (:func:`~mifaces.reflectance.fit.uncertainty.tile_clusters`).
    progress : bool
        Show the region fits' progress.
    """

    samples: object
    region_map: np.ndarray
    names: dict
    options: RegionFitOptions
    fixed_by_region: dict
    cluster: np.ndarray
    progress: bool = False

    @classmethod
    def of(cls, taken, brdf, options: FitOptions, progress: bool) -> FaceRegions:
        samples, face, resolution, fixed = taken.samples, taken.face, taken.resolution, options.fixed
        region_map = (samples.region_map if samples.region_map is not None
                      else texel_regions_of_mesh(face.region_map, face.uv, face.triangles, resolution))
        label = samples.label if samples.label is not None else samples.region(region_map)
        names = {REGIONS[n]: n for n in regions_present(face.region_map)}
        on_face = dataclasses.replace(samples, label=label).select(np.isin(label, list(names)))
        # parameters with a published value per region (Cook-Torrance's η) are fixed at it unless given
        per_region = {name: {k: v for k, v in brdf.fixed_in_region(name).items() if fixed is None or k not in fixed}
                      for name in names.values()}
        fit_options = RegionFitOptions(fixed=fixed, schedule=options.schedule, seed=options.seed)
        cluster = tile_clusters(on_face.texel, resolution, label=on_face.label)
        return cls(on_face, region_map, names, fit_options, per_region, cluster, progress)

    def with_samples(self, samples) -> FaceRegions:
        """These regions with other samples of their texels (the samples in per-texel normals' frames):
        the intervals' clusters made of those."""
        cluster = tile_clusters(samples.texel, len(self.region_map), label=samples.label)
        return dataclasses.replace(self, samples=samples, cluster=cluster)

    def in_tiles(self) -> FaceRegions:
        """These regions with the intervals' clusters tiles of texels (an albedo per texel)."""
        tile = max(1, round(TEXEL_TILE_AT_128 * len(self.region_map) / 128))
        return dataclasses.replace(self, cluster=tile_clusters(self.samples.texel, len(self.region_map),
                                                               label=self.samples.label, tile=tile))

    def uncertainty(self, method: str | None, offsets: AlbedoOffsets | None = None) -> Uncertainty | None:
        """Intervals by ``method`` (None: none) over these samples' clusters, the reflectance corrected by
        ``offsets``."""
        return None if method is None else Uncertainty(method, self.cluster, offsets)


def fit_samples(taken, brdf, options: FitOptions, *, progress: bool = True) -> BRDFEstimate:
    """Fit ``brdf`` (a :func:`mifaces.brdf.model`) per region to the samples ``taken``
    (:class:`~mifaces.reflectance.sample_stage.SampleSet`), by the stages of the module docstring."""
    t0 = time.perf_counter()
    plan = options.resolved()
    regions = FaceRegions.of(taken, brdf, options, progress)
    normals = None
    if plan.normals:  # normals per texel from one albedo per region; its offsets, with intervals, in their frames
        start = _refit(brdf, regions, None)  # the next fit warns
        normals = _refine_normals(brdf, start, regions, options.normal_options, progress)
    if normals is not None:
        regions = regions.with_samples(normals.samples)
        fits, texel_albedo = _albedo_rounds(brdf, regions, normals.fits, plan.albedo_rounds, plan.uncertainty,
                                            starts=True), False
    else:
        plan = dataclasses.replace(options, normals=False).resolved()
        fits, texel_albedo = GLOSSY_FITS[glossy_strategy(plan)](brdf, regions, plan)
    samples = regions.samples
    t_fit = time.perf_counter()
    by_label = {REGIONS[name]: fit.params for name, fit in fits.items()}
    albedo = refine_diffuse(brdf, by_label, samples, regions.region_map)
    specular = _specular_map(brdf, by_label, samples, regions.region_map) if options.specular_maps else None
    t_end = time.perf_counter()
    seconds = {"samples": taken.seconds, "fit": t_fit - t0, "refine": t_end - t_fit,
               "total": taken.seconds + t_end - t0}
    estimate = BRDFEstimate(model=brdf.name, options=options.brdf_options(), fits=fits, albedo=albedo,
                            region_map=regions.region_map, samples=len(samples), specular=specular,
                            measurements=tuple(taken.samples.measurement_names), seconds=seconds,
                            light_balance=taken.light_balance, interreflection=taken.interreflection,
                            texel_albedo=texel_albedo, fit_options=options)
    if normals is not None:
        first = next(name for name in estimate.measurements if name in taken.shapes)
        estimate.normals = mitsuba_tangent_normals(normals.normals, taken.face, taken.shapes[first]).astype(np.float32)
        estimate.normal_refinement = normals.summary()
    return estimate


# ------------------------------------------------------------------------------------- glossy strategies

def glossy_strategy(plan: FitOptions) -> str:
    """The name in :data:`GLOSSY_FITS` of the glossy fit a resolved plan runs."""
    return "texel_albedo" if plan.texel_albedo else "albedo_rounds" if plan.albedo_rounds else "region"


def _fit(brdf, regions: FaceRegions, method: str | None, *, offsets: AlbedoOffsets | None = None,
         starts: dict | None = None, texel_albedo: bool = False) -> dict:
    """:func:`fit_regions` of ``regions``' samples as every fit of them runs, its intervals by ``method``
    (None: none; :meth:`FaceRegions.uncertainty`), from ``starts``, with an albedo per texel where
    ``texel_albedo``."""
    options = dataclasses.replace(regions.options, texel_albedo=True) if texel_albedo else regions.options
    return fit_regions(brdf, regions.samples, regions.names, options=options,
                       uncertainty=regions.uncertainty(method, offsets), fixed_by_region=regions.fixed_by_region,
                       starts=starts, progress=regions.progress)


def _refit(brdf, regions: FaceRegions, method: str | None, *, offsets: AlbedoOffsets | None = None,
           starts: dict | None = None, texel_albedo: bool = False) -> dict:
    """:func:`_fit` of samples that a first fit has fitted, and warned about, already."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _fit(brdf, regions, method, offsets=offsets, starts=starts, texel_albedo=texel_albedo)


def _region_fits(brdf, regions: FaceRegions, plan: FitOptions) -> tuple[dict, bool]:
    """One albedo per region, as the paper fits it, with its intervals."""
    return _fit(brdf, regions, plan.uncertainty), False


def _rounds_fits(brdf, regions: FaceRegions, plan: FitOptions) -> tuple[dict, bool]:
    """The region fit, refitted ``albedo_rounds`` times with the albedo's per-texel offsets taken out."""
    fits = _fit(brdf, regions, None)
    return _albedo_rounds(brdf, regions, fits, plan.albedo_rounds, plan.uncertainty), False


def _texel_albedo_fits(brdf, regions: FaceRegions, plan: FitOptions) -> tuple[dict, bool]:
    """The glossy parts with an albedo per texel, started from the region fit, their intervals over tiles
    of texels; the region fit kept where skin's lobe is lost (too few photographs per texel to see it)."""
    fits = _fit(brdf, regions, None)
    refits = plan.uncertainty == "bootstrap"  # which does not refit albedos per texel: a last round does
    tiles = regions.in_tiles()
    per_texel = _refit(brdf, tiles, None if refits else plan.uncertainty, starts=_measured(fits), texel_albedo=True)
    lost = _lost_skin(fits, per_texel)
    if lost:
        warnings.warn(f"the glossy fit with an albedo per texel measured no lobe on skin ({lost}): every region "
                      "keeps the region fit, one albedo per region", stacklevel=4)
        return _refit(brdf, regions, plan.uncertainty, starts=_measured(fits)), False
    return _albedo_rounds(brdf, tiles, per_texel, int(refits), plan.uncertainty, starts=True), True


def _albedo_rounds(brdf, regions: FaceRegions, fits: dict, rounds: int, method: str | None, *,
                   starts: bool = False) -> dict:
    """``fits`` refitted ``rounds`` times with the albedo's per-texel offsets taken out, each round from the
    last one's parameters where ``starts``; the last round's intervals (by ``method``, over ``regions``'
    clusters) re-estimate the offsets per replicate."""
    samples = regions.samples
    for round_ in range(rounds):
        by_label = {REGIONS[name]: fit.params for name, fit in fits.items()}
        # unshrunk: the texel means (a texel effect per texel, consistent for the glossy part); shrunk
        # towards the region's albedo they leave part of the texture in, and bias skin's lobe
        offsets = AlbedoOffsets.of(refine_diffuse(brdf, by_label, samples, regions.region_map, shrinkage=False),
                                   samples.texel, samples.label)
        corrected = dataclasses.replace(samples, reflectance=samples.reflectance - offsets.offsets)
        last = round_ == rounds - 1
        fits = _refit(brdf, dataclasses.replace(regions, samples=corrected), method if last else None,
                      offsets=offsets if last else None, starts=_measured(fits) if starts else None)
    return fits


#: The glossy fits by strategy name (:func:`glossy_strategy`): each takes the BRDF model, the
#: :class:`FaceRegions` and the resolved plan, and returns the region fits and whether they have
#: an albedo per texel.
GLOSSY_FITS = {"region": _region_fits, "albedo_rounds": _rounds_fits, "texel_albedo": _texel_albedo_fits}


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


# ------------------------------------------------------------------------------------------------- maps

def _refine_normals(brdf, fits, regions: FaceRegions, options: dict | None, progress):
    """:func:`refine_texel_normals` on the face's samples with ``options`` (``FitOptions.normal_options``,
    the fields of :class:`~mifaces.reflectance.maps.normals.NormalOptions`), each round's region fit as the
    first's (without its progress or intervals), or None (with a warning) where no texel has
    :data:`MIN_OBSERVATIONS` samples (one light per texel: nothing to tell a normal from)."""
    samples = regions.samples
    quiet = dataclasses.replace(regions, progress=False)
    if not np.any(np.bincount(samples.texel) >= MIN_OBSERVATIONS):
        warnings.warn(f"per-texel normals left out: no texel has the {MIN_OBSERVATIONS} samples (lights and "
                      "poses) a normal needs", stacklevel=4)
        return None
    report = (lambda e: print(f"normals round {e['round']}: E {e['loss']:.6g}, {e['texels']} texels, "
                              f"mean tilt {e['mean_tilt_deg']:.2f} deg", flush=True)) if progress else None
    return refine_texel_normals(brdf, lambda rotated: _refit(brdf, dataclasses.replace(quiet, samples=rotated), None),
                                fits, samples, regions.names, options=NormalOptions(**(options or {})),
                                progress=report)


def _specular_map(brdf, by_label: dict, samples, region_map):
    """The specular reflectance per texel, or None (with a warning) for a model without one."""
    if any(p.name == "specular_reflectance" for p in brdf.specular_parameters()):
        return refine_specular(brdf, by_label, samples, region_map)
    warnings.warn(f"specular maps left out: {brdf.name} has no specular_reflectance", stacklevel=4)
    return None


__all__ = ["FaceRegions", "GLOSSY_FITS", "fit_samples", "glossy_strategy"]
