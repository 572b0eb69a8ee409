"""What runs without added mass identify: modes always, K and C when the lab states its masses.

:func:`identify_modal` fits the modal model of :mod:`momentid.estimation.modal`
to every selected run at once (shared modes, per-run sensor gains and clock
offsets); :func:`identify_per_run` fits each run on its own, and
:func:`amplitude_trend` says how the first mode changes with the response
amplitude across runs (a linear rig shows no trend).

From the identified modes (frequencies ``w``, damping ratios ``zeta``, shapes
``Phi`` scaled to 1 at the top floor):

* mass-normalised: ``M^-1 K = Phi diag(w^2) Phi^-1`` and
  ``M^-1 C = Phi diag(2 zeta w) Phi^-1`` (no masses needed);
* with stated masses M: the M-orthonormal set nearest to the M-normalised
  shapes, ``Psi`` (polar decomposition of ``M^1/2 Phi``), gives the symmetric
  ``K = M^1/2 Psi diag(w^2) Psi^T M^1/2`` and ``C`` likewise, whose modes are
  exactly the identified frequencies and damping ratios.  How far the shapes
  are from M-orthogonal is reported: it checks the stated masses.

Standard errors of every derived quantity: delta method from the fit's covariance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.analytic import Modes
from momentid.core.series import Experiment, RunData
from momentid.errors import IdentificationError
from momentid.estimation.modal import ModalModel
from momentid.estimation.modal_checks import ExtraMode, check, extra_modes
from momentid.estimation.modal_select import ModeSelection, select_modes
from momentid.estimation.damping import ModeDamping, Source, resolve_damping
from momentid.estimation.noise import NoiseSource, estimate_noise, quiet_lead_in
from momentid.estimation.periodic import forced_line
from momentid.estimation.peaks import response_amplitude
from momentid.estimation.trend import AmplitudeTrend, amplitude_trend, weighted_line

__all__ = ["ModalIdentification", "ExtraMode", "AmplitudeTrend", "identify_modal", "identify_per_run",
           "amplitude_trend", "weighted_line"]

#: A residual variance factor above this says the linear model does not explain
#: the data to the noise level (standard errors are inflated by its square root).
MISFIT_NOTE = 2.0
#: Relative step of the delta method's central differences.
DELTA_STEP = 1e-6


@dataclass(frozen=True)
class ModalIdentification:
    """Result of :func:`identify_modal` (runs without added mass).

    Attributes
    ----------
    frequency, frequency_std : ndarray, shape (d,)
        Undamped natural frequencies (Hz), mode 1 first, and standard errors.
    damping_ratio, damping_ratio_std : ndarray, shape (d,)
        Modal damping ratios (1) and standard errors.
    shapes, shapes_std : ndarray, shape (d, d)
        Mode shapes, one per column, 1 at the top floor; standard errors.
    stiffness_over_mass, stiffness_over_mass_std : ndarray, shape (d, d)
        ``M^-1 K`` (1/s^2) and standard errors.
    damping_over_mass, damping_over_mass_std : ndarray, shape (d, d)
        ``M^-1 C`` (1/s) and standard errors.
    masses : tuple of float or None
        The floor masses used to scale (kg), None: results are mass-normalised.
    M, K, C, K_std, C_std : ndarray, shape (d, d), or None
        Mass (kg), stiffness (N/m), damping (N s/m) from the stated masses.
    sensor_gain, sensor_gain_std, sensor_offset, sensor_offset_std : ndarray, shape (n_runs, d)
        Each floor sensor's gain (1) and clock offset (s, positive: lags) relative to the table's.
    amplitude : ndarray, shape (n_runs,)
        RMS top-floor acceleration relative to the table after the lead-in (m/s^2).
    residual_rms : float
        RMS of the whitened residual (1: the model explains the data to the noise level).
    runs : tuple of str
    noise : tuple of str
        Per run, where its noise levels came from.
    f_max : float
        Top of the fitted band (Hz).
    nfev : int
        Model evaluations of the fit.
    notes : tuple of str
        Choices and findings.
    warnings : tuple of str
        Results the data contradict or cannot support: unstable modes, capped fits,
        poorly determined modes, suspect sensors.  Never empty without reason;
        always shown by the CLI.
    estimator : str
        ``"modal-eiv"``.
    extra_modes : tuple of ExtraMode
        Resonances in the fitted band beyond the storey modes (see
        :mod:`momentid.estimation.modal_select`): frequency, damping ratio, per-sensor residues and the
        sensors that see them.  Fitted with the storey modes so that they do not distort them.
    damping_ratio_subspace : ndarray, shape (d,)
        The storey modes' damping ratios by the subspace estimate of the same data (NaN: no pole
        stable over model orders there); the fit's are checked against them.
    damping_is_answer : ndarray of bool, shape (d,)
        False where a damping ratio is not an answer; the reason is in ``damping_refusal``.
    damping_ratio_equivalent, equivalent_std : ndarray, shape (d,)
        The linear fit's damping ratios over the whole record (the equivalent linear damping at the
        record's amplitudes) and their (white-noise) standard errors; ``damping_ratio`` is the damping
        at small amplitude (:mod:`momentid.estimation.damping`).
    damping_interval : ndarray, shape (d, 2)
        95 % intervals of ``damping_ratio``.
    damping_refusal : tuple of str
        Per mode, why its damping ratio is not an answer ('' when it is).
    damping : tuple of ModeDamping
        Per mode, how the damping answer was reached (source, law, amplitudes, degrees of freedom).
    frequency_is_answer : ndarray of bool, shape (d,)
        False where a frequency is a periodic table's forced line's, not the mode's
        (:func:`~momentid.estimation.periodic.forced_line`; the reason is among ``warnings``).
    """

    frequency: np.ndarray
    frequency_std: np.ndarray
    damping_ratio: np.ndarray
    damping_ratio_std: np.ndarray
    shapes: np.ndarray
    shapes_std: np.ndarray
    stiffness_over_mass: np.ndarray
    stiffness_over_mass_std: np.ndarray
    damping_over_mass: np.ndarray
    damping_over_mass_std: np.ndarray
    masses: tuple | None
    M: np.ndarray | None
    K: np.ndarray | None
    C: np.ndarray | None
    K_std: np.ndarray | None
    C_std: np.ndarray | None
    sensor_gain: np.ndarray
    sensor_gain_std: np.ndarray
    sensor_offset: np.ndarray
    sensor_offset_std: np.ndarray
    amplitude: np.ndarray
    residual_rms: float
    runs: tuple
    noise: tuple
    f_max: float
    nfev: int
    notes: tuple = ()
    warnings: tuple = ()
    estimator: str = "modal-eiv"
    extra_modes: tuple = ()
    damping_ratio_subspace: np.ndarray | None = None
    damping_is_answer: np.ndarray | None = None
    damping_ratio_equivalent: np.ndarray | None = None
    equivalent_std: np.ndarray | None = None
    damping_interval: np.ndarray | None = None
    damping_refusal: tuple = ()
    damping: tuple = ()
    frequency_is_answer: np.ndarray | None = None

    @property
    def storeys(self) -> int:
        """Number of storey modes ``d``."""
        return self.frequency.shape[0]

    def frequency_answered(self, i: int) -> bool:
        """Whether mode ``i``'s (0-based) frequency is an answer (:attr:`frequency_is_answer`)."""
        return self.frequency_is_answer is None or bool(self.frequency_is_answer[i])

    @property
    def linear_damping_ratio(self) -> np.ndarray:
        """The linear fit's (equivalent linear) damping ratios: what replays the record; shape (d,)."""
        return self.damping_ratio if self.damping_ratio_equivalent is None else self.damping_ratio_equivalent

    @property
    def linear_damping_ratio_std(self) -> np.ndarray:
        """Their (white-noise) standard errors, shape (d,)."""
        return self.damping_ratio_std if self.equivalent_std is None else self.equivalent_std

    def modes(self) -> Modes:
        """Frequencies, equivalent linear damping ratios and shapes as :class:`~momentid.core.analytic.Modes`:
        the linear model that replays the record (consistent with ``C``)."""
        zeta = self.linear_damping_ratio
        damped = self.frequency * np.sqrt(np.clip(1 - zeta ** 2, 0.0, None))
        return Modes(frequency=self.frequency, damping_ratio=zeta, damped_frequency=damped, shapes=self.shapes)

    def to_dict(self) -> dict:
        """JSON-friendly dict in SI units; ``frequency_hz`` and ``damping_ratio`` lists, mode 1 first."""
        def lst(x):
            return None if x is None else np.asarray(x).tolist()
        return {
            "estimator": self.estimator, "runs": list(self.runs),
            "frequency_hz": lst(self.frequency), "damping_ratio": lst(self.damping_ratio),
            "mode_shapes": lst(self.shapes),
            "std": {"frequency_hz": lst(self.frequency_std), "damping_ratio": lst(self.damping_ratio_std),
                    "mode_shapes": lst(self.shapes_std), "M^-1 K": lst(self.stiffness_over_mass_std),
                    "M^-1 C": lst(self.damping_over_mass_std), "K": lst(self.K_std), "C": lst(self.C_std),
                    "sensor_gain": lst(self.sensor_gain_std), "sensor_offset_s": lst(self.sensor_offset_std)},
            "M^-1 K": lst(self.stiffness_over_mass), "M^-1 C": lst(self.damping_over_mass),
            "masses": None if self.masses is None else list(self.masses),
            "M": lst(self.M), "K": lst(self.K), "C": lst(self.C),
            "sensor_gain": lst(self.sensor_gain), "sensor_offset_s": lst(self.sensor_offset),
            "amplitude_m_s2": lst(self.amplitude), "residual_rms": self.residual_rms,
            "noise": list(self.noise), "f_max_hz": self.f_max, "nfev": self.nfev,
            "notes": list(self.notes), "warnings": list(self.warnings),
            "extra_modes": [m.to_dict() for m in self.extra_modes],
            "damping_ratio_subspace": None if self.damping_ratio_subspace is None else
            [None if np.isnan(z) else float(z) for z in self.damping_ratio_subspace],
            "damping_is_answer": None if self.damping_is_answer is None else [bool(a) for a in self.damping_is_answer],
            "damping_ratio_equivalent": lst(self.damping_ratio_equivalent),
            "damping_interval_95": lst(self.damping_interval),
            "damping_refusal": [r or None for r in self.damping_refusal],
            "damping": [m.to_dict() for m in self.damping],
            "frequency_is_answer": None if self.frequency_is_answer is None else
            [bool(a) for a in self.frequency_is_answer],
            "units": MODAL_UNITS,
        }

    def _repr_html_(self) -> str:
        """A notebook's summary: the words of the report page's answer
        (:func:`momentid.estimation.summary_html.modal_html`)."""
        from momentid.estimation.summary_html import modal_html
        return modal_html(self)

    def table(self, warnings: bool = True) -> str:
        """Plain-text report: modes with standard errors and the subspace estimate's damping, extra
        modes, matrices, sensors, notes and (``warnings=True``) warnings.  The CLI prints the warnings
        on stderr instead, once."""
        lines = [f"runs: {', '.join(self.runs)} (no added mass: modal fit, {self.estimator})",
                 "mode  frequency (Hz)        damping at small amplitude (%)   from           equiv. linear (%)  "
                 "subspace (%)  shape (floor 1..top)"]
        independent = (np.full(self.storeys, np.nan) if self.damping_ratio_subspace is None
                       else self.damping_ratio_subspace)
        answer = np.ones(self.storeys, bool) if self.damping_is_answer is None else self.damping_is_answer
        equivalent = self.damping_ratio if self.damping_ratio_equivalent is None else self.damping_ratio_equivalent
        for i in range(self.storeys):
            shape = " ".join(f"{x:+.3f}" for x in self.shapes[:, i])
            check = "      -     " if np.isnan(independent[i]) else f"{100 * independent[i]:9.3f}   "
            std = self.damping_ratio_std[i]
            z = f"{100 * self.damping_ratio[i]:7.3f} +- {100 * std:.3f}" if np.isfinite(std) else "      -         "
            flag = "          " if answer[i] else " NOT AN ANSWER"
            source = self.damping[i].source if self.damping else "linear fit"
            f = (f"{self.frequency[i]:8.4f} +- {self.frequency_std[i]:.4f}" if self.frequency_answered(i) else
                 f"{'NOT AN ANSWER':>18}")
            lines.append(f"{i + 1:>4}  {f}  {z}{flag:<16} "
                         f"{source:<16}{100 * equivalent[i]:8.3f}          {check} {shape}")
        if self.extra_modes:
            lines.append(f"extra modes (beyond the {self.storeys} storey modes; "
                         "fitted so that they do not distort them):")
            for m in self.extra_modes:
                seen = ", ".join(m.seen_by) or "no sensor beyond 3 standard errors"
                lines.append(f"   +  {m.frequency:8.4f} +- {m.frequency_std:.4f}  {100 * m.damping_ratio:7.3f} +- "
                             f"{100 * m.damping_ratio_std:.3f}  residues {' '.join(f'{x:+.3g}' for x in m.residues)}; "
                             f"seen by {seen}")
        if self.K is not None:
            lines.append(f"masses (stated, kg): {list(self.masses)}")
            lines.append("K (N/m):\n" + _matrix(self.K, self.K_std))
            lines.append("C (N s/m):\n" + _matrix(self.C, self.C_std))
        else:
            lines.append("no masses stated: mass-normalised results")
            lines.append("M^-1 K (1/s^2):\n" + _matrix(self.stiffness_over_mass, self.stiffness_over_mass_std))
            lines.append("M^-1 C (1/s):\n" + _matrix(self.damping_over_mass, self.damping_over_mass_std))
        for r, name in enumerate(self.runs):
            gains = " ".join(f"{g:.4f}" for g in self.sensor_gain[r])
            offsets = " ".join(f"{1e3 * t:+.2f}" for t in self.sensor_offset[r])
            lines.append(f"run {name}: RMS top-floor response {self.amplitude[r]:.3g} m/s^2; floor sensors vs "
                         f"table: gain {gains}, clock offset (ms) {offsets}")
        lines.append(f"residual RMS {self.residual_rms:.3g} x noise; fitted 0-{self.f_max:.3g} Hz")
        lines += [f"note: {n}" for n in self.notes]
        if warnings:
            lines += [f"WARNING: {w}" for w in self.warnings]
        return "\n".join(lines)


