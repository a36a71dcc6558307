"""One BRDF fit per face region (paper sec. 4.4, 5.2): each region with enough samples fitted on its
own (:func:`mifaces.reflectance.fit.region_fit.fit_region`), the others, and fits the samples do
not support (a glossy part at its start values, at a bound of its range, a spike), lent a
neighbour's glossy part (:data:`NEIGHBOURS`) or none."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from ... import brdf as brdf_models
from ...brdf.model import BRDFModel
from ...runtime.progress import progress as progress_bar
from ...runtime.status import AT_BOUND, AT_START, CONVERGED, DEFAULTS, PRIOR
from ..samples import ReflectanceSamples
from .intervals import prior_intervals
from .lobes import PEAK_FACTOR, SPIKE, glossy_peak, no_lobe
from .region_fit import RegionFit, RegionFitOptions, RegionSamples, Uncertainty, fit_region, min_samples


def prior_fit(model: BRDFModel, params: dict, samples: int, reason: str, status: str = PRIOR) -> RegionFit:
    """A region's BRDF taken from elsewhere: a fitted neighbour (status
    ``'prior'``) or the model's defaults (``status='defaults'``)."""
    return RegionFit(model=model.name, options=dict(model.options), params=params, loss=float("nan"),
                     samples=samples, seconds=0.0, status=status, reason=reason, iterations=0,
                     uncertainty=prior_intervals(params))


#: Where a region without enough samples borrows its BRDF from, in order
#: (``skin`` is always the last resort).
NEIGHBOURS = {"lips": ["skin"], "nostrils": ["skin"], "beard": ["skin"], "eyes": ["skin"],
              "eyebrows": ["hair", "beard"], "hair": ["eyebrows", "beard"]}


