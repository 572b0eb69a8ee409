"""Is the sample rate high enough for the structure's modes?

Two checks, from what is known:

* a stated nominal model: its highest natural frequency must lie below
  :data:`MODE_NYQUIST_FRACTION` of the Nyquist frequency, else the data
  cannot identify it (an error);
* the data: a resonance of the floors (relative to the table) standing
  :data:`PEAK_PROMINENCE` decades above its surroundings in the top
  ``1 - MODE_NYQUIST_FRACTION`` of the band is a mode at, or folded from
  beyond, the Nyquist frequency (a note: an aliased mode cannot be told
  from a real one by the data alone).
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from momentid.core import analytic
from momentid.core.structure import Structure
from momentid.errors import SensorDataError

__all__ = ["check_model_rate", "check_plausible_rate", "resonances_near_nyquist", "MODE_NYQUIST_FRACTION",
           "PEAK_PROMINENCE", "PLAUSIBLE_RATE"]

#: A mode above this fraction of the Nyquist frequency is too close to it to
#: be resolved (the anti-alias roll-off of an IMU starts around there).
MODE_NYQUIST_FRACTION = 0.8
#: Prominence (decades of power spectral density) of a spectral peak that
#: counts as a resonance: the shipped 120 Hz records have no peak above
#: 1.7 decades in their top 20 % of the band, the same records kept every
#: 3rd-6th sample show their folded modes at 2.2-3.7 decades.
PEAK_PROMINENCE = 2.0
#: Welch segment length (samples): ~4 s at 120 Hz, 0.23 Hz resolution.
WELCH_SEGMENT = 512
#: Sample rates (Hz) a shake-table record can have.  Below 5 Hz no structural mode above 2 Hz is
#: resolved (bench-top models start at 1-4 Hz, IMUs log at 60-200 Hz, data loggers up to tens of kHz);
#: a time column in ms makes a 1 kHz record look like 1 Hz, and one in us like 1 mHz.  Above 1 MHz
#: a time column in a unit larger than seconds is likelier than such a logger.
PLAUSIBLE_RATE = (5.0, 1e6)


def check_model_rate(structure: Structure, sample_rate: float, where: str) -> None:
    """Refuse a sample rate too low for the stated nominal model's modes.

    Raises
    ------
    SensorDataError
        Naming ``where``, the highest mode (Hz) and the rate it needs.
    """
    M, K = structure.mass_matrix(), structure.stiffness_matrix()
    top = float(analytic.modal_properties(M, np.zeros_like(M), K).frequency[-1])
    nyquist = 0.5 * sample_rate
    if top > MODE_NYQUIST_FRACTION * nyquist:
        raise SensorDataError(f"{where}: sample rate {sample_rate:.6g} Hz is too low for the stated model's "
                              f"highest mode at {top:.4g} Hz; expected above "
                              f"{top / (0.5 * MODE_NYQUIST_FRACTION):.4g} Hz")


def check_plausible_rate(sample_rate: float, where: str) -> None:
    """Refuse a sample rate no shake-table record has (a time column in the wrong unit), before any
    numerics run on it.

    Raises
    ------
    SensorDataError
        Naming ``where``, the rate and the likely cause.
    """
    low, high = PLAUSIBLE_RATE
    if low <= sample_rate <= high:
        return
    guess = ("is the time column in ms?" if sample_rate < low and sample_rate * 1e3 >= low
             else "is the time column in us?" if sample_rate < low
             else "is the time column in a unit larger than seconds?")
    raise SensorDataError(f"{where}: sample rate {sample_rate:.4g} Hz (time step {1 / sample_rate:.4g} s): "
                          f"expected {low:g} Hz to {high:g} Hz for a shake-table record, with times in s: {guess}")


def resonances_near_nyquist(values: np.ndarray, sample_rate: float) -> list[float]:
    """Frequencies (Hz) of floor resonances near the Nyquist frequency.

    Parameters
    ----------
    values : ndarray, shape (n, 1 + d)
        Table then floor accelerations (m/s^2), nan allowed (left out).
    sample_rate : float
        Hz.

    Returns
    -------
    list of float
        Peak frequencies above ``MODE_NYQUIST_FRACTION`` of Nyquist, any floor.
    """
    rows = np.all(np.isfinite(values), axis=1)
    relative = values[rows, 1:] - values[rows, :1]
    if relative.shape[0] < 2 * WELCH_SEGMENT // 4:
        return []
    freq, psd = signal.welch(relative, fs=sample_rate, axis=0, nperseg=min(WELCH_SEGMENT, relative.shape[0]))
    found = set()
    for k in range(psd.shape[1]):
        peaks, _ = signal.find_peaks(np.log10(np.maximum(psd[:, k], np.finfo(float).tiny)),
                                     prominence=PEAK_PROMINENCE)
        found.update(float(freq[i]) for i in peaks if freq[i] >= MODE_NYQUIST_FRACTION * 0.5 * sample_rate)
    return sorted(found)
