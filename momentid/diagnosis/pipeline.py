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
   (:mod:`momentid.mechanisms`) fitted where it could be, in the equation and replay residuals;
   :func:`~momentid.diagnosis.selection.choose` names the verdict.
6. **Refit by re-simulation and selection** (:func:`~momentid.diagnosis.selection.select`,
   :class:`~momentid.diagnosis.refit.Refitter`): the plausible candidates' augmented MuJoCo models
   replay the training runs; the best is sized, and kept only if it removes most of the misfit.
   Then (:func:`~momentid.diagnosis.compound.extend`) what it leaves is screened again: every further
   mechanism that earns its place is named, and all are refitted jointly in one model.
7. **Report** (:mod:`~momentid.diagnosis.report`): the held-out run replayed through the linear and
   augmented models (NRMSE before/after), the summary and the report folder.
8. **Open search** (:func:`~momentid.diagnosis.discovery.discover`), on an ``unexplained`` verdict only:
   a sparse force from a function library, located, put into the MuJoCo model and replayed on the
   held-out run (``discovered``; the verdict stays ``unexplained``, at the discovered place).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from momentid import mechanisms
from momentid.core.series import Experiment
from momentid.diagnosis.compound import extend
from momentid.diagnosis.discovery import as_unexplained, challenge, discover
from momentid.diagnosis.refit import replay_check
from momentid.diagnosis.report import Diagnosis, summary, write_report
from momentid.diagnosis.screening import Candidate
from momentid.diagnosis.stages import run_stages
from momentid.diagnosis.thresholds import ACCEPTED, EXCESS, EXPLAINED
from momentid.errors import MomentidError

__all__ = ["Candidate", "Diagnosis", "diagnose", "write_report", "verdicts", "EXCESS", "EXPLAINED", "ACCEPTED"]


def verdicts() -> tuple[str, ...]:
    """Every verdict :func:`diagnose` can give: ``none``, ``unexplained``, a mechanism of the library, or
    (recordings without added mass) ``amplitude_dependence``."""
    from momentid.diagnosis.real import AMPLITUDE_DEPENDENCE
    return ("none", "unexplained") + tuple(kind.name for kind in mechanisms.library()) + (AMPLITUDE_DEPENDENCE,)

#: Candidates listed in the report, best first.
REPORTED_CANDIDATES = 8


def diagnose(experiment: Experiment, *, replay: bool = True, hold_out: str | None = None):
    """Find, name and model the physics the linear shear model leaves out.

    Parameters
    ----------
    experiment : Experiment
        At least two runs (one with added mass); with three or more, the last
        run is held out for the before/after replay.
    replay : bool
        Replay the held-out run through the linear and augmented MuJoCo models
        (the NRMSE figures); off only for quick screening.

    hold_out : str, optional
        Runs without added mass only: the run to hold out (default: the last).

    Returns
    -------
    Diagnosis, or ModalDiagnosis when no run adds mass (accelerometer-only labs:
    :func:`momentid.diagnosis.real.diagnose_modal`)
    """
    if not any(np.any(run.added_mass) for run in experiment.runs):
        from momentid.diagnosis.real import diagnose_modal
        return replace(diagnose_modal(experiment, hold_out=hold_out), notes=tuple(experiment.notes))
    if hold_out is not None:
        raise MomentidError(f"{experiment.source}: hold_out = {hold_out!r}: choosing the held-out run works for "
                            f"runs without added mass only; this experiment adds mass (its last run is held out)")
    # Thousands of small dense products (8 x 8 exponentials in the errors-in-variables refits): BLAS
    # threads only add waiting, 6x on a busy 2-core machine.
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(experiment, replay)


def _diagnose(experiment: Experiment, replay: bool):
    """:func:`diagnose` of an experiment with added mass."""
    stages = run_stages(experiment, replay=replay)
    model, residuals, sensors, where = stages.model, stages.residuals, stages.sensors, stages.where
    screening, refitter = stages.screening, stages.refitter
    joint = extend(stages, replay=replay)
    found = joint.finding
    before = after = float("nan")
    curves, xml = {}, ""
    if replay:
        before, after, curves, xml = replay_check(model, refitter.linear_structure, found.structure, joint.entries,
                                                  found.records)
    discovered = discover(model, residuals, refitter, found, before)   # the open search, on "unexplained"
    if discovered is None and joint.mechanisms:   # ... and against named physics that leaves a misfit
        discovered = challenge(model, residuals, refitter, found, joint.entries, before, sensors.fault)
        if discovered is not None:   # a force outside the library beats the library's names
            found = as_unexplained(found, discovered, refitter)
            joint = replace(joint, finding=found, mechanisms=(), entries=())
            before, after, curves, xml = replay_check(model, refitter.linear_structure, found.structure, (), ())
    location = discovered.location if discovered is not None else found.location
    run, held_out = model.evaluation_run.name, model.holdout is not None
    text = summary(found.mechanism, location, found.parameters, found.std, residuals.excess,
                   screening.replay.excess, before, after, run, held_out, sensors.to_dict(), found.selection,
                   where.words, joint.mechanisms, discovered)
    return Diagnosis(mechanism=found.mechanism, location=location, parameters=found.parameters,
                     std=found.std, nrmse_before=before, nrmse_after=after, excess_equation=residuals.excess,
                     excess_replay=screening.replay.excess,
                     candidates=tuple(sorted(screening.candidates, key=lambda c: -c.explained)[:REPORTED_CANDIDATES]),
                     summary=text, holdout=run if held_out else f"{run} (no run held out)",
                     parameter_pattern=screening.pattern_info, sensor_check=sensors.to_dict(),
                     selection=found.selection, localisation=where.to_dict(), augmented_xml=xml, curves=curves,
                     notes=tuple(experiment.notes), mechanisms=joint.mechanisms, discovered=discovered)
