"""Sensors checked against each other: accelerations against differentiated displacements.

A floor accelerometer reads the floor's absolute acceleration, the table
accelerometer the table's, and a displacement transducer the floor's motion
relative to the table, so whatever the structure does::

    a_j(t) = zdd(t) + q_j''(t)

holds between the channels of every floor ``j``: a check that needs no model
of the structure.  A gain or a time shift on one channel breaks it in a way
that names the channel: on ``a_j`` or ``q_j`` only floor ``j``'s relation
breaks, on ``zdd`` every floor's; a gain on ``a_j`` scales the whole relation
while one on ``q_j`` scales only its relative part.  The check runs in the
frequency domain (Hann-windowed DFT of each run), in the band where the
structure responds; ``q''`` is the central second difference, corrected by its
exact frequency response.  Each bin is weighted by the noise the three
channels put into it (white levels from the top of each channel's
spectrum), so with consistent sensors the weighted residual power per bin is
about 1.

For every channel the fault model ``measured(t) = gain * true(t - delay)``
is fitted (gain and delay together, and each alone) by weighted least
squares over all runs, and scored by the share of the inconsistency it
removes.  Offsets (biases) do not enter: the band excludes 0 Hz.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from momentid.core.series import RunData
from momentid.estimation.noise import band_level, windowed_dft
from momentid.diagnosis.thresholds import EXCESS

__all__ = ["SensorFit", "KinematicCheck", "kinematic_check", "noise_sigma", "inter_sample", "ROUND_OFF"]

#: Delays searched (s): at most this, and at most 0.45 of the band's top period (no phase wrap).
MAX_DELAY = 0.05


@dataclass(frozen=True)
class SensorFit:
    """One fault hypothesis ``measured = gain * true(t - delay)`` on ``channel``."""

    channel: str
    gain: float
    delay: float              # s; positive: the channel lags
    gain_only: float          # fitted gain with no delay
    delay_only: float         # fitted delay (s) with unit gain
    explained: dict           # "both" / "gain" / "delay": share of the inconsistency removed
    gain_std: float = float("nan")    # of gain_only
    delay_std: float = float("nan")   # of delay_only (s)


@dataclass(frozen=True)
class KinematicCheck:
    """Result of :func:`kinematic_check`."""

    excess: dict              # per floor: weighted residual power per bin (about 1 when consistent)
    band: tuple               # (low, high) Hz
    fits: tuple               # SensorFit per channel, best explained first

    @property
    def consistent(self) -> bool:
        """Whether every channel's kinematic residual is within ``EXCESS`` of its noise."""
        return max(self.excess.values()) <= EXCESS


#: Band (fractions of the sample rate) of the diagnosis's noise estimate: far above the modes of
#: the rigs it checks at 1 kHz, below the anti-alias roll-off near the Nyquist frequency.
NOISE_BAND = (0.25, 0.45)


def noise_sigma(run: RunData) -> dict[str, float]:
    """White-noise RMS of every channel from the top of its spectrum (``NOISE_BAND`` of the
    sample rate, open at both edges), where a structure's response has died out; the estimator
    is :func:`momentid.estimation.noise.band_level` of the Hann-windowed DFT."""
    fs = run.sample_rate
    f = np.fft.rfftfreq(run.n_samples, 1 / fs)
    band = (f > NOISE_BAND[0] * fs) & (f < NOISE_BAND[1] * fs)
    return dict(zip(run.channels, band_level(windowed_dft(run.values), band)))


#: float64 round-off of one stored sample, relative to its channel's RMS: the least noise a record
#: can carry.  A level measured on noise-free data may lie below it (the top of a smooth spectrum).
ROUND_OFF = float(np.finfo(float).eps)


def inter_sample(omega_h: ArrayLike) -> np.ndarray:
    """Relative size of what a sampled signal leaves open between its samples, at ``omega h``.

    A band-limited signal and one held to a straight line between samples (a first-order hold:
    a simulator's table drive, a digital servo's command) share every sample, yet their second
    derivatives differ by ``(omega h)^2 / 12`` of the signal at ``omega`` (the second-order term of
    the trapezoid rule).  Nothing in the record tells them apart, so no relation between channels
    that differentiates or integrates them (``a = zdd + q''``, a replay) holds closer than this
    share of each one's own spectrum: a residual within it is no mismatch, whatever its ratio to
    a noise level that may be zero.  It is 3e-6 at 1 Hz sampled at 1 kHz and 8e-3 at 5 Hz sampled
    at 100 Hz, where a fault that small is below any sensor's calibration anyway.
    """
    return np.asarray(omega_h) ** 2 / 12


