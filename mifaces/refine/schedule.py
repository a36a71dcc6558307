"""The schedule of the refinement by differentiable rendering
(:mod:`mifaces.refine.reflectance`): iterations, samples, learning rates per
variable, and the average of the last iterates that the result is taken from.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

#: Largest factor by which ``RefineSchedule.pixel_reference`` raises a small region's learning rate.
MAX_RATE_SCALE = 2.0
#: A refinement by differentiable rendering (of the BRDFs or of the shape) is judged on pixels it
#: did not fit: this fraction of the blocks of each photograph's face pixels, blocks of this side
#: (render pixels), drawn at random.
HOLDOUT, HOLDOUT_BLOCK = 0.2, 4
#: Names of the refinement's variables that are not a region's: the albedo correction and the lights' log gains;
#: an estimated environment light's log radiance map is ``ENVIRONMENT + ":" + its name``.
ALBEDO, LIGHT_GAIN, ENVIRONMENT = "albedo", "light_gain", "environment"


def environment_variable(light: str) -> str:
    """The name of the refinement's variable holding estimated environment light ``light``'s log map."""
    return f"{ENVIRONMENT}:{light}"


def holdout_pixels(mask: np.ndarray, fraction: float, block: int, rng: np.random.Generator) -> np.ndarray:
    """A random ``fraction`` of the ``block``² blocks over ``mask``: the held-out pixels (H, W) bool."""
    blocks = rng.random(((mask.shape[0] + block - 1) // block, (mask.shape[1] + block - 1) // block)) < fraction
    return np.kron(blocks, np.ones((block, block), bool))[: mask.shape[0], : mask.shape[1]] & mask


@dataclass(frozen=True)
class RefineSchedule:
    """How the refinement runs.

    Attributes
    ----------
    iterations : int
        Adam steps; each renders one photograph (in turn) forward and backward.
    spp : int
        Samples per pixel of each render (the backward pass uses as many,
        with a decorrelated seed).
    downsample : int
        Render at 1/``downsample`` of the camera's resolution against the
        photograph averaged over ``downsample``² blocks.
    max_depth : int
        Path length: 2 direct light only, 3 one interreflection, ...
    learning_rate : float
        Adam's step in the unconstrained parameters (about the relative change
        per step of a parameter in logarithmic form).
    albedo_learning_rate : float or None
        With a number, the albedo is a variable too
        (:class:`~mifaces.refine.albedo_correction.AlbedoCorrection`),
        with this step (about the relative change per step); None keeps the
        texture-space albedo.
    albedo_cell : int
        Texels per side of a cell of the albedo's correction grid.
    light_gain_learning_rate : float or None
        With a number, each light's intensity is a variable too, a factor
        exp(g_l - mean g) on its photographs' renders (the mean fixed: the
        overall scale is the albedo's and the white target's), with this
        step (about the relative change per step): a calibrated light is off
        in distance by about a percent (steel spheres 190 mm apart locate a
        lamp 1.5 m away), which moves its irradiance by twice that, and a
        refinement whose lights are held absorbs that into the glossy
        parameters. None holds the lights as calibrated.
    environment_learning_rate : float or None
        With a number, an estimated environment light's map
        (:attr:`mifaces.capture.Light.estimated`) is a variable too, its log
        radiance per texel with this step, the mean log held (the overall
        scale is the albedo's); None holds it at the texture-space estimate.
        A given map is always held.
    environment_smoothness : float
        Weight of the estimated map's smoothness prior: this times the mean
        squared difference of neighbouring texels' log radiance, added to
        the loss (the loss is about the relative pixel error).
    restart_under_maps : bool
        Where a photograph is lit by an environment map, start the glossy
        parameters at the model's start values
        (:meth:`~mifaces.brdf.model.BRDFModel.start_values`) rather than at
        the texture-space fit's: that fit reads each texel as lit from one
        direction, which is right for the diffuse part and biased for the
        glossy one (``docs/unknown_lights.md``).
    decay : float
        The learning rates fall from their value to ``decay`` times it over
        the iterations (half a cosine).
    epsilon : float
        ε of the Charbonnier penalty, relative to the photograph's mean.
    evaluation_spp : int
        Samples per pixel of the loss reported before and after.
    average : float
        Fraction of the iterations, the last ones, whose iterates (in the
        unconstrained variables) are averaged into the result (Polyak-Ruppert
        averaging: the Monte Carlo noise of the last steps' gradients averages
        out instead of being left in the parameters); 0 keeps the last iterate.
    pixel_reference : int or None
        With a number, a region seen by ``pixels`` pixels (over all
        photographs) takes steps ``sqrt(pixel_reference / pixels)`` times the
        learning rate (at most :data:`MAX_RATE_SCALE` times): the texture-space
        fit's errors come from a region's border (blur, pixel footprint,
        interreflection at its edges), a fraction of its pixels that falls
        as 1/sqrt(pixels), so a large region needs smaller corrections (its
        well-determined start is not pulled about by the others' errors) and
        a small one larger. None: the same rate for every region.
    held_regions : tuple of str
        Regions whose glossy parameters keep their texture-space fit (the
        albedo correction still covers them).
    holdout, holdout_block : float, int
        The fraction of blocks (of that side, render pixels) of each
        photograph's face pixels left out of the fit: the refined estimate is
        returned only if its loss on them is lower than the texture-space
        fit's (:data:`HOLDOUT`, :data:`HOLDOUT_BLOCK`).

    The defaults come from the error-against-time measurements of
    ``validation/refine.py`` (``validation/results/refine.json``) and the
    variants compared in ``docs/refine.md`` (simulated default capture, 512²,
    seed 0): cells of 2 texels (4: eyebrow ρs 17 %, 16: worse still; 1: 13 %;
    2: 12 % after 72 iterations, still falling), the last quarter of the
    iterates averaged. Which regions to hold and whether the lights' gains are
    variables were chosen on the training captures of
    ``validation/refine_seeds.py`` (seeds 11, 12, 100;
    ``validation/results/refine_seeds_train.json``):
    holding skin and beard left their texture-space errors (ρs 23 % and 35 %)
    where refining them took them to 4 % and 5 %; refining the eyebrows took
    their ρs from 39 % to 48 % and their roughness from 10 % to 17 % at no
    gain under a novel light (4.67 % either way), so the eyebrows alone are
    held. The light gains recovered every light's calibration error to
    0.06 % and changed the errors little there (those lights were off by
    0.6 %); they remove a bias in skin's ρs where a light is off by more
    (``validation/refine_gradient.py``).
    """

    iterations: int = 96
    spp: int = 4
    downsample: int = 1
    max_depth: int = 3
    learning_rate: float = 0.05
    albedo_learning_rate: float | None = 0.02
    albedo_cell: int = 2
    light_gain_learning_rate: float | None = 0.005
    environment_learning_rate: float | None = 0.03
    environment_smoothness: float = 0.01
    restart_under_maps: bool = True
    decay: float = 0.1
    epsilon: float = 0.02
    evaluation_spp: int = 16
    average: float = 0.25
    pixel_reference: int | None = 20_000
    held_regions: tuple[str, ...] = ("eyebrows",)
    holdout: float = HOLDOUT
    holdout_block: int = HOLDOUT_BLOCK

    def __post_init__(self):
        object.__setattr__(self, "held_regions", tuple(self.held_regions))
        if not 0.0 < self.holdout < 1.0:
            raise ValueError(f"RefineSchedule.holdout must be in (0, 1), got {self.holdout!r}")
        if int(self.holdout_block) < 1:
            raise ValueError(f"RefineSchedule.holdout_block must be >= 1, got {self.holdout_block!r}")
        for name in ("iterations", "spp", "downsample", "evaluation_spp", "albedo_cell"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"RefineSchedule.{name} must be >= 1, got {getattr(self, name)!r}")
        if self.max_depth < 2:
            raise ValueError(f"RefineSchedule.max_depth must be >= 2 (direct light), got {self.max_depth!r}")
        if not self.environment_smoothness >= 0:
            raise ValueError(f"RefineSchedule.environment_smoothness must be >= 0, got {self.environment_smoothness!r}")
        for name in ("albedo_learning_rate", "light_gain_learning_rate", "environment_learning_rate"):
            if getattr(self, name) is not None and not getattr(self, name) > 0:
                raise ValueError(f"RefineSchedule.{name} must be > 0 or None, got {getattr(self, name)!r}")
        if self.pixel_reference is not None and self.pixel_reference < 1:
            raise ValueError(f"RefineSchedule.pixel_reference must be >= 1 or None, got {self.pixel_reference!r}")
        if not 0.0 <= self.average < 1.0:
            raise ValueError(f"RefineSchedule.average must be in [0, 1), got {self.average!r}")

    def rate(self, name: str, iteration: int, pixels: int | None = None) -> float:
        """Learning rate of variable ``name`` (``albedo`` or a region's, seen
        by ``pixels``) at ``iteration``: from its value (scaled by
        ``pixel_reference``) down to ``decay`` times it by half a cosine."""
        if name.startswith(ENVIRONMENT + ":"):
            rate, pixels = self.environment_learning_rate, None
        else:
            rate = {ALBEDO: self.albedo_learning_rate, LIGHT_GAIN: self.light_gain_learning_rate}.get(
                name, self.learning_rate)
        if name not in (ALBEDO, LIGHT_GAIN) and self.pixel_reference is not None and pixels:
            rate *= min(MAX_RATE_SCALE, float(np.sqrt(self.pixel_reference / pixels)))
        t = iteration / max(self.iterations - 1, 1)
        return rate * (self.decay + (1 - self.decay) * 0.5 * (1 + np.cos(np.pi * t)))

    @property
    def averaged_from(self) -> int:
        """First iteration (0-based) whose iterate enters the average."""
        return self.iterations - max(1, int(round(self.average * self.iterations)))


class IterateAverage:
    """Running mean of the optimiser's variables over the iterations from
    :attr:`RefineSchedule.averaged_from` on (the last iterate alone when
    ``average`` is 0)."""

    def __init__(self, names, schedule: RefineSchedule):
        self.names, self.start = list(names), schedule.averaged_from
        self.sums, self.count = {}, 0

    def add(self, iteration: int, variables) -> None:
        """Add the variables after step ``iteration`` (0-based) if it is averaged."""
        if iteration < self.start:
            return
        with dr.suspend_grad():
            for name in self.names:
                value = dr.detach(variables[name])
                self.sums[name] = value if name not in self.sums else self.sums[name] + value
            dr.eval(self.sums)
        self.count += 1

    def mean(self, variables) -> dict:
        """The averaged variables (``variables`` as they are before any average)."""
        if not self.count:
            return {name: variables[name] for name in self.names}
        out = {name: value / self.count for name, value in self.sums.items()}
        return {name: mi.TensorXf(v) if isinstance(variables[name], mi.TensorXf) else v for name, v in out.items()}


__all__ = ["RefineSchedule", "IterateAverage", "environment_variable"]
