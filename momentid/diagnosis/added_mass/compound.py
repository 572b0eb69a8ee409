"""Stage 6b of the added-mass diagnosis: several mechanisms at once.

After stage 6 names one mechanism (a :class:`~momentid.diagnosis.added_mass.selection.Finding`),
:func:`extend` asks what is left with it in the model, and names every further mechanism that
earns its place:

* a **sensor fault** (a kind sized by ``Refit.CORRECT_DATA``) is undone on every run, and unless the
  corrected training replays are at the noise level (within ``EXCESS``), the corrected experiment is
  diagnosed again (the physics behind a faulty channel is found on clean data);
* with a **physical mechanism** in the model, the library is screened again on what it leaves: its
  signature's columns are fitted with every candidate's (:func:`~momentid.diagnosis.added_mass.screening.
  screen_equation` with ``found``), on the equation residual's alternate blocks.  The best candidate
  of each kind that explains at least ``SHORTLIST_FLOOR`` of the excess left on the held-out blocks
  is re-simulated (beside a dashpot of the damping pattern, a dissipative force at its link too),
  and the model with it must remove at least ``EARNS`` of the training replays' misfit above noise
  that the model without it leaves.  The loop stops when none does, when the replays are at the
  noise level, or at ``MAX_MECHANISMS``.  The trials of a step run on two processes
  (:mod:`~momentid.core.processes`) and return their results as values.  (What a step screens:
  :mod:`~momentid.diagnosis.added_mass.compound_screening`.)  Then every mechanism named is **re-tested** by
  the same rule with the others in the model: the model without it, its other sizes searched again,
  must leave ``EARNS`` more of the misfit; the weakest that does not is dropped (:func:`_retest`);
* beside the physics, a **sensor fault** that contended with it in screening is undone and the
  corrected experiment diagnosed again (:func:`_fault_beside`); else a fault of the table channel
  that only the physics makes visible is sized by re-simulation with it (:func:`_table_fault`).

Every size is then refitted jointly (errors-in-variables with every force as an input, the damping
pattern on the refitted C, then each force's size searched by re-simulation with the others in the
model), and one augmented MuJoCo model carries them all.

Diagnosing corrected recordings again is not done here: :func:`extend` returns a :class:`Correction`
(the corrected experiment, and what to do with its diagnosis), and the pipeline
(:func:`momentid.diagnosis.added_mass.path.diagnose_added_mass`) runs the stages on it with their own refitter.

A stage-6 verdict of ``unexplained`` whose best candidate removed part of the misfit is also
extended: when that candidate and the further ones together remove ``ACCEPTED`` of the training
replays' misfit above noise, they are the diagnosis.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace
from collections.abc import Callable

from momentid.core.series import Experiment
from momentid.core.structure import Structure
from momentid.diagnosis.added_mass.compound_screening import (STEP_SHORTLIST, candidates, elastic, force_entries,
                                                              refitted, shortlist)
from momentid.diagnosis.added_mass.resimulation import SEARCH_RANGE, ForceRefit
from momentid.diagnosis.added_mass.augmented import Entry, identified_structure, records
from momentid.diagnosis.added_mass.screening import Candidate, Domain, pattern_fit
from momentid.diagnosis.added_mass.selection import Finding, Step, explained_share
from momentid.diagnosis.added_mass.stages import Stages
from momentid.diagnosis.thresholds import ACCEPTED, EXCESS, EXPLAINED
from momentid.diagnosis.verdict import Named, Verdict
from momentid.core.processes import run_forked
from momentid.mechanisms.base import Refit
from momentid.mechanisms.place import Place

__all__ = ["Compound", "Correction", "extend", "MAX_MECHANISMS", "STEP_SHORTLIST", "MAX_CORRECTIONS", "shortlist"]

#: At most this many mechanisms in one diagnosis: a guard on the loop, not the rule that stops it
#: (a further mechanism must earn its place, ``EARNS``).
MAX_MECHANISMS = 3
#: The joint refinement of a size found alone searches this range around it (the other mechanism
#: shifts it by tens of percent at most; a newcomer's regression may be 3x low: see refit.SEARCH_RANGE).
JOINT_SPAN = (0.7, 1.4)
#: Sizes replayed on a grid over the search range before each search of :func:`_descend` (a start
#: sized on the wrong model may be off by more than a sharp misfit's basin: P-Delta 1.8x too large
#: collapses the storey).  11: a factor 1.26 between neighbours over SEARCH_RANGE's factor of 10.
DESCENT_GRID = 11
#: Sensor faults undone and the stages run again at most this many times.
MAX_CORRECTIONS = 2


@dataclass(frozen=True)
class Compound:
    """Stage 6b: every mechanism of the diagnosis and their joint model.

    Attributes
    ----------
    finding : Finding
        The verdict: the primary mechanism (the first found) and the joint model's structure and records.
    mechanisms : tuple of Named
        Every named mechanism, primary first (empty for ``none`` and ``unexplained``).
    entries : tuple of Entry
        Each of them as :func:`~momentid.diagnosis.added_mass.augmented.joint_replay` replays them (sensor faults
        first: undone on the recordings).
    steps : tuple of Step
        Each further mechanism tried, and whether it earned its place.
    score : float or None
        The training runs' NRMSE through the joint model, when it was replayed.
    """

    finding: Finding
    mechanisms: tuple[Named, ...]
    entries: tuple[Entry, ...]
    steps: tuple[Step, ...] = ()
    score: float | None = None


@dataclass(frozen=True)
class Correction:
    """A request of :func:`extend`: diagnose ``experiment`` (the recordings with a sensor fault undone,
    whose training runs are identified as ``identification``) with at most ``corrections`` further
    corrections, then hand its :class:`Compound` to ``then``, which returns the diagnosis."""

    experiment: Experiment
    identification: object
    corrections: int
    then: Callable[[Compound], Compound]


@dataclass(frozen=True)
class _Start:
    """The mechanism a compound diagnosis continues from, its standard errors and its model's structure."""

    entry: Entry
    std: dict
    structure: Structure


