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
* **accelerations only** (set ``accel``): the weak form.  Equation (3) is
  tested against sliding smooth bumps and integrated by parts, so velocity
  and displacement enter only as integrals of the relative acceleration
  against the bump's derivatives (:func:`weak_form`): no time integration,
  no drift, exact for any initial state.

See ``docs/reconstruction.md`` for the comparison behind these choices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.signal
from scipy.interpolate import CubicSpline

from momentid.core.series import RunData
from momentid.errors import SensorDataError

__all__ = ["Prefilter", "prepare_run", "suggest_band", "band_filter"]


@dataclass(frozen=True)
class Prefilter:
    """Band applied to every channel: ``low`` (Hz high-pass corner, 0 = none)
    and ``high`` (Hz low-pass corner, 0 = none), zero-phase Butterworth."""

    low: float = 0.0
    high: float = 0.0
    order: int = 4

    @property
    def active(self) -> bool:
        """Whether the band filters anything (a corner is set)."""
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


def band_filter(x: np.ndarray, fs: float, band: Prefilter) -> np.ndarray:
    """``x`` filtered zero-phase to ``band`` (Butterworth of ``band.order``, forward and backward).

    The one band filter of momentid: identification prefilters and diagnosis replays use it.

    Parameters
    ----------
    x : ndarray, shape (n_samples, ...)
        Time-first samples.
    fs : float
        Sample rate (Hz).
    band : Prefilter
        ``low``/``high`` corners (Hz; 0 or None: open) and ``order``; an inactive band returns ``x``.
    """
    if not band.active:
        return x
    if band.low and band.high:
        sos = scipy.signal.butter(band.order, [band.low, band.high], btype="bandpass", fs=fs, output="sos")
    elif band.high:
        sos = scipy.signal.butter(band.order, band.high, btype="lowpass", fs=fs, output="sos")
    else:
        sos = scipy.signal.butter(band.order, band.low, btype="highpass", fs=fs, output="sos")
    padlen = 3 * (2 * len(sos) + 1)   # scipy's default edge padding of sosfiltfilt
    if x.shape[0] <= padlen:
        raise SensorDataError(f"{x.shape[0]} samples are too few to filter to {band.low:g}-{band.high or 'inf'} Hz "
                              f"without edge effects: expected more than {padlen} samples")
    return scipy.signal.sosfiltfilt(sos, x, axis=0)


def _bump(T: float, h: float):
    """``psi(t) = (1 - (t/T)^2)^4`` on [-T, T] and its first two derivatives, sampled."""
    t = np.arange(-T, T + 0.5 * h, h)
    s = np.clip(t / T, -1.0, 1.0)
    psi = (1 - s ** 2) ** 4
    d1 = -8 * s * (1 - s ** 2) ** 3 / T
    d2 = (-8 * (1 - s ** 2) ** 3 + 48 * s ** 2 * (1 - s ** 2) ** 2) / T ** 2
    return psi * h, d1 * h, d2 * h


def weak_form(t: np.ndarray, a: np.ndarray, zdd: np.ndarray, f_high: float) -> dict[str, np.ndarray]:
    """Equation (3) tested against sliding bumps: accelerations only, no integration.

    For a smooth bump ``psi`` of compact support, integration by parts gives
    exactly ``int psi'' q = int psi a_rel``... so with ``a_rel = a - z''``::

        <a, psi''>,  <v, psi''> = -<a_rel, psi'>,  <q, psi''> = <a_rel, psi>

    and eq. (3) holds for these three signals at every bump position inside
    the record, with no drift from unknown initial velocity or displacement.
    The bump's half-width ``T = 0.3 / f_high`` passes the band up to ``f_high``.
    """
    h = float(np.median(np.diff(t)))
    T = max(0.3 / f_high, 8 * h)
    psi, d1, d2 = _bump(T, h)
    rel = a - zdd[:, None]

    def corr(x, k):
        return scipy.signal.fftconvolve(x, k[::-1, None], mode="valid", axes=0)

    return {"a": corr(a, d2), "v": -corr(rel, d1), "q": corr(rel, psi),
            "zdd": corr(zdd[:, None], d2)[:, 0]}


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
        qf = band_filter(q, fs, band)
        if has_v:
            vf = band_filter(run.group("v", d), fs, band)
        else:
            vf = CubicSpline(run.time, qf, axis=0).derivative()(run.time)
        af = band_filter(a, fs, band)
    else:
        if zdd is None:
            raise SensorDataError(f"run {run.name!r}: without displacements the base acceleration zdd is needed")
        return weak_form(run.time, a, zdd, band.high or suggest_band(run, d))
    out = {"a": af, "v": vf, "q": qf}
    if zdd is not None:
        out["zdd"] = band_filter(zdd[:, None], fs, band)[:, 0]
    return out
