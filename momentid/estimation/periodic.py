"""A periodic table: a sine test and its harmonics force a mode only at the lines of one fundamental.

:func:`periodic_fundamental` finds that fundamental in the table's spectrum; :func:`periodic_refusal`
says when a mode is forced only at those lines (its damping then cannot be read from the forced
response: the lines read the detuning, not the damping); :func:`forced_line` when a mode's fitted frequency
sits on one of those lines, closer than the record resolves.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np

from momentid.core.series import RunData

__all__ = ["periodic_fundamental", "periodic_refusal", "forced_line", "FORCED_LINE", "ABOVE_RING_SIGMAS",
           "PERIODIC_SHARE", "LOCAL_LINE_SHARE", "NEAR_LINES", "CONCENTRATION", "LINE_BINS", "MIN_FUNDAMENTAL"]

#: A table motion is periodic when lines at the multiples of one fundamental (within
#: :data:`LINE_BINS` bins) hold this share of its power (a sine test beside its servo's noise) ...
PERIODIC_SHARE = 0.5
#: ... and it forces a mode only at its harmonics when they hold this share of the table's power within
#: :data:`NEAR_LINES` (relative) of the mode.
LOCAL_LINE_SHARE = 0.5
NEAR_LINES = 0.2
#: Combs whose shares differ by less than this hold the same lines (a denser one adds only noise bins).
COMB_SLACK = 0.05
#: ... and the power per bin on the lines is this many times the power per bin off them: a dense comb (a
#: low fundamental in a short record) covers most bins, and any broadband motion fills it (a broadband
#: table gives about 1, a sine test 10-100).
CONCENTRATION = 4.0
LINE_BINS = 2
#: Fundamentals (Hz) tried: the table's strongest lines and their halves and thirds, down to this.
MIN_FUNDAMENTAL = 0.3


def periodic_fundamental(table: np.ndarray, sample_rate: float) -> float | None:
    """The fundamental (Hz) of a periodic table motion (a sine test and its harmonics), or None.

    The table's power (Hann window) is periodic when lines at the multiples of one frequency hold
    :data:`PERIODIC_SHARE` of it, at :data:`CONCENTRATION` times the power per bin off them; the
    fundamentals tried are the five strongest lines (local maxima of the spectrum: the bins beside a
    line's peak are its window's main lobe, not lines of their own) and their halves and thirds.
    Remembered per table, by a digest of its samples (the refusals ask it for every mode of every run).
    """
    u = np.ascontiguousarray(table, float)
    key = (hashlib.blake2b(u.tobytes(), digest_size=16).digest(), u.size, float(sample_rate))
    if key not in _FUNDAMENTALS:
        if len(_FUNDAMENTALS) >= _REMEMBERED:
            _FUNDAMENTALS.pop(next(iter(_FUNDAMENTALS)))     # the oldest
        _FUNDAMENTALS[key] = _fundamental(u, float(sample_rate))
    return _FUNDAMENTALS[key]


#: Tables whose fundamental is remembered (keyed by a digest: a long record's samples are not kept).
_REMEMBERED = 64
_FUNDAMENTALS: dict[tuple, float | None] = {}


def _fundamental(u: np.ndarray, sample_rate: float) -> float | None:
    u = u - np.mean(u)
    n = u.size
    power = np.abs(np.fft.rfft(u * np.hanning(n))) ** 2
    freq = np.fft.rfftfreq(n, 1.0 / sample_rate)
    keep = freq > MIN_FUNDAMENTAL
    total = float(np.sum(power[keep]))
    if total <= 0:
        return None
    df = freq[1]
    found = []
    peak = np.r_[False, (power[1:-1] >= power[:-2]) & (power[1:-1] > power[2:]), False] & keep
    for k in np.argsort(np.where(peak, power, 0.0))[::-1][:5]:
        for m in (1, 2, 3):
            f0 = freq[k] / m
            if f0 < MIN_FUNDAMENTAL:
                continue
            lines = np.zeros(freq.size, bool)
            for h in np.arange(1, int(freq[-1] / f0) + 1):
                lines |= np.abs(freq - h * f0) <= LINE_BINS * df
            share = float(np.sum(power[lines & keep])) / total
            covered = float(np.count_nonzero(lines & keep)) / float(np.count_nonzero(keep))
            if share >= PERIODIC_SHARE and share * (1 - covered) >= CONCENTRATION * covered * (1 - share):
                found.append((share, float(f0)))
    if not found:
        return None
    best = max(share for share, _ in found)
    # the sparsest comb that holds as much of the power (a denser one holds its lines and more noise)
    return max(f0 for share, f0 in found if share >= best - COMB_SLACK)


def _forced_only(run: RunData, f_mode: float) -> tuple[float, int, float] | None:
    """``(f0, k, ratio)`` when ``run``'s table is periodic at ``f0`` (Hz) and forces the mode at ``f_mode``
    (Hz) only at its harmonics ``k f0`` and ``(k + 1) f0``, its power between them ``ratio`` times below
    theirs; None when the table is not periodic, or its broadband motion beside the mode is as strong as its
    harmonics there."""
    f0 = periodic_fundamental(run["zdd"], run.sample_rate)
    if f0 is None:
        return None
    k = int(np.floor(f_mode / f0))
    n = run.n_samples
    power = np.abs(np.fft.rfft((run["zdd"] - np.mean(run["zdd"])) * np.hanning(n))) ** 2
    freq = np.fft.rfftfreq(n, 1.0 / run.sample_rate)
    df = freq[1]
    near = np.abs(freq / f_mode - 1) <= NEAR_LINES
    lines = np.abs(freq / f0 - np.round(freq / f0)) * f0 <= LINE_BINS * df
    if float(np.sum(power[near & lines])) < LOCAL_LINE_SHARE * float(np.sum(power[near])):
        return None                        # beside the mode the table's broadband motion drives it too
    at = [float(np.max(power[np.abs(freq - h * f0) <= LINE_BINS * df])) for h in (k, k + 1)
          if h >= 1 and h * f0 < freq[-1] - LINE_BINS * df]
    between = (freq > k * f0 + 3 * df) & (freq < (k + 1) * f0 - 3 * df)
    level = float(np.median(power[between])) if between.any() else 0.0
    return f0, k, (min(at) / level if at and level > 0 else np.inf)


def periodic_refusal(runs: Sequence[RunData], f_mode: float) -> str:
    """Why a mode forced only by a periodic table cannot give its damping.

    Parameters
    ----------
    runs : sequence of RunData
        The runs the mode was fitted on (``zdd``, m/s^2).
    f_mode : float
        The mode's frequency (Hz).

    Returns
    -------
    str
        The refusal in words, or ``''`` when no run's table is periodic, or its broadband motion beside
        the mode is as strong as its harmonics there.
    """
    for run in runs:
        forced = _forced_only(run, f_mode)
        if forced is None:
            continue
        f0, k, ratio = forced
        # lines a few bins apart (a short record) leave no bin between them to compare
        between = (f"between them its power is {ratio:.2g} times below theirs" if np.isfinite(ratio) else
                   "the record holds no bin between them to compare")
        return (f"the table's motion in run {run.name!r} is periodic at {f0:.4g} Hz and never leaves the mode at "
                f"{f_mode:.4g} Hz ringing free: it forces it at its harmonics ({k * f0:.4g} and {(k + 1) * f0:.4g} "
                f"Hz), and {between}; a forced response there measures the detuning, not the damping")
    return ""


#: The words that mark a mode's frequency as not an answer (:func:`forced_line`).
FORCED_LINE = "its frequency is NOT AN ANSWER"
#: A mode forced only at a periodic table's lines whose fitted frequency lies more than this many standard
#: errors above where it rings free at small amplitude is not answered (:func:`forced_line`; 17 of the shipped
#: rigs' 18 fitted modes that ring free lie 9-204 standard errors below it, as joints that slip make them; the
#: 18th, 3.5 above, is forced between a 2 Hz table's 11th and 12th harmonics).
ABOVE_RING_SIGMAS = 3.0


def forced_line(runs: Sequence[RunData], frequency: float, ring_frequency: float | None = None,
                frequency_std: float = np.nan) -> str:
    """Why a mode's fitted frequency may be a periodic table's forced line, not the mode ('' when not).

    A table that moves periodically (a sine test and its harmonics, :func:`periodic_fundamental`) forces
    the structure only at multiples of its fundamental.  A fitted frequency closer to one of them than
    the record resolves (one DFT bin, ``1 / T``) is the line's as much as the mode's: the data cannot
    tell them apart.  Between two lines, when every run forces the mode only there, the fit interpolates
    between them: a fitted frequency more than :data:`ABOVE_RING_SIGMAS` standard errors above where the
    mode rings free at small amplitude is the lines' pull, not the mode (a joint that slips as the rig
    shakes harder lowers its frequency; a rig that hardens would raise it, which lines alone cannot tell).

    Parameters
    ----------
    runs : sequence of RunData
        The runs the mode was fitted on (``zdd``, m/s^2).
    frequency : float
        The mode's fitted frequency (Hz).
    ring_frequency : float, optional
        The frequency (Hz) at which the mode rings free at small amplitude in the record's free decays,
        quoted when given.
    frequency_std : float, optional
        The fitted frequency's standard error (Hz); without it the fit is not checked against
        ``ring_frequency``.

    Returns
    -------
    str
        The warning in words (containing :data:`FORCED_LINE`), or ``''``.
    """
    for run in runs:
        f0 = periodic_fundamental(run["zdd"], run.sample_rate)
        if f0 is None:
            continue
        k = max(int(round(frequency / f0)), 1)
        gap, resolution = abs(frequency - k * f0), run.sample_rate / run.n_samples
        if gap > resolution:
            continue
        ring = ("" if ring_frequency is None else
                f"; where it rings free, it rings at {ring_frequency:.4g} Hz at small amplitude")
        return (f"mode at {frequency:.4g} Hz: {FORCED_LINE}: it lies {gap:.2g} Hz from harmonic {k} "
                f"({k * f0:.4g} Hz) of run {run.name!r}'s periodic table ({f0:.4g} Hz), closer than the record "
                f"resolves (1/T = {resolution:.2g} Hz), so the fit cannot tell the mode from the forced line{ring}")
    if ring_frequency is None or not frequency - ring_frequency > ABOVE_RING_SIGMAS * frequency_std:
        return ""
    forced = [_forced_only(run, frequency) for run in runs]
    if not runs or any(f is None for f in forced):
        return ""
    f0, k, _ = forced[0]
    return (f"mode at {frequency:.4g} Hz: {FORCED_LINE}: the periodic table ({f0:.4g} Hz) of run(s) "
            f"{', '.join(repr(r.name) for r in runs)} forces it only at its harmonics ({k * f0:.4g} and "
            f"{(k + 1) * f0:.4g} Hz), and the fit puts it {frequency - ring_frequency:.2g} Hz "
            f"({(frequency - ring_frequency) / frequency_std:.1f} standard errors) above where it rings free at small "
            f"amplitude ({ring_frequency:.4g} Hz): between the lines the fit reads their pull (a joint that slips as "
            f"the rig shakes harder lowers its frequency; a stiffening rig would raise it, which the lines cannot "
            f"tell apart)")
