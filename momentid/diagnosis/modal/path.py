"""Diagnosis of recordings without added mass: a held-out check of the modal model and a verdict.

Its result is the :class:`~momentid.diagnosis.result.Diagnosis` of every recording, with a
:class:`~momentid.diagnosis.modal.words.ModalEvidence`, which words it.

:func:`diagnose_modal` is what :func:`momentid.diagnosis.dispatch.diagnose` runs when no run adds
mass (real labs: accelerometers only, no added-mass runs).  Stages:

1. **Hold-out**: the run the user names, else the last run of the recording (as on the added-mass
   path); the others train.  With a single run there is nothing to hold out: it is checked in-sample
   and the report says so.
2. **Linear model**: the modal model fitted on each training run
   (:func:`~momentid.diagnosis.modal.check.fit_runs`) and pooled into one amplitude-independent model
   (:func:`~momentid.diagnosis.modal.check.pooled`: weighted mean modes, mean residues; a joint fit of
   runs whose modes differ lets the sensor gains absorb the difference, 15 % on a simulated rig), replayed on the
   held-out run's measured table acceleration with the training runs' mean sensor gains and clock offsets:
   ``nrmse_before``.
3. **Noise baseline**: what sensor noise alone leaves on the held-out run
   (:func:`~momentid.diagnosis.modal.check.noise_nrmse`; levels from the lab's statement, the quiet
   lead-in or a high band, valid at any rate).
4. **Amplitude dependence** (the candidate the data can test): from the same per-run fits, each mode's
   frequency and damping ratio regressed on the run's response amplitude; the held-out run's modes
   predicted at *its* amplitude (measured: the RMS top-floor acceleration relative to the table, the
   only use of the held-out run's outputs), residues and sensors as in stage 2: ``nrmse_after``.
5. **Verdict**: ``none`` when the linear model is within :data:`~momentid.diagnosis.thresholds.EXCESS`
   x noise; ``amplitude_dependence`` when the candidate removes at least
   :data:`~momentid.diagnosis.thresholds.EXPLAINED` of the held-out misfit above noise; otherwise
   ``unexplained``, located on the floor sensor and the modal band that carry the held-out misfit.
   Sensor clock offsets beyond :data:`LATE_SAMPLES` of a sample in every run are findings;
   rocking/out-of-plane motion is a stated limit (the recording holds the shaking axis only).
6. **Open search** (when the verdict is not ``none`` and a run is held out): a nonlinear restoring law
   on one mode (:mod:`~momentid.diagnosis.modal.open_search`), reported as ``discovered`` with whether it
   beats the linear model on the held-out run; the verdict does not change.
"""

from __future__ import annotations


import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.series import Experiment
from momentid.diagnosis.modal import check as mc
from momentid.diagnosis.modal.open_search import discover_modal
from momentid.diagnosis.modal.words import ModalEvidence
from momentid.diagnosis.result import Diagnosis
from momentid.diagnosis.thresholds import EXCESS, EXPLAINED, removed_share
from momentid.diagnosis.verdict import Named, Verdict
from momentid.core.processes import run_forked
from momentid.errors import IdentificationError, MomentidError
from momentid.estimation.peaks import response_amplitude

__all__ = ["diagnose_modal", "AMPLITUDE_DEPENDENCE", "LATE_SAMPLES"]

#: Verdict name of the amplitude-dependence mechanism (modes that shift with the response amplitude).
AMPLITUDE_DEPENDENCE = "amplitude_dependence"
#: A floor sensor's fitted clock offset beyond this fraction of a sample, of one sign in every training
#: run, is reported as a finding (the fit resolves offsets far below a sample; 0.1 sample at 120 Hz is
#: 0.8 ms, a 5 degree phase error at 17 Hz); a single run's offset is reported beyond half a sample.
LATE_SAMPLES = 0.1
#: The held-out run's active part is split into this many windows to say when its misfit is largest.
TIME_WINDOWS = 8
#: Floor sensor gains fitted on the training runs that differ by more than this between runs are
#: reported: a real accelerometer's gain is constant to well below 1 %, so a 2 % spread is the
#: model absorbing something else (an amplitude-dependent response at low frequency, a loose mount).
GAIN_SPREAD = 0.02
#: The recording's limit, said in every report.
ROCKING_LIMIT = ("Rocking and out-of-plane motion cannot be tested: the recording holds the shaking axis "
                 "only (import the sensors' other axes to test them).")


def _split(experiment: Experiment, hold_out: str | None):
    names = [r.name for r in experiment.runs]
    if hold_out is not None and hold_out not in names:
        raise MomentidError(f"{experiment.source}: --hold-out {hold_out!r}: no such run; runs are {names}")
    held = hold_out or names[-1]
    train = [n for n in names if n != held] or [held]
    return held, train


