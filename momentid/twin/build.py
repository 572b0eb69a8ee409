"""``momentid twin``: identify a recording, build its calibrated MuJoCo twin, replay every trial.

:func:`build_twin` refuses what it cannot honour before building anything (:func:`check_recording`,
:func:`refusals`): fewer than two trials, a trial without a table sensor, an identification that
failed or that the data contradict: every WARNING of the identification (an unstable or poorly
determined mode, a fit stopped at its cap, a damping ratio that is not an answer, shapes that
contradict the stated masses), a sensor gain no accelerometer has, a K that is not positive definite.
A floor-sensor gain a few percent off the table's, which the identification warns about, is not a
refusal: the twin carries each sensor's gain, and the warning is repeated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from momentid.core.analytic import modal_properties
from momentid.core.series import Experiment
from momentid.errors import IdentificationError, SensorDataError
from momentid.twin.parameters import TwinParameters, from_identification
from momentid.twin.replay import Replay, replay_run
from momentid.twin.spec import Timing, model_matrices, timing, twin_spec

if TYPE_CHECKING:
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["Twin", "build_twin", "default_runs", "check_recording", "refusals", "check_xml", "MIN_TRIALS",
           "CHECK_STEPS", "MISFIT_FACTOR", "MISFIT_MARGIN", "misfit_warning"]

#: Trials a twin is calibrated on at least: one trial cannot tell the rig from that trial.
MIN_TRIALS = 2
#: Steps the written MJCF is stepped, unforced, to show it runs without MuJoCo warnings.
CHECK_STEPS = 1000
#: A trial whose replay misfit exceeds both this multiple of the noise alone's NRMSE and the noise plus
#: :data:`MISFIT_MARGIN` is one the linear twin does not predict: warned, naming the trials.  A
#: linear rig replays at its noise (the simulated rigs of tests/test_twin.py at 1.0-1.3 x, their sensor
#: gains and clock offsets fitted), so 3x is far outside what estimation scatter leaves.
MISFIT_FACTOR = 3.0
#: See :data:`MISFIT_FACTOR`: an NRMSE margin (fraction) that keeps near-noise-free replays quiet.
MISFIT_MARGIN = 0.05


@dataclass(frozen=True)
class Twin:
    """A calibrated twin and its replays.

    Attributes
    ----------
    parameters : TwinParameters
    identification : ModalIdentification or Identification
        What it was calibrated from.
    timing : Timing
        RK4 step of the written MJCF (at the recording's first trial's sample rate).
    xml : str
        The MJCF (nominal sensors), as written to ``twin.xml``.
    modes : Modes
        Frequencies and damping ratios of the MJCF itself (matrices read back from MuJoCo).
    replays : tuple of Replay
        Every trial of the recording, in recording order.
    source : str
        The recording.
    warnings : tuple of str
        The identification's warnings the twin accepts (sensor gains it carries).
    left_out : tuple of str
        One note per trial the default calibration left out as another rig state (:func:`default_runs`).
    """

    parameters: TwinParameters
    identification: object
    timing: Timing
    xml: str
    modes: object
    replays: tuple
    source: str
    warnings: tuple = ()
    left_out: tuple = ()

    @property
    def notes(self) -> tuple:
        """What the build noted: the trials left out, then the parameters' and the identification's notes."""
        return tuple(self.left_out) + tuple(self.parameters.notes) + tuple(self.identification.notes)

    def replay(self, run: str) -> Replay:
        """The replay of trial ``run``."""
        for r in self.replays:
            if r.run == run:
                return r
        raise SensorDataError(f"the twin of {self.source} has no trial {run!r}; it has "
                              f"{', '.join(r.run for r in self.replays)}")

    def to_dict(self) -> dict:
        """``twin.json``: parameters, sensors, the MJCF's own modes, every trial's NRMSE (SI units)."""
        from momentid.lab.tendons import tendon_layout

        p = self.parameters
        return {
            "source": self.source, "storeys": p.storeys, "calibrated_on": list(p.runs),
            "identification": p.source, "mass_normalised": p.mass_normalised,
            "masses_kg": p.masses.tolist(), "K_N_m": p.K.tolist(), "C_N_s_m": p.C.tolist(),
            "storey_heights_m": p.storey_heights.tolist(),
            "added_mass_damping_1_s": p.added_mass_damping,
            "modes": {"frequency_hz": self.modes.frequency.tolist(), "damping_ratio": self.modes.damping_ratio.tolist(),
                      "identified_frequency_hz": self.identification.modes().frequency.tolist(),
                      "identified_damping_ratio": self.identification.modes().damping_ratio.tolist()},
            "extra_modes": [e.to_dict() for e in p.extra_modes],
            "tendons": [{"name": t.name, "levels": [t.lower, t.upper], "stiffness_N_m": t.stiffness,
                         "damping_N_s_m": t.damping} for t in tendon_layout(p.K, p.C)],
            "sensors": {"nominal": p.nominal.to_dict(), "runs": {r: s.to_dict() for r, s in p.sensors.items()}},
            "simulation": {"integrator": "RK4", "timestep_s": self.timing.timestep,
                           "substeps_per_sample": self.timing.substeps, "sample_rate_hz": self.timing.sample_rate},
            "trials": [r.to_dict() for r in self.replays],
            "notes": list(self.notes), "warnings": list(self.warnings),
        }

    def _repr_html_(self) -> str:
        """A notebook's summary: the words of the report page's answer
        (:func:`momentid.twin.summary_html.twin_html`)."""
        from momentid.twin.summary_html import twin_html
        return twin_html(self)

    def summary(self) -> str:
        """Plain-text report: the rig, its modes, every trial's NRMSE."""
        p = self.parameters
        masses = ("mass-normalised (no floor masses stated)" if p.mass_normalised
                  else f"floor masses {', '.join(f'{m:g}' for m in p.masses)} kg")
        lines = [f"twin of {self.source}: {p.storeys} storeys, {masses}; calibrated on {', '.join(p.runs)}",
                 "mode  frequency (Hz)  damping ratio (%)   (of the MJCF written)"]
        lines += [f"{i + 1:>4}  {f:14.4f}  {100 * z:17.3f}"
                  for i, (f, z) in enumerate(zip(self.modes.frequency, self.modes.damping_ratio))]
        lines += [f"extra mode {e + 1}: {m.frequency:.4f} Hz, damping ratio {100 * m.damping_ratio:.3f} %"
                  for e, m in enumerate(p.extra_modes)]
        width = max(len("trial"), *(len(r.run) for r in self.replays))
        lines += ["", f"{'trial':<{width}}  {'sensors':<11}  {'NRMSE':>7}  {'noise alone':>11}  NRMSE per floor sensor"]
        for r in self.replays:
            floors = "  ".join(f"{100 * x:6.2f} %" for x in r.nrmse_floors)
            lines.append(f"{r.run:<{width}}  {'calibrated' if r.calibrated else 'nominal':<11}  "
                         f"{100 * r.nrmse:6.2f} %  {100 * r.noise_nrmse:9.2f} %  {floors}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def check_recording(experiment: Experiment, runs: Sequence[str] | None = None) -> tuple[str, ...]:
    """The run names a twin can be calibrated on; refuses what it cannot honour.

    Every trial of the recording is replayed, so every one needs the table sensor and each floor's.

    Raises
    ------
    SensorDataError
        A trial without the table sensor ``zdd`` or a floor sensor, or an unknown run name.
    IdentificationError
        A trial named twice, or fewer than :data:`MIN_TRIALS` trials selected.
    """
    names = [r.name for r in experiment.runs] if runs is None else list(runs)
    if len(set(names)) != len(names):
        raise IdentificationError(f"{experiment.source}: runs {names} name a trial twice: expected each once")
    for name in names:
        experiment.run(name)                      # an unknown name is refused with the runs there are
    d = experiment.storeys
    for run in experiment.runs:
        missing = [c for c in ["zdd"] + [f"a{j + 1}" for j in range(d)] if not run.has(c)]
        if missing:
            what = "no table sensor (zdd)" if "zdd" in missing else f"no {', '.join(missing)}"
            raise SensorDataError(f"{experiment.source}: run {run.name!r} has {what}: a twin is driven by the "
                                  f"recorded table acceleration and scored on every floor's accelerometer")
    if len(names) < MIN_TRIALS:
        raise IdentificationError(f"{experiment.source}: {len(names)} trial ({', '.join(names)}): a twin is "
                                  f"calibrated on at least {MIN_TRIALS} trials (one trial cannot tell the rig "
                                  f"from that trial)")
    return tuple(names)


def _is_gain_warning(text: str, runs) -> bool:
    """True for the identification's warning that a run's floor sensor reads a few percent off the table
    (``run 'X': floor sensor(s) a3 read 1.052 x the table sensor at low frequency: ...``): the twin
    carries each sensor's gain, so that one is not a refusal."""
    return "x the table sensor at low frequency" in text and any(
        text.startswith(f"run {run!r}: floor sensor(s) ") for run in runs)


def _modal_refusals(result) -> tuple[list, list]:
    """``(reasons to refuse, warnings the twin accepts)`` of a ModalIdentification."""
    from momentid.estimation.plausibility import GAIN_RANGE

    reasons = [f"mode {i + 1} at {f:.4g} Hz is unstable (damping ratio {z:.3g})"
               for i, (f, z) in enumerate(zip(result.frequency, result.linear_damping_ratio)) if not z > 0]
    gain = np.asarray(result.sensor_gain)
    for r, run in enumerate(result.runs):
        bad = [j for j in range(gain.shape[1]) if not GAIN_RANGE[0] <= gain[r, j] <= GAIN_RANGE[1]]
        if bad:
            reasons.append(f"run {run!r}: floor sensor(s) {', '.join(f'a{j + 1}' for j in bad)} read "
                           f"{', '.join(f'{gain[r, j]:.3g}' for j in bad)} x the table (expected "
                           f"{GAIN_RANGE[0]:g}-{GAIN_RANGE[1]:g}: a swapped, turned or loose sensor)")
    accepted = [w for w in result.warnings if _is_gain_warning(w, result.runs)]
    if reasons:
        return reasons, []
    # every other warning (an unstable, poorly determined or capped fit, a damping ratio that is not an
    # answer, shapes that contradict the masses) is a reason not to build the twin on it
    return [w for w in result.warnings if w not in accepted], accepted


def refusals(result: Identification | ModalIdentification) -> tuple[list, list]:
    """Why ``result`` cannot calibrate a twin, and which of its warnings the twin accepts.

    Parameters
    ----------
    result : ModalIdentification or Identification

    Returns
    -------
    reasons : list of str
        Empty when the twin can be built.
    accepted : list of str
        The identification's warnings about sensor gains within what accelerometers read (the twin
        carries the gains); repeated as the twin's warnings.
    """
    from momentid.estimation.scaled import ModalIdentification

    if isinstance(result, ModalIdentification):
        reasons, accepted = _modal_refusals(result)
    else:
        reasons, accepted = list(result.warnings), []
    for name, X in (("K", result.K), ("C", result.C)):
        if X is not None and not np.all(np.isfinite(X)):
            reasons.append(f"{name} is not finite")
    if result.K is not None and np.all(np.isfinite(result.K)) and np.min(np.linalg.eigvalsh(result.K)) <= 0:
        reasons.append("K is not positive definite (a rig that would not stand)")
    return reasons, accepted


def check_xml(xml: str) -> object:
    """Load ``xml`` in stock MuJoCo, step it unforced, and return its modes (matrices read back)."""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, CHECK_STEPS)
    warned = [mujoco.mjtWarning(i).name for i, w in enumerate(data.warning) if w.number > 0]
    if warned:
        raise IdentificationError(f"the twin's MJCF steps with MuJoCo warnings {warned}: expected none")
    M, C, K = model_matrices(model)
    return modal_properties(M, C, K)


