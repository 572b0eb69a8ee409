"""Held-out check of the modal model on recordings without added mass (accelerometers only).

Real labs record table and floor accelerations, often at 60-200 Hz, and add no mass: the
equation-(3) residuals of :mod:`~momentid.diagnosis.added_mass.residuals` need M, C, K, mu and
displacements, which such data cannot give.  What they can give is the modal model of
:mod:`momentid.estimation.modal` (frequencies, damping ratios, residues, per-run sensor gains and
clock offsets).  This module fits it on training runs and replays it on a held-out run:

* :func:`fit_runs`: the modal errors-in-variables fit of :func:`~momentid.estimation.modal.fit_modal`
  on the named runs (shared modes), returned with its parameter vector so that it can be replayed;
* :func:`replay`: floor accelerations ``a1..ad`` of a modal model driven by a run's *measured* table
  acceleration (exact first-order-hold discretisation, sensor gain and fractional clock offset);
* :func:`noise_nrmse`: the NRMSE noise alone leaves (floor noise, plus table noise through the model);
* :func:`amplitude_model`: the amplitude-dependence candidate: one fit per training run, each mode's
  frequency and damping ratio regressed on the run's response amplitude.

Every NRMSE here is ``sqrt(sum_j |a_j - a_j,model|^2 / sum_j |a_j|^2)`` over the floor channels and
the samples after the run's quiet lead-in (where the table moves).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from momentid.core.series import Experiment, RunData
from momentid.errors import IdentificationError
from momentid.estimation.linear import discretize, outputs, simulate_linear
from momentid.estimation.modal import ModalFit, ModalModel, fit_modal
from momentid.estimation.noise import estimate_noise, quiet_lead_in
from momentid.estimation.peaks import pick_resonances, response_amplitude
from momentid.estimation.scaled import weighted_line
from momentid.lab.sensors import gain_and_delay

__all__ = ["RunsFit", "AmplitudeModel", "fit_runs", "replay", "nrmse", "noise_nrmse", "amplitude_model",
           "active_start", "pooled"]

#: Training amplitudes must spread by at least this fraction of the largest for a trend to be fitted.
MIN_AMPLITUDE_SPREAD = 0.1
#: The impulse response of :func:`noise_nrmse` runs this many time constants of the slowest mode
#: (its energy is then complete to e^-20), at most :data:`MAX_IMPULSE_S` seconds (a mode fitted with
#: near-zero damping).
DECAY_TIME_CONSTANTS = 10.0
MAX_IMPULSE_S = 600.0


@dataclass(frozen=True)
class RunsFit:
    """A modal fit on some runs, in a form that can be replayed.

    Attributes
    ----------
    runs : tuple of str
    omega : ndarray, shape (d,)
        Undamped angular frequencies (rad/s), ascending.
    zeta, zeta_std : ndarray, shape (d,)
        Damping ratios (1) and standard errors.
    frequency_std : ndarray, shape (d,)
        Standard errors of ``omega / 2 pi`` (Hz).
    residues : ndarray, shape (d modes, d floors)
    gain, offset : ndarray, shape (n_runs, d)
        Floor sensors' gain (1) and clock offset (s, positive: lags) relative to the table's, per run.
    amplitude : ndarray, shape (n_runs,)
        RMS top-floor acceleration relative to the table after the lead-in (m/s^2).
    scale : float
        Residual variance factor of the fit (1: the model explains the data to the noise level).
    noise : tuple of str
        Where each run's noise levels came from.
    """

    runs: tuple
    omega: np.ndarray
    zeta: np.ndarray
    zeta_std: np.ndarray
    frequency_std: np.ndarray
    residues: np.ndarray
    gain: np.ndarray
    offset: np.ndarray
    amplitude: np.ndarray
    scale: float
    noise: tuple

    @property
    def frequency(self) -> np.ndarray:
        """Natural frequencies (Hz), ascending."""
        return self.omega / (2 * np.pi)


def _stated_noise(experiment: Experiment):
    return dict(experiment.statement.noise) if experiment.statement is not None else None


def fit_runs(experiment: Experiment, names: Sequence[str]) -> RunsFit:
    """Fit the modal model of :mod:`momentid.estimation.modal` to the runs ``names`` together.

    Parameters
    ----------
    experiment : Experiment
        Runs with ``zdd`` and ``a1..ad`` (m/s^2), no added mass.
    names : sequence of str

    Raises
    ------
    IdentificationError
        No noise source, fewer resonances than storeys, a singular fit.
    """
    from momentid.io.run_checks import check_run

    runs = tuple(check_run(experiment.run(n), experiment.source)[0] for n in names)
    d = experiment.storeys
    stated = _stated_noise(experiment)
    picked = pick_resonances(runs, d, estimate_noise(runs[0], stated=stated).sigma["zdd"])
    model = ModalModel(d, len(runs))
    fit: ModalFit = fit_modal(model, runs, picked, stated=stated)
    theta = fit.theta
    sd = np.sqrt(np.clip(np.diag(fit.covariance), 0, None))
    order = np.argsort(model.omega(theta))
    omega = model.omega(theta)[order]
    fitted_sensors = [model.sensors(theta, r) for r in range(len(runs))]
    return RunsFit(runs=tuple(names), omega=omega, zeta=model.zeta(theta)[order],
                   zeta_std=sd[d:2 * d][order], frequency_std=(omega / (2 * np.pi)) * sd[:d][order],
                   residues=model.residues(theta)[order], gain=np.array([g for g, _ in fitted_sensors]),
                   offset=np.array([t for _, t in fitted_sensors]),
                   amplitude=np.array([response_amplitude(r, d, active_start(r)) for r in runs]),
                   scale=fit.scale, noise=fit.noise_sources)


def pooled(fits: Sequence[RunsFit]) -> RunsFit:
    """One amplitude-independent linear model from per-run fits.

    Each mode's frequency and damping ratio: the inverse-variance weighted mean over the runs (the
    intercept-only version of :func:`amplitude_model`'s lines, so that the two models are nested);
    residues: the runs' mean; sensor gains, clock offsets and amplitudes: kept per run.

    Parameters
    ----------
    fits : sequence of RunsFit
        One fit per run, each from :func:`fit_runs` with one run.
    """
    fits = tuple(fits)

    def mean(values, std):
        w = 1.0 / np.maximum(np.asarray(std), 1e-12) ** 2
        return np.sum(w * np.asarray(values), axis=0) / np.sum(w, axis=0), 1.0 / np.sqrt(np.sum(w, axis=0))

    frequency, frequency_std = mean([f.frequency for f in fits], [f.frequency_std for f in fits])
    zeta, zeta_std = mean([f.zeta for f in fits], [f.zeta_std for f in fits])
    return RunsFit(runs=tuple(n for f in fits for n in f.runs), omega=2 * np.pi * frequency, zeta=zeta,
                   zeta_std=zeta_std, frequency_std=frequency_std,
                   residues=np.mean([f.residues for f in fits], axis=0),
                   gain=np.vstack([f.gain for f in fits]), offset=np.vstack([f.offset for f in fits]),
                   amplitude=np.concatenate([f.amplitude for f in fits]), scale=max(f.scale for f in fits),
                   noise=tuple(n for f in fits for n in f.noise))


def active_start(run: RunData) -> int:
    """First sample after the run's quiet lead-in (0 when it shakes from the start)."""
    return quiet_lead_in(run)


