"""When model and recordings disagree: locate the mismatch, name the physics, add it.

:func:`diagnose` is a pipeline of named stages with typed results between them:

1. **Linear model** (:func:`~momentid.diagnosis.residuals.fit_linear_model`): identified from the
   training runs, beside the nominal model the lab states.
2. **Residuals** (:func:`~momentid.diagnosis.residuals.equation_residuals`): the force per floor the
   linear model leaves unexplained, against what sensor noise alone leaves.
3. **Sensor check** (:func:`~momentid.diagnosis.sensor_check.check_sensors`): the channels against
   each other (``a_j = zdd + q_j''``).
4. **Localisation** (:func:`~momentid.diagnosis.locate.locate`): storey, runs, time, amplitude,
   band and shape of the mismatch.
5. **Screening** (:func:`~momentid.diagnosis.selection.screen`): every mechanism of the registry
   (:mod:`momentid.mechanisms`) fitted at every place of its target, in the equation and replay
   residuals; :func:`~momentid.diagnosis.selection.choose` names the verdict.
6. **Refit by re-simulation and selection** (:func:`~momentid.diagnosis.selection.select`,
   :class:`~momentid.diagnosis.refit.Refitter`): the plausible candidates' augmented MuJoCo models
   replay the training runs; the best is sized, and kept only if it removes most of the misfit.
   Then (:func:`~momentid.diagnosis.compound.extend`) what it leaves is screened again: every further
   mechanism that earns its place is named, and all are refitted jointly in one model; when a sensor
   fault is to be undone first, stages 1-6 run again on the corrected recordings (:func:`_compound`).
7. **Report** (:mod:`~momentid.diagnosis.report`): the held-out run replayed through the linear and
   augmented models (NRMSE before/after), the :class:`~momentid.diagnosis.result.Diagnosis` and its
   report folder.
8. **Open search** (:func:`~momentid.diagnosis.discovery.discover`), on an ``unexplained`` verdict:
   a sparse force from a function library, located, put into the MuJoCo model and replayed on the
   held-out run (``discovered``; the verdict stays ``unexplained``, at the discovered place).  When
   the named physics' model still replays above the noise, the open search challenges it
   (:func:`~momentid.diagnosis.discovery.challenge`): a force outside the library that removes most
   of what it leaves makes the verdict ``unexplained``, at the force's place.

Recordings without added mass (accelerometers only) run on the rig's MuJoCo twin when the lab states
its floor masses and recorded three trials or more (:func:`momentid.diagnosis.twin_diagnose.diagnose_twin`),
else take the modal path (:func:`momentid.diagnosis.real.diagnose_modal`); their result is the same
:class:`~momentid.diagnosis.result.Diagnosis`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.series import Experiment
from momentid.diagnosis.compound import Compound, Correction, extend
from momentid.diagnosis.data_check import diagnose_data
from momentid.diagnosis.discovery import as_unexplained, challenge, discover
from momentid.diagnosis.refit import noise_carrier, noise_ratios
from momentid.diagnosis.replay import replay_check
from momentid.diagnosis.report import write_report
from momentid.diagnosis.added_mass_words import AddedMassEvidence
from momentid.diagnosis.result import Diagnosis
from momentid.diagnosis.stages import Stages, run_stages
from momentid.errors import MomentidError

__all__ = ["Diagnosis", "diagnose", "write_report", "REPORTED_CANDIDATES"]

#: Candidates listed in the report, best first.
REPORTED_CANDIDATES = 8


def diagnose(experiment: Experiment, *, replay: bool = True, hold_out: str | None = None) -> Diagnosis:
    """Find, name and model the physics the linear shear model leaves out.

    Parameters
    ----------
    experiment : Experiment
        At least two runs (one with added mass); with three or more, the last
        run is held out for the before/after replay.  Runs without added mass
        (accelerometer-only labs) run on the twin
        (:func:`momentid.diagnosis.twin_diagnose.diagnose_twin`: stated floor masses and three trials or
        more), else take :func:`momentid.diagnosis.real.diagnose_modal`.
    replay : bool
        Replay the held-out run through the linear and augmented MuJoCo models
        (the NRMSE figures); off only for quick screening.
    hold_out : str, optional
        Runs without added mass only: the run to hold out (default: the last; on the twin, the last
        trial of the others' rig state inside their amplitudes).

    Returns
    -------
    Diagnosis
        When a recorded channel shows a fault by itself (a saturation's clipped peaks), that fault, named
        with no model (:func:`momentid.diagnosis.data_check.diagnose_data`): the model-based stages need
        channels without it.
    """
    named = diagnose_data(experiment)   # what the channels show by themselves (a saturation) comes first
    if named is not None:
        return named
    if not any(np.any(run.added_mass) for run in experiment.runs):
        from momentid.diagnosis import twin_diagnose
        if twin_diagnose.applies(experiment):        # stated masses, 3+ trials: on the MuJoCo twin
            with threadpool_limits(limits=1, user_api="blas"):
                return twin_diagnose.diagnose_twin(experiment, hold_out=hold_out)
        from momentid.diagnosis.real import diagnose_modal
        return replace(diagnose_modal(experiment, hold_out=hold_out), notes=tuple(experiment.notes))
    if hold_out is not None:
        raise MomentidError(f"{experiment.source}: hold_out = {hold_out!r}: choosing the held-out run works for "
                            f"runs without added mass only; this experiment adds mass (its last run is held out)")
    # Thousands of small dense products (8 x 8 exponentials in the errors-in-variables refits): BLAS
    # threads only add waiting, 6x on a busy 2-core machine.
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(experiment, replay)


def _compound(stages: Stages, replay: bool, corrections: int | None = None) -> Compound:
    """Stage 6b on ``stages``; when it asks for recordings with a sensor fault undone to be diagnosed
    first (a :class:`~momentid.diagnosis.compound.Correction`), stages 1-6 run on them, with their own
    refitter, and their diagnosis is handed back."""
    out = extend(stages, replay=replay) if corrections is None else extend(stages, replay=replay,
                                                                             corrections=corrections)
    if isinstance(out, Correction):
        again = run_stages(out.experiment, replay=True, result=out.identification)
        return out.then(_compound(again, True, out.corrections))
    return out


def _diagnose(experiment: Experiment, replay: bool) -> Diagnosis:
    """:func:`diagnose` of an experiment with added mass."""
    stages = run_stages(experiment, replay=replay)
    model, residuals, screening, refitter = stages.model, stages.residuals, stages.screening, stages.refitter
    joint = _compound(stages, replay)
    found = joint.finding
    before = after = float("nan")
    curves, xml = {}, ""
    if replay:
        before, after, curves, xml = replay_check(model, refitter.linear_structure, found.structure, joint.entries,
                                                  found.records)
    discovered = discover(model, residuals, refitter, found, before)   # the open search, on "unexplained"
    if discovered is None and joint.mechanisms:   # ... and against named physics that leaves a misfit
        discovered = challenge(model, residuals, refitter, found, joint.entries, before, stages.sensors.fault)
        if discovered is not None:   # a force outside the library beats the library's names
            found = as_unexplained(found, discovered, refitter)
            joint = replace(joint, finding=found, mechanisms=(), entries=())
            before, after, curves, xml = replay_check(model, refitter.linear_structure, found.structure, (), ())
    run = model.evaluation_run
    noise = float(np.mean(noise_ratios(noise_carrier(model), run, model.storeys, model.band)))
    evidence = AddedMassEvidence(
        run=run.name, held=model.holdout is not None, excess_equation=residuals.excess,
        excess_replay=screening.replay.excess,
        candidates=tuple(sorted(screening.candidates, key=lambda c: -c.explained)[:REPORTED_CANDIDATES]),
        parameter_pattern=screening.pattern_info, sensor_check=stages.sensors.to_dict(), selection=found.selection,
        localisation=stages.where)
    return Diagnosis(verdict=found.verdict, mechanism=found.mechanism,
                     location=discovered.location if discovered is not None else found.location,
                     parameters=found.parameters, std=found.std, mechanisms=joint.mechanisms,
                     held_out=run.name if evidence.held else f"{run.name} (no run held out)",
                     nrmse_before=before, nrmse_after=after, noise_nrmse=noise, evidence=evidence,
                     discovered=discovered, augmented_xml=xml, curves=curves, notes=tuple(experiment.notes))
