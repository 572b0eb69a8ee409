"""The measured table-to-floor transfer functions of a run: H1 estimates and their coherence.

``H_j(f) = S_za_j(f) / S_zz(f)``: the cross-spectrum of the table acceleration ``zdd`` and floor
sensor ``a_j`` over the table's auto-spectrum (Welch averages of Hann-windowed segments), with the
magnitude-squared coherence of the two.  Where the coherence is low the table barely drives that
band (a sine trial between its harmonics) and the estimate is noise: plots show only the bins at or
above :data:`MIN_COHERENCE`; files carry every bin with its coherence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal

from momentid.core.series import RunData
from momentid.errors import SensorDataError

__all__ = ["MeasuredTransfer", "measured_transfer", "MIN_COHERENCE", "SEGMENT"]

#: Least coherence of a recorded transfer estimate a plot shows: below it the table barely drives that
#: band (a sine trial between its harmonics), and the estimate is noise.
MIN_COHERENCE = 0.8
#: Longest Welch segment (samples): at 120 Hz, 0.03 Hz bins, a few across a 0.3 %-damped 17 Hz mode.
SEGMENT = 4096


@dataclass(frozen=True)
class MeasuredTransfer:
    """The H1 estimates of one run (:func:`measured_transfer`).

    Attributes
    ----------
    run : str
    frequency : ndarray, shape (nf,)
        Hz, evenly spaced from 0.
    h : ndarray, shape (nf, d), complex
        ``a_j / zdd`` (1: acceleration over acceleration).
    coherence : ndarray, shape (nf, d)
        Magnitude-squared coherence (0..1).
    start : int
        First sample used (after the run's quiet lead-in).
    segment : int
        Welch segment length (samples).
    """

    run: str
    frequency: np.ndarray
    h: np.ndarray
    coherence: np.ndarray
    start: int
    segment: int

    def shown(self) -> np.ndarray:
        """``|h|`` where the coherence reaches :data:`MIN_COHERENCE`, NaN elsewhere (for plots)."""
        return np.where(self.coherence >= MIN_COHERENCE, np.abs(self.h), np.nan)


def measured_transfer(run: RunData, storeys: int, start: int = 0) -> MeasuredTransfer:
    """H1 estimate of ``a_j / zdd`` for every floor sensor of ``run``, from sample ``start`` on.

    Parameters
    ----------
    run : RunData
        With ``zdd`` and ``a1..ad`` (m/s^2).
    storeys : int
        ``d``.
    start : int
        First sample (for instance after the quiet lead-in, which holds only noise).

    Returns
    -------
    MeasuredTransfer

    Raises
    ------
    SensorDataError
        The run lacks the table sensor or a floor sensor.
    """
    missing = [c for c in ["zdd", *(f"a{j + 1}" for j in range(storeys))] if not run.has(c)]
    if missing:
        raise SensorDataError(f"run {run.name!r} has no {', '.join(missing)}: a table-to-floor transfer function "
                              f"needs the table sensor and every floor's")
    fs = run.sample_rate
    zdd = run["zdd"][start:]
    nperseg = int(min(SEGMENT, 2 ** np.floor(np.log2(max(zdd.size // 4, 16)))))
    f, pzz = scipy.signal.welch(zdd, fs=fs, nperseg=nperseg)
    h = np.empty((f.size, storeys), complex)
    coherence = np.empty((f.size, storeys))
    for j in range(storeys):
        a = run[f"a{j + 1}"][start:]
        _, pza = scipy.signal.csd(zdd, a, fs=fs, nperseg=nperseg)
        _, coherence[:, j] = scipy.signal.coherence(zdd, a, fs=fs, nperseg=nperseg)
        h[:, j] = pza / np.maximum(pzz, 1e-300)
    return MeasuredTransfer(run.name, f, h, coherence, int(start), nperseg)
