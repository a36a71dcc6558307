"""The samples stage: the one owner of the reflectance samples, which ``measure`` and ``fit_brdf`` call
alike.

:func:`take_samples` takes the photographs' samples on the faces (:func:`capture_samples`).
:func:`without_bounced_light` then, with ``interreflection``, fits once, renders the light that fit
bounces between parts of the face (:func:`bounced_light`) and samples the photographs again without
it. :func:`with_balanced_lights` last, with ``balance_lights``, corrects the given lights' relative
intensities by the face's one albedo (:func:`balance_given_lights`), less the glossy part of a quick
fit, in rounds: after the bounced light, which differs from light to light too. Each returns a :class:`SampleSet`: the samples with the capture whose
lights they were taken under, and what the stage did, for the fit's record.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

from ..capture.types import Capture
from .fitting import fit_samples
from .interreflection import INDIRECT_DEPTH, INDIRECT_ROUNDS, bounced_light
from .light_balance import BALANCE_FIT_ROUNDS, balance_given_lights
from ..model.regions import REGIONS
from .maps.diffuse import specular_reflectance_factor
from .options import FitOptions
from .resampling import capture_samples
from .samples import ReflectanceSamples


@dataclass(frozen=True)
class SampleSet:
    """Reflectance samples and what they were taken from.

    Attributes
    ----------
    capture : Capture
        The capture, its lights as the samples were taken under them (balanced, with
        ``balance_lights``).
    shapes : dict
        Per measurement, the face's (V, 3) world vertices.
    face : MorphableModel
    samples : ReflectanceSamples
    light_balance : dict or None
        What :func:`balance_given_lights` changed (its capture's ``metadata['light_balance']``).
    interreflection : dict or None
        Where the bounced light was taken out: its renders' ``depth``, ``width``, ``spp`` and
        ``seconds``.
    seconds : float
        The stage's wall time.
    """

    capture: Capture
    shapes: dict
    face: object
    samples: ReflectanceSamples
    light_balance: dict | None = None
    interreflection: dict | None = None
    seconds: float = 0.0

    @property
    def resolution(self) -> int:
        return self.samples.resolution

    def on_shapes(self, shapes: dict, *, progress: bool = True) -> SampleSet:
        """The samples taken again on other ``shapes`` (a refined face), under the same lights."""
        t = time.perf_counter()
        samples = capture_samples(self.capture, shapes, self.face, self.resolution,
                                  measurements=self.samples.measurement_names, progress=progress)
        return dataclasses.replace(self, shapes=shapes, samples=samples, interreflection=None,
                                   seconds=time.perf_counter() - t)


def take_samples(capture: Capture, shapes: dict, face, options: FitOptions, *,
                 samples: ReflectanceSamples | None = None, measurements=None, progress: bool = True) -> SampleSet:
    """The samples of ``capture``'s photographs on ``shapes`` at ``options.resolution``, or the ``samples``
    given (taken before, at that resolution).

    Raises
    ------
    ValueError
        Where ``samples`` are at another resolution, or no texel gave a sample.
    """
    t = time.perf_counter()
    if samples is None:
        samples = capture_samples(capture, shapes, face, options.resolution, measurements=measurements,
                                  progress=progress)
    elif samples.resolution != options.resolution:
        raise ValueError(f"the samples are at resolution {samples.resolution}, not {options.resolution}")
    if len(samples) == 0:
        raise ValueError("no valid reflectance samples: every texel is hidden, shadowed, grazing or saturated")
    return SampleSet(capture, shapes, face, samples, seconds=time.perf_counter() - t)


def without_bounced_light(taken: SampleSet, brdf, options: FitOptions, *, progress: bool = True) -> SampleSet:
    """``taken``, and where ``options.interreflection``, its samples taken again without the light bounced
    between parts of the face: in each round of :data:`~mifaces.reflectance.interreflection.INDIRECT_ROUNDS`,
    a fit of ``brdf`` (no intervals, normals or specular maps) to the samples so far, its bounced light
    rendered, the photographs sampled again less it. Samples it already took the
    bounced light out of come back as they are: :func:`mifaces.measure` takes it out once, with its
    first model, and every model's fit shares those samples (the bounced light is mostly the
    albedo's, which every model fits alike)."""
    if not options.interreflection or taken.interreflection is not None:
        return taken
    t = time.perf_counter()
    quick = dataclasses.replace(options, interreflection=False, uncertainty=None, normals=False, specular_maps=False)
    samples = taken.samples
    for width, spp in INDIRECT_ROUNDS:
        fit = fit_samples(dataclasses.replace(taken, samples=samples), brdf, quick, progress=progress)
        bounced = bounced_light(taken.capture, taken.shapes, taken.face, fit, measurements=fit.measurements,
                                width=width, spp=spp, progress=progress)
        samples = capture_samples(taken.capture, taken.shapes, taken.face, taken.resolution,
                                  measurements=fit.measurements, progress=progress, indirect=bounced)
    seconds = time.perf_counter() - t
    record = {"depth": INDIRECT_DEPTH, "rounds": [{"width": w, "spp": n} for w, n in INDIRECT_ROUNDS],
              "fitted_with": brdf.name, "seconds": seconds}
    return dataclasses.replace(taken, samples=samples, interreflection=record, seconds=taken.seconds + seconds)


def with_balanced_lights(taken: SampleSet, brdf, options: FitOptions) -> SampleSet:
    """``taken``, and where ``options.balance_lights``, its given lights' relative intensities corrected
    (:func:`balance_given_lights`): :data:`BALANCE_FIT_ROUNDS` times, a quick fit of ``brdf`` (no
    normals, intervals or specular maps) predicts each sample's glossy part, and the lights are balanced
    on what is left (or, where the factors spread beyond a calibration's, left as given:
    ``light_balance`` then empty). Samples balanced before come back as they are (:func:`mifaces.measure` balances
    once, with its first model, for every model's fit: a lamp's error is the capture's, not a model's)."""
    if not options.balance_lights or taken.light_balance is not None:
        return taken
    t = time.perf_counter()
    quick = dataclasses.replace(options, interreflection=False, balance_lights=False, uncertainty=None,
                                normals=False, specular_maps=False)
    capture, samples = taken.capture, taken.samples
    for _ in range(BALANCE_FIT_ROUNDS):
        fit = fit_samples(dataclasses.replace(taken, capture=capture, samples=samples), brdf, quick, progress=False)
        glossy = specular_reflectance_factor(brdf, {REGIONS[name]: f.params for name, f in fit.fits.items()},
                                             samples.light, samples.view, samples.labels(), samples.footprint)
        capture, samples = balance_given_lights(capture, samples, glossy)
        if capture.metadata.get("light_balance_refused"):  # factors beyond a calibration's: left as given
            break
    seconds = time.perf_counter() - t
    return dataclasses.replace(taken, capture=capture, samples=samples,
                               light_balance=capture.metadata.get("light_balance") or {},
                               seconds=taken.seconds + seconds)


__all__ = ["SampleSet", "take_samples", "with_balanced_lights", "without_bounced_light"]