def replay(omega: ArrayLike, zeta: ArrayLike, residues: ArrayLike, gain: ArrayLike, offset: ArrayLike, zdd: np.ndarray,
           dt: float) -> np.ndarray:
    """Floor accelerations of the modal model driven by a measured table acceleration.

    ``a_j = z'' + sum_i R_ij eta_i''`` with ``eta_i'' + 2 zeta_i w_i eta_i' + w_i^2 eta_i = -z''``
    (at rest at the first sample), then each floor sensor's gain and clock offset.

    Parameters
    ----------
    omega, zeta : array_like, shape (d,)
        Angular frequencies (rad/s) and damping ratios (1).
    residues : array_like, shape (d modes, d floors)
    gain, offset : array_like, shape (d,)
        Floor sensors' gain (1) and clock offset (s, positive: lags).
    zdd : ndarray, shape (n,)
        Table acceleration (m/s^2).
    dt : float
        Sample interval (s).

    Returns
    -------
    ndarray, shape (n, d)
        Floor accelerations (m/s^2, absolute).
    """
    omega, zeta = np.asarray(omega, float), np.asarray(zeta, float)
    R = np.asarray(residues, float)
    d = omega.size
    oscillators = discretize(np.eye(d), np.diag(2 * zeta * omega), np.diag(omega ** 2), dt)
    absolute = outputs(oscillators, simulate_linear(oscillators, zdd))["a"]   # eta'' + z'', (n, d)
    a = absolute @ R + (1.0 - R.sum(axis=0))[None, :] * zdd[:, None]
    return gain_and_delay(a, gain, offset, dt)