def build_twin(experiment: Experiment, runs: Sequence[str] | None = None) -> Twin:
    """Identify ``experiment`` on ``runs``, build its MJCF twin and replay every trial through it.

    Parameters
    ----------
    experiment : Experiment
        Runs with ``zdd`` and ``a1..ad`` (m/s^2): accelerometers only, or a simulated or added-mass
        recording (identified with :func:`momentid.estimation.identification.identify`).
    runs : sequence of str, optional
        The trials to calibrate on; by default every trial but those of another rig state
        (:func:`default_runs`, with a note).  Every trial is replayed; those left out with the
        calibrated runs' mean sensors.

    Returns
    -------
    Twin

    Raises
    ------
    IdentificationError, SensorDataError
        What :func:`check_recording` and :func:`refusals` refuse, with the reasons in one line.
    """
    from momentid.estimation.plausibility import implausible
    from momentid.core.processes import run_forked
    from momentid.estimation.identification import identify

    left_out: tuple = ()
    if runs is None:
        runs, left_out = default_runs(experiment)
    names = check_recording(experiment, runs)
    cannot = f"{experiment.source}: the identification of {', '.join(names)} cannot calibrate a twin: "
    try:
        result = identify(experiment, runs=list(names))
    except IdentificationError as exc:
        raise IdentificationError(cannot + str(exc) + " (leave a trial out with --runs)") from None
    reasons, accepted = refusals(result)
    reasons += implausible(experiment, result)
    if reasons:
        raise IdentificationError(cannot + "; ".join(reasons) + " (leave a trial out with --runs)")
    params = from_identification(result, experiment)
    stated = dict(experiment.statement.noise) if experiment.statement is not None else None
    t = timing(params, experiment.runs[0].sample_rate)
    xml = twin_spec(params, t.timestep, name=f"{experiment.name}_twin").to_xml()
    replays = tuple(run_forked(lambda run: replay_run(params, run, stated_noise=stated), experiment.runs))
    # each calibrated run's sensors with the bias its replay fitted
    params = replace(params, sensors={r.run: r.sensors for r in replays if r.calibrated})
    return Twin(parameters=params, identification=result, timing=t, xml=xml, modes=check_xml(xml),
                replays=replays, source=experiment.source, warnings=tuple(accepted) + misfit_warning(replays),
                left_out=left_out)