def fit_regions(model: BRDFModel | str, samples: ReflectanceSamples, region_names: dict, *,
                options: RegionFitOptions | None = None, uncertainty: Uncertainty | None = Uncertainty(),
                fixed_by_region: dict | None = None, starts: dict | None = None, neighbours: dict | None = None,
                progress: bool = False) -> dict[str, RegionFit]:
    """Fit ``model`` separately in every region (paper sec. 4.4, 5.2).

    ``samples.label`` gives each sample's region label, ``region_names`` label -> name.
    Each region with enough samples is fitted on its own, by :func:`fit_region` with ``options``
    (with :attr:`~RegionFitOptions.texel_albedo`, every texel, ``samples.texel``, has its own
    albedo) and ``uncertainty`` (its clusters and albedo offsets, one per sample, taken for the
    region's samples). ``fixed_by_region`` (name -> parameters) holds parameters fixed in one
    region on top of ``options.fixed``; ``starts`` (name -> parameters) are the regions' start
    values. ``progress`` shows a bar over the regions fitted.

    A region with fewer than :func:`min_samples` samples gets a warning and
    the parameters of its first fitted neighbour in ``neighbours`` (name ->
    names; default :data:`NEIGHBOURS`), else of ``skin``, else the model's
    defaults; its status is ``'prior'``. So does the glossy part of a region
    with fewer than 10x that many samples whose own fit ended at a bound of
    the parameters' range (status ``'at_bound'``); a larger region keeps such
    a fit, with a warning. Regions without samples are not
    fitted either. A region that takes the model's defaults
    because no region has a fit to lend (skin's own fit a spike, say) has
    status ``'defaults'``, and a warning says so; a fit whose glossy
    parameters stayed at their start values measured nothing of them: it takes
    its neighbour's glossy part (status ``'prior'``, the reason says so) and
    lends nothing.
    """
    model = brdf_models.model(model) if isinstance(model, str) else model
    options = options or RegionFitOptions()
    neighbours = NEIGHBOURS if neighbours is None else neighbours
    region = samples.labels()
    fixed = options.fixed
    needed = min_samples(model, model.fixed_defaults() if fixed is None else fixed)
    counts = {name: int(np.count_nonzero(region == label)) for label, name in region_names.items()}
    fits: dict[str, RegionFit] = {}
    fitted = [(label, name) for label, name in region_names.items() if counts[name] >= needed]
    bar = progress_bar(fitted, desc=f"fitting {model.name}", unit="region", enabled=progress)
    held = {}  # region name -> its fixed parameters
    for label, name in bar:
        bar.set_postfix_str(f"{name}: {counts[name]} samples")
        mask = region == label
        region_options = options
        held[name] = model.fixed_defaults() if fixed is None else fixed
        if fixed_by_region and name in fixed_by_region:
            held[name] = {**held[name], **fixed_by_region[name]}
            region_options = dataclasses.replace(options, fixed=held[name])
        part = samples.select(mask)
        fits[name] = fit_region(model, RegionSamples.of(part), start=starts.get(name) if starts else None,
                                options=region_options,
                                uncertainty=None if uncertainty is None else uncertainty.select(mask))
        peak = glossy_peak(model, fits[name].params)
        seen = float(np.max(part.reflectance)) if mask.any() else 0.0
        if fits[name].status in (CONVERGED, AT_BOUND) and SPIKE not in fits[name].reason \
                and peak > PEAK_FACTOR * max(seen, 1e-6):
            # a lobe brighter than anything the photographs showed: fitted to a few samples' noise
            fits[name] = dataclasses.replace(fits[name], status=AT_BOUND, reason=(
                f"{fits[name].reason}; {SPIKE}: its peak (pi f = {peak:.3g}) is more than {PEAK_FACTOR:g} times "
                f"the brightest sample ({seen:.3g})"))
    def donor_of(name):
        # a neighbour's fit that is rendered as it stands can be lent: a converged one, or a large
        # region's fit at a bound that it keeps (never a spike, start values or defaults)
        donors = list(neighbours.get(name, [])) + ["skin"]
        return next((d for d in donors if d != name and d in fits and fits[d].status not in (AT_START, DEFAULTS)
                     and not (fits[d].status == AT_BOUND and (SPIKE in fits[d].reason or counts[d] < 10 * needed))),
                    None)

    # A fit whose glossy part never left its start values measured nothing of it: rendering those
    # (a Phong exponent of 1800, say) would invent a highlight. It takes a neighbour's glossy part,
    # keeping its own albedo, flagged 'prior' (the model's defaults, 'defaults', without a neighbour).
    def borrow(name, why):
        """Region ``name`` keeps its albedo and takes its donor's glossy part (or none), for ``why``."""
        donor = donor_of(name)
        glossy = fits[donor].params if donor else no_lobe(model)
        borrowed = {**glossy, **held[name], "diffuse_reflectance": fits[name].params["diffuse_reflectance"]}
        source = repr(donor) if donor else "no region: no glossy part"
        reason = f"{counts[name]} samples, and {why}: the glossy part of {source}"
        warnings.warn(f"region {name!r}: {reason}", stacklevel=3)
        fits[name] = prior_fit(model, borrowed, counts[name], reason, PRIOR if donor else DEFAULTS)

    for name in [n for n, fit in fits.items() if fit.status == AT_START]:
        borrow(name, f"{fits[name].reason.split('; ')[-1]} (not measured)")

    # A small region (fewer than 10x the samples a fit needs) whose best fit lies at a
    # bound of the valid range is more likely fitting noise than showing a material
    # the model cannot represent: it takes its neighbour's glossy part, keeping its own
    # albedo. A large one keeps its own fit, flagged at_bound, unless its lobe became a
    # spike (sharper than the grid resolves), which no photograph shows: any region does.
    for name in [n for n, fit in fits.items() if fit.status == AT_BOUND]:
        donor = donor_of(name)
        spike = SPIKE in fits[name].reason
        if not spike and (donor is None or counts[name] >= 10 * needed):
            warnings.warn(f"region {name!r}: the fit ended {fits[name].reason.split('; ')[-1]}", stacklevel=2)
            continue
        borrow(name, f"its own fit ended {fits[name].reason.split('; ')[-1]}")
    for label, name in region_names.items():
        if name in fits:
            continue
        donor = donor_of(name)
        params = fits[donor].params if donor else no_lobe(model)
        source = f"the fit of {donor!r}" if donor else "no region to borrow from: no glossy part"
        reason = f"{counts[name]} samples, fewer than the {needed} a {model.name} fit needs: {source}"
        if counts[name] > 0:
            warnings.warn(f"region {name!r}: {reason}", stacklevel=2)
        fits[name] = prior_fit(model, params, counts[name], reason, PRIOR if donor else DEFAULTS)
    return fits



__all__ = ["NEIGHBOURS", "prior_fit", "fit_regions"]
