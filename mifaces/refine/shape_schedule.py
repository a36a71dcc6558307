"""How the shape refinement (:func:`mifaces.refine.shape.refine_shape`) runs: its schedule."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..options.fields import check, option
from .schedule import HOLDOUT, HOLDOUT_BLOCK


#: The longest side (pixels) the refinement renders at by default (:attr:`ShapeRefineSchedule.downsample`):
#: the resolutions its schedule was chosen at (128² and 256²). On a tuning capture at 512², full resolution
#: took 2.2 times as long for the same distances and normals 0.1° closer (docs/refine_shape.md, "Render
#: resolution").
RENDER_SIDE = 256


@dataclass(frozen=True)
class ShapeRefineSchedule:
    """How :func:`~mifaces.refine.shape.refine_shape` runs.

    Attributes
    ----------
    iterations : int
        Adam steps; each renders every photograph forward and backward.
    learning_rate : float
        The step of UniformAdam (Nicolet et al. 2021, sec. 5: one step size
        for all vertices, the largest second moment's) in LargeSteps' latent
        variable u = (I + λL) d, mm: the largest change of u per step (a
        bump a few edges wide has u several times its height).
    smoothing : float
        λ of LargeSteps' ``I + λL``: larger, smoother steps (the paper's
        advice: grow it with the mesh's resolution).
    spp : int
        Samples per pixel of the continuous derivatives (``sppc``) and of the primal.
    spp_silhouette : int
        Samples per pixel of the primary-visibility derivatives (``sppp``: silhouettes).
    spp_shadow : int
        Samples per pixel of the indirect-visibility derivatives (``sppi``:
        cast shadows of an area lamp; 0 leaves them out, as a point light's
        hard shadows have no projective samples).
    downsample : int or None
        Render at 1/``downsample`` of the camera's resolution. None (the default): the smallest
        factor that brings the camera's longer side to at most :data:`RENDER_SIDE` pixels
        (:meth:`factor`), so that a photograph's size does not set the refinement's cost.
    decay : float
        The learning rate falls to ``decay`` times its value over the
        iterations (half a cosine).
    epsilon : float
        ε of the Charbonnier penalty, relative to the photograph's mean.
    evaluation_spp : int
        Samples per pixel of the held-out loss before and after.
    holdout : float
        Fraction of the blocks of each photograph's face pixels left out of
        the fit, to judge the result on.
    holdout_block : int
        Side of those blocks (render pixels).
    early_stop : bool
        Half of the held-out blocks (drawn at random) choose the iteration:
        their loss is read off every iteration's renders, and the displacement
        of the iteration where it was lowest (:func:`~mifaces.refine.shape_choice.chosen_iteration`)
        is the result; the other half alone judges it. Off (the default): the
        last iteration's, judged on all the held-out blocks. On the tuning
        captures (``docs/refine_shape.md``) it cut the harm to the normals of
        faces near the model's span, and recovered less of a bump beyond it on one of two.
    judged : int
        Photographs held out of the fit entirely, to judge the result under
        lamps the refinement did not see (:func:`~mifaces.refine.shape_choice.judged_photographs`); none
        where fewer than ``judged + 2`` photographs have shapes. 0 (the
        default): the held-out pixels judge alone; ``docs/refine_shape.md``
        measures both (the held-out photograph rejected the refinements that
        relit Yale's held-out lights better, and kept one that relights the
        default capture worse).
    carry_over : float
        The judged photographs' loss must fall by at least this fraction of
        the relative fall on the fitted photographs' held-out pixels: a
        refinement whose gain does not carry over to a photograph it did not
        see has fitted the photographs, not the face. Half the gain: a round
        value, not tuned. Of the verdicts in ``docs/refine_shape.md`` two
        depend on it: the 256² default capture's (kept below 0.13) and Yale
        subject B03's (kept below 0.39).

    The defaults were chosen on simulated captures with seeds other than the
    default (0), see ``docs/refine_shape.md``.
    """

    iterations: int = 32
    learning_rate: float = 4.0
    smoothing: float = 20.0
    spp: int = 8
    spp_silhouette: int = 4
    spp_shadow: int = 0
    downsample: int | None = None
    decay: float = 0.5
    epsilon: float = 0.02
    evaluation_spp: int = 32
    holdout: float = HOLDOUT
    holdout_block: int = HOLDOUT_BLOCK
    early_stop: bool = option(False, help="Let half of --refine-shape's held-out pixels choose its iteration, the "
                                          "other half judge it (docs/refine_shape.md).")
    judged: int = option(0, bounds=(0, None), help="Photographs held out of --refine-shape to judge it by (the last "
                                                   "ones; 0: held-out pixels only; docs/refine_shape.md).")
    carry_over: float = 0.5

    def __post_init__(self):
        check(self)
        counts = ["iterations", "spp", "evaluation_spp", "holdout_block"]
        if self.downsample is not None:  # None: chosen per camera (factor)
            counts.append("downsample")
        for name in counts:
            if isinstance(getattr(self, name), bool) or int(getattr(self, name)) < 1:
                raise ValueError(f"ShapeRefineSchedule.{name} must be an integer >= 1, got {getattr(self, name)!r}")
        for name in ("spp_silhouette", "spp_shadow"):
            if isinstance(getattr(self, name), bool) or int(getattr(self, name)) < 0:
                raise ValueError(f"ShapeRefineSchedule.{name} must be >= 0, got {getattr(self, name)!r}")
        for name in ("learning_rate", "smoothing", "epsilon"):
            if not float(getattr(self, name)) > 0:
                raise ValueError(f"ShapeRefineSchedule.{name} must be > 0, got {getattr(self, name)!r}")
        if not 0.0 < self.holdout < 1.0:
            raise ValueError(f"ShapeRefineSchedule.holdout must be in (0, 1), got {self.holdout!r}")
        if not 0.0 <= self.carry_over <= 1.0:
            raise ValueError(f"ShapeRefineSchedule.carry_over must be in [0, 1], got {self.carry_over!r}")
        if not 0.0 < self.decay <= 1.0:
            raise ValueError(f"ShapeRefineSchedule.decay must be in (0, 1], got {self.decay!r}")

    def factor(self, camera) -> int:
        """The renders' :attr:`downsample` for ``camera``'s photographs."""
        if self.downsample is not None:
            return int(self.downsample)
        return max(1, -(-max(camera.width, camera.height) // RENDER_SIDE))

    def rate(self, iteration: int) -> float:
        """Adam's learning rate at ``iteration``: from :attr:`learning_rate`
        down to ``decay`` times it by half a cosine."""
        t = iteration / max(self.iterations - 1, 1)
        return self.learning_rate * (self.decay + (1 - self.decay) * 0.5 * (1 + np.cos(np.pi * t)))

    def integrator(self) -> dict:
        """The Mitsuba integrator of the renders."""
        return {"type": "direct_projective", "sppc": int(self.spp), "sppp": int(self.spp_silhouette),
                "sppi": int(self.spp_shadow), "hide_emitters": True}


__all__ = ["RENDER_SIDE", "ShapeRefineSchedule"]