def _sensor_findings(fit: mc.RunsFit, dt: float) -> list[str]:
    out = []
    late = np.abs(fit.offset) > LATE_SAMPLES * dt                      # (runs, d)
    for j in range(fit.offset.shape[1]):
        if late[:, j].all() and (np.all(fit.offset[:, j] > 0) or np.all(fit.offset[:, j] < 0)):
            out.append(f"sensor timing: a{j + 1} is {1e3 * fit.offset[:, j].min():+.2f} to "
                       f"{1e3 * fit.offset[:, j].max():+.2f} ms ({fit.offset[:, j].mean() / dt:+.2f} samples) off the "
                       f"table sensor's clock in every training run (fitted; the replay uses the mean)")
        for r in np.flatnonzero(late[:, j] & ~late[:, j].all() & (np.abs(fit.offset[:, j]) > 0.5 * dt)):
            out.append(f"sensor timing: run {fit.runs[r]!r}, a{j + 1} is {1e3 * fit.offset[r, j]:+.2f} ms "
                       f"({fit.offset[r, j] / dt:+.2f} samples) off the table sensor's clock (fitted)")
    spread = np.ptp(fit.gain, axis=0) if len(fit.runs) > 1 else np.zeros(fit.gain.shape[1])
    for j in np.flatnonzero(spread > GAIN_SPREAD):
        out.append(f"sensor gain: a{j + 1} reads {fit.gain[:, j].min():.3f}-{fit.gain[:, j].max():.3f} x the table "
                   f"sensor across the training runs (a real accelerometer's gain does not change between runs)")
    return out


def _location(measured, model, fit: mc.RunsFit, dt: float, t0: float) -> dict:
    """Worst floor sensor, the modal band (between neighbouring modes) holding most of its residual power,
    and the time window (of :data:`TIME_WINDOWS`, from ``t0`` s) where its misfit is largest relative to
    its signal (a free decay after the table stops shows there when the model's modes drift off)."""
    per = mc.channel_nrmse(measured, model)
    worst = int(np.argmax(per))
    resid = np.fft.rfft(measured[:, worst] - model[:, worst])
    freq = np.fft.rfftfreq(measured.shape[0], dt)
    f = fit.frequency
    edges = np.concatenate([[0.0], np.sqrt(f[:-1] * f[1:]), [freq[-1] + 1.0]])
    power = np.array([np.sum(np.abs(resid[(freq >= lo) & (freq < hi)]) ** 2) for lo, hi in zip(edges, edges[1:])])
    mode = int(np.argmax(power))
    windows = np.array_split(np.arange(measured.shape[0]), TIME_WINDOWS)
    relative = [float(np.sqrt(np.sum((measured[w, worst] - model[w, worst]) ** 2) /
                              np.sum((measured[w, worst] - measured[:, worst].mean()) ** 2))) for w in windows]
    k = int(np.argmax(relative))
    return {"sensor": f"a{worst + 1}", "mode": mode + 1,
            "band_hz": [round(float(edges[mode]), 3), round(float(min(edges[mode + 1], freq[-1])), 3)],
            "band_share": round(float(power[mode] / power.sum()), 3),
            "worst_window_s": [round(float(t0 + windows[k][0] * dt), 2), round(float(t0 + windows[k][-1] * dt), 2)],
            "worst_window_nrmse": round(relative[k], 3)}


def diagnose_modal(experiment: Experiment, *, hold_out: str | None = None) -> Diagnosis:
    """Check the modal model on a held-out run and name what it misses (see the module docstring).

    Parameters
    ----------
    experiment : Experiment
        Runs without added mass, channels ``zdd`` and ``a1..ad`` (m/s^2).
    hold_out : str, optional
        Run to hold out (default: the last run).

    Returns
    -------
    Diagnosis
        With a :class:`~momentid.diagnosis.modal.words.ModalEvidence`: the per-channel misfit, the
        training runs' pooled modal model, the amplitude model tried, the sensor findings.

    Raises
    ------
    MomentidError
        Unknown ``hold_out``; :class:`~momentid.errors.IdentificationError` when the training runs
        cannot be fitted (no noise source, too little excitation).
    """
    with threadpool_limits(limits=1, user_api="blas"):     # small dense products: threads only add waiting
        return _diagnose(experiment, hold_out)


def _fits(experiment: Experiment, train):
    """One modal fit per training run, on the machine's cores (:func:`~momentid.core.processes.run_forked`)."""
    return run_forked(lambda name: mc.fit_runs(experiment, [name]), list(train))