def extend(stages: Stages, *, replay: bool, corrections: int = MAX_CORRECTIONS) -> Compound | Correction:
    """Stage 6b: continue from stage 6's finding (``stages.found``) on what it leaves (see the module
    docstring); ``replay`` off: stage 6's answer as it is.  A :class:`Correction` when the recordings
    with a sensor fault undone are to be diagnosed first (the caller runs the stages on them)."""
    if not replay:
        return _single(stages.found)
    start = _start(stages)
    if start is None:
        return _single(stages.found)
    if start.entry.kind.refit is Refit.CORRECT_DATA:
        return _after_correction(stages, start, corrections)
    physics = _physics(stages, start)
    return _fault_beside(stages, physics, corrections) if physics.mechanisms and corrections else physics


def _single(found: Finding) -> Compound:
    if found.kind is None:
        return Compound(found, (), ())
    named = Named(found.mechanism, found.location, found.parameters, found.std)
    return Compound(found, (named,), (Entry(found.kind, found.place, found.parameters),))


def _start(stages: Stages) -> _Start | None:
    """The mechanism to continue from: stage 6's, or the partial candidate of an ``unexplained``."""
    found, refitter, screening = stages.found, stages.refitter, stages.screening
    if found.kind is not None:
        return _Start(Entry(found.kind, found.place, found.parameters), found.std, found.structure)
    part = found.selection.partial
    if part is None:
        return None
    extra = [screening.pattern.candidate] if screening.pattern else []
    for c in list(screening.pool) + extra:
        if c.same_as(part.candidate):
            aug = part.augmented if c == part.candidate else refitter.augment(c.kind, c.place, c.parameters, c.std)
            params = dict(aug.parameters, **part.parameters)
            return _Start(Entry(c.kind, c.place, params), aug.std or c.std, aug.structure)
    return None


def _corrected(experiment: Experiment, entry: Entry) -> Experiment:
    """``experiment`` with the sensor fault ``entry`` undone on every run."""
    return replace(experiment, runs=tuple(entry.kind.correct_run(r, entry.place, entry.parameters)
                                          for r in experiment.runs))