def _spectra(run: RunData, d: int, band: tuple[float, float]):
    """Windowed DFT bins of a_j, zdd and corrected q_j'' in ``band``, and their noise variances."""
    fs = run.sample_rate
    h = 1.0 / fs
    a = run.group("a", d)[1:-1]
    z = run["zdd"][1:-1]
    q = run.group("q", d)
    qdd = (q[2:] - 2 * q[1:-1] + q[:-2]) / h ** 2
    n = a.shape[0]
    w = np.hanning(n)
    f = np.fft.rfftfreq(n, h)
    keep = (f >= band[0]) & (f <= band[1])
    f = f[keep]
    omega = 2 * np.pi * f

    def dft(x):
        return np.fft.rfft(x * (w[:, None] if x.ndim == 2 else w), axis=0)[keep]

    # the second difference is -(2 - 2 cos wh) / h^2 where q'' is -w^2: undo the ratio exactly
    exact = np.where(omega > 0, (omega * h) ** 2 / np.maximum(2 - 2 * np.cos(omega * h), 1e-300), 1.0)
    A, Z, Y = dft(a), dft(z), dft(qdd) * exact[:, None]
    # white noise, at least each sample's round-off (q's amplified by the second difference's omega^4) ...
    sig = {c: max(s, ROUND_OFF * float(np.sqrt(np.mean(run[c] ** 2)))) for c, s in noise_sigma(run).items()}
    power = float(np.sum(w ** 2))
    s_z = sig.get("zdd", 0.0) ** 2
    var = np.column_stack([(sig[f"a{j + 1}"] ** 2 + s_z + omega ** 4 * sig[f"q{j + 1}"] ** 2) * power
                           for j in range(d)])
    # ... and what the three channels leave open between their samples
    var += inter_sample(omega * h)[:, None] ** 2 * (np.abs(A) ** 2 + np.abs(Z[:, None]) ** 2 + np.abs(Y) ** 2)
    return omega, A, Z, Y, np.maximum(var, 1e-300)


def _fit_shift(X, T, W, omega, taus):
    """Best (gain, delay) for ``T ~ gain * X e^{i w delay}`` (weights W), and each alone.

    Returns the RSS of every variant: dict name -> (rss, gain, delay).
    """
    # rss(tau, g) = sum W |T|^2 - 2 g Re sum W conj(X e^{iwt}) T + g^2 sum W |X|^2
    tt = np.sum(W * np.abs(T) ** 2)
    xx = np.sum(W * np.abs(X) ** 2)
    cross = np.real(np.exp(-1j * np.outer(taus, omega)) @ (W * np.conj(X) * T))   # (n_tau,)
    g = cross / xx
    rss_both = tt - cross * g
    rss_delay = tt - 2 * cross + xx
    i, k = int(np.argmin(rss_both)), int(np.argmin(rss_delay))
    zero = int(np.argmin(np.abs(taus)))
    return {"both": (float(rss_both[i]), float(g[i]), float(taus[i])),
            "delay": (float(rss_delay[k]), 1.0, float(taus[k])),
            "gain": (float(rss_both[zero]), float(g[zero]), 0.0),
            "info": (float(xx), float(np.sum(W * omega ** 2 * np.abs(X) ** 2)))}