def _matrix(X, S) -> str:
    return "\n".join("  " + "  ".join(f"{x:11.4g} +- {s:<9.2g}" for x, s in zip(row, srow))
                     for row, srow in zip(X, S))


def _masses(experiment: Experiment, notes: list):
    statement = experiment.statement
    if statement is not None and statement.masses is not None:
        return tuple(float(m) for m in statement.masses)
    if experiment.structure is not None:
        notes.append("masses from the recording's nominal model (no lab statement)")
        return tuple(experiment.structure.masses)
    return None


def _derived(model: ModalModel, theta, masses) -> dict:
    """Every reported quantity of the modal part of ``theta``."""
    w, z, R = model.omega(theta), model.zeta(theta), model.residues(theta)
    order = np.argsort(w)
    w, z, R = w[order], z[order], R[order]
    Phi = R.T / R[:, -1][None, :]                       # columns: mode shapes, 1 at the top floor
    Phi_inv = np.linalg.inv(Phi)
    out = {"frequency": w / (2 * np.pi), "damping_ratio": z, "shapes": Phi,
           "stiffness_over_mass": Phi @ np.diag(w ** 2) @ Phi_inv,
           "damping_over_mass": Phi @ np.diag(2 * z * w) @ Phi_inv}
    if masses is not None:
        m_half = np.sqrt(np.asarray(masses, float))
        Phi_n = Phi / np.sqrt(np.sum(masses * Phi.T ** 2, axis=1))[None, :]
        U, _, Vt = np.linalg.svd(m_half[:, None] * Phi_n)
        Psi = U @ Vt                                     # nearest orthonormal set (polar decomposition)
        S = m_half[:, None] * Psi
        out["K"] = S @ np.diag(w ** 2) @ S.T
        out["C"] = S @ np.diag(2 * z * w) @ S.T
        gram = Phi_n.T @ np.diag(masses) @ Phi_n
        out["orthogonality"] = float(np.max(np.abs(gram - np.eye(model.d))))
    return out