def _after_correction(stages: Stages, start: _Start, corrections: int) -> Compound | Correction:
    """A sensor fault: undo it on every run and diagnose the corrected experiment.

    A fault that stage 6 left ``unexplained`` (it removed too little alone) is named with what the
    corrected data show only when together they remove ``ACCEPTED`` of the training replays' misfit
    above noise.
    """
    found, refitter = stages.found, stages.refitter
    entry = start.entry
    first = _single(found)
    left, noise = found.selection.augmented, found.selection.noise
    if corrections == 0 or (found.verdict is not Verdict.UNEXPLAINED and left is not None and left <= EXCESS * noise):
        return first   # the corrected recordings' replays are at the noise level: nothing more to find
    known = refitter.identify_corrected(*entry)   # identified while the fault was sized

    def then(again: Compound) -> Compound:
        if not again.mechanisms or any((e.kind, e.place) == (entry.kind, entry.place) for e in again.entries):
            return first   # nothing more (or the same fault again: its correction is all there is)
        entries = (entry,) + again.entries
        selection = replace(found.selection, after_correction=again.finding.selection)
        if found.verdict is Verdict.UNEXPLAINED:
            score = refitter.score_joint(again.finding.structure, entries, again.finding.records)
            share = explained_share(refitter.linear_score(), score, refitter.noise_nrmse())
            selection = replace(selection, joint=score, joint_explained=share)
            if share < ACCEPTED:
                return Compound(replace(found, selection=selection), (), (), again.steps)
        kind, place, params = entry
        joint = Finding(Verdict.MECHANISM, kind, place, place.location, params, start.std, again.finding.structure,
                        again.finding.records, selection)
        named = Named(kind.name, place.location, params, start.std)
        return Compound(joint, (named,) + again.mechanisms, entries, again.steps)
    return Correction(_corrected(stages.model.experiment, entry), known, corrections - 1, then)


def _quadrature(sim_std: dict, std: dict) -> dict:
    """A search's standard errors (conditional on the linear model) with a refit's (marginal), in quadrature."""
    return {k: float(math.hypot(v, std.get(k, 0.0))) for k, v in sim_std.items()}


def _joint(stages: Stages, entries, stds, *, newcomer: bool, at: Place | None = None):
    """The joint model of ``entries`` (:class:`Entry` each): the linear part refitted with every
    force, and sizes searched by re-simulation with the others in the model.

    With ``newcomer``, the last entry is new: it starts from the joint regression and only its size
    is searched (over the full range); without, every size but the last is searched again around its
    value (``JOINT_SPAN``: one pass of coordinate descent after a newcomer joined); with ``at``, the
    place of a mechanism that left, the sizes of the forces at its link (those that can take in what it
    did, as a storey's friction does its damper's dissipation).  A newcomer whose size is not searched (a dashpot
    read from the damping pattern) has the others' sizes searched again beside it instead: they were
    sized without it and took in what it does (a friction grown by the damper's dissipation).
    Returns (structure, entries, stds), or None when a size comes out unphysical.
    """
    refitter, model = stages.refitter, stages.model
    entries, stds = list(entries), [dict(s) for s in stds]
    last = len(entries) - 1
    searched = set(range(last)) if at is None else {i for i, e in enumerate(entries) if _same_link(e.place, at)}
    if newcomer and entries[last].kind.refit is Refit.RESIMULATE:
        searched = {last}
    forces = [i for i, e in enumerate(entries) if e.kind.refit is Refit.RESIMULATE]
    result, structure = model.result, refitter.linear_structure
    refit = refitted(stages, entries)
    if refit is not None:
        result = refit.result
        structure = identified_structure(result, model.nominal)
        for i, p, s in zip(forces, refit.parameters, refit.std):
            if i in searched:             # to be searched: the refit's std, in quadrature below
                stds[i] = dict(s)
            if newcomer and i == last:    # the newcomer starts from the joint regression
                entries[i] = entries[i]._replace(parameters=p)
    for i, (kind, place, params) in enumerate(entries):
        if kind.refit is Refit.DAMPING_PATTERN:
            _, (a, b, c) = pattern_fit(elastic(stages, entries, result), kind.damping_pattern(place, model.storeys))
            structure = replace(structure, rayleigh_mu=max(a, 0.0), rayleigh_kappa=max(b, 0.0))
            entries[i] = Entry(kind, place, dict(params, **{kind.fitted.name: float(c)}))
    if not all(e.kind.physical(e.parameters) for e in entries):
        return None
    if model.nominal is not None:
        structure = refitter.better_of((structure, model.nominal), entries)
    for i in forces:
        if i not in searched:
            continue
        params, sim_std = refitter.resimulate(structure, entries[i], entries[:i] + entries[i + 1:],
                                              SEARCH_RANGE if i == last and newcomer else JOINT_SPAN)
        entries[i] = entries[i]._replace(parameters=params)
        stds[i] = _quadrature(sim_std, stds[i])
    return structure, entries, stds


