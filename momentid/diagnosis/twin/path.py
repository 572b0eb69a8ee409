"""``momentid diagnose`` of an accelerometer-only recording, on the rig's MuJoCo twin.

What :func:`diagnose_twin` does with a recording of trials without added mass and with stated floor
masses:

1. **Rig state.** Every trial is identified on its own (:func:`~momentid.estimation.scaled.identify_per_run`)
   and :func:`~momentid.estimation.rig_state.check_state` says which trials do not belong with the
   others (their modes lie off the others' trend: another day, sensors re-mounted).  Those are said,
   left out of the fit, and never called missing physics.
2. **Hold-out.** ``hold_out`` when given (any trial, one of another state too); else the last trial
   that belongs whose response amplitude lies inside the other such trials' (an interpolation: the
   twin is not asked to extrapolate by default), else the last that belongs.
3. **The linear twin** (``nrmse_before``): ``momentid twin`` calibrated on the training trials
   (:func:`momentid.twin.build_twin`), replayed on the held-out trial with its nominal sensors; its
   MJCF is ``twin.xml``.
4. **Re-simulation** (:func:`~momentid.diagnosis.twin.folds.hold_out`): from that twin, the physics
   the training trials alone choose (each real-rig kind of the registry, per storey or shared, and the
   linear twin, fitted with one training trial held out and scored on it), the linear twin refitted to
   all training trials at once through MuJoCo (``nrmse_linear_refit``), the twin with the chosen physics
   fitted the same way (``nrmse_after``; its MJCF is ``model_augmented.xml``), a linear twin fitted to
   the held-out trial itself (``nrmse_linear_own``) and what its sensor noise alone leaves
   (``noise_nrmse``).
5. **Reference**: amplitude-dependent viscous damping (each mode's frequency and damping ratio
   regressed on the training trials' response amplitude, predicted at the held-out trial's) replayed
   on the linear refit's modes: a figure to compare with, not an answer.
6. **Verdict** (:class:`~momentid.diagnosis.verdict.Verdict`): ``ANOTHER_RIG_STATE`` when the held-out
   trial is one the rig-state check left out (its misfit is a different rig, not missing physics);
   ``NONE`` when a linear twin is within ``EXCESS`` x noise, or when the training trials chose the
   linear twin and its refit is within ``LINEAR_ROOM`` x the held-out trial's own linear fit (the rig
   is linear within its trials); ``MECHANISM`` (the chosen kind, one entry per storey at its place) when
   the augmented twin removes at least ``EXPLAINED`` of the linear refit's held-out misfit above noise
   (a WARNING when what is left is still above noise); otherwise ``UNEXPLAINED``, located in words
   (floor sensor, mode band).

The result is the :class:`~momentid.diagnosis.result.Diagnosis` of every recording, with a
:class:`~momentid.diagnosis.twin.words.TwinEvidence`, which words it.
Its ``location`` is where the held-out misfit left is largest (floor sensor, mode band); the joints'
places are their ``mechanisms`` entries'.
"""

from __future__ import annotations

from collections.abc import Sequence
import time

import numpy as np

from momentid.core.series import Experiment
from momentid.diagnosis.modal import check as mc
from momentid.diagnosis.twin import folds as twin_folds
from momentid.twin import fit as twin_fit
from momentid.diagnosis.result import Diagnosis
from momentid.estimation.rig_state import StateCheck, check_state
from momentid.diagnosis.thresholds import EXCESS, EXPLAINED, LINEAR_ROOM, removed_share
from momentid.diagnosis.twin.words import TwinEvidence
from momentid.diagnosis.verdict import Named, Verdict
from momentid.errors import IdentificationError, MomentidError
from momentid.estimation.scaled import ModalIdentification, identify_per_run, weighted_line
from momentid.lab import resim
from momentid.mechanisms import joint_friction as jf
from momentid.mechanisms import registry

__all__ = ["diagnose_twin", "applies", "default_hold_out", "MIN_TRAINING"]

#: Training trials the twin's fits need at least: one parameter set over several amplitudes.
MIN_TRAINING = 2


