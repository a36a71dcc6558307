"""What :func:`mifaces.refine.shape.refine_shape` keeps: the iteration (chosen by half of the
held-out blocks), the photographs held out to judge the result, and the verdict on it."""

from __future__ import annotations

import numpy as np


#: Iterations averaged (centred) before the lowest loss of the blocks that choose is taken: one
#: iteration's renders carry Monte Carlo noise of the size of the differences between iterations.
CHOICE_WINDOW = 5


def chosen_iteration(losses, window: int = CHOICE_WINDOW) -> int:
    """The iteration :func:`refine_shape` keeps (:attr:`ShapeRefineSchedule.early_stop`): where the
    loss of the blocks that choose, averaged over ``window`` iterations centred on it (fewer at the
    ends), is lowest; the earliest such."""
    losses = np.asarray(losses, np.float64)
    if losses.ndim != 1 or losses.size == 0:
        raise ValueError("chosen_iteration needs one loss per iteration")
    half = int(window) // 2
    means = [losses[max(0, i - half): i + half + 1].mean() for i in range(losses.size)]
    return int(np.argmin(means))


def judged_photographs(names: list[str], count: int) -> list[str]:
    """The photographs :func:`refine_shape` holds out of its fit to judge the result on: the last
    ``count`` of ``names`` (the capture's order); none where that would leave fewer than two to fit."""
    count = int(count)
    return list(names[-count:]) if count > 0 and len(names) >= count + 2 else []


def verdict(before: dict, after: dict, judged: list[str], carry_over: float) -> tuple[bool, str]:
    """Whether the refined shape is kept, and why in words: the loss fell on the fitted photographs'
    held-out pixels and, where there are judged photographs, fell on them too by at least
    ``carry_over`` times the held-out pixels' relative fall."""
    gain = 1.0 - after["heldout"] / before["heldout"]
    words = f"held-out pixels {before['heldout']:.5g} -> {after['heldout']:.5g} ({-100 * gain:+.1f} %)"
    if gain <= 0:
        return False, f"loss on {words}: did not fall, the model fit is kept"
    if not judged:
        return True, f"loss on {words}: fell, the refined shape is kept"
    carried = 1.0 - after["judged"] / before["judged"]
    label = f"held-out photograph{'s' * (len(judged) > 1)} {', '.join(judged)}"
    words += f"; {label} {before['judged']:.5g} -> {after['judged']:.5g} ({-100 * carried:+.1f} %)"
    if carried >= carry_over * gain:
        return True, f"loss on {words}: fell on both, the refined shape is kept"
    return False, (f"loss on {words}: the fall did not carry over to the {label} (at least {carry_over:g} "
                   f"of the held-out pixels' needed), the model fit is kept")


__all__ = ["CHOICE_WINDOW", "chosen_iteration", "judged_photographs", "verdict"]