def nrmse(measured: np.ndarray, model: np.ndarray) -> float:
    """``sqrt(sum |measured - model|^2 / sum |measured - mean|^2)`` over every sample and channel."""
    centred = measured - measured.mean(axis=0)
    return float(np.sqrt(np.sum((measured - model) ** 2) / np.sum(centred ** 2)))


def channel_nrmse(measured: np.ndarray, model: np.ndarray) -> np.ndarray:
    """:func:`nrmse` of each channel (column), shape (d,)."""
    centred = measured - measured.mean(axis=0)
    return np.sqrt(np.sum((measured - model) ** 2, axis=0) / np.sum(centred ** 2, axis=0))


def noise_nrmse(fit_omega: ArrayLike, fit_zeta: ArrayLike, residues: ArrayLike, gain: ArrayLike, run: RunData,
                experiment: Experiment) -> float:
    """NRMSE that sensor noise alone leaves on ``run``'s floor channels after its lead-in.

    ``fit_omega`` (rad/s), ``fit_zeta``, ``residues`` (modes, d) and ``gain`` (d,): the model of
    :func:`replay`.

    Expected power of the floor sensors' noise (``sigma_aj^2``) plus the table sensor's white noise
    pushed through the model (``sigma_zdd^2 sum_k h_jk^2``, ``h`` the model's impulse response over
    :data:`DECAY_TIME_CONSTANTS` time constants of its slowest mode, built up from the replay's start at
    rest): what a perfect model still misses.  The expectation, not one noise draw: through a lightly
    damped mode one 20 s draw scatters by ~20 %.
    """
    d = experiment.storeys
    sigma = estimate_noise(run, stated=_stated_noise(experiment)).sigma
    start = active_start(run)
    n = run.n_samples - start
    dt = 1.0 / run.sample_rate
    decay = np.min(np.abs(np.asarray(fit_zeta)) * np.asarray(fit_omega))
    length = int(min(DECAY_TIME_CONSTANTS / max(decay, 1e-12), MAX_IMPULSE_S) / dt) + 1
    impulse = np.zeros(length)
    impulse[1] = 1.0      # not at sample 0: the replay starts at rest there, so u_0 enters only half its hold
    h = replay(fit_omega, fit_zeta, residues, gain, np.zeros(d), impulse, dt)
    # Sample k of the replay (at rest at sample 0) holds the table noise of samples 1..k: its expected
    # power is the impulse response's energy up to lag k-1, which builds up over the first time constants.
    built_up = np.cumsum(np.sum(h[1:] ** 2, axis=1))
    lags = np.minimum(np.arange(start, run.n_samples), built_up.size) - 1
    table = float(np.sum(built_up[lags[lags >= 0]]))
    power = n * sum(sigma[f"a{j + 1}"] ** 2 for j in range(d)) + sigma["zdd"] ** 2 * table
    measured = run.group("a", d)[start:]
    return float(np.sqrt(power / np.sum((measured - measured.mean(axis=0)) ** 2)))


