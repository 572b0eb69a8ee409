"""Clipping found in a channel's samples: the flat runs at its extreme a transducer's range leaves.

:func:`find_clipping` reports it; the recorded runs' checks refuse a clipped channel
(:func:`momentid.io.run_checks.check_clipping`) and the diagnosis names it (the ``sensor_saturation`` kind
reads its level from it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Clipping", "find_clipping", "runs_of", "CLIP_STEP_QUANTA", "PEAK_TOLERANCE"]

#: A flat run at a channel's peak entered or left by a step larger than this
#: many quantisation steps is clipping; a quantised smooth peak is entered by one.
CLIP_STEP_QUANTA = 2.5

#: Relative tolerance for "at the peak value" (floating-point round-off only).
PEAK_TOLERANCE = 1e-12


def runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of every run of True in a boolean vector, shape (n,): ``mask[start:stop]`` is the run."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[::2], edges[1::2]))


@dataclass(frozen=True)
class Clipping:
    """What :func:`find_clipping` finds on a channel: the level its reading is held at (the channel's
    unit), the samples held there, and the first flat run: its start (index), length and value."""

    level: float
    samples: int
    first: int
    first_run: int
    first_value: float


def find_clipping(x: np.ndarray, clip_samples: int = 3) -> Clipping | None:
    """A channel's clipping, reported: flat runs of at least ``clip_samples`` samples at the channel's
    extreme, each entered or left by a step larger than :data:`CLIP_STEP_QUANTA` quantisation steps (a
    quantised smooth peak is entered by one).  None when there is none.

    Parameters
    ----------
    x : ndarray, shape (n,)
        One channel's samples (finite).
    clip_samples : int
        The shortest flat run at the extreme that counts.
    """
    peak = float(np.max(np.abs(x)))
    if peak == 0:
        return None
    levels = np.unique(x)
    quantum = float(np.min(np.diff(levels))) if levels.size > 1 else peak
    at_peak = np.abs(np.abs(x) - peak) <= PEAK_TOLERANCE * peak
    held, first = 0, None
    for a, b in runs_of(at_peak):
        if b - a < clip_samples:
            continue
        steps = [abs(x[a] - x[a - 1])] if a > 0 else []
        steps += [abs(x[b] - x[b - 1])] if b < x.size else []
        if steps and max(steps) > CLIP_STEP_QUANTA * quantum:
            held += int(b - a)
            first = (int(a), int(b - a), float(x[a])) if first is None else first
    return Clipping(peak, held, *first) if first is not None else None
