"""Starting values for the fit without added mass: resonances picked from the spectra.

A lightly damped structure on a shake table shows its modes as peaks of the
floors' response *relative to the table*, ``a_j - z''``, wherever the table
itself does not put the peak there (a sine drive and its harmonics do).  The
score at each frequency is the relative response power over the table's
power plus a floor at the table's noise level::

    S(f) = sum_j P[a_j - z''](f) / (P[z''](f) + NOISE_FLOOR_FACTOR * noise PSD)

so a drive harmonic scores ``|H(f) - 1|^2`` (small off resonance) and a
resonance rung by any excitation (transients, the start and stop of a sine,
the table's own harmonics) scores high.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import scipy.signal

from momentid.core.series import RunData
from momentid.errors import IdentificationError

__all__ = ["pick_resonances", "peak_candidates", "require_resonances", "response_amplitude"]

#: Welch segment length (s): 0.1 Hz resolution, enough to separate the modes of
#: a shear building (their spacing is a large fraction of the first frequency).
SEGMENT = 10.0
#: The table-noise floor in the score's denominator, in units of its white-noise PSD.
NOISE_FLOOR_FACTOR = 10.0
#: Resonances are looked for between this fraction of the lowest resolvable
#: frequency ...
LOWEST_CYCLES = 5.0
#: ... and this fraction of the sample rate (below the anti-alias roll-off).
HIGHEST_FRACTION = 0.42
#: Half-width (Hz multiples of the Welch resolution) searched on the full-record
#: spectrum to refine a picked peak.
REFINE_BINS = 1.5
#: Peaks returned by :func:`peak_candidates`: this many per storey plus :data:`MAX_EXTRA_CANDIDATES`.
MAX_CANDIDATES_PER_STOREY = 2
MAX_EXTRA_CANDIDATES = 4


def _score(run: RunData, d: int, sigma_u: float):
    fs = run.sample_rate
    nper = int(min(run.n_samples, round(SEGMENT * fs)))
    u = run["zdd"]
    rel = run.group("a", d) - u[:, None]
    f, Puu = scipy.signal.welch(u, fs, nperseg=nper)
    _, Prel = scipy.signal.welch(rel, fs, nperseg=nper, axis=0)
    floor = NOISE_FLOOR_FACTOR * 2.0 * sigma_u ** 2 / fs     # one-sided PSD of white noise
    return f, np.sum(Prel, axis=1) / (Puu + floor)


def peak_candidates(runs: Sequence[RunData], d: int, sigma_u: float) -> tuple[np.ndarray, np.ndarray]:
    """Every peak of the score, most prominent first: frequencies (Hz, refined on the full record) and
    prominences (of the score's logarithm averaged over runs).

    Parameters
    ----------
    runs : sequence of RunData
        With ``zdd`` and ``a1..ad``.
    d : int
        Storeys (floor accelerometers).
    sigma_u : float
        Noise standard deviation of the table accelerometer (m/s^2).
    """
    total, f = None, None
    for run in runs:
        f_run, s = _score(run, d, sigma_u)
        if total is None:
            f, total = f_run, np.log(s)
        else:
            total = total + np.interp(f, f_run, np.log(s))
    total = total / len(runs)
    df = f[1] - f[0]
    fs = runs[0].sample_rate
    keep = (f > LOWEST_CYCLES * df) & (f < HIGHEST_FRACTION * fs)
    peaks, props = scipy.signal.find_peaks(np.where(keep, total, -np.inf), prominence=0.0)
    order = np.argsort(props["prominences"])[::-1][:MAX_CANDIDATES_PER_STOREY * d + MAX_EXTRA_CANDIDATES]
    run = max(runs, key=lambda r: r.n_samples)
    rel = run.group("a", d) - run["zdd"][:, None]
    power = np.sum(np.abs(np.fft.rfft(rel * np.hanning(run.n_samples)[:, None], axis=0)) ** 2, axis=1)
    freq = np.fft.rfftfreq(run.n_samples, 1.0 / run.sample_rate)
    freqs = np.array([_refine(freq, power, f[k], REFINE_BINS * df) for k in peaks[order]])
    return freqs, props["prominences"][order]


def pick_resonances(runs: Sequence[RunData], d: int, sigma_u: float) -> np.ndarray:
    """The ``d`` most prominent resonances of the runs (Hz), ascending.

    Parameters
    ----------
    runs : sequence of RunData
        With ``zdd`` and ``a1..ad``.
    d : int
        Storeys (= modes looked for).
    sigma_u : float
        Noise standard deviation of the table accelerometer (m/s^2).

    Raises
    ------
    IdentificationError
        Fewer than ``d`` resonances stand out of the spectrum.
    """
    freqs, _ = peak_candidates(runs, d, sigma_u)
    require_resonances(runs, d, freqs.size)
    return np.sort(freqs[:d])


def require_resonances(runs: Iterable[RunData], d: int, found: int) -> None:
    """:class:`IdentificationError` unless ``found`` resonances are at least the ``d`` storeys'."""
    if found < d:
        raise IdentificationError(
            f"runs {[r.name for r in runs]}: {found} resonances stand out of the floors' response "
            f"relative to the table, expected {d} (one per storey): the table motion does not excite "
            f"the structure's modes")


def _refine(freq: np.ndarray, power: np.ndarray, f0: float, half_width: float) -> float:
    """Peak frequency on the full-record spectrum ``power`` at ``freq`` (finer than Welch's) near ``f0``."""
    near = np.flatnonzero(np.abs(freq - f0) <= half_width)
    if near.size == 0:
        return f0
    return float(freq[near[np.argmax(power[near])]])


def response_amplitude(run: RunData, d: int, start: int = 0) -> float:
    """RMS (m/s^2) of the top floor's acceleration relative to the table, from sample ``start``."""
    rel = run[f"a{d}"][start:] - run["zdd"][start:]
    return float(np.sqrt(np.mean((rel - np.mean(rel)) ** 2)))