def _candidate(per_run, run, start: int, linear: mc.RunsFit, gain, offset):
    """The amplitude model and its replay of the held-out run (``None, None, dict`` when not fitted)."""
    dt, d = 1.0 / run.sample_rate, linear.omega.size
    try:
        trend = mc.amplitude_model(per_run)
    except IdentificationError as err:
        return None, None, {"mechanism": AMPLITUDE_DEPENDENCE, "not_fitted": str(err)}
    amplitude = float(response_amplitude(run, d, start))
    omega, zeta = trend.predict(amplitude)
    replayed = mc.replay(omega, zeta, linear.residues, gain, offset, run["zdd"], dt)
    return trend, replayed, {"mechanism": AMPLITUDE_DEPENDENCE, "held_out_amplitude_m_s2": amplitude,
                             "predicted_frequency_hz": (omega / (2 * np.pi)).tolist(),
                             "predicted_damping_ratio": zeta.tolist(), **trend.to_dict()}


def _verdict(before: float, after: float, noise: float, tested: bool) -> Verdict:
    """``none`` within :data:`EXCESS` x noise; the candidate if it removes :data:`EXPLAINED` of the rest."""
    if before <= EXCESS * noise:
        return Verdict.NONE
    return Verdict.MECHANISM if tested and removed_share(before, after, noise) >= EXPLAINED else Verdict.UNEXPLAINED


def _diagnose(experiment: Experiment, hold_out: str | None) -> Diagnosis:
    held, train = _split(experiment, hold_out)
    run = experiment.run(held)
    dt, d = 1.0 / run.sample_rate, experiment.storeys
    per_run = _fits(experiment, train)
    linear = mc.pooled(per_run)
    gain, offset = linear.gain.mean(axis=0), linear.offset.mean(axis=0)
    start = mc.active_start(run)
    measured = run.group("a", d)[start:]
    before_full = mc.replay(linear.omega, linear.zeta, linear.residues, gain, offset, run["zdd"], dt)
    noise = mc.noise_nrmse(linear.omega, linear.zeta, linear.residues, gain, run, experiment)
    trend, after_full, candidate = (_candidate(per_run, run, start, linear, gain, offset)
                                    if held not in train else (None, None, {}))
    after_full = before_full if after_full is None else after_full
    before, after = mc.nrmse(measured, before_full[start:]), mc.nrmse(measured, after_full[start:])
    candidate["explained"] = removed_share(before, after, noise)
    verdict = _verdict(before, after, noise, trend is not None)
    best = after_full if verdict is Verdict.MECHANISM else before_full
    location = {} if verdict is Verdict.NONE else _location(measured, best[start:], linear, dt, float(run.time[start]))
    parameters, std = ({"df_dA_hz_per_m_s2": trend.frequency_coef[:, 1].tolist(),
                        "dzeta_dA_per_m_s2": trend.damping_coef[:, 1].tolist()},
                       {"df_dA_hz_per_m_s2": trend.frequency_slope_std.tolist(),
                        "dzeta_dA_per_m_s2": trend.damping_slope_std.tolist()}) \
        if verdict is Verdict.MECHANISM else ({}, {})
    per = {f"a{j + 1}": {"before": float(b), "after": float(a)} for j, (b, a) in
           enumerate(zip(mc.channel_nrmse(measured, before_full[start:]),
                         mc.channel_nrmse(measured, after_full[start:])))}
    searched = verdict is not Verdict.NONE and held not in train and len(train) > 1
    discovered = discover_modal(experiment, linear, train, held, location, before) if searched else None
    findings = tuple(_sensor_findings(linear, dt)) + (ROCKING_LIMIT,)
    training = {"runs": list(train), "frequency_hz": linear.frequency.tolist(), "damping_ratio": linear.zeta.tolist(),
                "residual_variance_factor": linear.scale, "sensor_gain": linear.gain.tolist(),
                "sensor_offset_s": linear.offset.tolist(), "noise": list(linear.noise)}
    held_name = held if held not in train else f"{held} (no run held out: checked on its own training data)"
    curves = {"time": run.time[start:], "measured": {"a": measured}, "linear": {"a": before_full[start:]},
              "augmented": {"a": after_full[start:]}}
    mechanism = AMPLITUDE_DEPENDENCE if verdict is Verdict.MECHANISM else verdict.value
    named = (Named(AMPLITUDE_DEPENDENCE, location, parameters, std),) if verdict is Verdict.MECHANISM else ()
    evidence = ModalEvidence(channel_nrmse=per, training=training, candidate=candidate, findings=findings,
                             trend=trend, amplitude=candidate.get("held_out_amplitude_m_s2"), searched=searched)
    return Diagnosis(verdict=verdict, mechanism=mechanism, location=location, parameters=parameters, std=std,
                     mechanisms=named, held_out=held_name, nrmse_before=before, nrmse_after=after, noise_nrmse=noise,
                     evidence=evidence, discovered=discovered, curves=curves)
