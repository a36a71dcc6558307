"""How :func:`mifaces.reflectance.fit_brdf` fits: one value that travels from the CLI and
:func:`mifaces.measure` to the fit, instead of a dozen forwarded flags. Each option is declared
once (:func:`mifaces.options.fields.option`): its default, range, help and flag."""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

from ..brdf import MAX_LOBES
from ..io.image_files import MAX_IMAGE_PIXELS
from ..options.fields import check, from_record, option, record
from .fit.region_fit import SubsetSchedule
from .fit.uncertainty import METHODS

#: Largest texture resolution R (R x R texels): an image's pixel limit.
MAX_TEXTURE = math.isqrt(MAX_IMAGE_PIXELS)


@dataclass(frozen=True)
class FitOptions:
    """Options of the BRDF fit.

    Attributes
    ----------
    resolution : int
        R of the R × R texture space (the paper used 1000).
    lobes : int
        Lafortune lobes.
    model_options : dict
        Further options of the BRDF model (``fresnel=``, ``normalization=``, …).
    fixed : dict, optional
        Parameters held fixed in every region (default: the model's
        ``fixed_in_region``, e.g. Cook-Torrance's η at each region's published
        value, :data:`mifaces.brdf.materials.REFRACTIVE_INDEX`).
    schedule : SubsetSchedule, optional
        The Levenberg-Marquardt subset hierarchy.
    seed : int
        Seed of the subset draws.
    normals : bool
        Estimate a normal per texel from its samples, alternating with a fit of one
        albedo per region (:func:`mifaces.reflectance.maps.normals.refine_texel_normals`),
        then refit the glossy part in the normals' frames with the albedo's per-texel
        offsets taken out (``albedo_rounds``, at least one), with its intervals
        (conditional on the normals): fitted shapes' normals are a few degrees off, and
        real faces have detail no model shape has. On by default: on the ten
        development Yale subjects it took the held-out relighting error below photometric
        stereo's (``docs/results.md``). Left out, with a warning, when no texel has the
        samples it needs.
    normal_options : dict, optional
        Fields of :class:`~mifaces.reflectance.maps.normals.NormalOptions`, the options of
        ``refine_texel_normals`` (``prior_weight``, ``rounds``, ``tol``, ...).
    specular_maps : bool
        Estimate the specular reflectance per texel, shrunk towards each
        region's (:func:`mifaces.reflectance.maps.specular.refine_specular`;
        models with a ``specular_reflectance``). The region fits stay the summary.
    uncertainty : str or None
        How each region fit's parameter uncertainty is estimated
        (:data:`mifaces.reflectance.fit.uncertainty.METHODS`; the jackknife over
        texel tiles by default, see ``docs/uncertainty.md``), or None. With
        ``normals``, the intervals of the last fit in the normals' frames: they hold
        the normals as measured and leave out their own uncertainty.
    albedo_rounds : int
        Alternations of the region fit with the per-texel albedo: each refits the
        regions on the reflectance less each sample's albedo offset from its
        region's mean (:func:`mifaces.reflectance.maps.diffuse.albedo_offsets`), the
        albedo map refitted with the last round's glossy parts. 0: none (the fit
        ``texel_albedo`` chooses). Given, it replaces ``texel_albedo``'s fit. With
        ``normals``, the rounds after theirs (at least one).
        The offsets are each texel's mean (not shrunk); the last round's intervals
        re-estimate them in every jackknife or sandwich replicate
        (:mod:`mifaces.reflectance.fit.uncertainty`), and still hold the truth less often
        than they say on simulated faces (``docs/uncertainty.md``): off by default.
    texel_albedo : bool
        Fit each region's glossy part with an albedo of its own for every texel, eliminated
        from the problem (``RegionFitOptions(texel_albedo=True)``): the glossy part is then measured from
        how each texel changes between photographs, and the albedo texture no longer leaks
        into it. The same optimum as ``albedo_rounds`` alternated to convergence, reached in
        one fit; its intervals come from its own projected sums, each texel's albedo
        following the lobe in every replicate (the bootstrap: one more such round from
        that optimum), over tiles of
        :data:`~mifaces.reflectance.fit.uncertainty.TEXEL_TILE_AT_128`. On by default
        (``docs/uncertainty.md`` says why); False: the paper's one albedo per region.
        Ignored with ``normals`` (on by default: ``--no-normals`` for this fit) or ``albedo_rounds``. Where it measures no lobe on skin and
        the region fit does (too few photographs per texel), the region fit is kept, with a
        warning.
    balance_lights : bool
        Correct the given lights' relative intensities by the face's one albedo before
        fitting, less the glossy part of a quick fit, in rounds
        (:func:`mifaces.reflectance.sample_stage.with_balanced_lights`; the mean kept),
        after the bounced light where ``interreflection``: a calibrated lamp a fraction of
        a percent off in distance biases the glossy fit by several percent
        (``docs/reflectance.md``, "Where skin's bias comes from"). On by default, with
        ``interreflection``: the two together take skin's glossy bias from -6.6 % to
        +0.8 % over 20 development captures (``validation/results/reflectance_bias.json``);
        either alone does not. A light whose factor lies 2 times or more from the median
        light's has failed (a strobe that did not fire): its photographs are left out, with a
        warning (:data:`~mifaces.reflectance.light_balance.FAILED_LIGHT_FACTOR`); where the
        others spread beyond a calibration's error (real faces, whose model misses the
        photographs by more), the lights are left as given (``BALANCE_LIMIT``).
    interreflection : bool
        Take the light bounced between parts of the face out of the samples: fit, render
        that light with the fit (:func:`mifaces.reflectance.interreflection.bounced_light`),
        sample the photographs again without it and fit again. It removes most of skin's
        glossy bias on simulated captures (``docs/reflectance.md``). On by default;
        costs a second fit and two coarse renders per photograph, once per capture in
        :func:`~mifaces.pipeline.measure` (shared by every model).
    """

    resolution: int = option(512, bounds=(8, MAX_TEXTURE), help="Texture resolution R (R x R texels).")
    lobes: int = option(1, bounds=(1, MAX_LOBES), help="Lafortune lobes.")
    model_options: dict = option(factory=dict)
    fixed: dict | None = None
    schedule: SubsetSchedule | None = option(None, nested=SubsetSchedule)
    seed: int = option(0, bounds=(0, None))
    normals: bool = option(True, help="Estimate a normal per texel alternating with a fit of one albedo per "
                                      "region, the glossy fit then in its frames (normals.exr, which scene.xml and "
                                      "the renders read); --no-normals: the fitted shape's normals.")
    normal_options: dict | None = None
    specular_maps: bool = option(False, help="Estimate the specular reflectance per texel (specular.exr; renders "
                                             "read it).")
    uncertainty: str | None = option(METHODS[0], choices=METHODS + (None,),
                                     help="How the parameters' 95 % intervals are estimated (docs/uncertainty.md); "
                                          "'none' leaves them out.")
    albedo_rounds: int = option(0, bounds=(0, None))
    texel_albedo: bool = option(True, help="An albedo per texel in the glossy fit; --no-: one per region, as the "
                                           "paper (docs/uncertainty.md).")
    balance_lights: bool = option(True, help="Correct the given lights' relative intensities by the face's one "
                                              "albedo, less a quick fit's glossy part, before the BRDF fits (a lamp "
                                              "a fraction of a percent off biases the glossy fit).")
    interreflection: bool = option(True, help="Take the light bounced between parts of the face out of the "
                                               "samples (a second fit; bounced light biases skin's lobe low).")

    def __post_init__(self):
        check(self)

    def to_record(self) -> dict:
        """Every option, as a JSON object (:meth:`from_record` reads it back, equal)."""
        return record(self)

    @classmethod
    def from_record(cls, data: dict) -> FitOptions:
        """The options :meth:`to_record` wrote."""
        return from_record(cls, data)

    def resolved(self) -> FitOptions:
        """These options as :func:`~mifaces.reflectance.fit_brdf` plans to run them: ``normals`` (whose
        rounds take the albedo's per-texel offsets out) makes ``albedo_rounds`` at least 1 and turns off
        ``texel_albedo``; ``albedo_rounds`` turns off ``texel_albedo``. (What the fit then left out,
        where the data did not allow it: :meth:`BRDFEstimate.effective_options
        <mifaces.reflectance.result.BRDFEstimate.effective_options>`.)"""
        if self.normals:
            return dataclasses.replace(self, albedo_rounds=max(1, self.albedo_rounds), texel_albedo=False)
        return dataclasses.replace(self, texel_albedo=self.texel_albedo and not self.albedo_rounds)

    def brdf_options(self) -> dict:
        """The BRDF model's options, with ``lobes`` where it is not 1."""
        options = dict(self.model_options)
        if self.lobes != 1:
            options["lobes"] = int(self.lobes)  # brdf.model refuses it for a model with one lobe
        return options


