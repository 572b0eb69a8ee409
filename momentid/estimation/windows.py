"""Forced windows: the linear modal model refitted on consecutive stretches of a record.

Each window of :data:`WINDOW_CYCLES` cycles of mode 1 (at least :data:`MIN_WINDOWS` per record) is refitted
with its own transient, the record's sensor gains and clock offsets held; per storey mode it gives a
damping ratio, a frequency, their standard errors and the mode's amplitude there (:func:`forced_windows`).
:func:`random_effects` pools such estimates with what they scatter beyond their own errors;
:func:`frequency_trend` and :func:`drift_words` say how a mode's frequency moves with its amplitude.
:mod:`momentid.estimation.damping` reads the damping at small amplitude from them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from momentid.core.processes import run_forked
from momentid.core.series import RunData
from momentid.errors import MomentidError
from momentid.estimation import ringdown
from momentid.estimation.eiv import spectra
from momentid.estimation.modal import refine
from momentid.estimation.modal_model import MAX_ABS_DAMPING, ModalModel

if TYPE_CHECKING:
    from momentid.estimation.modal_select import ModeSelection

__all__ = ["Window", "forced_windows", "refit_bounds", "random_effects", "frequency_trend", "drift_words", "drift",
           "band_noise", "WINDOW_CYCLES", "MIN_WINDOWS", "DRIFT_LIMIT", "WINDOW_FREQUENCY_SPAN", "BOUND_SLACK",
           "MIN_SIGNAL_TO_NOISE"]

#: Windows of the forced-response estimate hold this many cycles of mode 1 ...
WINDOW_CYCLES = 25
#: ... and a record is cut into at least this many (shorter windows when it is short).
MIN_WINDOWS = 6
#: A window refit may move a mode's frequency this far (relative) from the whole record's ...
WINDOW_FREQUENCY_SPAN = 0.05
#: ... and a window whose mode ends this close (relative frequency, or damping ratio) to a bound of its
#: refit read no mode there (held at 5 % off, or at 50 % damping: the window's noise, not the mode).
BOUND_SLACK = 1e-6
#: A mode's response in its band must stand this many times above the sensors' noise there (RMS) before
#: its damping is read: below, the 'mode' is the noise's own ripple, or a pole the fit put anywhere.
MIN_SIGNAL_TO_NOISE = 3.0
#: A mode's frequency that moves with its amplitude across the windows by more than this share of its
#: half-power half-width (``zeta f``) spreads what a linear fit of the record reads as damping.
DRIFT_LIMIT = 1.0


class Window(NamedTuple):
    """One window's estimate of one mode (:func:`forced_windows`)."""

    damping_ratio: float
    damping_ratio_std: float
    frequency: float
    """Hz."""
    frequency_std: float
    """Hz."""
    amplitude: float
    """RMS of the mode's relative acceleration on its strongest floor in the window (m/s^2)."""


def _window_runs(run: RunData, length: int) -> list:
    """Consecutive windows of ``length`` samples as runs of their own (time from 0)."""
    return [run.window(a, a + length, name=f"{run.name}@{a / run.sample_rate:.3g}s")
            for a in range(0, run.n_samples - length + 1, length)]