def _descend(stages: Stages, entries, stds):
    """The lab's nominal model with every force of ``entries`` sized by re-simulation in turn (over the
    full range, the others in the model as they stand), starting from the joint regression.

    For a start that stage 6 left partial: its size was searched on a model that lacked the newcomer
    and took in what the newcomer does (P-Delta grown to absorb a friction's effect), and the linear
    part identified beside it has taken in the rest (the friction as viscous damping); the nominal
    model has taken in neither.  Returns (structure, entries, stds), or None (no nominal model, no joint
    regression, or a size it makes unphysical).
    """
    refitter, nominal = stages.refitter, stages.model.nominal
    refit = refitted(stages, entries)
    if nominal is None or refit is None:
        return None
    entries, stds = list(entries), [dict(s) for s in stds]
    forces = [i for i, e in enumerate(entries) if e.kind.refit is Refit.RESIMULATE]
    for i, p in zip(forces, refit.parameters):
        entries[i] = entries[i]._replace(parameters=p)
    if not all(e.kind.physical(e.parameters) for e in entries):
        return None
    for i in forces:
        params, sim_std = refitter.resimulate(nominal, entries[i], entries[:i] + entries[i + 1:], grid=DESCENT_GRID)
        entries[i] = entries[i]._replace(parameters=params)
        stds[i] = _quadrature(sim_std, stds[i])
    return nominal, entries, stds


class _How(enum.Enum):
    """How a newcomer is tried: the joint model (:func:`_joint`) or the descent (:func:`_descend`);
    or a mechanism re-tested: the joint model of the others, those at its link re-sized (``WITHOUT``)."""

    JOINT = "joint"
    DESCENT = "descent"
    WITHOUT = "without"


@dataclass(frozen=True)
class _Task:
    """One trial of a step: a newcomer ``candidate`` beside the mechanisms found, and how it is sized
    (``WITHOUT``: ``entries`` are the mechanisms found but the one at ``at``; ``candidate`` is None)."""

    candidate: Candidate | None
    how: _How
    entries: tuple[Entry, ...]
    stds: tuple[dict, ...]
    at: Place | None = None


@dataclass(frozen=True)
class _Trial:
    """What a trial returns: the training NRMSE of its joint model (None: a size came out unphysical),
    the model, and the errors-in-variables refit of its forces (recorded by the refitter)."""

    task: _Task
    score: float | None
    structure: Structure | None
    entries: tuple[Entry, ...]
    stds: tuple[dict, ...]
    forces: tuple[Entry, ...]
    refit: ForceRefit | None


def _trial(stages: Stages, task: _Task) -> _Trial:
    """One trial (runs in a worker process: its results come back as this value)."""
    if task.how is _How.DESCENT:
        sized = _descend(stages, task.entries, task.stds)
    else:
        sized = _joint(stages, task.entries, task.stds, newcomer=task.how is _How.JOINT, at=task.at)
    forces = tuple(force_entries(stages, task.entries))
    refit = stages.refitter.refit_forces(forces) if forces else None
    if sized is None:
        return _Trial(task, None, None, task.entries, task.stds, forces, refit)
    structure, entries, stds = sized
    score = stages.refitter.score_joint(structure, entries, records(entries))
    return _Trial(task, score, structure, tuple(entries), tuple(stds), forces, refit)


