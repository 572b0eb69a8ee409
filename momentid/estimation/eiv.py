"""Errors-in-variables maximum likelihood: the estimator noise cannot bias.

Every channel a lab records is noisy, the table accelerometer included.
Equation-error least squares (``identify``'s ``"equation"`` form) treats the
recorded ``a``, ``v``, ``q`` as exact regressors and is biased; an output-error
fit that simulates the model from the *measured* table acceleration is
biased too, because the input noise passes through the lightly damped
structure (amplified ~1/(2 zeta) at resonance) and looks like a model error.

This module fits ``theta = (M, C, K, mu)`` by the frequency-domain
errors-in-variables maximum likelihood (Pintelon & Schoukens, *System
Identification: A Frequency Domain Approach*, ch. 7 and 10):

* each run's discretised model (:mod:`momentid.estimation.linear`) relates the DFTs of
  input and outputs exactly, ``Y_k = G_k U_k + T_k beta``, where the
  transient term ``T_k beta`` absorbs the unknown initial and final states
  (and any constant input bias): ``beta`` is eliminated by variable projection;
* at every DFT bin the residual ``e_k = Y_k - G_k U_k - T_k beta`` has
  covariance ``C_k = diag(s_y^2) + s_u^2 G_k G_k^H`` (output noise plus input
  noise through the model); the estimate minimises ``sum_k e_k^H C_k^-1 e_k``;
* only the bins where the structure responds are used (a few hundred
  instead of tens of thousands of samples), which makes it fast, and the
  noise levels ``s_y``, ``s_u`` come from :mod:`momentid.estimation.noise`
  (stated by the lab, the quiet lead-in of a real record, or the bins above
  that band where a high-rate recording holds noise only).

With white sensor noise the estimate is consistent and efficient: its
covariance ``(J^H C^-1 J)^-1`` is the Cramér-Rao bound of the experiment, which
:func:`fisher_information` evaluates for a designed experiment.

Why not ``mujoco.sysid``: it is an output-error fit that re-simulates the
MuJoCo model (this rig needs a Python control callback at every integrator
stage, ~40 k steps/s), and output error is biased by table-accelerometer noise.
The MuJoCo rig stays the "lab"; the estimator needs only its linear equations.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
import scipy.optimize

from momentid.core.series import RunData
from momentid.errors import IdentificationError
from momentid.estimation.bins import Spectra
from momentid.estimation.columns import point_map
from momentid.estimation.eiv_jacobian import whitened_jacobian
from momentid.estimation.layout import Layout
from momentid.estimation.noise import estimate_noise
from momentid.estimation.linear import discretize, force_response, frequency_response, output_matrix

__all__ = ["EivFit", "fit_eiv", "Spectra", "spectra", "fisher_information", "output_groups",
           "whitened_residual", "whiten_and_project"]


def output_groups(run: RunData, d: int) -> list[str]:
    """Measured floor channel groups used as outputs: ``a``, ``q``, ``v`` where complete."""
    return [g for g in ("a", "q", "v") if all(run.has(f"{g}{i + 1}") for i in range(d))]


def spectra(run: RunData, d: int, f_max: float, *, noise_floor: tuple[float, float] | None = None,
            sigma: dict | None = None, stated: dict | None = None, groups: Iterable[str] | None = None) -> Spectra:
    """DFTs of a run restricted to ``(0, f_max]`` Hz, with noise levels.

    Noise levels come from ``sigma`` (``{'zdd': s_u, 'a1': ..}``, known
    sensors) or from :func:`momentid.estimation.noise.estimate_noise`
    (``stated`` levels, the quiet lead-in, or the bins in ``noise_floor``,
    default from ``3 f_max`` to 0.8 x Nyquist).  ``groups`` restricts the
    outputs (default: every complete group of :func:`output_groups`).
    """
    if not run.has("zdd"):
        raise IdentificationError(f"run {run.name!r}: the errors-in-variables fit needs the base acceleration zdd")
    groups = output_groups(run, d) if groups is None else list(groups)
    y = np.column_stack([run.group(g, d) for g in groups])
    u = run["zdd"]
    n = u.shape[0]
    fs = run.sample_rate
    U = np.fft.rfft(u) / np.sqrt(n)
    Y = np.fft.rfft(y, axis=0) / np.sqrt(n)
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    k_max = int(np.searchsorted(freq, f_max, side="right"))
    if k_max < 4:
        raise IdentificationError(f"run {run.name!r}: only {k_max} frequency bins below {f_max:g} Hz: "
                                  f"the record is too short for the structure's band")
    if sigma is None:
        estimate = estimate_noise(run, f_max=f_max, stated=stated, noise_floor=noise_floor)
        sigma, source = estimate.sigma, f"{estimate.source.value} ({estimate.detail})"
    else:
        source = "given"
    s_u = float(sigma["zdd"])
    s_y = np.array([sigma[f"{g}{i + 1}"] for g in groups for i in range(d)], float)
    scale = np.max(np.abs(Y[1:k_max]), axis=0)
    s_y = np.maximum(s_y, 1e-9 * scale)        # noise-free data: keep the weights finite
    s_u = max(s_u, 1e-12 * float(np.max(np.abs(U[1:k_max]))))
    k = np.arange(1, k_max)
    return Spectra(run=run.name, added_mass=np.asarray(run.added_mass, float), h=1.0 / fs, groups=groups,
                   z=np.exp(2j * np.pi * k / n), U=U[k], Y=Y[k], sigma_u=s_u, sigma_y=s_y, freq=freq[k],
                   noise_source=source)


def whitened_residual(layout: Layout, theta: np.ndarray, sp: Spectra) -> tuple[np.ndarray, int]:
    """Noise-whitened DFT residual of one run, the transient term projected out.

    Parameters
    ----------
    layout : momentid.estimation.layout.Layout
    theta : ndarray, shape (p,) or (p + m,)
        Parameters (plus force coefficients when ``sp`` carries forces).
    sp : Spectra
        One run's spectra; the residual is whitened by its noise levels.

    Returns
    -------
    r : ndarray, shape (2 bins n_out,)
        Real residual with unit variance per entry when the model and noise levels are right.
    n_nuisance : int
        Transient parameters projected out (they cost degrees of freedom).
    """
    M, C, K, mu = layout.unpack(theta[:layout.p])
    dm = np.diag(sp.added_mass)
    model = discretize(M + dm, C + mu * dm, K, sp.h)
    H = output_matrix(model, sp.groups)
    G, T = frequency_response(model, H, sp.z)
    e = sp.Y - G * sp.U[:, None]                              # (m, n_out)
    if sp.F is not None:                                      # extra force signals, coefficients theta[p:]
        Gf = force_response(M + dm, C + mu * dm, K, sp.h, sp.forces, H, sp.z, model.lam, model.V, sp.groups)
        e = e - np.einsum("mok,mk->mo", Gf, sp.F * theta[layout.p:][None, :])
    return whiten_and_project(sp, G, T, e)


def whiten_and_project(sp: Spectra, G: np.ndarray, T: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, int]:
    """Whiten the DFT residual ``e`` of any linear model and project its transient term out.

    Parameters
    ----------
    sp : Spectra
    G : ndarray, shape (bins, n_out), complex
        The model's response to the table acceleration at each bin.
    T : ndarray, shape (bins, n_out, n_transient), complex
        Its transient term (unknown initial and final states).
    e : ndarray, shape (bins, n_out), complex
        ``Y - G U`` (and any other known inputs removed).

    Returns
    -------
    r : ndarray, shape (2 bins n_out,)
        Unit variance per entry when model and noise levels are right.
    n_nuisance : int
        Transient parameters projected out.
    """
    # Whitening by C_k^-1/2, C_k = D + s_u^2 g g^H, D = diag(s_y^2): a rank-one update.
    inv_sd = 1.0 / sp.sigma_y
    gt = G * inv_sd[None, :]                                  # D^-1/2 g
    c = sp.sigma_u ** 2 * np.sum(np.abs(gt) ** 2, axis=1)     # (m,)
    norm = np.sqrt(np.sum(np.abs(gt) ** 2, axis=1))
    norm[norm == 0] = 1.0
    uhat = gt / norm[:, None]
    f = 1.0 / np.sqrt(1.0 + c) - 1.0

    def whiten(x):                                            # x: (m, n_out, ...) complex
        xt = x * inv_sd[(None, slice(None)) + (None,) * (x.ndim - 2)]
        proj = np.einsum("mo,mo...->m...", np.conj(uhat), xt)
        return xt + (f[:, None] * uhat)[(...,) + (None,) * (x.ndim - 2)] * proj[:, None]

    ew = whiten(e)
    Tw = whiten(T)                                            # (m, n_out, n_transient)
    # sqrt(2): real and imaginary parts of a whitened bin each get unit variance.
    r = np.sqrt(2.0) * np.concatenate([ew.real.ravel(), ew.imag.ravel()])
    B = np.sqrt(2.0) * np.concatenate([Tw.real.reshape(-1, Tw.shape[2]), Tw.imag.reshape(-1, Tw.shape[2])])
    norms = np.linalg.norm(B, axis=0)
    norms[norms == 0] = 1.0
    Bs = B / norms
    beta = np.linalg.lstsq(Bs.T @ Bs, Bs.T @ r, rcond=1e-12)[0]
    return r - Bs @ beta, Bs.shape[1]


class _Problem:
    def __init__(self, layout, spectra_list):
        self.layout = layout
        self.spectra = spectra_list
        self.n_nuisance = 0

    def jacobian(self, theta):
        """The residual's Jacobian (:func:`~momentid.estimation.eiv_jacobian.whitened_jacobian`), zero on a run
        whose model cannot be simulated (its residual is then the constant penalty)."""
        parts = []
        for sp in self.spectra:
            try:
                J = whitened_jacobian(self.layout, theta, sp)
            except (IdentificationError, np.linalg.LinAlgError, ValueError):
                J = np.zeros((2 * sp.Y.size, theta.size))
            parts.append(np.where(np.isfinite(J), J, 0.0))
        return np.vstack(parts)

    def residual(self, theta):
        parts = []
        self.n_nuisance = 0
        for sp in self.spectra:
            try:
                r, k = whitened_residual(self.layout, theta, sp)
            except (IdentificationError, np.linalg.LinAlgError, ValueError):
                # A trial step into a physically impossible model (singular or defective): make it
                # so costly the optimiser steps back.
                r, k = np.full(2 * sp.Y.size, 1e6), 0
            if not np.all(np.isfinite(r)):
                r = np.full(2 * sp.Y.size, 1e6)
            parts.append(r)
            self.n_nuisance += k
        return np.concatenate(parts)


@dataclass(frozen=True)
class EivFit:
    """Result of :func:`fit_eiv`."""

    theta: np.ndarray
    covariance: np.ndarray
    cost: float
    n_residuals: int
    n_nuisance: int
    nfev: int
    f_max: float
    scale: float      # residual variance factor (1 when the noise levels are right)
    capped: bool = False             # the optimiser stopped at max_nfev, not at convergence
    noise_sources: tuple = ()        # per run: where its noise levels came from


def _scales(layout, theta):
    s = np.ones_like(theta)
    M, C, K, mu = layout.unpack(theta[:layout.p])
    s[layout.p:] = np.maximum(np.abs(theta[layout.p:]), 1e-6 * max(np.max(np.abs(K)), 1e-12))
    s[layout.m_columns] = max(np.max(np.abs(M)), 1e-12)
    s[np.unique(layout.c)] = max(np.max(np.abs(C)), 1e-12)
    s[np.unique(layout.k)] = max(np.max(np.abs(K)), 1e-12)
    s[layout.mu] = max(abs(mu), 1e-3 * s[layout.c[0, 0]] / s[layout.m_columns[0]])
    return s


def _with_forces(sp: Spectra, run: RunData, force) -> Spectra:
    directions, signals = force
    n = run.n_samples
    F = np.fft.rfft(np.asarray(signals, float), axis=0) / np.sqrt(n)
    k = np.rint(np.angle(sp.z) / (2 * np.pi) * n).astype(int) % n
    from dataclasses import replace as _replace
    return _replace(sp, forces=np.asarray(directions, float), F=F[k])


def _rescaled_start(layout, problem, theta0, evaluate):
    """Best overall scale of M, C, K for the start.

    Noise biases the equation-form start mostly as a common scale factor
    (the scale comes only from the small added-mass terms), and the EIV cost
    can have a local minimum near such a start: try scales first.
    """
    def scaled(f):
        t = theta0 * f
        t[layout.mu] = theta0[layout.mu]
        t[layout.p:] = theta0[layout.p:] * f
        return t

    factors = np.geomspace(0.3, 30.0, 41)
    costs = [float(r @ r) for r in evaluate([scaled(f) for f in factors])]   # (residual() catches failures)
    best = int(np.argmin(costs))
    return scaled(factors[best]) if np.isfinite(costs[best]) else theta0


#: Dense Jacobians (residuals x parameters) the fit holds at its peak: scipy's trust-region solver
#: keeps the Jacobian and a scaled working copy, and the covariance step forms one more.
_JACOBIAN_COPIES = 3


def _require_memory(spectra_list, n_theta: int, runs) -> None:
    """Refuse, before the fit starts, one whose Jacobians cannot fit in memory."""
    from momentid.core.resources import require_memory

    n_residuals = sum(2 * sp.Y.shape[0] * sp.Y.shape[1] for sp in spectra_list)
    needed = 8.0 * (_JACOBIAN_COPIES * n_residuals * n_theta + 4.0 * n_theta * n_theta)
    require_memory(needed, f"errors-in-variables fit of {n_theta} unknowns to {n_residuals} residuals "
                   f"({len(spectra_list)} runs)",
                   "use estimator 'equation' (memory independent of the record's length), or fewer "
                   f"runs ({', '.join(r.name for r in runs)}) or a shorter record")


def fit_eiv(layout: Layout, runs: Sequence[RunData], theta0: np.ndarray, *, f_max: float, sigma: dict | None = None,
            max_nfev: int = 60, forces: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
            stated: dict | None = None) -> EivFit:
    """Refine ``theta0`` by the errors-in-variables ML over ``runs``.

    Parameters
    ----------
    layout : momentid.estimation.layout.Layout
    runs : sequence of RunData
        With ``zdd`` and floor accelerations (and displacements/velocities
        where measured), uniformly sampled.
    theta0 : ndarray, shape (p,)
        Starting point (the equation-form estimate on low-passed data).
    f_max : float
        Upper edge (Hz) of the band fitted.
    sigma : dict, optional
        Known noise RMS per channel; estimated from the noise-only band otherwise.
    forces : list of (directions (d, m), signals (n, m)) per run, optional
        Extra generalised floor forces of known shape (a mechanism's
        signature); their m coefficients are appended to ``theta``.
    stated : dict, optional
        The lab's stated noise levels per channel group (see
        :func:`momentid.estimation.noise.estimate_noise`).
    """
    spectra_list = [spectra(r, layout.d, f_max, sigma=sigma, stated=stated) for r in runs]
    if forces is not None:
        spectra_list = [_with_forces(sp, r, f) for sp, r, f in zip(spectra_list, runs, forces)]
    _require_memory(spectra_list, len(theta0), runs)
    problem = _Problem(layout, spectra_list)
    with point_map(problem.residual) as evaluate:
        theta0 = _rescaled_start(layout, problem, np.asarray(theta0, float), evaluate)
    scale = _scales(layout, theta0)
    # Each iteration's Jacobian is exact and costs about one residual (momentid.estimation.eiv_jacobian),
    # where forward differences cost one residual per unknown.
    result = scipy.optimize.least_squares(
        lambda delta: problem.residual(theta0 + scale * delta), np.zeros_like(theta0),
        jac=lambda delta: problem.jacobian(theta0 + scale * delta) * scale[None, :],
        method="trf", x_scale="jac", ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=max_nfev,
    )
    theta = theta0 + scale * result.x
    r = problem.residual(theta)
    J = problem.jacobian(theta) * scale[None, :]
    dof = max(r.size - theta.size - problem.n_nuisance, 1)
    s2 = float(r @ r) / dof
    try:
        cov = np.linalg.inv(J.T @ J) * np.outer(scale, scale)
    except np.linalg.LinAlgError:
        raise IdentificationError("errors-in-variables fit: singular information matrix; the runs do not "
                                  "identify the unknowns") from None
    # With estimated noise levels s2 ~ 1; scale the covariance when it is not (a model misfit shows here).
    return EivFit(theta=theta, covariance=cov * max(s2, 1.0), cost=float(r @ r) / 2, n_residuals=r.size,
                  n_nuisance=problem.n_nuisance, nfev=int(result.nfev), f_max=f_max, scale=s2,
                  capped=result.status == 0, noise_sources=tuple(f"{sp.run}: {sp.noise_source}" for sp in spectra_list))


def fisher_information(layout: Layout, runs: Iterable[RunData], theta: ArrayLike, sigma: dict, f_max: float
                       ) -> np.ndarray:
    """Fisher information of theta for noise-free ``runs`` measured with noise ``sigma``.

    ``runs`` carry the outputs the designed experiment would produce without
    noise; ``sigma`` the noise RMS of every channel (``zdd`` included).  The
    transient terms are projected out, so the inverse is the Cramér-Rao bound
    of an estimator that, like :func:`fit_eiv`, does not know the initial state.
    """
    spectra_list = [spectra(r, layout.d, f_max, sigma=sigma) for r in runs]
    problem = _Problem(layout, spectra_list)
    J = problem.jacobian(np.asarray(theta, float))
    return J.T @ J
