"""Cheap spectral evidence of where each accelerometer sits: operating shapes and low-frequency gains.

From one run's table and floor accelerations (no model fit) this module estimates, label-free:

* the cross-spectral matrix ``S(f)`` of every channel (Welch, Hann windows, half overlap), and of
  the first and second half of the record apart (their difference is the estimate's scatter);
* the **resonances**: peaks of the first singular value of ``S(f)``, each with its operating shape
  (the first singular vector, rotated to real: a lightly damped mode moves every sensor in or out of
  phase), the shape's scatter, and how well one mode holds the peak (the shapes one bin either side);
* the **first mode**: the lowest resonance where the channels' powers differ by
  :data:`MIN_POWER_RATIO` or more, with two or more channels moving and all in phase (a sensor
  mounted reversed counted by its low-frequency sign): there the floors resonate and the table,
  which drives them, barely moves.  Its shape grows from the table up the building, whatever the
  labels say;
* the **low-frequency gains** ``G[t, j]``: channel j's response per unit of channel t's below the
  first mode, where every sensor on a shear building reads the table's motion (gain ~1; a floor
  sensor turned off the shaking axis reads less, one mounted reversed reads -1).

Everything is computed for all channels at once, so that a check can try other labels (a table that
is a floor, two floors swapped) by permuting rows, without computing the spectra again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

__all__ = ["Resonance", "RunSpectra", "run_spectra", "mac", "MIN_POWER_RATIO", "MIN_SECONDS"]

#: Segment length (s) of the Welch estimate at most: 16 s resolves 0.06 Hz (a 1 % mode spacing at
#: 6 Hz); shorter records use a sixth of their length, so that at least 11 half-overlapping
#: segments average the noise down (the scatter of a cross-spectrum falls as 1/sqrt(segments)).
MAX_SEGMENT_SECONDS = 16.0
#: Fewest samples of a segment: 64 samples resolve 1/64 of the sample rate (1.9 Hz at 120 Hz).
MIN_SEGMENT = 64
#: Shortest record (s) whose shapes are estimated: six segments of 2 s resolve 0.5 Hz, enough to
#: separate the first mode of a bench-top model (~2-5 Hz) from its drive.
MIN_SECONDS = 12.0
#: Lowest frequency (Hz) searched: below it an IMU's drift and the table's stroke dominate.
LOW_EDGE = 0.3
#: Highest frequency searched, as a fraction of the sample rate: below the IMUs' anti-alias roll-off.
HIGH_EDGE = 0.42
#: Prominence (decades of power) of a peak of the first singular value: a resonance of a lightly
#: damped structure stands 1-5 decades above its flanks on the shipped trials; half a decade keeps
#: weak higher modes and refuses the wiggles of a noisy estimate (a few tenths of a decade).
PEAK_PROMINENCE = 0.5
#: Smallest ratio of the largest to the smallest channel power at the first mode: a floor with 1-3 %
#: damping moves 15-50 times the table there (power 200-2500; 400-7000 on the shipped trials); a
#: ratio of 30 (5.5 in amplitude) keeps rigs damped up to ~10 % and refuses the harmonics of a sine
#: drive below the first mode (ratios 2-10, the quasi-static gain of the floors).
MIN_POWER_RATIO = 30.0
#: A channel counts as moving in a shape when its entry is at least this fraction of the largest:
#: a resonance of the building moves two or more sensors; a peak that moves one alone (the table's
#: own noise above the modes, where the floors are still) is no mode of the building.
MOVING = 0.25
#: Bins searched either side of a peak for its half-power points.
HALF_POWER_BINS = 20
#: The first mode moves every sensor in phase (the table, nearly still, may lag): an entry below
#: -IN_PHASE (fraction of the largest) makes a peak a higher mode, or not the building's.
IN_PHASE = 0.1
#: Coherence (squared) a low-frequency bin needs to count in a gain: 0.9 (the sensors' noise at most
#: a third of the motion) leaves the gain's scatter at a few percent per bin.
GAIN_COHERENCE = 0.9
#: The gains are read up to this fraction of the lowest resonance's frequency: the floors' quasi-static
#: amplification there is below (0.5)^2 = 25 % of the first mode's participation (~1.3 at the top
#: of a uniform shear building), small against the factor 2 that marks a turned or missing axis.
GAIN_BAND = 0.5


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """Modal assurance criterion of two real shapes: 1 for proportional shapes, 0 for orthogonal ones."""
    den = float(a @ a) * float(b @ b)
    return float((a @ b) ** 2 / den) if den > 0 else 0.0


@dataclass(frozen=True)
class Resonance:
    """A peak of the first singular value of the cross-spectral matrix.

    Attributes
    ----------
    frequency : float
        Hz.
    shape : ndarray, shape (c,)
        Operating shape over every channel (the run's column order), real, largest entry +1.
    scatter : ndarray, shape (c,)
        Half the difference of the shapes of the record's two halves (same normalisation).
    single : float
        Least MAC of the shape at the peak with those at the half-power points either side: ~1 when
        one mode holds the peak.
    power_ratio : float
        Largest over smallest channel power at the peak.
    power : float
        The first singular value at the peak ((m/s^2)^2/Hz): how strongly the run excites it.
    """

    frequency: float
    shape: np.ndarray
    scatter: np.ndarray
    single: float
    power_ratio: float
    power: float

    def moving(self) -> int:
        """Channels moving at least :data:`MOVING` of the largest."""
        return int(np.sum(np.abs(self.shape) >= MOVING))


@dataclass(frozen=True)
class RunSpectra:
    """What one run's spectra say about its channels (see the module docstring).

    Attributes
    ----------
    resolution : float
        Hz between spectral bins.
    resonances : tuple of Resonance
        By frequency.
    first : Resonance or None
        The first mode (label-free); None when no peak qualifies.
    gains : ndarray, shape (c, c)
        ``gains[t, j]``: channel j per unit of channel t below the first mode (real part of the
        coherence-weighted mean transfer function); nan without a coherent bin.
    """

    resolution: float
    resonances: tuple[Resonance, ...]
    first: Resonance | None
    gains: np.ndarray


def _segments(n: int, rate: float) -> int:
    nper = 2 ** int(np.floor(np.log2(max(n / 6.0, MIN_SEGMENT))))
    return int(min(nper, 2 ** int(np.ceil(np.log2(MAX_SEGMENT_SECONDS * rate)))))


def _welch(x: np.ndarray, rate: float, nper: int) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Frequencies (nf,), the cross-spectral matrix (nf, c, c) and those of the record's two halves."""
    n = x.shape[0]
    starts = np.arange(0, n - nper + 1, nper // 2)
    window = signal.windows.hann(nper, sym=False)
    segs = x[starts[:, None] + np.arange(nper)[None, :], :]
    segs = segs - segs.mean(axis=1, keepdims=True)
    X = np.fft.rfft(segs * window[None, :, None], axis=1)
    P = np.einsum("kfi,kfj->kfij", X, X.conj())
    half = max(len(starts) // 2, 1)
    return np.fft.rfftfreq(nper, 1.0 / rate), P.mean(axis=0), [P[:half].mean(axis=0), P[half:].mean(axis=0)]


def _shape(S: np.ndarray) -> np.ndarray:
    """First singular vector of a Hermitian (c, c) matrix, rotated to real, largest entry +1."""
    _, vectors = np.linalg.eigh(S)
    v = vectors[:, -1]
    v = v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))]))
    real = np.real(v)
    return real / real[np.argmax(np.abs(real))]


