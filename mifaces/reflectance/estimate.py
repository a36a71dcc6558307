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
   (:func:`mifaces.reflectance.fitting.fit_regions`; a region with too few samples
   borrows a neighbour's fit, a region with none is not evaluated);
4. optionally (``normals=True``, beyond the paper), a normal per texel
   alternated with step 3 (:func:`mifaces.reflectance.texel_normals.refine_texel_normals`);
5. the diffuse albedo refitted per texel with the glossy part fixed
   (:func:`mifaces.reflectance.diffuse.refine_diffuse`).

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
from dataclasses import dataclass, field

import numpy as np

from .. import brdf as brdf_models
from ..capture import Capture, load_capture
from ..geometry import load_geometry
from ..model.regions import REGIONS, regions_present, texel_regions_of_mesh
from ..render import FaceScene
from .diffuse import AlbedoOffsets, DiffuseMap, refine_diffuse
from .fitting import RegionFit, SubsetSchedule, fit_regions
from .io import FILES, write_estimate
from .light_balance import balance_given_lights
from .refine import RefineSchedule, refine_estimate
from .samples import ReflectanceSamples, capture_samples
from .specular_maps import SpecularMap, refine_specular
from .uncertainty import METHODS, tile_clusters
from .texel_normals import MIN_OBSERVATIONS, encode, mitsuba_tangent_normals, refine_texel_normals

#: Fit statistics stored per region under ``brdf.json``'s ``"fit"``.
FIT_KEYS = ("diffuse_reflectance", "loss", "samples", "seconds", "status", "reason", "iterations")


@dataclass
class BRDFEstimate:
    """Fitted BRDFs of one capture.

    Attributes
    ----------
    model : str
        Plugin name (``phong``, ``cooktorrance``, ``ward``, ``lafortune``).
    options : dict
        The model's options (e.g. ``{"lobes": 2}`` for Lafortune).
    fits : dict
        Region name -> :class:`~mifaces.reflectance.fitting.RegionFit`.
    albedo : DiffuseMap
        Per-texel diffuse albedo after refinement (sec. 5.3).
    region_map : (R, R) uint8
        Region label per texel of the albedo map.
    samples : int
        Reflectance samples used.
    measurements : tuple of str
    seconds : dict
        Wall time of each step: ``samples``, ``fit``, ``refine``, ``total``.
    refinement : dict or None
        How the fit was refined by differentiable rendering
        (:func:`mifaces.reflectance.refine.refine_estimate`), with its image
        loss before and after; None if it was not.
    normals : ndarray (R, R, 3) or None
        Per-texel unit normals relative to Mitsuba's shading frame of the
        face mesh (:func:`mifaces.reflectance.texel_normals.mitsuba_tangent_normals`),
        if they were estimated (``fit_brdf(..., normals=True)``).
    normal_refinement : dict or None
        How they were (:meth:`~mifaces.reflectance.texel_normals.TexelNormals.summary`).
    specular : SpecularMap or None
        Per-texel specular reflectance shrunk towards each region's
        (:func:`mifaces.reflectance.specular_maps.refine_specular`), if estimated.
    lighting : dict or None
        How the lights were known where they were estimated from the photographs
        (:mod:`mifaces.lighting`): ``{"lights": "estimated", "reflectance": "relative", "note"}``,
        written to ``brdf.json``; None for a capture whose lights are given.
    light_balance : dict or None
        Light name -> the factor its given intensity was off by, as the face's one albedo
        says (``fit_brdf(..., balance_lights=True)``,
        :func:`mifaces.reflectance.light_balance.balance_given_lights`); None where not balanced.
    """

    model: str
    options: dict
    fits: dict[str, RegionFit]
    albedo: DiffuseMap
    region_map: np.ndarray
    samples: int
    measurements: tuple[str, ...]
    seconds: dict = field(default_factory=dict)
    refinement: dict | None = None
    normals: np.ndarray | None = None
    normal_refinement: dict | None = None
    specular: SpecularMap | None = None
    lighting: dict | None = None
    light_balance: dict | None = None

    def fitted_light(self, light):
        """``light`` (:class:`~mifaces.capture.Light`) as this estimate was fitted under it: an
        estimated environment map that the refinement refined (``refinement['environment_maps']``,
        kept only where the refinement was) is that refined map; any other light is itself."""
        maps = (self.refinement or {}).get("environment_maps") or {}
        if light.environment and light.estimated and light.name in maps:
            return dataclasses.replace(light, envmap=np.asarray(maps[light.name], np.float32))
        return light

    def normal_texture(self) -> np.ndarray | None:
        """The normals as a ``normalmap`` texture ((n + 1) / 2), or None."""
        return None if self.normals is None else encode(self.normals)

    def specular_texture(self) -> np.ndarray | None:
        """The per-texel specular reflectance (R, R, 3) that renders read, or None."""
        return None if self.specular is None else self.specular.specular

    @property
    def resolution(self) -> int:
        return int(self.region_map.shape[0])

    def regions(self) -> dict[str, dict]:
        """Region -> the plugin's glossy parameters (no diffuse: that is the albedo map)."""
        return {name: {k: v for k, v in fit.params.items() if k != "diffuse_reflectance"}
                for name, fit in self.fits.items()}

    def to_json(self) -> dict:
        """The ``brdf.json`` document."""
        options = {k: v for k, v in self.options.items()}
        return {"model": self.model, "options": options, "regions": self.regions(),
                "fit": {name: {k: (fit.params.get(k) if k == "diffuse_reflectance" else getattr(fit, k))
                               for k in FIT_KEYS} for name, fit in self.fits.items()},
                "samples": int(self.samples), "resolution": self.resolution,
                "measurements": list(self.measurements), "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
                "albedo": FILES["albedo"], "refinement": self.refinement,
                "uncertainty": {name: fit.uncertainty for name, fit in self.fits.items()},
                **({} if self.albedo.std is None else {"albedo_std": FILES["albedo_std"]}),
                **({} if self.lighting is None else {"lighting": self.lighting}),
                **({} if self.light_balance is None else {"light_balance": self.light_balance}),
                **({} if self.normals is None else {"normals": FILES["normals"],
                                                    "normal_refinement": self.normal_refinement}),
                **({} if self.specular is None else {"specular": FILES["specular"], "specular_shrinkage": {
                    name: self.specular.shrinkage.get(REGIONS[name]) for name in self.fits}})}


def fit_brdf(capture, model: str = "cooktorrance", geometry="ground-truth", *, face_model=None,
             resolution: int = 512, lobes: int = 1, options: dict | None = None, fixed: dict | None = None,
             schedule: SubsetSchedule | None = None, samples: ReflectanceSamples | None = None, measurements=None,
             out=None, seed: int = 0, progress: bool = True, force: bool = False,
             refine: bool | RefineSchedule = False, normals: bool = False,
             normal_options: dict | None = None, specular_maps: bool = False,
             uncertainty: str | None = METHODS[0], albedo_rounds: int = 0,
             balance_lights: bool = False) -> BRDFEstimate:
    """Fit a BRDF model per region to the photographs of a capture.

    Parameters
    ----------
    capture : Capture or path
    model : str
        ``phong``, ``cooktorrance``, ``ward`` or ``lafortune``.
    geometry : ``'ground-truth'``, path or mapping
        Per-measurement face geometry (see :func:`load_geometry`).
    face_model : MorphableModel or path, optional
    resolution : int
        R of the R × R texture space (the paper used 1000).
    lobes : int
        Lafortune lobes.
    options : dict, optional
        Further model options (``fresnel=``, ``normalization=``, …).
    fixed : dict, optional
        Parameters held fixed in every region (default: the model's
        ``fixed_in_region``, e.g. Cook-Torrance's η at each region's published
        value, :data:`mifaces.brdf.materials.REFRACTIVE_INDEX`).
    schedule : SubsetSchedule, optional
        The LM subset hierarchy.
    samples : ReflectanceSamples, optional
        Samples computed before (skips step 1; must match ``resolution``).
    measurements : sequence of str, optional
        Fit to these measurements only (default: all with geometry).
    out : path, optional
        Write the result there (:func:`mifaces.reflectance.io.write_estimate`).
    force : bool
        Replace a fitted BRDF that ``out`` holds.
    refine : bool or RefineSchedule
        Refine the fit by differentiable rendering against the photographs
        (:func:`mifaces.reflectance.refine.refine_estimate`, with this schedule
        or the default one).
    normals : bool
        Estimate a normal per texel from its samples, alternating with the
        region fit (:func:`mifaces.reflectance.texel_normals.refine_texel_normals`):
        for fitted shapes, whose normals are a few degrees off. Left out, with
        a warning, when no texel has the samples it needs. (``refine`` renders
        without the normal map.)
    normal_options : dict, optional
        Keyword arguments of ``refine_texel_normals`` (``prior_weight``, ``rounds``, ``tol``).
    specular_maps : bool
        Estimate the specular reflectance per texel, shrunk towards each
        region's (:func:`mifaces.reflectance.specular_maps.refine_specular`;
        models with a ``specular_reflectance``). The region fits stay the summary.
    uncertainty : str or None
        How each region fit's parameter uncertainty is estimated
        (:data:`mifaces.reflectance.uncertainty.METHODS`; the jackknife over
        texel tiles by default, see ``docs/uncertainty.md``), or None. Not
        estimated with ``normals`` (whose fits see texels through their normals
        too) nor after ``refine``: those fits get empty ``uncertainty``.
    albedo_rounds : int
        Alternations of the region fit with the per-texel albedo: each refits the
        regions on the reflectance less each sample's albedo offset from its
        region's mean (:func:`mifaces.reflectance.diffuse.albedo_offsets`), the
        albedo map refitted with the last round's glossy parts. 0: the paper's
        one region fit. (With ``normals``, whose rounds do the same, ignored.)
        The offsets are each texel's mean (not shrunk); the last round's intervals
        re-estimate them in every jackknife or sandwich replicate
        (:mod:`mifaces.reflectance.uncertainty`), and still hold the truth less often
        than they say on simulated faces (``docs/uncertainty.md``): off by default.
    balance_lights : bool
        Correct the given lights' relative intensities by the face's one albedo before
        fitting (:func:`mifaces.reflectance.light_balance.balance_given_lights`; the mean
        kept): a calibrated lamp a percent off in distance biases the glossy fit
        (``docs/uncertainty.md``). The refinement, if on, starts from the balanced lights.

    Returns
    -------
    BRDFEstimate
    """
    t0 = time.perf_counter()
    capture = capture if isinstance(capture, Capture) else load_capture(capture)
    options = dict(options or {})
    if lobes != 1:
        options["lobes"] = int(lobes)  # brdf_models.model refuses it for a model with one lobe
    brdf = brdf_models.model(model, **options)
    face, shapes = load_geometry(capture, geometry, face_model)
    if samples is None:
        samples = capture_samples(capture, shapes, face, resolution, measurements=measurements, progress=progress)
    elif samples.resolution != resolution:
        raise ValueError(f"the samples are at resolution {samples.resolution}, not {resolution}")
    if len(samples) == 0:
        raise ValueError("no valid reflectance samples: every texel is hidden, shadowed, grazing or saturated")
    light_balance = None
    if balance_lights:
        capture, samples = balance_given_lights(capture, samples)
        light_balance = capture.metadata.get("light_balance")
    t_samples = time.perf_counter()
    region_map = (samples.region_map if samples.region_map is not None
                  else texel_regions_of_mesh(face.region_map, face.uv, face.triangles, resolution))
    label = samples.label if samples.label is not None else samples.region(region_map)
    names = {REGIONS[n]: n for n in regions_present(face.region_map)}
    on_face = np.isin(label, list(names))
    light, view, r, sigma, texel, label, measurement = (
        a[on_face] for a in (samples.light, samples.view, samples.reflectance, samples.sigma, samples.texel, label,
                             samples.measurement))
    # parameters with a published value per region (Cook-Torrance's η) are fixed at it unless given
    per_region = {name: {k: v for k, v in brdf.fixed_in_region(name).items() if fixed is None or k not in fixed}
                  for name in names.values()}
    if uncertainty is not None and uncertainty not in METHODS:
        raise ValueError(f"uncertainty must be one of {METHODS} or None, got {uncertainty!r}")
    rounds = 0 if normals else int(albedo_rounds)
    region_fit = dict(progress=progress, fixed=fixed, fixed_by_region=per_region, schedule=schedule, seed=seed,
                      cluster=tile_clusters(texel, resolution))
    fits = fit_regions(brdf, light, view, r, sigma, label, names, **region_fit,
                       uncertainty=None if normals or rounds else uncertainty)
    for round_ in range(rounds):
        by_label = {REGIONS[name]: fit.params for name, fit in fits.items()}
        # unshrunk: the texel means (a texel effect per texel, consistent for the glossy part); shrunk
        # towards the region's albedo they leave part of the texture in, and bias skin's lobe
        offsets = AlbedoOffsets.of(refine_diffuse(brdf, by_label, light, view, r, sigma, texel, label, region_map,
                                                  shrinkage=False), texel, label)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the first fit has warned already
            last = round_ == rounds - 1  # its intervals re-estimate the offsets per replicate
            fits = fit_regions(brdf, light, view, r - offsets.offsets, sigma, label, names, **region_fit,
                               uncertainty=uncertainty if last else None, offsets=offsets if last else None)
    texel_normals = None
    if normals:
        texel_normals = _refine_normals(brdf, fits, (light, view, r, sigma, texel, measurement, label), names,
                                        resolution, normal_options, progress,
                                        dict(fixed=fixed, fixed_by_region=per_region, schedule=schedule, seed=seed,
                                             uncertainty=None))
        if texel_normals is not None:
            light, view, r, sigma, keep = texel_normals.samples
            texel, label, fits = texel[keep], label[keep], texel_normals.fits
    t_fit = time.perf_counter()
    by_label = {REGIONS[name]: fit.params for name, fit in fits.items()}
    albedo = refine_diffuse(brdf, by_label, light, view, r, sigma, texel, label, region_map)
    specular = None
    if specular_maps:
        if any(p.name == "specular_reflectance" for p in brdf.specular_parameters()):
            specular = refine_specular(brdf, by_label, light, view, r, sigma, texel, label, region_map)
        else:
            warnings.warn(f"specular maps left out: {brdf.name} has no specular_reflectance", stacklevel=2)
    t_end = time.perf_counter()
    estimate = BRDFEstimate(model=brdf.name, options=dict(options), fits=fits, albedo=albedo,
                            region_map=region_map, samples=int(len(texel)), specular=specular,
                            measurements=tuple(samples.measurement_names),
                            seconds={"samples": t_samples - t0, "fit": t_fit - t_samples, "refine": t_end - t_fit,
                                     "total": t_end - t0}, light_balance=light_balance)
    if texel_normals is not None:
        first = next(name for name in estimate.measurements if name in shapes)
        estimate.normals = mitsuba_tangent_normals(texel_normals.normals, face, shapes[first]).astype(np.float32)
        estimate.normal_refinement = texel_normals.summary()
    if refine:
        estimate = refine_estimate(estimate, capture, shapes, face, None if refine is True else refine, seed=seed,
                                   progress=progress)
        estimate.seconds["total"] = time.perf_counter() - t0
    if out is not None:
        first = next(m for m in capture.measurements if m.name == estimate.measurements[0])
        write_estimate(estimate, out, FaceScene(face, shapes[first.name]), capture.camera, capture.light(first.light),
                       force=force)
    return estimate


def _refine_normals(brdf, fits, arrays, names, resolution, options, progress, fit_options):
    """:func:`refine_texel_normals` on the face's samples, the region fit as :func:`fit_brdf`'s
    (``fit_options`` of :func:`fit_regions`), or None (with a warning) where no texel has
    :data:`MIN_OBSERVATIONS` samples (one light per texel: nothing to tell a normal from)."""
    def fit(*samples):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the fit at the model's normals has warned already
            return fit_regions(brdf, *samples, names, **fit_options)

    texel = arrays[4]
    if not np.any(np.bincount(texel) >= MIN_OBSERVATIONS):
        warnings.warn(f"per-texel normals left out: no texel has the {MIN_OBSERVATIONS} samples (lights and "
                      "poses) a normal needs", stacklevel=3)
        return None
    report = (lambda e: print(f"normals round {e['round']}: E {e['loss']:.6g}, {e['texels']} texels, "
                              f"mean tilt {e['mean_tilt_deg']:.2f} deg", flush=True)) if progress else None
    return refine_texel_normals(brdf, fit, fits, *arrays, names, resolution, progress=report, **(options or {}))


__all__ = ["FIT_KEYS", "BRDFEstimate", "fit_brdf"]