def applies(experiment: Experiment) -> bool:
    """Whether :func:`diagnose_twin` can run: stated floor masses and at least ``MIN_TRAINING + 1`` trials."""
    st = experiment.statement
    return st is not None and st.masses is not None and len(experiment.runs) >= MIN_TRAINING + 1


def default_hold_out(per_run: Sequence[ModalIdentification], state: StateCheck) -> str:
    """The last trial that belongs whose amplitude lies inside the other such trials' (module docstring)."""
    inside = [r for r in per_run if state.belongs(r.runs[0])]
    if not inside:
        return per_run[-1].runs[0]
    amplitude = {r.runs[0]: float(r.amplitude[0]) for r in inside}
    for name in reversed(list(amplitude)):
        others = [a for n, a in amplitude.items() if n != name]
        if others and min(others) <= amplitude[name] <= max(others):
            return name
    return inside[-1].runs[0]


def diagnose_twin(experiment: Experiment, *, hold_out: str | None = None) -> Diagnosis:
    """Diagnose ``experiment`` on its twin (see the module docstring).

    Parameters
    ----------
    experiment : Experiment
        Trials without added mass, channels ``zdd`` and ``a1..ad`` (m/s^2), stated floor masses.
    hold_out : str, optional
        The trial to hold out (default: :func:`default_hold_out`).

    Raises
    ------
    MomentidError
        Unknown ``hold_out``; :class:`~momentid.errors.IdentificationError` with fewer than
        :data:`MIN_TRAINING` training trials of one rig state.
    """
    clock = {"began": time.perf_counter(), "cpu": time.process_time()}
    names = [r.name for r in experiment.runs]
    if hold_out is not None and hold_out not in names:
        raise MomentidError(f"{experiment.source}: --hold-out {hold_out!r}: no such run; runs are {names}")
    per_run = identify_per_run(experiment)
    state = check_state(per_run)
    held = hold_out or default_hold_out(per_run, state)
    training = [n for n in names if n != held and state.belongs(n)]
    if len(training) < MIN_TRAINING:
        raise IdentificationError(f"{experiment.source}: {len(training)} training trial(s) of one rig state besides "
                                  f"{held!r} ({training}): the twin's fits need at least {MIN_TRAINING}")
    seconds = {"per_run_identification": time.perf_counter() - clock["began"]}
    twin, start, twin_note = _linear_twin(experiment, training)
    seconds["linear_twin"] = time.perf_counter() - clock["began"] - sum(seconds.values())
    fold = twin_folds.hold_out(experiment, held, training, start=start)
    seconds["fits"] = time.perf_counter() - clock["began"] - sum(seconds.values())
    tr = twin_fit.trial(experiment.run(held), experiment.storeys)
    curves = _curves(experiment, twin, fold, tr)
    measured = tr.a[tr.start:]
    before = twin.replay(held).nrmse if twin is not None else fold.nrmse_linear_refit
    reference = _reference(per_run, training, held, start, tr)
    verdict = Verdict.ANOTHER_RIG_STATE if held in state.outliers else _verdict(before, fold)
    residual_of = curves["augmented"]["a"] if verdict is Verdict.MECHANISM else curves["linear_refit"]["a"]
    location = {} if verdict is Verdict.NONE else _location(measured, residual_of, fold, tr.dt)
    named = _named(fold.augmented.model) if verdict is Verdict.MECHANISM else ()
    per = {f"a{j + 1}": {key: float(v) for key, v in zip(
        ("before", "linear_refit", "after"),
        [mc.channel_nrmse(measured, curves[k]["a"])[j] for k in ("linear", "linear_refit", "augmented")])}
        for j in range(experiment.storeys)}
    fits = {"linear_refit": fold.linear.model.to_dict(), "augmented": fold.augmented.model.to_dict(),
            "own": fold.own.model.to_dict(), "training_nrmse": {"linear_refit": fold.linear.nrmse,
                                                                "augmented": fold.augmented.nrmse},
            "chosen": fold.chosen.name, "inner_held_out": fold.inner_held_out, "selection": fold.selection}
    notes = tuple(experiment.notes) + ((twin_note,) if twin_note else ())
    seconds["total"] = time.perf_counter() - clock["began"]
    seconds["cpu"] = time.process_time() - clock["cpu"]
    evidence = TwinEvidence(training=tuple(training), state=state,
                            excluded=tuple(state.sentence(r) for r in state.outliers), channel_nrmse=per,
                            fits=fits, reference=reference,
                            twin_xml=twin.xml if twin is not None else _xml(fold.linear.model, tr.dt),
                            seconds=seconds, fold=fold, per_run=tuple(per_run))
    return Diagnosis(verdict=verdict, mechanism=named[0].mechanism if named else verdict.value, location=location,
                     parameters={}, std={}, mechanisms=named, held_out=held, nrmse_before=float(before),
                     nrmse_after=fold.nrmse_after, noise_nrmse=fold.noise_nrmse, evidence=evidence,
                     nrmse_linear_refit=fold.nrmse_linear_refit, nrmse_linear_own=fold.nrmse_linear_own,
                     augmented_xml=_xml(fold.augmented.model, tr.dt), curves=curves, notes=notes)


