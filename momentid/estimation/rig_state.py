"""Which trials of a recording belong to one rig state: a check from the trials' own modes.

A rig whose joints slip more as it shakes harder moves all its modes together: the harder a trial
shook, the lower every mode sits, each along one curve of the rig.  Mode 1's frequency is the rig's
own measure of how far its joints have slipped (a trial's RMS response is not: a sine held at
resonance and a short earthquake of the same RMS slip the joints differently), so within one rig
state the higher modes follow mode 1 along a line.  A trial from another rig state (another day,
sensors or clamps re-mounted, a bolt re-tightened) sits off that line: its stiffness pattern, not
only its amplitude, has changed.

:func:`check_state` fits, for every trial, the other trials' higher-mode frequencies against their
mode-1 frequency (:func:`~momentid.estimation.scaled.weighted_line`: weighted by the identification's
standard errors, widened by the scatter beyond them) and states how far the trial's own modes lie off
that line, in combined standard errors (the line's prediction, the trial's own error, and the trial's
mode-1 error carried through the slope).  A trial further off than :data:`OFF_TREND_SIGMAS` does not
belong with the others.  A trial that shook beyond the others (its mode 1 outside their range) is read
off a line's extrapolation, and a joint that reaches macro-slip bends the trend there: such a trial is
off only when, besides, its modes moved from the nearest trial against the trend's direction (a
simulated 5-storey rig with joint friction in storey 2 had its hardest trial 6.4 standard errors off
the line, every mode further along the trend; the shipped flexible rig's trial of another day moved
mode 1 down and mode 2 0.1 Hz up).  The check never reads a trial's name or date.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from momentid.estimation.scaled import ModalIdentification, weighted_line

__all__ = ["StateCheck", "check_state", "OFF_TREND_SIGMAS", "MIN_OTHERS"]

#: A trial whose higher modes lie further than this many combined standard errors off the others'
#: trend against mode 1 is from another rig state.  On the shipped rig the four same-day trials lie
#: within 1.7 and the trial of another day 15.7 off; the identification's standard errors of a real
#: rig are optimistic by a few times (its residuals are not white), hence a margin well above 3.
OFF_TREND_SIGMAS = 6.0
#: Other trials a trial is checked against at least: a line through two points has no scatter to
#: widen its errors with.
MIN_OTHERS = 3


@dataclass(frozen=True)
class StateCheck:
    """Each trial's distance from the other trials' mode trend (:func:`check_state`).

    Attributes
    ----------
    runs : tuple of str
        The trials checked, in recording order.
    sigmas : dict
        Per trial: its largest distance off the others' trend (combined standard errors); empty when
        not tested.
    worst : dict
        Per trial: ``{"mode", "frequency_hz", "expected_hz", "std_hz", "mode1_hz"}`` of its mode
        furthest off.
    outliers : tuple of str
        Trials further off than :data:`OFF_TREND_SIGMAS`.
    tested : bool
        False when there are too few trials (fewer than ``MIN_OTHERS + 1``) or modes (one).
    """

    runs: tuple
    sigmas: dict
    worst: dict
    outliers: tuple
    tested: bool

    def belongs(self, run: str) -> bool:
        """Whether trial ``run`` belongs with the others (it is no outlier)."""
        return run not in self.outliers

    def sentence(self, run: str) -> str:
        """One line saying why ``run`` does not belong with the others."""
        w = self.worst[run]
        return (f"run {run} does not belong with the others: its own modes lie off their trend by "
                f"{self.sigmas[run]:.1f} standard errors (mode {w['mode']} at {w['frequency_hz']:.3f} Hz where the "
                f"other trials, at its mode-1 frequency of {w['mode1_hz']:.3f} Hz, put it at {w['expected_hz']:.3f} "
                f"+- {w['std_hz']:.3f} Hz; the others lie within {self.spread():.1f}): another rig state (another "
                f"day, sensors or joints re-mounted), not physics the twin leaves out; it is left out of the fit")

    def spread(self) -> float:
        """The largest distance of a trial that belongs (standard errors)."""
        inside = [s for r, s in self.sigmas.items() if r not in self.outliers]
        return max(inside) if inside else float("nan")

    def to_dict(self) -> dict:
        """The check as a JSON-ready dict (distances in standard errors)."""
        return {"tested": self.tested, "threshold_sigmas": OFF_TREND_SIGMAS, "sigmas": dict(self.sigmas),
                "worst": dict(self.worst), "outliers": list(self.outliers)}


def check_state(results: Sequence[ModalIdentification]) -> StateCheck:
    """Check which trials belong to one rig state (module docstring).

    Parameters
    ----------
    results : sequence of ModalIdentification
        One per trial (:func:`~momentid.estimation.scaled.identify_per_run`), each with ``runs``,
        ``frequency`` and ``frequency_std`` of shape (modes,) in Hz, modes in ascending order.

    Returns
    -------
    StateCheck
    """
    runs = tuple(r.runs[0] for r in results)
    n_modes = min(len(r.frequency) for r in results)
    if len(results) < MIN_OTHERS + 1 or n_modes < 2:
        return StateCheck(runs, {}, {}, (), False)
    F = np.array([np.asarray(r.frequency, float)[:n_modes] for r in results])
    S = np.array([np.maximum(np.asarray(r.frequency_std, float)[:n_modes], 1e-9) for r in results])
    sigmas, worst = {}, {}
    for i, run in enumerate(runs):
        others = np.array([j for j in range(len(runs)) if j != i])
        best = None
        for m in range(1, n_modes):
            expected, std = _predict(F[others, 0], F[others, m], S[others, m], F[i, 0], S[i, 0])
            dev = abs(F[i, m] - expected) / float(np.hypot(std, S[i, m]))
            if not F[others, 0].min() <= F[i, 0] <= F[others, 0].max():      # shook beyond the others
                dev = min(dev, _against_trend(F[others], S[others], F[i], S[i], m, expected))
            if best is None or dev > best[0]:
                best = (dev, {"mode": m + 1, "frequency_hz": float(F[i, m]), "expected_hz": expected,
                              "std_hz": float(np.hypot(std, S[i, m])), "mode1_hz": float(F[i, 0])})
        sigmas[run], worst[run] = float(best[0]), best[1]
    outliers = tuple(r for r in runs if sigmas[r] > OFF_TREND_SIGMAS)
    return StateCheck(runs, sigmas, worst, outliers, True)


def _against_trend(F: np.ndarray, S: np.ndarray, f: np.ndarray, s: np.ndarray, m: int, expected: float) -> float:
    """How far (combined standard errors) mode ``m`` of a trial whose mode 1 lies beyond the others' range
    moved from the nearest trial *against* the trend (``F``, ``S``: the others' frequencies and errors, a
    row per trial; ``f``, ``s``: the trial's; ``expected``: the line's value there, which gives the trend's
    direction).  0 when it moved with the trend, however far."""
    near = int(np.argmin(np.abs(F[:, 0] - f[0])))
    direction = np.sign(expected - F[near, m])
    against = max(0.0, -direction * (f[m] - F[near, m])) if direction else abs(f[m] - F[near, m])
    return against / float(np.hypot(S[near, m], s[m]))


def _predict(x, y, s, x0: float, s0: float) -> tuple[float, float]:
    """The weighted line through ``(x, y)`` (errors ``s``) at ``x0``, and its standard error: the line's,
    widened by the scatter beyond ``s`` as :func:`~momentid.estimation.scaled.weighted_line` does, and
    ``x0``'s own error ``s0`` carried through the slope."""
    coef, slope_std = weighted_line(x, y, s)
    A = np.column_stack([np.ones_like(x), x]) / s[:, None]
    cov = np.linalg.inv(A.T @ A)
    cov *= slope_std ** 2 / cov[1, 1]                 # the same widening as the slope's
    v = np.array([1.0, x0])
    return float(v @ coef), float(np.sqrt(v @ cov @ v + (coef[1] * s0) ** 2))