def fit_options(options, flags: dict, caller: str) -> FitOptions:
    """``options`` (a :class:`FitOptions`, or None for the defaults) with ``flags`` applied: the
    keyword arguments ``caller`` took one by one before :class:`FitOptions` (``resolution=``,
    ``normals=``, ...; deprecated, with a :class:`DeprecationWarning`). A dict ``options`` is the
    BRDF model's options, as ``fit_brdf`` took them then (``model_options`` now).

    Raises
    ------
    TypeError
        For a keyword no :class:`FitOptions` field has (``refine``: the refinement is the next
        stage's call, :func:`mifaces.refine.refine_estimate`).
    """
    flags = dict(flags)
    if isinstance(options, dict):
        flags = {"model_options": options, **flags}
        options = None
    if "refine" in flags:
        raise TypeError(f"{caller}() no longer refines: call mifaces.refine.refine_estimate(estimate, capture, "
                        "shapes, face_model) on the estimate it returns")
    unknown = sorted(set(flags) - {f.name for f in dataclasses.fields(FitOptions)})
    if unknown:
        raise TypeError(f"{caller}() got unexpected keyword argument(s) {unknown}")
    if flags:
        shown = ", ".join(f"{key}=..." for key in flags)
        warnings.warn(f"{caller}({shown}) is deprecated and goes in the next release: pass "
                      f"options=FitOptions({shown})", DeprecationWarning, stacklevel=3)
    if isinstance(options, FitOptions) and not flags:
        return options  # a value already: normalised where it was made
    return dataclasses.replace(options or FitOptions(), **flags)


__all__ = ["MAX_TEXTURE", "FitOptions", "fit_options"]