def _physics(stages: Stages, start: _Start) -> Compound:
    """Physical mechanisms: add the one that earns its place most, while one does."""
    refitter, found = stages.refitter, stages.found
    entries, stds, structure = [start.entry], [dict(start.std)], start.structure
    noise, linear = refitter.noise_nrmse(), refitter.linear_score()
    score = refitter.score_joint(structure, entries, records(entries))
    partial = found.verdict is Verdict.UNEXPLAINED   # the start was sized on a model that lacked the rest
    steps = []
    while len(entries) < MAX_MECHANISMS and score > EXCESS * noise:
        tasks = []
        for c in shortlist(candidates(stages, entries)):
            trial = (tuple(entries) + (Entry(c.kind, c.place, dict(c.parameters)),), tuple(stds) + (dict(c.std),))
            tasks.append(_Task(c, _How.JOINT, *trial))
            if partial and len(entries) == 1 and c.kind.refit is Refit.RESIMULATE:
                tasks.append(_Task(c, _How.DESCENT, *trial))
        trials = [t for t in _run(stages, tasks) if t.score is not None]
        if not trials:
            break
        best = min(trials, key=lambda t: t.score)
        c = best.task.candidate
        steps.append(Step(c.mechanism, c.location, c.explained, score, best.score, noise,
                          explained_share(score, best.score, noise)))
        if not steps[-1].earned and partial and len(entries) == 1:
            # the partial start may be wrong (a damper taking in a friction's dissipation a storey
            # away): the two best newcomers together, without it
            best = _pair(stages, trials)
            if best is not None:
                c = best.task.candidate
                steps.append(Step(c.mechanism, c.location, c.explained, score, best.score, noise,
                                  explained_share(score, best.score, noise)))
        if not steps[-1].earned:
            break
        score, structure, entries, stds = best.score, best.structure, list(best.entries), list(best.stds)
    steps = tuple(steps)
    if len(entries) == 1:   # stage 6's answer stands
        return replace(_single(replace(found, selection=replace(found.selection, steps=steps))), steps=steps,
                       score=score)
    if any(e.kind.refit is Refit.RESIMULATE for e in entries[:-1]) and entries[-1].kind.refit is Refit.RESIMULATE:
        # the earlier sizes were searched before the last mechanism came in: refine them with it (a
        # dashpot's trial did, :func:`_joint`)
        joint = _joint(stages, entries, stds, newcomer=False)
        if joint is not None:
            structure, entries, stds = joint
            score = refitter.score_joint(structure, entries, records(entries))
    structure, entries, stds, score, retests = _retest(stages, structure, entries, stds, score)
    steps += retests
    overall = explained_share(linear, score, noise)
    selection = replace(found.selection, steps=steps, joint=score, joint_explained=overall)
    if found.verdict is Verdict.UNEXPLAINED and overall < ACCEPTED:   # together still too little: unexplained
        return Compound(replace(found, selection=selection), (), (), steps, score)
    named = tuple(_named(stages, e, sd) for e, sd in zip(entries, stds))
    first = entries[0]
    finding = Finding(Verdict.MECHANISM, first.kind, first.place, named[0].location, named[0].parameters,
                      named[0].std, structure, records(entries), selection)
    return Compound(finding, named, tuple(entries), steps, score)


def _pair(stages: Stages, trials) -> _Trial | None:
    """The two newcomers whose trials beside a partial start replayed best (storey forces at two
    places), sized together by the descent on the lab's nominal model without the start: its trial,
    or None (fewer than two such newcomers, or a size unphysical)."""
    ranked, places = [], set()
    for t in sorted(trials, key=lambda t: t.score):
        c = t.task.candidate
        if c is not None and c.kind.refit is Refit.RESIMULATE and c.place not in places:
            places.add(c.place)
            ranked.append(c)
    if len(ranked) < 2:
        return None
    c1, c2 = ranked[:2]
    entries = (Entry(c1.kind, c1.place, dict(c1.parameters)), Entry(c2.kind, c2.place, dict(c2.parameters)))
    trial = _run(stages, [_Task(c2, _How.DESCENT, entries, (dict(c1.std), dict(c2.std)))])[0]
    return trial if trial.score is not None else None


def _same_link(place: Place, other: Place) -> bool:
    """Whether two places are the same link between two nodes of the rig."""
    return place.target.link and other.target.link and place.nodes == other.nodes