def _delta(model: ModalModel, theta, cov, masses) -> dict:
    """Standard errors of :func:`_derived` by central differences over the modal parameters."""
    base = _derived(model, theta, masses)
    keys = [k for k in base if k != "orthogonality"]
    n = model.n_modal
    grads = {k: [] for k in keys}
    for i in range(n):
        step = DELTA_STEP * max(abs(theta[i]), 1.0)
        tp, tm = theta.copy(), theta.copy()
        tp[i] += step
        tm[i] -= step
        up, down = _derived(model, tp, masses), _derived(model, tm, masses)
        for k in keys:
            grads[k].append(((up[k] - down[k]) / (2 * step)).ravel())
    c = cov[:n, :n]
    return {k: np.sqrt(np.clip(np.einsum("ip,ij,jp->p", np.array(g), c, np.array(g)), 0, None)).reshape(
        np.shape(base[k])) for k, g in grads.items()}


def identify_modal(experiment: Experiment, runs: Sequence[str] | None = None) -> ModalIdentification:
    """Identify modes (and K, C with stated masses) from runs without added mass.

    Parameters
    ----------
    experiment : Experiment
        Runs with ``zdd`` and ``a1..ad`` (m/s^2, absolute, one time base each);
        ``experiment.statement`` may state masses and noise levels.
    runs : sequence of str, optional
        Run names (all by default); fitted together with shared modes.

    Returns
    -------
    ModalIdentification

    Raises
    ------
    IdentificationError
        No noise source, fewer resonances than storeys, a singular fit, or a floor sensor whose gain
        the data put outside 0.5-2 of the table's.
    """
    notes: list[str] = []
    selected = _checked_runs(experiment, runs, notes)
    d = experiment.storeys
    masses = _run_masses(experiment, selected[0].added_mass, notes)
    stated = dict(experiment.statement.noise) if experiment.statement is not None else None
    with threadpool_limits(limits=1, user_api="blas"):     # small dense products: threads only add waiting
        selection = select_modes(selected, d, masses=masses, stated=stated)
    model, fit = selection.model, selection.fit
    keep = model.select_indices(selection.storey)
    storey_model = ModalModel(d, len(selected))
    theta, cov = fit.theta[keep], fit.covariance[np.ix_(keep, keep)]
    m_arr = None if masses is None else np.asarray(masses, float)
    values = _derived(storey_model, theta, m_arr)
    std = _delta(storey_model, theta, cov, m_arr)
    gain, offset, gain_std, offset_std = _sensor_estimates(storey_model, theta, cov, len(selected))
    amplitude = np.array([response_amplitude(r, d, quiet_lead_in(r)) for r in selected])
    warnings, check_notes, answer = check(selection, values, std, selected, gain, offset, masses)
    notes += _notes(fit, selected, offset, values, len(selected)) + list(selection.notes) + list(fit.notes)
    notes += check_notes
    equivalent, equivalent_std = values["damping_ratio"].copy(), std["damping_ratio"].copy()
    damping = _small_amplitude_damping(selected, selection, stated, values["frequency"], warnings, notes)
    answer = answer & np.array([m.is_answer for m in damping])
    # where the mode rings free at small amplitude: from decays good enough to answer its damping (decays too
    # few or too short to, on the simulated set, read 2-10 % off the mode)
    rings = [m.frequency if m.source in (Source.FREE_DECAY, Source.POOLED) and m.cycles > 0 and m.is_answer else None
             for m in damping]
    forced = [forced_line(selected, float(f), r, float(s))
              for f, r, s in zip(values["frequency"], rings, std["frequency"])]
    warnings += [w for w in forced if w]
    if selection.extra:
        notes.append(f"the data hold {model.n} resonances in 0-{fit.f_max:.3g} Hz, {len(selection.extra)} more "
                     f"than the {d} storeys: the extra ones are fitted with the storey modes and reported apart")
    has_k = masses is not None
    return ModalIdentification(
        frequency=values["frequency"], frequency_std=std["frequency"],
        damping_ratio=np.array([m.damping_ratio for m in damping]),
        damping_ratio_std=np.array([m.damping_ratio_std for m in damping]),
        shapes=values["shapes"], shapes_std=std["shapes"],
        stiffness_over_mass=values["stiffness_over_mass"], stiffness_over_mass_std=std["stiffness_over_mass"],
        damping_over_mass=values["damping_over_mass"], damping_over_mass_std=std["damping_over_mass"],
        masses=masses, M=np.diag(masses) if has_k else None, K=values.get("K"), C=values.get("C"),
        K_std=std.get("K"), C_std=std.get("C"),
        sensor_gain=gain, sensor_gain_std=gain_std, sensor_offset=offset, sensor_offset_std=offset_std,
        amplitude=amplitude, residual_rms=float(np.sqrt(fit.scale)), runs=tuple(r.name for r in selected),
        noise=fit.noise_sources, f_max=fit.f_max, nfev=fit.nfev, notes=tuple(notes), warnings=tuple(warnings),
        extra_modes=extra_modes(selection),
        damping_ratio_subspace=selection.independent[list(selection.storey)], damping_is_answer=answer,
        damping_ratio_equivalent=equivalent, equivalent_std=equivalent_std,
        damping_interval=np.array([m.interval for m in damping]),
        damping_refusal=tuple(m.refusal for m in damping), damping=damping,
        frequency_is_answer=np.array([not w for w in forced]),
    )