def _linear_twin(experiment: Experiment, training):
    """``momentid twin`` on the training trials, and the re-simulation's start from it; when the twin
    builder refuses, no twin and the modal identification of the training trials as the start."""
    from momentid.core.analytic import modal_properties
    from momentid.twin import build_twin

    try:
        twin = build_twin(experiment, runs=training)
    except MomentidError as err:               # a refusal of the twin builder (identification, sensors, step)
        start = twin_folds.linear_start(experiment, training)
        return None, start, f"the linear twin of `momentid twin` was refused ({err}); the linear refit stands for it"
    p = twin.parameters
    zeta = np.clip(modal_properties(np.diag(p.masses), p.C, p.K).damping_ratio, 1e-4, None)
    return twin, twin_fit.FittedRig(np.asarray(p.masses, float), np.asarray(p.K, float), zeta), ""


def _xml(model: twin_fit.FittedRig, dt: float) -> str:
    """The MJCF of a re-simulated twin at the fits' step (loads in stock MuJoCo)."""
    return resim.build_spec(model.rig(), dt / resim.substeps_for(dt)).to_xml()


def _verdict(before: float, fold) -> Verdict:
    noise = fold.noise_nrmse
    if min(before, fold.nrmse_linear_refit) <= EXCESS * noise:
        return Verdict.NONE
    if fold.chosen is not None and fold.chosen.linear:
        # the training trials chose no physics: linear within its trials when the refit is as good as the
        # held-out trial's own linear fit allows, else a mismatch no candidate explains
        return Verdict.NONE if fold.nrmse_linear_refit <= LINEAR_ROOM * fold.nrmse_linear_own else Verdict.UNEXPLAINED
    if removed_share(fold.nrmse_linear_refit, fold.nrmse_after, noise) >= EXPLAINED:
        return Verdict.MECHANISM
    return Verdict.UNEXPLAINED


def _curves(experiment: Experiment, twin, fold, tr) -> dict:
    s = tr.start
    linear = twin.replay(tr.name).twin if twin is not None else twin_fit.predict(fold.linear.model, tr)
    return {"time": np.asarray(experiment.run(tr.name).time)[s:], "measured": {"a": tr.a[s:]},
            "linear": {"a": linear[s:]}, "linear_refit": {"a": twin_fit.predict(fold.linear.model, tr)[s:]},
            "augmented": {"a": twin_fit.predict(fold.augmented.model, tr)[s:]}}


def _location(measured: np.ndarray, model: np.ndarray, fold, dt: float) -> dict:
    """Worst floor sensor and the modal band (between neighbouring modes of the linear refit) holding most
    of its residual power, in numbers and in words."""
    per = mc.channel_nrmse(measured, model)
    worst = int(np.argmax(per))
    resid = np.fft.rfft(measured[:, worst] - model[:, worst])
    freq = np.fft.rfftfreq(measured.shape[0], dt)
    f = np.sort(twin_fit.twin_modes(fold.linear.model)[0]) / (2 * np.pi)
    edges = np.concatenate([[0.0], np.sqrt(f[:-1] * f[1:]), [freq[-1]]])
    power = np.array([np.sum(np.abs(resid[(freq >= lo) & (freq < hi)]) ** 2) for lo, hi in zip(edges, edges[1:])])
    mode = int(np.argmax(power))
    band = [round(float(edges[mode]), 2), round(float(edges[mode + 1]), 2)]
    share = float(power[mode] / power.sum())
    words = (f"floor-{worst + 1} sensor, mode-{mode + 1} band ({band[0]:g}-{band[1]:g} Hz, {100 * share:.0f} % of "
             f"its misfit power)")
    return {"sensor": f"a{worst + 1}", "floor": worst + 1, "mode": mode + 1, "band_hz": band,
            "band_share": round(share, 3), "words": words}