def _run(stages: Stages, tasks) -> list[_Trial]:
    """The trials of ``tasks``, on the worker processes; their refits recorded by the refitter.

    The descents (a grid of replays for each force) start first, so that the short trials fill
    the cores at the end; the trials come back in the order of ``tasks``.
    """
    order = sorted(range(len(tasks)), key=lambda i: tasks[i].how is not _How.DESCENT)
    trials: list = [None] * len(tasks)
    for i, t in zip(order, run_forked(lambda task: _trial(stages, task), [tasks[i] for i in order])):
        trials[i] = t
    for t in trials:
        if t.forces:
            stages.refitter.remember_refit(t.forces, t.refit)
    return trials


def _retest(stages: Stages, structure, entries, stds, score):
    """Every mechanism named is tested again by the rule it joined by, now that the others are in the
    model: the model without it (the linear part refitted with the other forces, the sizes of those at
    its link searched again) must leave at least ``EARNS`` more misfit above noise than the model with it.  The one that
    earns least is dropped; the others are tested again only when more than one did not earn (one that
    earned beside a mechanism adding less than ``EARNS`` keeps its verdict).  (A mechanism found first
    may hold what a later one does: a friction's dissipation taken in by a storey damper before the
    friction joined.)  The last to join earned its place beside all the others and is not tested
    again until one leaves.  Returns (structure, entries, stds, score, steps).
    """
    noise, steps = stages.refitter.noise_nrmse(), []
    tested = list(range(len(entries) - 1))
    while tested:
        tasks = [_Task(None, _How.WITHOUT, tuple(entries[:i] + entries[i + 1:]), tuple(stds[:i] + stds[i + 1:]),
                       entries[i].place) for i in tested]
        trials = [(i, t) for i, t in zip(tested, _run(stages, tasks)) if t.score is not None]
        # (a model without it that replays within the noise, or better than with it: it removes nothing)
        retests = [(Step(entries[i].kind.name, entries[i].place.location, None, t.score, score, noise,
                         explained_share(t.score, score, noise) if t.score > max(score, noise) else 0.0,
                         retest=True), t) for i, t in trials]
        steps += [s for s, _ in retests]
        failed = [st for st in retests if not st[0].earned]
        if not failed:
            break
        t = min(failed, key=lambda st: st[0].explained)[1]
        structure, entries, stds, score = t.structure, list(t.entries), list(t.stds), t.score
        tested = list(range(len(entries))) if len(failed) > 1 and len(entries) > 1 else []
    return structure, entries, stds, score, tuple(steps)


def _fault_beside(stages: Stages, physics: Compound, corrections: int) -> Compound | Correction:
    """A sensor fault beside the physics found: the one screening explains best (at least
    ``EXPLAINED`` of the equation residual's excess), of those that contended with the physics
    (:func:`_contender`), is undone on every run and the corrected experiment diagnosed again; the
    fault joins when the corrected diagnosis with it removes at least ``EARNS`` of the training
    replays' misfit above noise that the physics alone leaves.

    (A fault that screens well may lose stage 6's replay to physics that takes in part of its effect,
    a storey damper for a biased displacement transducer; what the physics leaves then holds the rest.)
    """
    refitter = stages.refitter
    noise = refitter.noise_nrmse()
    score = physics.score
    if score <= EXCESS * noise:
        return physics
    faults = [c for c in sorted(stages.screening.candidates, key=lambda c: -c.explained)
              if c.kind.refit is Refit.CORRECT_DATA and c.explained >= EXPLAINED and _contender(stages, physics, c)]
    if not faults:
        return _table_fault(stages, physics)
    c = faults[0]
    fault = Entry(c.kind, c.place, dict(c.parameters))

    def then(again: Compound) -> Compound:
        if not again.entries:
            return physics
        entries = (fault,) + again.entries
        after = refitter.score_joint(again.finding.structure, entries, again.finding.records)
        step = Step(c.mechanism, c.location, c.explained, score, after, noise, explained_share(score, after, noise))
        steps = physics.steps + (step,)
        if not step.earned:
            finding = replace(physics.finding, selection=replace(physics.finding.selection, steps=steps))
            return replace(physics, finding=finding, steps=steps)
        selection = replace(physics.finding.selection, steps=steps, after_correction=again.finding.selection,
                            joint=after)
        named = again.mechanisms + (Named(c.mechanism, c.location, fault.parameters, dict(c.std)),)
        return Compound(replace(again.finding, selection=selection), named, entries, steps, after)
    return Correction(_corrected(stages.model.experiment, fault), refitter.identify_corrected(*fault),
                      corrections - 1, then)


