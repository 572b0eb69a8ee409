"""Signals the equations need but the lab did not measure, and noise-reducing prefilters.

Equation (3) needs ``a``, ``v`` and ``q`` of every floor.  A lab measures some
of them; this module supplies the rest so that the equation still holds for
the signals it returns:

* **one linear filter on every channel.**  Equation (3) is a pointwise linear
  relation between channels, so it holds exactly for any linear
  time-invariant filter applied identically to all of them.  A zero-phase
  low-pass removes the broadband sensor noise above the structure's band.
* **velocity from displacement** (sensor set ``accel+disp``): the derivative
  of the cubic spline through the *filtered* displacement.  Differentiating
  the low-passed signal is the discrete form of the weak (modulating
  function) formulation: the derivative falls on the smooth filter kernel,
  not on the noise.
* **velocity and displacement from acceleration** (set ``accel``): the
  relative acceleration ``a - z''`` is integrated in the frequency domain
  with a high-pass weighting, and the *same* band-pass is applied to the
  accelerations, so drift (integrated noise, bias, unknown initial state)
  is removed without breaking the equation inside the band.

See ``docs/reconstruction.md`` for the comparison behind these choices.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.fft
import scipy.signal
from scipy.interpolate import CubicSpline

from .data import RunData
from .errors import SensorDataError

__all__ = ["Prefilter", "prepare_run", "suggest_band"]


@dataclass(frozen=True)
class Prefilter:
    """Band applied to every channel: ``low`` (Hz high-pass corner, 0 = none)
    and ``high`` (Hz low-pass corner, 0 = none), zero-phase Butterworth."""

    low: float = 0.0
    high: float = 0.0
    order: int = 4

    @property
    def active(self) -> bool:
        return bool(self.low or self.high)


def suggest_band(run: RunData, d: int, *, fraction: float = 0.995, margin: float = 2.0) -> float:
    """A low-pass corner (Hz) that keeps the structure's response.

    The frequency below which ``fraction`` of the relative floor
    acceleration's power lies, times ``margin``, capped at 0.4 x sample rate.
    """
    rel = run.group("a", d) - run["zdd"][:, None] if run.has("zdd") else run.group("a", d)
    f, p = scipy.signal.welch(rel, fs=run.sample_rate, axis=0, nperseg=min(4096, rel.shape[0]))
    power = p.sum(axis=1)
    if not np.any(power > 0):
        return 0.4 * run.sample_rate
    cum = np.cumsum(power) / power.sum()
    f_keep = float(f[np.searchsorted(cum, fraction)])
    return float(min(max(margin * f_keep, 1.0), 0.4 * run.sample_rate))


def _filter(x: np.ndarray, fs: float, band: Prefilter) -> np.ndarray:
    if not band.active:
        return x
    if band.low and band.high:
        sos = scipy.signal.butter(band.order, [band.low, band.high], btype="bandpass", fs=fs, output="sos")
    elif band.high:
        sos = scipy.signal.butter(band.order, band.high, btype="lowpass", fs=fs, output="sos")
    else:
        sos = scipy.signal.butter(band.order, band.low, btype="highpass", fs=fs, output="sos")
    return scipy.signal.sosfiltfilt(sos, x, axis=0)


def _integrate(x: np.ndarray, fs: float, low: float) -> np.ndarray:
    """Frequency-domain integral of ``x`` (n, c) with everything below ``low`` removed."""
    n = x.shape[0]
    nfft = scipy.fft.next_fast_len(2 * n)
    X = np.fft.rfft(x - x.mean(axis=0), n=nfft, axis=0)
    w = 2 * np.pi * np.fft.rfftfreq(nfft, 1 / fs)
    out = np.zeros_like(X)
    keep = w > 2 * np.pi * low
    out[keep] = X[keep] / (1j * w[keep, None])
    return np.fft.irfft(out, n=nfft, axis=0)[:n]


def prepare_run(run: RunData, d: int, band: Prefilter) -> dict[str, np.ndarray]:
    """``a``, ``v``, ``q`` (each (n, d)) and ``zdd`` (n,) for equation (3).

    Uses the measured channels where present and reconstructs the others
    (see the module docstring); every returned signal has passed the same
    filter ``band``.
    """
    fs = run.sample_rate
    if not run.has("a1"):
        raise SensorDataError(f"run {run.name!r}: no floor accelerations a1..a{d}: identification needs them")
    a = run.group("a", d)
    zdd = run["zdd"] if run.has("zdd") else None
    has_q, has_v = run.has("q1"), run.has("v1")
    if has_q:
        q = run.group("q", d)
        qf = _filter(q, fs, band)
        if has_v:
            vf = _filter(run.group("v", d), fs, band)
        else:
            vf = CubicSpline(run.time, qf, axis=0).derivative()(run.time)
        af = _filter(a, fs, band)
    else:
        if zdd is None:
            raise SensorDataError(f"run {run.name!r}: without displacements the base acceleration zdd is needed")
        low = band.low or 0.1
        band = replace(band, low=low)
        rel = a - zdd[:, None]
        v = _integrate(rel, fs, low)
        q = _integrate(v, fs, low)
        af, vf, qf = (_filter(x, fs, band) for x in (a, v, q))
    out = {"a": af, "v": vf, "q": qf}
    if zdd is not None:
        out["zdd"] = _filter(zdd[:, None], fs, band)[:, 0]
    return out