def _checked_runs(experiment: Experiment, runs: Sequence[str] | None, notes: list[str]) -> tuple[RunData, ...]:
    """The runs to fit, each checked (its repairs appended to ``notes``); refused when there are none or
    when they carry different added masses."""
    from momentid.io.run_checks import check_run

    selected = experiment.select(runs)
    if not selected:
        raise IdentificationError(f"{experiment.source}: no runs to identify from")
    checked = []
    for run in selected:
        run, repairs = check_run(run, experiment.source)
        notes.extend(repairs)
        checked.append(run)
    selected = tuple(checked)
    added = selected[0].added_mass
    if any(not np.array_equal(r.added_mass, added) for r in selected):
        raise IdentificationError(
            f"{experiment.source}: runs {[r.name for r in selected]} carry different added masses: one modal "
            f"model fits runs of one structure; fit them one by one (--per-run)")
    return selected


def _run_masses(experiment: Experiment, added: np.ndarray, notes: list[str]) -> tuple[float, ...] | None:
    """The floor masses (kg) the runs carry: the stated ones plus the runs' ``added`` mass (None unstated)."""
    masses = _masses(experiment, notes)
    if masses is not None and np.any(added):
        masses = tuple(float(m) for m in np.asarray(masses) + added)
        notes.append(f"masses include the run's added mass: {list(masses)} kg")
    return masses