def _table_fault(stages: Stages, physics: Compound) -> Compound:
    """A fault of the table channel beside the physics found, by re-simulation: of those the replay
    screening fitted (:func:`~momentid.diagnosis.added_mass.screening.screen_replay`) and the kinematic check
    does not rule out, the one that replays best with the physics at its screened size is sized with
    the physics in the model, and joins when it removes at least ``EARNS`` of the training replays'
    misfit above noise that the physics alone leaves.

    Screening fits a table channel's faults on the linear model's replay, where a bias of the table
    accelerometer is a step response that the band removes almost entirely; a storey that slips by
    friction turns the same bias into a steady shear (the floors' weight times it) that makes its
    slips one-sided: the fault shows only with the physics in the model.  (The floor equations, which
    named the physics, do not read the table channel: the physics stands as found.)  Physics the MJCF
    holds as springs and dashpots (no ``callback`` force) leaves the model linear: screening's replay
    was the faults' test.
    """
    refitter, found = stages.refitter, physics.finding
    noise, score = refitter.noise_nrmse(), physics.score
    faults = [c for c in stages.screening.candidates if c.domain is Domain.REPLAY
              and c.kind.refit is Refit.CORRECT_DATA and c.kind.physical(c.parameters)]
    if score is None or score <= EXCESS * noise or not faults or not any(e.kind.callback for e in physics.entries):
        return physics

    def replayed(c: Candidate, params: dict) -> float:
        entries = (Entry(c.kind, c.place, params),) + physics.entries
        return refitter.score_joint(found.structure, entries, found.records)
    c = min(faults, key=lambda c: replayed(c, c.parameters))
    params, std = refitter.resimulate(found.structure, Entry(c.kind, c.place, dict(c.parameters)), physics.entries)
    after = replayed(c, params)
    step = Step(c.mechanism, c.location, c.explained, score, after, noise, explained_share(score, after, noise))
    steps = physics.steps + (step,)
    if not step.earned:
        return replace(physics, finding=replace(found, selection=replace(found.selection, steps=steps)), steps=steps)
    fault = Entry(c.kind, c.place, params)
    finding = replace(found, selection=replace(found.selection, steps=steps, joint=after))
    return Compound(finding, physics.mechanisms + (Named(c.mechanism, c.location, params, std),),
                    (fault,) + physics.entries, steps, after)


def _contender(stages: Stages, physics: Compound, fault: Candidate) -> bool:
    """Whether a sensor fault contended with the physics named: stage 6 re-simulated it (it was the
    screening's choice), or it screens at least as well as any of the physics named.  (Diagnosing the
    corrected experiment costs a second pass of stages 1-6: not for every fault that screens well
    beside a force whose replay is imperfect.)"""
    if any(t.candidate.same_as(fault) for t in stages.found.selection.tried):
        return True
    named = {(e.kind, e.place) for e in physics.entries}
    rivals = [c.explained for c in stages.screening.candidates if (c.kind, c.place) in named]
    return fault.explained >= max(rivals, default=math.inf)


def _named(stages: Stages, entry: Entry, std: dict) -> Named:
    """A mechanism in the lab's terms; a damper from the damping pattern takes the standard error of
    the same damper fitted to the equation residual (as stage 6 does)."""
    kind, place, params = entry
    key = kind.fitted.name
    if kind.refit is Refit.DAMPING_PATTERN and not std.get(key):
        same = [c for c in stages.screening.candidates
                if c.kind is kind and c.place == place and c.std.get(key)]
        if same:
            std = {key: float(max(same, key=lambda c: c.explained).std[key])}
    params, std = kind.in_lab_terms(params, std, place, stages.model.nominal)
    return Named(kind.name, place.location, params, std)
