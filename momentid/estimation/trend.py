"""Mode 1 against response amplitude across per-run results: a linear rig shows no trend.

:func:`amplitude_trend` fits mode 1's frequency and equivalent linear damping ratio of every run's own
fit (:func:`momentid.estimation.scaled.identify_per_run`) against the run's RMS response with
:func:`weighted_line`; a run whose mode-1 frequency is not an answer (a periodic table's lines pulled it)
gives no frequency to that line.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from momentid.errors import IdentificationError

__all__ = ["AmplitudeTrend", "amplitude_trend", "weighted_line"]


@dataclass(frozen=True)
class AmplitudeTrend:
    """How the first mode changes with response amplitude across runs (:func:`amplitude_trend`).

    Attributes
    ----------
    results : tuple of ModalIdentification
        One per run, sorted by amplitude.
    frequency_slope, frequency_slope_std : float
        Weighted least-squares slope of mode 1's frequency over amplitude (Hz per m/s^2).
    damping_slope, damping_slope_std : float
        Same for its damping ratio (1 per m/s^2).
    """

    results: tuple
    frequency_slope: float
    frequency_slope_std: float
    damping_slope: float
    damping_slope_std: float

    def table(self) -> str:
        """A text table: each run's response amplitude and mode 1, then the trend and its verdict."""
        lines = ["run                 RMS response (m/s^2)  mode-1 frequency (Hz)  mode-1 damping at small "
                 "amplitude (%)   equiv. linear (%)"]
        for r in self.results:
            answer = r.damping_is_answer is None or bool(r.damping_is_answer[0])
            z = (f"{100 * r.damping_ratio[0]:6.3f} +- {100 * r.damping_ratio_std[0]:.3f}" if answer else
                 "NOT AN ANSWER  ")
            f = (f"{r.frequency[0]:8.4f} +- {r.frequency_std[0]:.4f}" if r.frequency_answered(0) else
                 f"{'NOT AN ANSWER':>18}")
            lines.append(f"{r.runs[0]:<20}{r.amplitude[0]:>10.3g}          {f}   {z:<30}"
                         f"{100 * r.linear_damping_ratio[0]:8.3f}")
        left_out = [r.runs[0] for r in self.results if not r.frequency_answered(0)]
        without = f" (without {', '.join(left_out)}: not an answer)" if left_out else ""
        lines.append(f"trend: frequency {self.frequency_slope:+.3g} +- {self.frequency_slope_std:.2g} Hz per m/s^2"
                     f"{without}, equivalent linear damping ratio {100 * self.damping_slope:+.3g} "
                     f"+- {100 * self.damping_slope_std:.2g} % per m/s^2"
                     f" ({self.verdict()})")
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """A notebook's summary: the words of the report page's answer
        (:func:`momentid.estimation.summary_html.trend_html`)."""
        from momentid.estimation.summary_html import trend_html
        return trend_html(self)

    def verdict(self) -> str:
        """The trend in words: ``not linear: larger responses are softer ...`` or ``no trend beyond two
        standard errors``."""
        softer = self.frequency_slope < -2 * self.frequency_slope_std
        damped = self.damping_slope > 2 * self.damping_slope_std
        if softer or damped:
            return ("not linear: larger responses are " + " and ".join(
                w for w, flag in (("softer", softer), ("more damped", damped)) if flag))
        return "no trend beyond two standard errors"

    def to_dict(self) -> dict:
        """The per-run results and the slopes (per m/s^2 of RMS response) with their standard errors."""
        return {"runs": [r.to_dict() for r in self.results],
                "frequency_slope_hz_per_m_s2": self.frequency_slope,
                "frequency_slope_std": self.frequency_slope_std,
                "damping_slope_per_m_s2": self.damping_slope, "damping_slope_std": self.damping_slope_std}


def weighted_line(x: np.ndarray, y: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, float]:
    """Weighted least-squares line ``y = c0 + c1 x`` (weights ``1/s^2``).

    Parameters
    ----------
    x, y, s : ndarray, shape (n,)
        Abscissae, ordinates and the ordinates' standard errors.

    Returns
    -------
    coef : ndarray, shape (2,)
        ``(c0, c1)``.
    slope_std : float
        Standard error of ``c1``, widened by the scatter beyond the stated errors.
    """
    A = np.column_stack([np.ones_like(x), x]) / s[:, None]
    cov = np.linalg.inv(A.T @ A)
    coef = cov @ A.T @ (y / s)
    resid = (y - coef[0] - coef[1] * x) / s
    scale = max(float(resid @ resid) / max(x.size - 2, 1), 1.0)   # scatter beyond the errors widens it
    return coef, float(np.sqrt(cov[1, 1] * scale))


def _slope(x, y, s):
    """Slope of :func:`weighted_line` and its standard error."""
    coef, std = weighted_line(x, y, s)
    return float(coef[1]), std


def amplitude_trend(results: Iterable[Any]) -> AmplitudeTrend:
    """Mode 1's frequency and damping ratio against response amplitude over per-run results.

    Parameters
    ----------
    results : iterable of ModalIdentification
        One per run (:func:`~momentid.estimation.scaled.identify_per_run`).  A run whose mode-1
        frequency is not an answer gives none to the frequency's line.

    Returns
    -------
    AmplitudeTrend
        The results sorted by amplitude and both slopes (per m/s^2 of RMS response); the frequency's is
        NaN when fewer than two runs answer it.

    Raises
    ------
    IdentificationError
        Fewer than two runs.
    """
    results = tuple(sorted(results, key=lambda r: float(r.amplitude[0])))
    if len(results) < 2:
        raise IdentificationError(f"{len(results)} run(s): an amplitude trend needs at least two")
    x = np.array([r.amplitude[0] for r in results])
    fs, fstd = (np.array([getattr(r, k)[0] for r in results]) for k in ("frequency", "frequency_std"))
    zs = np.array([r.linear_damping_ratio[0] for r in results])
    zstd = np.array([r.linear_damping_ratio_std[0] for r in results])
    keep = np.array([r.frequency_answered(0) for r in results])
    f_slope, f_std = (_slope(x[keep], fs[keep], np.maximum(fstd[keep], 1e-12)) if np.count_nonzero(keep) >= 2
                      else (float("nan"), float("inf")))
    z_slope, z_std = _slope(x, zs, np.maximum(zstd, 1e-12))
    return AmplitudeTrend(results, f_slope, f_std, z_slope, z_std)