def _sensor_estimates(model: ModalModel, theta: np.ndarray, cov: np.ndarray, n_runs: int) -> tuple[np.ndarray, ...]:
    """Per run and floor sensor: gain, clock offset (s) and their standard errors, each ``(n_runs, d)``."""
    d = model.d
    sd_all = np.sqrt(np.clip(np.diag(cov), 0, None))
    gain = np.array([model.sensors(theta, r)[0] for r in range(n_runs)])
    offset = np.array([model.sensors(theta, r)[1] for r in range(n_runs)])
    slices = [model.sensor_slice(r) for r in range(n_runs)]
    gain_std = np.array([gain[r] * sd_all[s.start:s.start + d] for r, s in enumerate(slices)])
    offset_std = np.array([sd_all[s.start + d:s.stop] for s in slices])
    return gain, offset, gain_std, offset_std


def _small_amplitude_damping(selected: tuple[RunData, ...], selection: ModeSelection, stated: dict | None,
                             frequency: np.ndarray, warnings: list[str], notes: list[str]) -> tuple[ModeDamping, ...]:
    """Each storey mode's damping at small amplitude, in ascending frequency order; what each says (or why
    it is no answer) appended to ``notes`` (``warnings``)."""
    fit, model = selection.fit, selection.model
    estimates = [estimate_noise(r, f_max=fit.f_max, stated=stated) for r in selected]
    scatter = any(e.source is NoiseSource.LOCAL_POLYNOMIAL for e in estimates)
    with threadpool_limits(limits=1, user_api="blas"):
        damping = resolve_damping(selected, selection, sigma=[e.sigma for e in estimates], scatter=scatter)
    order = np.argsort([model.omega(fit.theta)[i] for i in selection.storey])     # storey order -> ascending
    damping = tuple(damping[k] for k in order)
    for i, m in enumerate(damping):
        if not m.is_answer:
            warnings.append(f"mode {i + 1} at {frequency[i]:.4g} Hz: damping at small amplitude NOT AN "
                            f"ANSWER: {m.refusal}; the equivalent linear damping over the record is "
                            f"{100 * m.equivalent:.3g} %")
        else:
            notes.append(f"mode {i + 1} at {frequency[i]:.4g} Hz: {m.words()}")
    notes.append("C and M^-1 C hold the equivalent linear damping of the record (what replays it); the damping "
                 "ratios are the structure's at small amplitude")
    return damping