def random_effects(z: np.ndarray, s: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Random-effects least squares ``z = X b + u + e``.

    ``e`` are the estimates' own errors ``s``; ``u`` what they scatter beyond them, its variance by the
    method of moments (DerSimonian-Laird).

    Parameters
    ----------
    z, s : ndarray, shape (n,)
        The estimates and their standard errors.
    X : ndarray, shape (n, k)
        The regressors (a column of ones: their mean).

    Returns
    -------
    b : ndarray, shape (k,)
        The coefficients.
    cov : ndarray, shape (k, k)
        Their covariance, the scatter beyond the estimates' own errors included.
    """
    def wls(v):
        W = 1 / v
        cov = np.linalg.pinv(X.T @ (W[:, None] * X))      # pinv: windows of one amplitude leave no slope
        return cov @ X.T @ (W * z), cov
    b, _ = wls(s ** 2)
    w = 1 / s ** 2
    q = float(np.sum(w * (z - X @ b) ** 2))
    P = np.diag(w) - (w[:, None] * X) @ np.linalg.pinv(X.T @ (w[:, None] * X)) @ (X.T * w[None, :])
    tau2 = max((q - (z.size - X.shape[1])) / max(float(np.trace(P)), 1e-300), 0.0)
    return wls(s ** 2 + tau2)


def forced_windows(runs: Sequence[RunData], selection: ModeSelection, sigma: Sequence[dict],
                   storey_index: Sequence[int]) -> list[list[Window]]:
    """The linear modal model refitted window by window: each storey mode's estimate per window.

    A window whose refit fails, whose mode ends at a bound of the refit (:data:`BOUND_SLACK`), or where
    the mode stands less than :data:`MIN_SIGNAL_TO_NOISE` times above the sensor noise adds no estimate.

    Parameters
    ----------
    runs : sequence of RunData
        The runs of ``selection`` (``zdd``, ``a1..ad``, m/s^2).
    selection : ModeSelection
        The linear modal fit of the whole record (its modes, sensor gains and clock offsets).
    sigma : sequence of dict
        Per run, the noise standard deviation (m/s^2) of every channel.
    storey_index : sequence of int
        The storey modes' indices in the model.

    Returns
    -------
    list of list of Window
        Per storey mode (in the order of ``storey_index``), its windows in time order.
    """
    model, fit = selection.model, selection.fit
    f1 = float(np.min(model.omega(fit.theta)[storey_index]) / (2 * np.pi))
    bounds = refit_bounds(model, fit.theta)
    tasks = []
    for r, run in enumerate(runs):
        length = int(min(WINDOW_CYCLES / f1, run.n_samples / run.sample_rate / MIN_WINDOWS) * run.sample_rate)
        tasks += [(r, window) for window in _window_runs(run, max(length, 8))]
    # the windows' refits are independent: on forked workers (each a small GIL-bound least-squares fit),
    # their estimates gathered in time order, as one after another
    found = run_forked(lambda task: _window_estimates(task[1], task[0], runs[task[0]].sample_rate, selection,
                                                     sigma[task[0]], storey_index, bounds), tasks)
    out = [[] for _ in storey_index]
    for estimates in found:
        for k, window in estimates:
            out[k].append(window)
    return out


def _window_estimates(window: RunData, r: int, sample_rate: float, selection: ModeSelection, sigma: dict,
                      storey_index: Sequence[int], bounds: dict) -> list[tuple[int, Window]]:
    """One window's refit (run ``r`` of ``selection``): ``(k, Window)`` per storey mode it reads
    (:func:`forced_windows`)."""
    model, fit = selection.model, selection.fit
    d = model.d
    single = type(model)(d, 1, model.n - d, model.quadrature)
    theta1 = np.concatenate([fit.theta[:model.n_modal], fit.theta[model.sensor_slice(r)]])
    free = np.arange(single.p) < single.n_modal              # the record's sensors stay as they are
    try:
        sp = [spectra(window, d, fit.f_max, sigma=sigma, groups=["a"])]
        w_fit = refine(single, sp, [("whole record", theta1)], sample_rates=[sample_rate], f_max=fit.f_max,
                       free=free, fix_nuisance=False, frequency_bounds=bounds)
    except (MomentidError, np.linalg.LinAlgError, ValueError):
        return []                          # a window the model cannot fit adds no estimate
    sd = np.sqrt(np.clip(np.diag(w_fit.covariance), 0, None))
    w = single.omega(w_fit.theta) / (2 * np.pi)
    out = []
    for k, i in enumerate(storey_index):
        z, s = float(w_fit.theta[single.n + i]), float(sd[single.n + i])
        # a window whose frequency or damping ends at its bound (held there, its standard error then the
        # bound's, not the data's) read no mode
        if not (np.isfinite(z) and np.isfinite(s) and s > 0 and sd[i] > 0) or _held(w[i], z, bounds[i]):
            continue
        amplitude, noise = _window_amplitude(window, w_fit, single, i, sigma)
        # a window where the mode stands barely above the sensor noise (a quiet lead-in or tail) reads the
        # noise's ripple, not the mode: it would lever any trend in amplitude
        if amplitude >= MIN_SIGNAL_TO_NOISE * noise:
            out.append((k, Window(z, s, float(w[i]), float(w[i] * sd[i]), amplitude)))
    return out


def refit_bounds(model: ModalModel, theta: np.ndarray) -> dict[int, tuple[float, float]]:
    """Per mode of ``model``, the frequency range (Hz) a refit of part of a record may move it in:
    :data:`WINDOW_FREQUENCY_SPAN` either side of the whole record's (``theta``).

    Parameters
    ----------
    model : ModalModel
    theta : ndarray, shape (p,)
        The whole record's fit.

    Returns
    -------
    dict of int to (float, float)
        ``refine``'s ``frequency_bounds``.
    """
    f0 = model.omega(theta) / (2 * np.pi)
    return {i: (f0[i] * (1 - WINDOW_FREQUENCY_SPAN), f0[i] * (1 + WINDOW_FREQUENCY_SPAN)) for i in range(model.n)}


def _held(f: float, z: float, f_bounds: tuple[float, float]) -> bool:
    """Whether a window's mode ended at a bound of its refit: its frequency (Hz) at ``f_bounds`` or its
    damping ratio at :data:`~momentid.estimation.modal_model.MAX_ABS_DAMPING`."""
    return (min(abs(np.log(f / f_bounds[0])), abs(np.log(f / f_bounds[1]))) < BOUND_SLACK
            or abs(z) > MAX_ABS_DAMPING - BOUND_SLACK)


def _window_amplitude(window: RunData, w_fit, model, i: int, sigma: dict) -> tuple[float, float]:
    """RMS (m/s^2) of mode ``i``'s relative acceleration on its strongest floor in a window, read from the
    record band-passed around the mode's frequency there, and the white sensor noise's RMS in that band."""
    R = model.residues(w_fit.theta)
    j = int(np.argmax(np.abs(R[i])))
    f = float(model.omega(w_fit.theta)[i] / (2 * np.pi))
    band = ringdown.band_for(f, [f], window.sample_rate)
    env, _, _ = ringdown.envelope(window["zdd"] - window[f"a{j + 1}"], band, window.sample_rate)
    return float(np.sqrt(np.mean(env ** 2) / 2)), band_noise(sigma, j, band, window.sample_rate)


def band_noise(sigma: dict, j: int, band: tuple[float, float], sample_rate: float) -> float:
    """RMS (m/s^2) of the white sensor noise of ``zdd - a<j+1>`` in a band.

    Parameters
    ----------
    sigma : dict
        The noise standard deviation (m/s^2) of ``zdd`` and each ``a<j>``.
    j : int
        The floor's index (0: ``a1``).
    band : tuple of float
        Low and high edge (Hz).
    sample_rate : float
        Hz.

    Returns
    -------
    float
        m/s^2.
    """
    return float(np.hypot(sigma["zdd"], sigma[f"a{j + 1}"]) * np.sqrt(2 * (band[1] - band[0]) / sample_rate))


def frequency_trend(windows: Sequence[Window]) -> tuple[float, float]:
    """The windows' frequency trend in amplitude (random effects).

    Parameters
    ----------
    windows : sequence of Window
        One mode's windows.

    Returns
    -------
    slope : float
        Hz per m/s^2 (0 with fewer than four windows, or all at one amplitude).
    t : float
        The slope over its standard error.
    """
    if len(windows) < 4:
        return 0.0, 0.0
    _, _, f, sf, amp = (np.array(x) for x in zip(*windows))
    if np.ptp(amp) <= 0:
        return 0.0, 0.0
    b, cov = random_effects(f, np.maximum(sf, 1e-12), np.column_stack([np.ones_like(amp), amp]))
    sd = float(np.sqrt(max(cov[1, 1], 0.0)))
    return float(b[1]), float(b[1] / sd) if sd > 0 else 0.0


def drift_words(windows: Sequence[Window], equivalent: float) -> str:
    """How far a mode's frequency moves with its amplitude across the windows, in words.

    Parameters
    ----------
    windows : sequence of Window
        One mode's windows.
    equivalent : float
        The whole record's damping ratio of the mode (its half-power half-width is ``zeta f``).

    Returns
    -------
    str
        The words, when the move exceeds :data:`DRIFT_LIMIT` of the half-power half-width; else ``''``.
    """
    if len(windows) < 2:
        return ""
    z, _, f, sf, amp = (np.array(x) for x in zip(*windows))
    spread = drift(f, sf, amp) / float(np.median(f))
    width = max(min(float(np.median(z)), equivalent), 1e-5)
    if spread <= DRIFT_LIMIT * width:
        return ""
    return (f"the mode's frequency moves by {100 * spread:.2g} % ({spread / width:.2g} half-power half-widths) "
            f"across the record, with its amplitude")


def drift(f: np.ndarray, sf: np.ndarray, amp: np.ndarray) -> float:
    """How far a mode's frequency moves with its amplitude over the amplitudes its windows span.

    The random-effects trend's change from the quietest to the strongest window, when the trend stands
    beyond :data:`~momentid.estimation.ringdown.SLOPE_SIGMAS` standard errors; else 0 (a linear rig's
    windows scatter, they do not drift).

    Parameters
    ----------
    f, sf : ndarray, shape (n,)
        The windows' frequencies and their standard errors (Hz).
    amp : ndarray, shape (n,)
        Their amplitudes (m/s^2).

    Returns
    -------
    float
        Hz.
    """
    if f.size < 4:
        return 0.0
    b, cov = random_effects(f, np.maximum(sf, 1e-12), np.column_stack([np.ones_like(amp), amp]))
    if abs(b[1]) <= ringdown.SLOPE_SIGMAS * np.sqrt(cov[1, 1]):
        return 0.0
    return float(abs(b[1]) * np.ptp(amp))
