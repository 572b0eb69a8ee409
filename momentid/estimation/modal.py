"""Identification without added mass: what table and floor accelerometers identify.

With no run that adds mass, the table-to-floor transfer ``z'' -> a`` depends on ``M^-1 K`` and
``M^-1 C`` only: frequencies, damping ratios and mode shapes are identified, M, C and K only up to a
common scale.  Stated floor masses fix that scale (K, C in SI units, see
:mod:`momentid.estimation.scaled`); without them the results are mass-normalised.

Model (:mod:`momentid.estimation.modal_model`): classical normal modes, each with its own frequency,
damping ratio and residues (no shear-building constraint: a real frame's floors rotate and its
columns bend, and forcing it into d storey springs moves the frequencies by percents), per-run floor
sensor gains and clock offsets, the band-limited response at each DFT bin and the modes' sampled free
decays as the transient.  The damping ratios are fitted without sign constraint so that an unstable
mode shows as a negative ratio (and is warned about), never hidden by the parameterisation.

Estimator: the frequency-domain errors-in-variables likelihood (noise on table and floors) over the
bins up to :data:`FIT_BAND_FACTOR` x the top resonance, below :data:`NYQUIST_FRACTION` x the sample
rate, minimised by a bounded trust-region method with the analytic Jacobian.  What keeps it from
degenerate answers:

* **starts**: the poles of the subspace estimate (:mod:`momentid.estimation.subspace`) and the
  picked spectral peaks, each completed by the residues and gains that fit best at those poles (a
  linear least-squares problem); the fit starts from the one the likelihood prefers, and a fit that
  reaches :data:`MAX_NFEV` is restarted from the others before it is reported as capped;
* **bounds**: gains within 0.5-2, clock offsets within 1.5 samples, damping ratios within
  +-:data:`~momentid.estimation.modal_model.MAX_ABS_DAMPING`;
* **identifiable or fixed**: a gain the data determine no better than :data:`GAIN_STD_LIMIT`, or a
  clock offset no better than :data:`OFFSET_STD_LIMIT` samples, trades with the residues and the
  damping instead of being measured: it is fixed (gain 1, offset 0: a calibrated sensor on the table's
  clock) and the fit repeated, with a note; so is a clock offset that ends at its bound when fixing it at 0
  costs no more than chance allows (:data:`OFFSET_SIGNIFICANCE`; a misfit pulls an offset that nothing
  determines there), else the run is refused by the checks.

Covariance: the Jacobian of the whitened residual at the optimum, scaled by the residual variance
factor when the model explains the data less well than the noise allows.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike
import scipy.linalg
import scipy.optimize
import scipy.stats

from momentid.core.analytic import shear_stiffness
from momentid.core.series import RunData
from momentid.errors import IdentificationError
from momentid.estimation.eiv import Spectra, spectra
from momentid.estimation.modal_model import OFFSET_BOUND, Hold, Likelihood, ModalModel, mode_response

__all__ = ["ModalModel", "ModalFit", "fit_modal", "fit_band", "modal_spectra", "linear_start", "refine",
           "with_fixed_sensors", "f_test", "at_offset_bound", "OFFSET_SIGNIFICANCE", "BOUND_TOLERANCE",
           "FIT_BAND_FACTOR", "START_DAMPING", "NYQUIST_FRACTION", "MAX_NFEV"]

#: The fit uses DFT bins up to this multiple of the highest resonance (the resonance's flanks carry
#: its damping), capped by :data:`NYQUIST_FRACTION`.
FIT_BAND_FACTOR = 1.5
#: Highest fitted frequency as a fraction of the sample rate: below the sensors' anti-alias roll-off.
NYQUIST_FRACTION = 0.42
#: Damping ratio a picked spectral peak starts from: wider than a real structure's, so that a start a
#: few half-power bandwidths off the peak still sees its slope.
START_DAMPING = 0.02
#: Evaluations one fit may use; reaching it is a capped fit (restarted from the other starts).
MAX_NFEV = 200
#: Convergence tolerances of the trust-region fit: a relative cost change of 1e-7 on a cost of ~1e4-1e5
#: whitened residuals is ~1e-3, far below the change of 1 that a one-standard-error step makes.
FTOL, XTOL, GTOL = 1e-7, 1e-8, 1e-8
#: A gain whose standard error exceeds this is not measured by the data: it is fixed at 1.
GAIN_STD_LIMIT = 0.05
#: A clock offset that ends at the fit's bound (:data:`~momentid.estimation.modal_model.OFFSET_BOUND` samples)
#: is fixed at 0 and the fit repeated; the data determine it, and the run is refused, when fixing it raises
#: the cost beyond this p-value of the F-test (a misfit pulls an offset that nothing determines to the bound:
#: a record that mostly rings free, whose transients read no clock offset).
OFFSET_SIGNIFICANCE = 1e-3
#: "At a bound": within this fraction of it (log gain, or offset).
BOUND_TOLERANCE = 1e-3
#: A clock offset whose standard error exceeds this many samples is fixed at 0.
OFFSET_STD_LIMIT = 0.5
#: Clock offsets tried by :func:`linear_start` over the fit's bounds (a quarter of a sample apart).
START_OFFSETS = 13
#: A start's gain outside this range (the linear fit at fixed poles) is replaced by 1.
START_GAIN_RANGE = (0.7, 1.4)


@dataclass(frozen=True)
class ModalFit:
    """Raw result of :func:`fit_modal` / :func:`refine` (see :class:`momentid.estimation.scaled.ModalIdentification`).

    Attributes
    ----------
    theta : ndarray, shape (p,)
    covariance : ndarray, shape (p, p)
        Scaled by ``max(scale, 1)``; zero rows and columns for fixed parameters.
    scale : float
        Residual variance factor (1: the model explains the data to the noise level).
    n_residuals : int
    nfev : int
        Model evaluations over every start and restart.
    capped : bool
        Every start tried stopped at :data:`MAX_NFEV`, not at convergence.
    f_max : float
        Top of the fitted band (Hz).
    noise_sources : tuple of str
        Per run: where its noise levels came from.
    cost : float
        Sum of squared whitened residuals.
    free : ndarray of bool, shape (p,)
        Parameters fitted (the others fixed).
    n_nuisance : int
        Transient terms projected out.
    hold : str
        The :class:`~momentid.estimation.modal_model.Hold` of the response.
    notes : tuple of str
        Starts, restarts and fixed sensor parameters, in words.
    """

    theta: np.ndarray
    covariance: np.ndarray
    scale: float
    n_residuals: int
    nfev: int
    capped: bool
    f_max: float
    noise_sources: tuple
    cost: float = 0.0
    free: np.ndarray | None = None
    notes: tuple = ()

    n_nuisance: int = 0
    hold: str = Hold.BAND_LIMITED.value

    @property
    def dof(self) -> int:
        """Residual degrees of freedom: residuals - fitted parameters - transient terms."""
        free = self.theta.size if self.free is None else int(np.count_nonzero(self.free))
        return max(self.n_residuals - free - self.n_nuisance, 1)


def fit_band(frequency_hz: ArrayLike, sample_rate: float) -> float:
    """Top of the fitted band (Hz) for resonances ``frequency_hz``."""
    return float(min(FIT_BAND_FACTOR * float(np.max(frequency_hz)), NYQUIST_FRACTION * sample_rate))


def modal_spectra(runs: Iterable[RunData], d: int, f_max: float, stated: dict | None = None) -> list[Spectra]:
    """The DFT bins of every run up to ``f_max`` with their noise levels (floor accelerations only)."""
    return [spectra(r, d, f_max, stated=stated, groups=["a"]) for r in runs]


def _basis(w_bins, zinv, omega, zeta, h, hold: Hold):
    """``H`` (m, n) and the transient basis (m, n, 2) at the bins."""
    H, _ = mode_response(hold, w_bins, h, omega, zeta)
    p = np.exp(omega * (-zeta + 1j * np.sqrt(1 - np.minimum(zeta ** 2, 0.99))) * h)
    A, Ab = 1 / (1 - p * zinv[:, None]), 1 / (1 - np.conj(p) * zinv[:, None])
    return H, np.stack([A + Ab, 1j * (A - Ab)], axis=2)


def linear_start(model: ModalModel, spectra_list: Sequence[Spectra], omega: ArrayLike, zeta: ArrayLike,
                 hold: Hold = Hold.BAND_LIMITED) -> np.ndarray:
    """theta with the given poles (``omega`` rad/s and ``zeta``, each (n,)) and the residues, gains and clock
    offsets that fit best at them.

    At fixed poles and clock offsets the response ``g_j (1 - sum_i R_ij H_i)`` is linear in
    ``c_j = g_j`` and ``b_ij = g_j R_ij``, and so is the transient: one least-squares problem per floor
    and run, solved for each clock offset of a grid over the bounds (:data:`START_OFFSETS` points; a
    third of a sample is a radian at 40 % of the sample rate, which no residue can absorb) and kept at
    the best.  Residues are averaged over runs; a gain outside :data:`START_GAIN_RANGE` starts at 1.
    """
    omega, zeta = np.asarray(omega, float), np.asarray(zeta, float)
    n, d = model.n, model.d
    residues, gains, offsets = [], np.ones((model.n_runs, d)), np.zeros((model.n_runs, d))
    for r, sp in enumerate(spectra_list):
        w_bins = 2 * np.pi * sp.freq
        H, basis = _basis(w_bins, np.conj(sp.z), omega, zeta, sp.h, hold)
        X = np.hstack([sp.U[:, None], -H * sp.U[:, None], basis.reshape(basis.shape[0], 2 * n)])
        A = np.vstack([X.real, X.imag])
        pinv = np.linalg.pinv(A)
        grid = np.linspace(-OFFSET_BOUND, OFFSET_BOUND, START_OFFSETS) * sp.h
        best = np.full(d, np.inf)
        coef = np.zeros((A.shape[1], d))
        for tau in grid:
            Y = sp.Y * np.exp(1j * w_bins * tau)[:, None]                  # the delay undone
            b = np.vstack([Y.real, Y.imag])
            c_tau = pinv @ b
            sse = np.sum((b - A @ c_tau) ** 2, axis=0)
            better = sse < best
            best[better], offsets[r, better], coef[:, better] = sse[better], tau, c_tau[:, better]
        c = coef[0]
        good = (c > START_GAIN_RANGE[0]) & (c < START_GAIN_RANGE[1])
        gains[r] = np.where(good, c, 1.0)
        residues.append(coef[1:1 + n] / np.where(good, c, 1.0)[None, :])
    return model.pack(omega, zeta, np.mean(residues, axis=0), gains=gains, offsets=offsets)


def shear_start(model: ModalModel, frequency_hz: ArrayLike, masses: ArrayLike | None = None) -> np.ndarray:
    """theta of a shear building with the given ``d`` frequencies, :data:`START_DAMPING`, ideal sensors."""
    f = np.sort(np.asarray(frequency_hz, float))
    m = np.ones(model.d) if masses is None else np.asarray(masses, float)
    M = np.diag(m)
    target = np.log(2 * np.pi * f)

    def shear(logk):
        w2, phi = scipy.linalg.eigh(shear_stiffness(np.exp(logk)), M)
        return np.sqrt(np.clip(w2, 1e-24, None)), phi

    logk0 = np.full(model.d, np.log(np.mean(m)) + 2 * target[0])
    logk = scipy.optimize.least_squares(lambda lk: np.log(shear(lk)[0]) - target, logk0).x
    _, phi = shear(logk)
    gamma = phi.T @ M @ np.ones(model.d)
    return model.pack(np.exp(target), np.full(model.d, START_DAMPING), gamma[:, None] * phi.T)


@dataclass
class _Outcome:
    theta: np.ndarray
    cost: float
    nfev: int
    capped: bool


def _solve(lik: Likelihood, theta0, lo, hi, max_nfev: int) -> _Outcome:
    free = lik.free
    span = hi[free] - lo[free]
    inset = np.where(np.isfinite(span), 1e-6 * np.where(np.isfinite(span), span, 0.0), 0.0)
    x0 = np.clip(theta0[free], lo[free] + inset, hi[free] - inset)
    try:
        result = scipy.optimize.least_squares(
            lik.residual, x0, jac=lik.jacobian, bounds=(lo[free], hi[free]), method="trf", x_scale="jac",
            ftol=FTOL, xtol=XTOL, gtol=GTOL, max_nfev=max_nfev)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return _Outcome(theta0, np.inf, max_nfev, True)
    return _Outcome(lik.full(result.x), float(2 * result.cost), int(result.nfev), result.status == 0)


def refine(model: ModalModel, spectra_list: Sequence[Spectra], starts: Iterable[tuple[str, np.ndarray]], *,
           sample_rates: Sequence[float], f_max: float, free: np.ndarray | None = None, fix_nuisance: bool = True,
           hold: Hold = Hold.BAND_LIMITED, frequency_bounds: dict[int, tuple[float, float]] | None = None
           ) -> ModalFit:
    """Fit ``model`` from the best of ``starts``, restarting from the others when capped.

    Parameters
    ----------
    model : ModalModel
    spectra_list : sequence of Spectra
        From :func:`modal_spectra`, one per run.
    starts : sequence of (str, ndarray)
        Named starting parameter vectors, shape (p,).
    sample_rates : sequence of float
        Per run (Hz): the clock-offset bounds.
    f_max : float
        Top of the fitted band (Hz).
    free : ndarray of bool, optional
        Parameters fitted (all by default).
    fix_nuisance : bool
        Fix the sensor gains and clock offsets the data do not determine, then fit again.
    hold : Hold
        How the table acceleration behaves between samples.
    frequency_bounds : dict of int to (float, float), optional
        Per mode, a narrower frequency range (Hz) than the model's (a mode tried near a candidate).

    Raises
    ------
    IdentificationError
        The information matrix is singular (a mode the table never excites).
    """
    lo, hi = model.bounds(sample_rates)
    for i, (f_lo, f_hi) in (frequency_bounds or {}).items():
        lo[i], hi[i] = np.log(2 * np.pi * f_lo), np.log(2 * np.pi * f_hi)
    free = np.ones(model.p, bool) if free is None else np.asarray(free, bool).copy()
    lik = Likelihood(model, spectra_list, free=free, hold=hold)
    ranked = sorted(starts, key=lambda s: _cost(lik, s[1]))
    nfev, notes, best, best_name = 0, [], None, ""
    for k, (name, theta0) in enumerate(ranked):
        lik.base = np.asarray(theta0, float).copy()
        out = _solve(lik, lik.base, lo, hi, MAX_NFEV)
        nfev += out.nfev
        if best is None or (best.capped and not out.capped) or (out.capped == best.capped and out.cost < best.cost):
            best, best_name = out, name
        if not out.capped:
            if k:
                notes.append(f"the fit from the {ranked[0][0]} start reached its evaluation cap ({MAX_NFEV}); "
                             f"restarted from the {name} start, which converged")
            break
    fit = _finish(model, lik, best, spectra_list, f_max, nfev, tuple(notes) + (f"started from the {best_name}",))
    if not fix_nuisance:
        return fit
    names = [sp.run for sp in spectra_list]
    again = dict(sample_rates=sample_rates, f_max=f_max, fix_nuisance=False, hold=hold,
                 frequency_bounds=frequency_bounds)
    fixed, why = _unidentified(model, fit, sample_rates, names)
    if fixed.any():
        refit = refine(model, spectra_list, [("previous fit", with_fixed_sensors(model, fit.theta, fixed))],
                       free=free & ~fixed, **again)
        fit = replace(refit, nfev=refit.nfev + fit.nfev, notes=fit.notes + tuple(why))
    at = _offsets_at_bound(model, fit, sample_rates)
    if not at.any():
        return fit
    refit = refine(model, spectra_list, [("offsets at the bound fixed", with_fixed_sensors(model, fit.theta, at))],
                   free=fit.free & ~at, **again)
    F, p = f_test(refit.cost, fit.cost, int(at.sum()), fit.dof)
    if p < OFFSET_SIGNIFICANCE:
        return fit            # the data put the offset at the bound: refused by the checks, with the reason
    note = (f"the clock offset(s) {_offset_names(model, at, names)} reached the fit's bound of {OFFSET_BOUND:g} "
            f"samples, yet fixed at 0 the fit is no worse beyond chance (F = {F:.3g}, p = {p:.2g}): the data do not "
            f"determine them (a free decay reads no clock offset): fixed at 0")
    return replace(refit, nfev=refit.nfev + fit.nfev, notes=fit.notes + (note,))


def at_offset_bound(offset: ArrayLike, sample_rate: float) -> np.ndarray:
    """Which clock offsets (s) sit at the fit's bound of :data:`~momentid.estimation.modal_model.OFFSET_BOUND`
    samples, within :data:`BOUND_TOLERANCE` of it.

    Parameters
    ----------
    offset : array_like, shape (d,)
        One run's floor-sensor clock offsets (s).
    sample_rate : float
        The run's rate (Hz).

    Returns
    -------
    ndarray of bool, shape (d,)
    """
    limit = OFFSET_BOUND / sample_rate
    return np.abs(np.abs(np.asarray(offset, float)) - limit) < BOUND_TOLERANCE * limit


def _offsets_at_bound(model: ModalModel, fit: ModalFit, sample_rates) -> np.ndarray:
    """Mask over theta of the free clock offsets at the fit's bound (:func:`at_offset_bound`)."""
    at = np.zeros(model.p, bool)
    for r, fs in enumerate(sample_rates):
        s = model.sensor_slice(r)
        t = np.arange(s.start + model.d, s.stop)
        at[t] = fit.free[t] & at_offset_bound(fit.theta[t], fs)
    return at