def kinematic_check(runs: Sequence[RunData], d: int, f_top: float) -> KinematicCheck | None:
    """Check ``a_j = zdd + q_j''`` on every floor of ``runs``; fit a fault on each channel.

    Parameters
    ----------
    runs : sequence of RunData
        Runs with ``zdd``, ``a1..ad`` and ``q1..qd`` (else None is returned).
    d : int
        Storeys.
    f_top : float
        Highest natural frequency (Hz): the band is 0.3 Hz to 3 ``f_top``
        (at most 0.4 of the sample rate).

    Returns
    -------
    KinematicCheck or None
    """
    runs = [r for r in runs if r.has("zdd") and all(r.has(f"{g}{j + 1}") for g in "aq" for j in range(d))]
    if not runs:
        return None
    fs = runs[0].sample_rate
    band = (max(0.3, 4.0 * fs / min(r.n_samples for r in runs)), min(3.0 * f_top, 0.4 * fs))
    if band[1] <= band[0]:
        return None
    parts = [_spectra(r, d, band) for r in runs]
    omega = np.concatenate([p[0] for p in parts])
    A = np.concatenate([p[1] for p in parts])
    Z = np.concatenate([p[2] for p in parts])
    Y = np.concatenate([p[3] for p in parts])
    W = 1.0 / np.concatenate([p[4] for p in parts])
    n_bins = omega.size
    resid = A - Z[:, None] - Y
    rss0 = np.sum(W * np.abs(resid) ** 2, axis=0)          # per floor
    excess = {f"floor{j + 1}": float(rss0[j] / n_bins) for j in range(d)}
    tau_max = min(MAX_DELAY, 0.45 / band[1])
    taus = np.linspace(-tau_max, tau_max, 2 * int(round(tau_max * fs * 10)) + 1)   # 0.1-sample steps
    total0 = float(np.sum(rss0))
    noise = float(n_bins * d)
    fits = []

    def score(rss_new_total):
        return (total0 - rss_new_total) / max(total0 - noise, 1e-12 * total0)

    # The faulty channel's true signal is what the others imply; its fitted gain/delay map it there:
    # a_j: a_meas e^{iwt} / g = zdd + q''; q_j: q''_meas e^{iwt} / g = a - zdd; zdd: zdd_meas e^{iwt} / g = a - q''.
    for j in range(d):
        for ch, X, T in ((f"a{j + 1}", A[:, j], Z + Y[:, j]), (f"q{j + 1}", Y[:, j], A[:, j] - Z)):
            r = _fit_shift(X, T, W[:, j], omega, taus)
            others = total0 - rss0[j]
            fits.append(_as_fit(ch, r, {k: score(others + r[k][0]) for k in ("both", "gain", "delay")}, n_bins))
    # zdd is one channel for every floor: one gain and delay over all, from the pooled normal equations
    cross = sum(np.real(np.exp(-1j * np.outer(taus, omega)) @ (W[:, j] * np.conj(Z) * (A[:, j] - Y[:, j])))
                for j in range(d))
    xx = sum(np.sum(W[:, j] * np.abs(Z) ** 2) for j in range(d))
    tt = sum(np.sum(W[:, j] * np.abs(A[:, j] - Y[:, j]) ** 2) for j in range(d))
    g = cross / xx
    both, delay = tt - cross * g, tt - 2 * cross + xx
    i, k = int(np.argmin(both)), int(np.argmin(delay))
    zero = int(np.argmin(np.abs(taus)))
    pooled = {"both": (float(both[i]), float(g[i]), float(taus[i])),
              "delay": (float(delay[k]), 1.0, float(taus[k])),
              "gain": (float(both[zero]), float(g[zero]), 0.0),
              "info": (float(xx), float(sum(np.sum(W[:, j] * omega ** 2 * np.abs(Z) ** 2) for j in range(d))))}
    fits.append(_as_fit("zdd", pooled, {k: score(pooled[k][0]) for k in ("both", "gain", "delay")}, n_bins * d))
    fits.sort(key=lambda s: -max(s.explained.values()))
    return KinematicCheck(excess=excess, band=band, fits=tuple(fits))


#: Hann-windowed DFT bins are correlated: the equivalent noise bandwidth is 1.5 bins.
_ENBW = 1.5


def _as_fit(channel, r, explained, n_bins) -> SensorFit:
    """Fitted map ``true = meas e^{iw tau} / g`` back to the fault ``meas = g true(t - tau)``.

    Standard errors from the weighted normal equations (weights are inverse
    noise variances, so Var(g) = 1 / (2 sum W |X|^2)), scaled by the residual
    power per bin and by the window's correlation between bins.
    """
    def gain(x):
        return float(1.0 / x) if x != 0 else float("inf")
    xx, wxx = r["info"]
    g_only = r["gain"][1]
    scale = _ENBW * max(r["gain"][0] / n_bins, 1.0)
    g_std = np.sqrt(scale / (2 * xx)) / max(g_only * g_only, 1e-12)
    t_std = np.sqrt(_ENBW * max(r["delay"][0] / n_bins, 1.0) / (2 * wxx))
    return SensorFit(channel=channel, gain=gain(r["both"][1]), delay=r["both"][2], gain_only=gain(g_only),
                     delay_only=r["delay"][2], explained={k: float(v) for k, v in explained.items()},
                     gain_std=float(g_std), delay_std=float(t_std))