def _notes(fit, runs, offset, values, n_runs) -> list[str]:
    out = [f"noise levels: {'; '.join(fit.noise_sources)}",
           "damping model: classical modal damping (one ratio per mode); C from the modes"]
    if fit.scale > MISFIT_NOTE:
        out.append(f"the linear model explains the data to {np.sqrt(fit.scale):.3g} x the noise level only "
                   f"(a rig that is not quite linear, or more modes than it fits): standard "
                   f"errors are inflated by that factor" + ("; try --per-run" if n_runs > 1 else ""))
    for r, run in enumerate(runs):
        h = 1.0 / run.sample_rate
        late = np.flatnonzero(np.abs(offset[r]) > 0.5 * h)
        for j in late:
            out.append(f"run {run.name!r}: sensor a{j + 1} is {1e3 * offset[r][j]:+.2f} ms "
                       f"({offset[r][j] / h:+.2f} samples) off the table sensor's clock (fitted and removed)")
    return out


def identify_per_run(experiment: Experiment, runs: Sequence[str] | None = None) -> tuple[ModalIdentification, ...]:
    """:func:`identify_modal` on every run on its own, on the machine's cores (forked workers, see
    :func:`momentid.core.processes.run_forked`); tuple of results in run order."""
    from momentid.core.processes import run_forked

    names = [r.name for r in experiment.select(runs)]
    return tuple(run_forked(lambda name: identify_modal(experiment, runs=[name]), names))


#: The unit of each quantity of :meth:`ModalIdentification.to_dict` (SI; their standard errors in
#: ``std`` share them).
MODAL_UNITS = {"frequency_hz": "Hz", "damping_ratio": "1 (fraction of critical)", "mode_shapes": "1 (floor 1..top)",
               "M": "kg", "K": "N/m", "C": "N s/m", "masses": "kg", "M^-1 K": "1/s^2", "M^-1 C": "1/s",
               "sensor_gain": "1 (x the table sensor)", "sensor_offset_s": "s", "amplitude_m_s2": "m/s^2",
               "residual_rms": "m/s^2", "f_max_hz": "Hz"}