@dataclass(frozen=True)
class AmplitudeModel:
    """Each mode's frequency and damping ratio as straight lines in the response amplitude.

    Attributes
    ----------
    runs : tuple of RunsFit
        One fit per training run.
    frequency_coef, damping_coef : ndarray, shape (d, 2)
        Per mode: intercept (Hz; 1) and slope (Hz per m/s^2; 1 per m/s^2).
    frequency_slope_std, damping_slope_std : ndarray, shape (d,)
        Standard errors of the slopes (widened by the scatter beyond the fits' errors).
    """

    runs: tuple
    frequency_coef: np.ndarray
    damping_coef: np.ndarray
    frequency_slope_std: np.ndarray
    damping_slope_std: np.ndarray

    @property
    def amplitude_range(self) -> tuple:
        """Smallest and largest training amplitude (m/s^2)."""
        x = [float(r.amplitude[0]) for r in self.runs]
        return min(x), max(x)

    def predict(self, amplitude: float) -> tuple[np.ndarray, np.ndarray]:
        """Angular frequencies (rad/s) and damping ratios at response amplitude ``amplitude`` (m/s^2)."""
        f = self.frequency_coef[:, 0] + self.frequency_coef[:, 1] * amplitude
        z = self.damping_coef[:, 0] + self.damping_coef[:, 1] * amplitude
        return 2 * np.pi * f, z

    def to_dict(self) -> dict:
        """Each training run's amplitude (m/s^2), frequencies (Hz) and damping ratios, and the slopes with their
        standard errors.
        """
        return {"runs": [r.runs[0] for r in self.runs],
                "amplitude_m_s2": [float(r.amplitude[0]) for r in self.runs],
                "frequency_hz": [r.frequency.tolist() for r in self.runs],
                "damping_ratio": [r.zeta.tolist() for r in self.runs],
                "df_dA_hz_per_m_s2": self.frequency_coef[:, 1].tolist(),
                "df_dA_std": self.frequency_slope_std.tolist(),
                "dzeta_dA_per_m_s2": self.damping_coef[:, 1].tolist(),
                "dzeta_dA_std": self.damping_slope_std.tolist()}


def amplitude_model(fits: Sequence[RunsFit]) -> AmplitudeModel:
    """Regress each mode's frequency and damping ratio on the response amplitude over per-run fits.

    Parameters
    ----------
    fits : sequence of RunsFit
        One fit per training run (:func:`fit_runs` with one run each).

    Raises
    ------
    IdentificationError
        Fewer than two runs, or runs of (nearly) one amplitude: no trend to fit.
    """
    fits = tuple(fits)
    x = np.array([f.amplitude[0] for f in fits])
    if len(fits) < 2 or np.ptp(x) <= MIN_AMPLITUDE_SPREAD * np.max(x):
        raise IdentificationError(f"runs {[f.runs[0] for f in fits]}: amplitudes {x.tolist()} m/s^2: an amplitude "
                                  f"trend needs at least two training runs whose amplitudes differ by over "
                                  f"{100 * MIN_AMPLITUDE_SPREAD:.0f} %")
    f_coef, z_coef, f_std, z_std = [], [], [], []
    for i in range(fits[0].omega.size):
        c, s = weighted_line(x, np.array([f.frequency[i] for f in fits]),
                     np.maximum([f.frequency_std[i] for f in fits], 1e-12))
        f_coef.append(c)
        f_std.append(s)
        c, s = weighted_line(x, np.array([f.zeta[i] for f in fits]), np.maximum([f.zeta_std[i] for f in fits], 1e-12))
        z_coef.append(c)
        z_std.append(s)
    return AmplitudeModel(fits, np.array(f_coef), np.array(z_coef), np.array(f_std), np.array(z_std))