def _offset_names(model: ModalModel, mask: np.ndarray, names) -> str:
    """``run 'name': a1, a3; ...`` for the clock offsets in ``mask``."""
    out = []
    for r, name in enumerate(names):
        s = model.sensor_slice(r)
        j = np.flatnonzero(mask[s.start + model.d:s.stop])
        if j.size:
            out.append(f"of run {name!r}: {', '.join(f'a{k + 1}' for k in j)}")
    return "; ".join(out)


def f_test(cost_small: float, cost_big: float, extra_parameters: int, dof_big: int) -> tuple[float, float]:
    """F statistic and p-value of a nested model's cost decrease, against the larger model's residual
    variance (which absorbs a misfit beyond the noise level as well as the noise).

    Parameters
    ----------
    cost_small, cost_big : float
        Sums of squared whitened residuals of the nested (fewer parameters) and the larger fit.
    extra_parameters : int
        Parameters the larger fit frees.
    dof_big : int
        The larger fit's residual degrees of freedom.

    Returns
    -------
    F, p : float
    """
    F = ((cost_small - cost_big) / extra_parameters) / (cost_big / dof_big)
    return float(F), float(scipy.stats.f.sf(F, extra_parameters, dof_big))


def with_fixed_sensors(model: ModalModel, theta: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """``theta`` with the ``fixed`` gains at 1 and clock offsets at 0 (the start of a refit without them).

    A gain the data do not determine trades with its floor's residues (a record that is mostly free
    decay determines only their product ``g_j R_ij``): where floor j's gain is fixed in every run, its
    residues take the gains' geometric mean, so the refit starts where the data put the modes' shapes.

    Parameters
    ----------
    model : ModalModel
    theta : ndarray, shape (p,)
    fixed : ndarray of bool, shape (p,)
        The sensor parameters to fix (others ignored).

    Returns
    -------
    ndarray, shape (p,)
    """
    theta = np.asarray(theta, float).copy()
    log_g = np.array([theta[model.sensor_slice(r)][:model.d] for r in range(model.n_runs)])     # (runs, d)
    gain_fixed = np.array([fixed[model.sensor_slice(r)][:model.d] for r in range(model.n_runs)])
    scale = np.where(gain_fixed.all(axis=0), np.exp(log_g.mean(axis=0)), 1.0)                  # (d,)
    theta[model.residue_slice] = (model.residues(theta) * scale[None, :]).ravel()
    quad = slice(model.residue_slice.stop, model.n_modal)
    theta[quad] = (theta[quad].reshape(-1, model.d) * scale[None, :]).ravel()
    for r in range(model.n_runs):
        s = model.sensor_slice(r)
        theta[s.start:s.start + model.d][fixed[s.start:s.start + model.d]] = 0.0     # log g = 0
        theta[s.start + model.d:s.stop][fixed[s.start + model.d:s.stop]] = 0.0       # tau = 0
    return theta


def _cost(lik: Likelihood, theta) -> float:
    lik.base = np.asarray(theta, float).copy()
    try:
        r = lik.residual(theta[lik.free])
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return np.inf
    return float(r @ r) if np.all(np.isfinite(r)) else np.inf


def _finish(model, lik: Likelihood, out: _Outcome, spectra_list, f_max, nfev, notes) -> ModalFit:
    lik.base = out.theta.copy()
    x = out.theta[lik.free]
    r, J = lik.residual(x), lik.jacobian(x)
    dof = max(r.size - int(lik.free.sum()) - lik.n_nuisance, 1)
    s2 = float(r @ r) / dof
    cov = np.zeros((model.p, model.p))
    try:
        info = J.T @ J
        cov[np.ix_(lik.free, lik.free)] = np.linalg.inv(info) * max(s2, 1.0)
    except np.linalg.LinAlgError:
        raise IdentificationError(
            f"runs {[sp.run for sp in spectra_list]}: singular information matrix: the runs do not identify "
            f"the {int(lik.free.sum())} parameters of {model.n} modes (a mode the table never excites?)") from None
    fit = ModalFit(theta=out.theta, covariance=cov, scale=s2, n_residuals=r.size, nfev=nfev, capped=out.capped,
                   f_max=f_max, noise_sources=tuple(f"{sp.run}: {sp.noise_source}" for sp in spectra_list),
                   cost=float(r @ r), free=lik.free.copy(), notes=notes, n_nuisance=lik.n_nuisance,
                   hold=lik.hold.value)
    return fit


def _unidentified(model: ModalModel, fit: ModalFit, sample_rates, names):
    """Sensor parameters the data do not determine (standard error above :data:`GAIN_STD_LIMIT` or
    :data:`OFFSET_STD_LIMIT` samples): mask over theta, and a note per run."""
    sd = np.sqrt(np.clip(np.diag(fit.covariance), 0, None))
    fixed = np.zeros(model.p, bool)
    notes = []
    for r, (fs, run) in enumerate(zip(sample_rates, names)):
        s = model.sensor_slice(r)
        g, t = np.arange(s.start, s.start + model.d), np.arange(s.start + model.d, s.stop)
        weak_g = fit.free[g] & (sd[g] > GAIN_STD_LIMIT)
        weak_t = fit.free[t] & (sd[t] * fs > OFFSET_STD_LIMIT)
        fixed[g[weak_g]] = True
        fixed[t[weak_t]] = True
        if weak_g.any():
            weak = ", ".join(f"a{j + 1}" for j in np.flatnonzero(weak_g))
            notes.append(f"run {run!r}: the gain of floor sensor(s) {weak} "
                         f"is not determined by the data (standard error above {GAIN_STD_LIMIT:.0%}): fixed at 1")
        if weak_t.any():
            notes.append(f"run {run!r}: the clock offset of floor sensor(s) "
                         f"{', '.join(f'a{j + 1}' for j in np.flatnonzero(weak_t))} is not determined by the data "
                         f"(standard error above {OFFSET_STD_LIMIT:g} sample): fixed at 0")
    return fixed, notes


def fit_modal(model: ModalModel, runs: Sequence[RunData], frequency_hz: ArrayLike, *, masses: ArrayLike | None = None,
              stated: dict | None = None, hold: Hold = Hold.FIRST_ORDER) -> ModalFit:
    """Fit ``model`` (``d`` modes) to ``runs`` from resonances near ``frequency_hz`` (Hz).

    Starts: the picked resonances (:data:`START_DAMPING`), and the subspace estimate's poles nearest
    to them when it finds all ``d``; each completed by :func:`linear_start`.  See :func:`refine`.
    The first-order hold by default: the diagnosis replays this fit by an exact first-order-hold
    simulation (:mod:`momentid.diagnosis.modal.check`), which it must match; ``identify`` uses
    :func:`momentid.estimation.modal_select.select_modes` and the band-limited response.

    Parameters
    ----------
    model : ModalModel
    runs : sequence of RunData
        ``zdd`` and ``a1..ad``, uniformly sampled.
    frequency_hz : array_like, shape (n,)
        Starting resonances (see :func:`momentid.estimation.peaks.pick_resonances`).
    masses : array_like, shape (d,), optional
        Stated floor masses (kg): shape the shear-building start only.
    stated : dict, optional
        Stated noise levels per channel group.
    hold : Hold
        How the table acceleration behaves between samples.
    """
    from momentid.estimation.subspace import stable_poles

    fs = min(r.sample_rate for r in runs)
    f_max = fit_band(frequency_hz, fs)
    spectra_list = modal_spectra(runs, model.d, f_max, stated)
    f0 = np.sort(np.asarray(frequency_hz, float))
    starts = [("picked peaks",
               linear_start(model, spectra_list, 2 * np.pi * f0, np.full(model.n, START_DAMPING), hold))]
    if model.n == model.d:
        starts.append(("shear building at the picked peaks", shear_start(model, f0, masses)))
    longest = max(runs, key=lambda r: r.n_samples)
    poles = stable_poles(longest["zdd"], longest.group("a", model.d), 1.0 / longest.sample_rate, model.n, f_max)
    if len(poles) >= model.n:
        pf = np.array([p.frequency for p in poles])
        pick = [int(np.argmin(np.abs(pf / f - 1))) for f in f0]
        if len(set(pick)) == model.n:
            starts.append(("subspace poles", linear_start(model, spectra_list, 2 * np.pi * pf[pick],
                                                          np.array([poles[k].start_damping for k in pick]), hold)))
    return refine(model, spectra_list, starts, sample_rates=[r.sample_rate for r in runs], f_max=f_max, hold=hold)
