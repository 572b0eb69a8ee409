"""Identification without added mass: what table and floor accelerometers identify.

With no run that adds mass, the table-to-floor transfer ``z'' -> a`` depends on
``M^-1 K`` and ``M^-1 C`` only: frequencies, damping ratios and mode shapes are
identified, M, C and K only up to a common scale.  Stated floor masses fix that
scale (K, C in SI units, see :mod:`momentid.estimation.scaled`); without them
the results are mass-normalised.

Model: classical normal modes, each with its own frequency, damping ratio and
residues (no shear-building constraint: a real frame's floors rotate and its
columns bend, and forcing it into d storey springs moves the frequencies by
percents).  Floor j's absolute acceleration per unit table acceleration is::

    a_j / z'' = 1 - sum_i R_ij s^2 / (s^2 + 2 zeta_i w_i s + w_i^2)

with ``R_ij = Gamma_i phi_ji`` (participation factor x mode shape), evaluated
exactly in discrete time (first-order hold between samples) through the modal
oscillators ``eta_i'' + 2 zeta_i w_i eta_i' + w_i^2 eta_i = -z''``.  The damping
ratios are fitted without sign constraint so that an unstable mode shows as a
negative ratio (and is warned about), never hidden by the parameterisation.

Estimator: the frequency-domain errors-in-variables likelihood of
:mod:`momentid.estimation.eiv` (transient term projected out, noise on table
and floors), over the bins up to :data:`FIT_BAND_FACTOR` x the top resonance,
started from the spectral peaks of :mod:`momentid.estimation.peaks`.  Noise
levels come from :mod:`momentid.estimation.noise` (stated, quiet lead-in, or
high band).  Covariance: the Jacobian of the whitened residual at the optimum,
scaled by the residual variance factor when the model explains the data less
well than the noise allows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize

from momentid.core.analytic import shear_stiffness
from momentid.errors import IdentificationError
from momentid.estimation.eiv import Spectra, spectra, whiten_and_project
from momentid.estimation.linear import discretize, frequency_response, output_matrix

__all__ = ["ModalModel", "ModalFit", "fit_modal", "FIT_BAND_FACTOR", "START_DAMPING"]

#: The fit uses DFT bins up to this multiple of the highest resonance (the
#: resonance's flanks carry its damping), capped by :data:`NYQUIST_FRACTION`.
FIT_BAND_FACTOR = 1.5
#: Highest fitted frequency as a fraction of the sample rate: below the sensors'
#: anti-alias roll-off, where the first-order hold between samples is accurate.
NYQUIST_FRACTION = 0.42
#: Damping ratio every mode starts from: wider than a real structure's, so that
#: a start a few half-power bandwidths off the peak still sees its slope.
START_DAMPING = 0.02
#: Evaluations the optimiser may use; reaching it is reported as a capped fit.
MAX_NFEV = 400
#: Relative step of the central differences of the covariance Jacobian.
JACOBIAN_STEP = 1e-6


class ModalModel:
    """Parameter vector of ``d`` classical normal modes seen by ``d`` floor accelerometers.

    ``theta = [log w (d, rad/s), zeta (d), R (d x d: row i = mode i, column j = floor j),
    then per run: log g (d), tau (d, s)]``.

    ``g_j`` and ``tau_j`` are floor sensor j's gain and clock offset relative to the
    table sensor in that run.  Real accelerometers differ in gain by up to a few
    percent and separately clocked devices are synchronised to a sample at best; at
    the drive frequency of a sine test the data are so precise that, without these
    two nuisances, the fit bends the first mode's damping to absorb a phase error
    (to negative values on real trials).  They are separable from the modes: the
    gain is the response at zero frequency, the offset a phase linear in frequency,
    the damping a phase change local to its resonance.

    Parameters
    ----------
    d : int
        Storeys (= modes = floor accelerometers).
    n_runs : int
        Runs fitted together (each gets its own sensor gains and clock offsets).
    """

    def __init__(self, d: int, n_runs: int = 1):
        self.d = d
        self.n_runs = n_runs
        self.n_modal = 2 * d + d * d
        self.p = self.n_modal + 2 * d * n_runs

    def omega(self, theta) -> np.ndarray:
        """Undamped angular frequencies (rad/s), shape (d,)."""
        return np.exp(theta[:self.d])

    def zeta(self, theta) -> np.ndarray:
        """Damping ratios, shape (d,)."""
        return np.asarray(theta[self.d:2 * self.d], float)

    def residues(self, theta) -> np.ndarray:
        """``R``, shape (d modes, d floors)."""
        return np.asarray(theta[2 * self.d:self.n_modal], float).reshape(self.d, self.d)

    def sensors(self, theta, run: int):
        """Gains (1) and clock offsets (s) of the floor sensors in run ``run``, each shape (d,)."""
        start = self.n_modal + 2 * self.d * run
        return np.exp(theta[start:start + self.d]), np.asarray(theta[start + self.d:start + 2 * self.d])

    def response(self, theta, sp: Spectra, run: int = 0):
        """``(G, T)`` of the measured floor accelerations at the bins of ``sp``.

        See :func:`~momentid.estimation.linear.frequency_response`; shapes (bins, d)
        and (bins, d, 2d).
        """
        w, z, R = self.omega(theta), self.zeta(theta), self.residues(theta)
        oscillators = discretize(np.eye(self.d), np.diag(2 * z * w), np.diag(w ** 2), sp.h)
        G_mod, T_mod = frequency_response(oscillators, output_matrix(oscillators, ["a"]), sp.z)
        gain, offset = self.sensors(theta, run)
        omega_bins = np.angle(sp.z) / sp.h
        sensor = gain[None, :] * np.exp(-1j * omega_bins[:, None] * offset[None, :])
        G = (G_mod @ R + (1.0 - R.sum(axis=0))[None, :]) * sensor
        T = np.einsum("mil,ij->mjl", T_mod, R) * sensor[:, :, None]
        return G, T

    def start(self, frequency_hz, masses=None) -> np.ndarray:
        """Picked frequencies, :data:`START_DAMPING`, residues of the shear building with those
        frequencies, ideal sensors.  ``masses`` (kg) shape the residues; equal when not stated.
        """
        f = np.sort(np.asarray(frequency_hz, float))
        m = np.ones(self.d) if masses is None else np.asarray(masses, float)
        M = np.diag(m)
        target = np.log(2 * np.pi * f)

        def shear(logk):
            w2, phi = scipy.linalg.eigh(shear_stiffness(np.exp(logk)), M)
            return np.sqrt(np.clip(w2, 1e-24, None)), phi

        logk0 = np.full(self.d, np.log(np.mean(m)) + 2 * target[0])
        logk = scipy.optimize.least_squares(lambda lk: np.log(shear(lk)[0]) - target, logk0).x
        _, phi = shear(logk)
        gamma = phi.T @ M @ np.ones(self.d)
        R = gamma[:, None] * phi.T
        return np.concatenate([target, np.full(self.d, START_DAMPING), R.ravel(),
                               np.zeros(2 * self.d * self.n_runs)])


@dataclass(frozen=True)
class ModalFit:
    """Raw result of :func:`fit_modal` (see :class:`momentid.estimation.scaled.ScaledIdentification`).

    Attributes
    ----------
    theta : ndarray, shape (p,)
    covariance : ndarray, shape (p, p)
        Scaled by ``max(scale, 1)``.
    scale : float
        Residual variance factor (1: the model explains the data to the noise level).
    n_residuals : int
    nfev : int
    capped : bool
        The optimiser stopped at :data:`MAX_NFEV`, not at convergence.
    f_max : float
        Top of the fitted band (Hz).
    noise_sources : tuple of str
        Per run: where its noise levels came from.
    """

    theta: np.ndarray
    covariance: np.ndarray
    scale: float
    n_residuals: int
    nfev: int
    capped: bool
    f_max: float
    noise_sources: tuple


class _Residual:
    def __init__(self, model: ModalModel, spectra_list):
        self.model = model
        self.spectra = spectra_list
        self.n_nuisance = 0

    def __call__(self, theta):
        parts, self.n_nuisance = [], 0
        for i, sp in enumerate(self.spectra):
            try:
                G, T = self.model.response(theta, sp, i)
                r, k = whiten_and_project(sp, G, T, sp.Y - G * sp.U[:, None])
            except (IdentificationError, np.linalg.LinAlgError, ValueError):
                r, k = np.full(2 * sp.Y.size, 1e6), 0      # an impossible trial step: step back
            parts.append(np.where(np.isfinite(r), r, 1e6))
            self.n_nuisance += k
        return np.concatenate(parts)


def fit_modal(model: ModalModel, runs, frequency_hz, *, masses=None, stated=None) -> ModalFit:
    """Fit ``model`` to ``runs`` from resonances ``frequency_hz`` (Hz).

    Parameters
    ----------
    model : ModalModel
    runs : sequence of RunData
        ``zdd`` and ``a1..ad``, uniformly sampled.
    frequency_hz : array_like, shape (d,)
        Starting resonances (see :func:`momentid.estimation.peaks.pick_resonances`).
    masses : array_like, shape (d,), optional
        Stated floor masses (kg): shape the start only.
    stated : dict, optional
        Stated noise levels per channel group.
    """
    fs = min(r.sample_rate for r in runs)
    f_max = min(FIT_BAND_FACTOR * float(np.max(frequency_hz)), NYQUIST_FRACTION * fs)
    spectra_list = [spectra(r, model.d, f_max, stated=stated, groups=["a"]) for r in runs]
    residual = _Residual(model, spectra_list)
    theta0 = model.start(frequency_hz, masses)
    result = scipy.optimize.least_squares(residual, theta0, method="trf", x_scale="jac", ftol=1e-12,
                                          xtol=1e-12, gtol=1e-12, max_nfev=MAX_NFEV)
    theta = result.x
    r = residual(theta)
    J = np.empty((r.size, theta.size))
    for i in range(theta.size):
        step = JACOBIAN_STEP * max(abs(theta[i]), 1.0)
        e = np.zeros_like(theta)
        e[i] = step
        J[:, i] = (residual(theta + e) - residual(theta - e)) / (2 * step)
    dof = max(r.size - theta.size - residual.n_nuisance, 1)
    s2 = float(r @ r) / dof
    try:
        cov = np.linalg.inv(J.T @ J) * max(s2, 1.0)
    except np.linalg.LinAlgError:
        raise IdentificationError(
            f"runs {[r.name for r in runs]}: singular information matrix: the runs do not identify the "
            f"{model.p} parameters (a mode the table never excites?)") from None
    return ModalFit(theta=theta, covariance=cov, scale=s2, n_residuals=r.size, nfev=int(result.nfev),
                    capped=result.status == 0, f_max=f_max,
                    noise_sources=tuple(f"{sp.run}: {sp.noise_source}" for sp in spectra_list))