def _half_power(S: np.ndarray, top: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    """Shapes at the bins where the first singular value ``top`` falls to half its peak's, either side
    (at least one bin away): one mode holds its whole half-power band, a second mode beside it holds
    the centre or a flank."""
    lo, hi = p - 1, p + 1
    while lo > 0 and top[lo] > 0.5 * top[p] and p - lo < HALF_POWER_BINS:
        lo -= 1
    while hi < S.shape[0] - 1 and top[hi] > 0.5 * top[p] and hi - p < HALF_POWER_BINS:
        hi += 1
    return _shape(S[max(lo, 0)]), _shape(S[min(hi, S.shape[0] - 1)])


def _resonance(f: np.ndarray, S: np.ndarray, halves: list[np.ndarray], power: np.ndarray, top: np.ndarray,
               p: int) -> Resonance:
    lo, hi = max(p - 1, 0), min(p + 2, S.shape[0])
    shape = _shape(S[lo:hi].sum(axis=0))
    parts = [_shape(H[lo:hi].sum(axis=0)) for H in halves]
    parts = [s * (1.0 if s @ shape >= 0 else -1.0) for s in parts]
    below, above = _half_power(S, top, p)
    centre = _shape(S[p])
    return Resonance(frequency=float(f[p]), shape=shape, scatter=np.abs(parts[0] - parts[1]) / 2,
                     single=min(mac(centre, below), mac(centre, above)),
                     power_ratio=float(power[p].max() / max(power[p].min(), 1e-300)),
                     power=float(top[p]))


def _gains(f: np.ndarray, S: np.ndarray, power: np.ndarray, top: float) -> np.ndarray:
    c = S.shape[1]
    band = (f >= max(LOW_EDGE, 2 * f[1])) & (f <= top)
    out = np.full((c, c), np.nan)
    for t in range(c):
        for j in range(c):
            coherence = np.abs(S[band, t, j]) ** 2 / np.maximum(power[band, t] * power[band, j], 1e-300)
            use = coherence >= GAIN_COHERENCE
            if use.any():
                ratio = np.real(S[band, t, j][use] / power[band, t][use])
                out[t, j] = float(np.average(ratio, weights=coherence[use] / (1.0 - np.minimum(coherence[use],
                                                                                              0.999))))
    return out


def run_spectra(values: np.ndarray, rate: float) -> RunSpectra | None:
    """Resonances, first mode and low-frequency gains of one run.

    Parameters
    ----------
    values : ndarray, shape (n, c)
        Accelerations (m/s^2), the table first; non-finite samples are interpolated linearly
        (a repaired record has none).
    rate : float
        Sample rate (Hz).

    Returns
    -------
    RunSpectra or None
        None when the record is shorter than :data:`MIN_SECONDS`.
    """
    n, c = values.shape
    if n < MIN_SECONDS * rate or c < 2:
        return None
    x = np.array(values, dtype=float)
    for j in range(c):
        bad = ~np.isfinite(x[:, j])
        if bad.all():
            return None
        if bad.any():
            x[bad, j] = np.interp(np.flatnonzero(bad), np.flatnonzero(~bad), x[~bad, j])
    f, S, halves = _welch(x, rate, _segments(n, rate))
    power = np.real(np.einsum("fii->fi", S))
    band = (f >= max(LOW_EDGE, 3 * f[1])) & (f <= HIGH_EDGE * rate)
    if band.sum() < 5:
        return None
    top = np.linalg.eigvalsh(S)[:, -1]
    log_top = np.log10(np.maximum(top, 1e-300))
    peaks, _ = signal.find_peaks(np.where(band, log_top, log_top[band].min()), prominence=PEAK_PROMINENCE)
    resonances = tuple(_resonance(f, S, halves, power, top, int(p)) for p in peaks)
    building = [r for r in resonances if r.moving() >= 2 or c == 2]
    if not building:
        return RunSpectra(resolution=float(f[1]), resonances=resonances, first=None, gains=np.full((c, c), np.nan))
    gains = _gains(f, S, power, GAIN_BAND * building[0].frequency)
    signs = np.where(gains[0] < 0, -1.0, 1.0)  # below the modes every sensor moves with the table
    first = None
    for res, p in zip(resonances, peaks):
        in_phase = np.min(res.shape * signs) >= -IN_PHASE
        # a 1-storey rig: one of its two sensors (the floor, whichever file it is listed as) moves most; the
        # placement check then puts the table where the mode is stillest (a swapped table and floor)
        moving = res.moving() >= 2 if c > 2 else np.max(power[p]) > 0
        if res.power_ratio >= MIN_POWER_RATIO and in_phase and moving:
            first = res
            break
    return RunSpectra(resolution=float(f[1]), resonances=resonances, first=first, gains=gains)