def _named(model: twin_fit.FittedRig) -> tuple:
    """The augmented twin's mechanisms as ``report.json`` mechanisms: joints per storey in N/m, N and mm;
    another kind's parameters in its own units."""
    out = []
    for m in model.friction:
        p = dict(m.parameters)
        if m.type != "joint_friction":
            out.append(Named(m.type, registry.get(m.type).place(m.location).location, p, {}))
            continue
        out.append(Named(m.type, registry.get(m.type).place(m.location).location, {
            "stiffness_n_per_m": p["stiffness"], "slip_drift_mm": 1e3 * p["slip_drift"], "exponent": p["exponent"],
            "slip_force_n": float(jf.backbone(p, p["slip_drift"])),
            "stiffness_lost_at_1mm_n_per_m": p["stiffness"] * jf.lost_fraction(1e-3, p["slip_drift"], p["exponent"]),
            "stiffness_lost_at_5mm_n_per_m": p["stiffness"] * jf.lost_fraction(5e-3, p["slip_drift"], p["exponent"])},
            {}))
    return tuple(out)


def _reference(per_run, training, held: str, start: twin_fit.FittedRig, tr) -> dict:
    """Amplitude-dependent viscous damping (module docstring, stage 5): each mode's frequency and damping
    ratio from the training trials' own identifications, on a line against their response amplitude,
    predicted at the held-out trial's; replayed exactly (no integrator) with the residues of the twin's
    identification and the training trials' mean sensor gains and clock offsets."""
    train = [r for r in per_run if r.runs[0] in training]
    amplitude = {r.runs[0]: float(r.amplitude[0]) for r in per_run}
    x = np.array([amplitude[r.runs[0]] for r in train])
    if np.ptp(x) <= mc.MIN_AMPLITUDE_SPREAD * max(float(np.max(x)), 1e-12):
        return {"mechanism": "amplitude_dependent_viscous_damping", "not_fitted": "training amplitudes too alike"}
    _, _, residues = twin_fit.twin_modes(start)
    coef = {}
    for key, name in (("frequency", "frequency"), ("damping_ratio", "linear_damping_ratio")):
        coef[key] = [weighted_line(x, np.array([getattr(r, name)[m] for r in train]),
                                   np.maximum(np.array([getattr(r, name + "_std")[m] for r in train]), 1e-12))[0]
                     for m in range(residues.shape[0])]
    f = np.array([c[0] + c[1] * amplitude[held] for c in coef["frequency"]])
    zeta = np.clip([c[0] + c[1] * amplitude[held] for c in coef["damping_ratio"]], 1e-5, None)
    gain = np.mean([np.ravel(r.sensor_gain) for r in train], axis=0)
    offset = np.mean([np.ravel(r.sensor_offset) for r in train], axis=0)
    a = mc.replay(2 * np.pi * f, zeta, residues, gain, offset, tr.zdd, tr.dt)
    return {"mechanism": "amplitude_dependent_viscous_damping", "nrmse": mc.nrmse(tr.a[tr.start:], a[tr.start:]),
            "held_out_amplitude_m_s2": amplitude[held], "training_amplitude_m_s2": x.tolist(),
            "df_dA_hz_per_m_s2": [float(c[1]) for c in coef["frequency"]],
            "dzeta_dA_per_m_s2": [float(c[1]) for c in coef["damping_ratio"]],
            "predicted_frequency_hz": f.tolist(), "predicted_damping_ratio": zeta.tolist(),
            "note": "a reference figure, not an answer: each mode's frequency and viscous damping set by the trial's "
                    "response amplitude (measured on the held-out trial itself)"}
