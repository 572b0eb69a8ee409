"""The diagnosis of a rig identified with added masses: locate the mismatch, name the physics, add it.

:func:`diagnose_added_mass` runs the stages, with typed results between them (the stage numbers of
``docs/diagnosis.md``; stage 0, the channels by themselves, ran before: :mod:`~momentid.diagnosis.data_check`):

1. **Linear model** (:func:`~momentid.diagnosis.added_mass.residuals.fit_linear_model`): identified from the
   training runs, beside the nominal model the lab states.
2. **Residuals** (:func:`~momentid.diagnosis.added_mass.residuals.equation_residuals`): the force per floor the
   linear model leaves unexplained, against what sensor noise alone leaves.
3. **Sensor check** (:func:`~momentid.diagnosis.added_mass.sensor_faults.check_sensors`): the channels against
   each other (``a_j = zdd + q_j''``).
4. **Localisation** (:func:`~momentid.diagnosis.added_mass.locate.locate`): storey, runs, time, amplitude,
   band and shape of the mismatch.
5. **Screening** (:func:`~momentid.diagnosis.added_mass.selection.screen`): every mechanism of the registry
   (:mod:`momentid.mechanisms`) fitted at every place of its target, in the equation and replay
   residuals; :func:`~momentid.diagnosis.added_mass.selection.choose` names the verdict.
6. **Refit by re-simulation and selection** (:func:`~momentid.diagnosis.added_mass.selection.select`,
   :class:`~momentid.diagnosis.added_mass.resimulation.Refitter`): the plausible candidates' augmented MuJoCo models
   replay the training runs; the best is sized, and kept only if it removes most of the misfit.
   Then (:func:`~momentid.diagnosis.added_mass.compound.extend`) what it leaves is screened again: every further
   mechanism that earns its place is named, and all are refitted jointly in one model; when a sensor
   fault is to be undone first, stages 1-6 run again on the corrected recordings (:func:`_compound`).
7. **Report** (:mod:`~momentid.diagnosis.report`): the held-out run replayed through the linear and
   augmented models (NRMSE before/after), the :class:`~momentid.diagnosis.result.Diagnosis` and its
   report folder.
8. **Open search** (:func:`~momentid.diagnosis.added_mass.open_search.discover`), on an ``unexplained`` verdict:
   a sparse force from a function library, located, put into the MuJoCo model and replayed on the
   held-out run (``discovered``; the verdict stays ``unexplained``, at the discovered place).  When
   the named physics' model still replays above the noise, the open search challenges it
   (:func:`~momentid.diagnosis.added_mass.open_search.challenge`): a force outside the library that removes most
   of what it leaves makes the verdict ``unexplained``, at the force's place.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from momentid.core.series import Experiment
from momentid.diagnosis.added_mass.compound import Compound, Correction, extend
from momentid.diagnosis.added_mass.open_search import as_unexplained, challenge, discover
from momentid.diagnosis.added_mass.resimulation import noise_carrier, noise_ratios
from momentid.diagnosis.added_mass.augmented import replay_check
from momentid.diagnosis.added_mass.words import AddedMassEvidence
from momentid.diagnosis.result import Diagnosis
from momentid.diagnosis.added_mass.stages import Stages, run_stages

__all__ = ["diagnose_added_mass", "REPORTED_CANDIDATES"]

#: Candidates listed in the report, best first.
REPORTED_CANDIDATES = 8


def _compound(stages: Stages, replay: bool, corrections: int | None = None) -> Compound:
    """Stage 6b on ``stages``; when it asks for recordings with a sensor fault undone to be diagnosed
    first (a :class:`~momentid.diagnosis.added_mass.compound.Correction`), stages 1-6 run on them, with their own
    refitter, and their diagnosis is handed back."""
    out = extend(stages, replay=replay) if corrections is None else extend(stages, replay=replay,
                                                                             corrections=corrections)
    if isinstance(out, Correction):
        again = run_stages(out.experiment, replay=True, result=out.identification)
        return out.then(_compound(again, True, out.corrections))
    return out


def diagnose_added_mass(experiment: Experiment, replay: bool = True) -> Diagnosis:
    """The diagnosis of an experiment with added mass (the module docstring's stages).

    Parameters
    ----------
    experiment : Experiment
        At least two runs, one with added mass; with three or more the last is held out.
    replay : bool
        Replay the held-out run through the linear and augmented models (the NRMSE figures).

    Returns
    -------
    Diagnosis
        With an :class:`~momentid.diagnosis.added_mass.words.AddedMassEvidence`.
    """
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