def default_runs(experiment: Experiment) -> tuple:
    """The trials a twin is calibrated on by default, and a note per trial left out.

    Every trial, but those the rig-state check (:func:`momentid.estimation.rig_state.check_state`, on
    each trial's own modal fit) sets apart as another rig state: a twin of two rig states is the
    twin of neither.  Naming such a trial in ``runs`` calibrates on it all the same.

    Returns
    -------
    tuple
        ``(names or None, notes)``: None (all trials) when no trial is set apart or the check cannot
        run (fewer than ``MIN_OTHERS + 1`` trials, added masses, a trial its own fit refuses).
    """
    from momentid.estimation.rig_state import MIN_OTHERS, check_state
    from momentid.estimation.scaled import identify_per_run

    if len(experiment.runs) < MIN_OTHERS + 1 or any(np.any(r.added_mass) for r in experiment.runs):
        return None, ()
    try:
        state = check_state(identify_per_run(experiment))
    except IdentificationError:
        return None, ()
    if not state.outliers:
        return None, ()
    notes = tuple(f"{state.sentence(run)} (name it in --runs to calibrate on it all the same)"
                  for run in state.outliers)
    return [r.name for r in experiment.runs if state.belongs(r.name)], notes


def misfit_warning(replays: Sequence[Replay]) -> tuple[str, ...]:
    """A WARNING (one-tuple) when some trials replay far above their noise (:data:`MISFIT_FACTOR`), else ().

    The twin is still written: it is the best linear model of the rig, and the gap is what
    ``momentid diagnose`` sets out to explain; but its replay is not a prediction of those trials.
    """
    far = [r for r in replays if r.nrmse > max(MISFIT_FACTOR * r.noise_nrmse, r.noise_nrmse + MISFIT_MARGIN)]
    if not far:
        return ()
    said = ", ".join(f"{r.run} {100 * r.nrmse:.1f} % (noise alone {100 * r.noise_nrmse:.1f} %)" for r in far)
    return (f"the linear twin does not predict {len(far)} of {len(replays)} trials: replay NRMSE {said}; the rig "
            f"does something the linear model leaves out (amplitude dependence, a mode it lacks, a sensor "
            f"fault): see `momentid diagnose`",)

