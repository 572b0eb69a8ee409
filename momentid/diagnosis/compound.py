"""Stage 6b of the diagnosis: several mechanisms at once.

After stage 6 names one mechanism (a :class:`~momentid.diagnosis.selection.Finding`),
:func:`extend` asks what is left with it in the model, and names every further mechanism that
earns its place:

* a **sensor fault** (a kind sized by ``Refit.CORRECT_DATA``) is undone on every run, and unless the
  corrected training replays are at the noise level (within ``EXCESS``), the stages run again on the
  corrected experiment (the physics behind a faulty channel is found on clean data);
* with a **physical mechanism** in the model, the library is screened again on what it leaves: its
  signature's columns are fitted with every candidate's (:func:`~momentid.diagnosis.screening.
  screen_equation` with ``found``), on the equation residual's alternate blocks.  The best candidate
  of each kind that explains at least ``SHORTLIST_FLOOR`` of the excess left on the held-out blocks
  is re-simulated (beside a damper of the damping pattern, a dissipative storey force there too),
  and the model with it must remove at least ``EARNS`` of the training replays' misfit above noise
  that the model without it leaves.  The loop stops when none does, when the replays are at the
  noise level, or at ``MAX_MECHANISMS``.  The trials of a step run on two processes
  (:mod:`~momentid.diagnosis.workers`);
* beside the physics, a **sensor fault** that contended with it in screening is undone and the
  corrected experiment diagnosed again (:func:`_fault_beside`).

Every size is then refitted jointly (errors-in-variables with every storey force as an input,
the damping pattern on the refitted C, then each storey force's size searched by re-simulation
with the others in the model), and one augmented MuJoCo model carries them all.

A stage-6 verdict of ``unexplained`` whose best candidate removed part of the misfit is also
extended: when that candidate and the further ones together remove ``ACCEPTED`` of the training
replays' misfit above noise, they are the diagnosis.
"""

from __future__ import annotations

import enum
import json
import math
from dataclasses import dataclass, replace

from momentid import mechanisms
from momentid.core.structure import Mechanism
from momentid.diagnosis.refit import SEARCH_RANGE, identified_structure, kind_of
from momentid.diagnosis.screening import (Candidate, Domain, damping_pattern, remaining_excess, screen_equation,
                                          storey_damper)
from momentid.diagnosis.selection import SHORTLIST_FLOOR, Finding, explained_share
from momentid.diagnosis.stages import Stages, run_stages
from momentid.diagnosis.thresholds import ACCEPTED, EXCESS, EXPLAINED
from momentid.diagnosis.workers import run_forked
from momentid.mechanisms.base import Refit, Target

__all__ = ["Named", "Compound", "extend", "MAX_MECHANISMS", "EARNS"]

#: At most this many mechanisms in one diagnosis: a guard on the loop, not the rule that stops it
#: (a further mechanism must earn its place).
MAX_MECHANISMS = 3
#: A further mechanism must remove at least this share of the training replays' misfit above noise
#: that the model without it leaves (half: it does more than any one-parameter fit of noise can).
EARNS = 0.5
#: Candidates re-simulated per step: the best of each kind, by the share of the remaining excess they
#: explain, up to this many (the replay test, ``EARNS``, decides among them).
STEP_SHORTLIST = 3
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
class Named:
    """One named mechanism: ``report.json``'s ``mechanisms`` entry (parameters in the lab's terms)."""

    mechanism: str
    location: dict
    parameters: dict
    std: dict

    def to_dict(self) -> dict:
        return {"mechanism": self.mechanism, "location": self.location, "parameters": self.parameters,
                "std": self.std}


@dataclass(frozen=True)
class Compound:
    """Stage 6b: every mechanism of the diagnosis and their joint model.

    Attributes
    ----------
    finding : Finding
        The verdict: the primary mechanism (the first found) and the joint model's structure and records.
    mechanisms : tuple of Named
        Every named mechanism, primary first (empty for ``none`` and ``unexplained``).
    entries : tuple
        (kind, location, fitted parameters) of each, as :func:`~momentid.diagnosis.refit.joint_replay`
        replays them (sensor faults first: undone on the recordings).
    steps : list of dict
        Each further mechanism tried: the training NRMSE before and with it, and whether it earned its place.
    """

    finding: Finding
    mechanisms: tuple[Named, ...]
    entries: tuple
    steps: list


def extend(stages: Stages, *, replay: bool) -> Compound:
    """Stage 6b: continue from stage 6's finding (``stages.found``) on what it leaves (see the module
    docstring); ``replay`` off: stage 6's answer as it is."""
    return _extend(stages, replay, MAX_CORRECTIONS)


def _single(stages: Stages) -> Compound:
    found = stages.found
    kind = kind_of(found.mechanism)
    if kind is None:
        return Compound(found, (), (), [])
    named = Named(found.mechanism, found.location, found.parameters, found.std)
    return Compound(found, (named,), ((kind, found.location, found.parameters),), [])


def _extend(stages: Stages, replay: bool, corrections: int) -> Compound:
    if not replay:
        return _single(stages)
    start = _start(stages)
    if start is None:
        return _single(stages)
    if start[0][0].refit is Refit.CORRECT_DATA:
        return _after_correction(stages, start, corrections)
    physics = _physics(stages, start)
    return _fault_beside(stages, physics, corrections) if physics.mechanisms and corrections else physics


def _start(stages: Stages):
    """The mechanism to continue from: stage 6's, or the partial candidate of an ``unexplained``.

    Returns ((kind, location, parameters), std, structure) or None.
    """
    found, refitter, screening = stages.found, stages.refitter, stages.screening
    kind = kind_of(found.mechanism)
    if kind is not None:
        return (kind, found.location, found.parameters), found.std, found.structure
    part = found.selection.get("partial")
    if part is None:
        return None
    extra = [screening.pattern.candidate] if screening.pattern else []
    for c in list(screening.pool) + extra:
        if (c.mechanism, c.location) == (part["mechanism"], part["location"]):
            aug = refitter.augment(c.mechanism, c.location, c.parameters, c.std)
            params = dict(aug.parameters, **part["parameters"])
            return (kind_of(c.mechanism), c.location, params), aug.std or c.std, aug.structure
    return None


def _after_correction(stages: Stages, start, corrections: int) -> Compound:
    """A sensor fault: undo it on every run and diagnose the corrected experiment.

    A fault that stage 6 left ``unexplained`` (it removed too little alone) is named with what the
    corrected data show only when together they remove ``ACCEPTED`` of the training replays' misfit
    above noise.
    """
    found, refitter = stages.found, stages.refitter
    (kind, loc, params), std, _ = start
    first = _single(stages)
    left, noise = found.selection.get("training_nrmse_augmented"), found.selection.get("training_nrmse_noise")
    if corrections == 0 or (found.mechanism != "unexplained" and left is not None and left <= EXCESS * noise):
        return first   # the corrected recordings' replays are at the noise level: nothing more to find
    experiment = stages.model.experiment
    fixed = replace(experiment, runs=tuple(kind.correct_run(r, loc, params) for r in experiment.runs))
    known = refitter.identify_corrected(kind, loc, params)   # identified while the fault was sized
    again = _extend(run_stages(fixed, replay=True, result=known), True, corrections - 1)
    if not again.mechanisms or any((n.mechanism, n.location) == (kind.name, loc) for n in again.mechanisms):
        return first   # nothing more (or the same fault again: its correction is all there is)
    entries = ((kind, loc, params),) + again.entries
    selection = dict(found.selection, after_correction=again.finding.selection)
    if found.mechanism == "unexplained":
        score = refitter.score_joint(again.finding.structure, entries, again.finding.records)
        share = explained_share(refitter.linear_score(), score, refitter.noise_nrmse())
        selection.update(training_nrmse_joint=score, joint_explained=share)
        if share < ACCEPTED:
            return Compound(replace(found, selection=selection), (), (), again.steps)
    joint = Finding(kind.name, loc, params, std, again.finding.structure, again.finding.records, selection)
    return Compound(joint, (Named(kind.name, loc, params, std),) + again.mechanisms, entries, again.steps)


def _records(entries) -> tuple[Mechanism, ...]:
    return tuple(r for kind, loc, params in entries for r in kind.as_records(loc, params))


def _candidates(stages: Stages, entries) -> list[Candidate]:
    """The library screened on what the mechanisms of ``entries`` leave in the equation residual,
    in the domains (identified, nominal model) where an excess is left; best first."""
    model, residuals = stages.model, stages.residuals
    # A sensor fault is undone on the data, not fitted; an attachment's equation signature is a grid
    # over frequencies, not a few columns: neither is carried as columns, and an attachment is not
    # screened again (its replay screening, stage 4, is its test; the grid would cost most of the time).
    found = [(kind, loc) for kind, loc, _ in entries
             if kind.target is not Target.CHANNEL and kind.refit is not Refit.ATTACHMENT]
    domains = [(model.result, residuals.rows, Domain.EQUATION)]
    if residuals.nominal_rows is not None:
        domains.append((model.nominal_result, residuals.nominal_rows, Domain.NOMINAL))
    out = []
    for result, rows, domain in domains:
        if remaining_excess(result, rows, residuals.noise_floor, model.f_top, found).max() > EXCESS:
            out += screen_equation(result, rows, residuals.noise_floor, model.f_top, domain, found,
                                   kinds=[k for k in mechanisms.library() if k.refit is not Refit.ATTACHMENT])
    done = {(kind.name, json.dumps(loc, sort_keys=True)) for kind, loc, _ in entries}
    # A linear damper leaves no residual: the pattern of C shows it, once C is refitted with the storey
    # forces found (unmodelled, they distort the identified C).
    pattern = damping_pattern(_elastic(stages, entries, _refitted(stages, entries)[0]), model.storeys)
    if pattern is not None:
        out.append(pattern.candidate)
    out = [c for c in out if (c.mechanism, json.dumps(c.location, sort_keys=True)) not in done
           and kind_of(c.mechanism).physical(c.parameters) and kind_of(c.mechanism).refit is not Refit.CORRECT_DATA]
    return sorted(out, key=lambda c: -c.explained)


def _shortlist(candidates: list[Candidate]) -> list[Candidate]:
    """The best candidate of each kind that explains at least ``SHORTLIST_FLOOR`` of what is left (and
    the damping pattern), up to ``STEP_SHORTLIST``, and beside a damper of the damping pattern the
    best dissipative storey force at its storey: the replay decides among them.

    Not ``EXPLAINED``: with a mechanism in the model, what is left is partly that mechanism's own
    misfit (friction's signature, a smoothed sign of noisy drift velocities, leaves part of a
    friction force in the residual), so a second mechanism that is really there may explain well
    under half of it in screening and still halve the replays' misfit.  And a friction the identified
    C has taken in as an equivalent viscous damping leaves little in the residual at all: the
    pattern shows a damper where it is.
    """
    out, kinds = [], set()
    for c in candidates:
        if c.mechanism in kinds or (c.domain is not Domain.PARAMETERS and c.explained < SHORTLIST_FLOOR):
            continue
        kinds.add(c.mechanism)
        out.append(c)
    out = out[:STEP_SHORTLIST]
    for damper in [c for c in out if c.domain is Domain.PARAMETERS]:
        rivals = [c for c in candidates if c.location == damper.location and c.mechanism not in kinds
                  and kind_of(c.mechanism).dissipative and kind_of(c.mechanism).refit is Refit.RESIMULATE]
        if rivals:
            kinds.add(rivals[0].mechanism)
            out.append(rivals[0])
    return out


def _refitted(stages: Stages, entries):
    """The linear model refitted by errors-in-variables with the storey forces (``RESIMULATE`` kinds)
    of ``entries`` as inputs: (result, [their parameters], [their std]); the identified model and
    empty lists when there are none (or noise-free data, or runs the refit cannot use)."""
    model = stages.model
    forces = [e for e in entries if e[0].refit is Refit.RESIMULATE]
    refit = stages.refitter.refit_forces(forces) if forces and not model.ideal else None
    return refit if refit is not None else (model.result, [], [])


def _elastic(stages: Stages, entries, result):
    """``result`` with its stiffness matrix as the storeys' elastic one, the one Rayleigh damping is
    proportional to: without what the mechanisms of ``entries`` take from it in the model (P-Delta's
    loss to the floors' own weight, which an identified K holds)."""
    structure = identified_structure(result, stages.model.nominal)
    for kind, loc, params in entries:
        structure = kind.replay_structure(structure, loc, params, True)
    return replace(result, K=structure.stiffness_matrix())


def _joint(stages: Stages, entries, stds, *, newcomer: bool):
    """The joint model of ``entries`` ((kind, location, parameters) each): the linear part refitted
    with every storey force, and sizes searched by re-simulation with the others in the model.

    With ``newcomer``, the last entry is new: it starts from the joint regression and only its size
    is searched (over the full range); without, every size but the last is searched again around its
    value (``JOINT_SPAN``: one pass of coordinate descent after a newcomer joined).
    Returns (structure, entries, stds), or None when a size comes out unphysical.
    """
    refitter, model = stages.refitter, stages.model
    entries, stds = list(entries), [dict(s) for s in stds]
    last = len(entries) - 1
    forces = [i for i, (kind, _, _) in enumerate(entries) if kind.refit is Refit.RESIMULATE]
    result, structure = model.result, refitter.linear_structure
    refit = _refitted(stages, entries)
    if refit[1]:
        result, params, std = refit
        structure = identified_structure(result, model.nominal)
        for i, p, s in zip(forces, params, std):
            if (i == last) == newcomer:   # to be searched: the refit's std, in quadrature below
                stds[i] = dict(s)
            if newcomer and i == last:    # the newcomer starts from the joint regression
                entries[i] = (entries[i][0], entries[i][1], p)
    for i, (kind, loc, params) in enumerate(entries):
        if kind.refit is Refit.DAMPING_PATTERN:
            _, (a, b, c) = storey_damper(_elastic(stages, entries, result), loc["storey"] - 1)
            structure = replace(structure, rayleigh_mu=max(a, 0.0), rayleigh_kappa=max(b, 0.0))
            entries[i] = (kind, loc, dict(params, **{kind.fitted.name: float(c)}))
    if not all(kind.physical(params) for kind, _, params in entries):
        return None
    if model.nominal is not None:
        structure = min((structure, model.nominal), key=lambda b: refitter.misfit(b, entries))
    for i in forces:
        if (i == last) != newcomer:
            continue
        kind, loc, params = entries[i]
        params, sim_std = refitter.resimulate(structure, kind, loc, params, entries[:i] + entries[i + 1:],
                                              SEARCH_RANGE if newcomer else JOINT_SPAN)
        entries[i] = (kind, loc, params)
        stds[i] = {k: float(math.hypot(v, stds[i].get(k, 0.0))) for k, v in sim_std.items()}
    return structure, entries, stds


def _descend(stages: Stages, entries, stds):
    """The lab's nominal model with every storey force of ``entries`` sized by re-simulation in turn
    (over the full range, the others in the model as they stand), starting from the joint regression.

    For a start that stage 6 left partial: its size was searched on a model that lacked the newcomer
    and took in what the newcomer does (P-Delta grown to absorb a friction's effect), and the linear
    part identified beside it has taken in the rest (the friction as viscous damping); the nominal
    model has taken in neither.  Returns (structure, entries, stds), or None (no nominal model, no joint
    regression, or a size it makes unphysical).
    """
    refitter, nominal = stages.refitter, stages.model.nominal
    refit = _refitted(stages, entries)
    if nominal is None or not refit[1]:
        return None
    entries, stds = list(entries), [dict(s) for s in stds]
    forces = [i for i, (kind, _, _) in enumerate(entries) if kind.refit is Refit.RESIMULATE]
    for i, p in zip(forces, refit[1]):
        entries[i] = (entries[i][0], entries[i][1], p)
    if not all(kind.physical(params) for kind, _, params in entries):
        return None
    for i in forces:
        kind, loc, params = entries[i]
        params, sim_std = refitter.resimulate(nominal, kind, loc, params, entries[:i] + entries[i + 1:],
                                              grid=DESCENT_GRID)
        entries[i] = (kind, loc, params)
        stds[i] = {k: float(math.hypot(v, stds[i].get(k, 0.0))) for k, v in sim_std.items()}
    return nominal, entries, stds


class _Trial(enum.Enum):
    """How a newcomer is tried: the joint model (:func:`_joint`) or the descent (:func:`_descend`)."""

    JOINT = "joint"
    DESCENT = "descent"


def _trial(stages: Stages, task):
    """(training NRMSE, structure, entries, stds) of one trial ((candidate, how, entries, stds)), or
    None (an unphysical size)."""
    _, how, entries, stds = task
    joint = _joint(stages, entries, stds, newcomer=True) if how is _Trial.JOINT else _descend(stages, entries, stds)
    if joint is None:
        return None
    structure, entries, stds = joint
    return stages.refitter.score_joint(structure, entries, _records(entries)), structure, entries, stds


def _physics(stages: Stages, start) -> Compound:
    """Physical mechanisms: add the one that earns its place most, while one does."""
    refitter = stages.refitter
    (entry, std, structure) = start
    entries, stds = [entry], [dict(std)]
    noise, linear = refitter.noise_nrmse(), refitter.linear_score()
    score = refitter.score_joint(structure, entries, _records(entries))
    partial = stages.found.mechanism == "unexplained"   # the start was sized on a model that lacked the rest
    steps = []
    while len(entries) < MAX_MECHANISMS and score > EXCESS * noise:
        tasks = []
        for c in _shortlist(_candidates(stages, entries)):
            trial = (entries + [(kind_of(c.mechanism), c.location, dict(c.parameters))], stds + [dict(c.std)])
            tasks.append((c, _Trial.JOINT, *trial))
            if partial and len(entries) == 1 and kind_of(c.mechanism).refit is Refit.RESIMULATE:
                tasks.append((c, _Trial.DESCENT, *trial))
        outs = run_forked(lambda task: _trial(stages, task), tasks, refitter)
        trials = [(out[0], c, *out[1:]) for (c, *_), out in zip(tasks, outs) if out]
        if not trials:
            break
        after, c, s, e, sd = min(trials, key=lambda t: t[0])
        share = explained_share(score, after, noise)
        steps.append({"mechanism": c.mechanism, "location": c.location, "screening_explained": c.explained,
                      "training_nrmse_before": score, "training_nrmse_with": after, "training_nrmse_noise": noise,
                      "explained": share, "earns_above": EARNS, "earned": share >= EARNS})
        if share < EARNS:
            break
        score, structure, entries, stds = after, s, e, sd
    found = stages.found
    if len(entries) == 1:   # stage 6's answer stands
        single = _single(replace(stages, found=replace(found, selection=dict(found.selection, compound=steps))))
        return replace(single, steps=steps)
    if any(kind.refit is Refit.RESIMULATE for kind, _, _ in entries[:-1]):
        # the earlier sizes were searched before the last mechanism came in: refine them with it
        joint = _joint(stages, entries, stds, newcomer=False)
        if joint is not None:
            structure, entries, stds = joint
            score = refitter.score_joint(structure, entries, _records(entries))
    overall = explained_share(linear, score, noise)
    selection = dict(found.selection, compound=steps, training_nrmse_joint=score, joint_explained=overall)
    if found.mechanism == "unexplained" and overall < ACCEPTED:   # together still too little: unexplained
        return Compound(replace(found, selection=selection), (), (), steps)
    named = tuple(_named(stages, kind, loc, params, sd) for (kind, loc, params), sd in zip(entries, stds))
    first = named[0]
    finding = Finding(first.mechanism, first.location, first.parameters, first.std, structure, _records(entries),
                      selection)
    return Compound(finding, named, tuple(entries), steps)


def _fault_beside(stages: Stages, physics: Compound, corrections: int) -> Compound:
    """A sensor fault beside the physics found: the one screening explains best (at least
    ``EXPLAINED`` of the equation residual's excess), of those that contended with the physics
    (:func:`_contender`), is undone on every run and the corrected
    experiment diagnosed again; the fault joins when the corrected diagnosis with it removes at
    least ``EARNS`` of the training replays' misfit above noise that the physics alone leaves.

    (A fault that screens well may lose stage 6's replay to physics that takes in part of its effect,
    a storey damper for a biased displacement transducer; what the physics leaves then holds the rest.)
    """
    refitter = stages.refitter
    noise = refitter.noise_nrmse()
    score = refitter.score_joint(physics.finding.structure, physics.entries, physics.finding.records)
    if score <= EXCESS * noise:
        return physics
    faults = [c for c in sorted(stages.screening.candidates, key=lambda c: -c.explained)
              if kind_of(c.mechanism) is not None and kind_of(c.mechanism).refit is Refit.CORRECT_DATA
              and c.explained >= EXPLAINED and _contender(stages, physics, c)]
    if not faults:
        return physics
    c = faults[0]
    kind, loc, params = kind_of(c.mechanism), c.location, dict(c.parameters)
    experiment = stages.model.experiment
    fixed = replace(experiment, runs=tuple(kind.correct_run(r, loc, params) for r in experiment.runs))
    again = _extend(run_stages(fixed, replay=True, result=refitter.identify_corrected(kind, loc, params)), True,
                    corrections - 1)
    if not again.entries:
        return physics
    entries = ((kind, loc, params),) + again.entries
    after = refitter.score_joint(again.finding.structure, entries, again.finding.records)
    share = explained_share(score, after, noise)
    step = {"mechanism": kind.name, "location": loc, "screening_explained": c.explained,
            "training_nrmse_before": score, "training_nrmse_with": after, "training_nrmse_noise": noise,
            "explained": share, "earns_above": EARNS, "earned": share >= EARNS}
    steps = physics.steps + [step]
    if share < EARNS:
        selection = dict(physics.finding.selection, compound=steps)
        return replace(physics, finding=replace(physics.finding, selection=selection), steps=steps)
    selection = dict(physics.finding.selection, compound=steps, after_correction=again.finding.selection,
                     training_nrmse_joint=after)
    finding = replace(again.finding, selection=selection)
    named = again.mechanisms + (Named(kind.name, loc, params, dict(c.std)),)
    return Compound(finding, named, entries, steps)


def _contender(stages: Stages, physics: Compound, fault: Candidate) -> bool:
    """Whether a sensor fault contended with the physics named: stage 6 re-simulated it (it was the
    screening's choice), or it screens at least as well as any of the physics named.  (Diagnosing the
    corrected experiment costs a second pass of stages 1-6: not for every fault that screens well
    beside a storey force whose replay is imperfect.)"""
    tried = stages.found.selection.get("training_nrmse", [])
    if any((t["mechanism"], t["location"]) == (fault.mechanism, fault.location) for t in tried):
        return True
    named = {(n.mechanism, json.dumps(n.location, sort_keys=True)) for n in physics.mechanisms}
    rivals = [c.explained for c in stages.screening.candidates
              if (c.mechanism, json.dumps(c.location, sort_keys=True)) in named]
    return fault.explained >= max(rivals, default=math.inf)


def _named(stages: Stages, kind, loc: dict, params: dict, std: dict) -> Named:
    """A mechanism in the lab's terms; a damper from the damping pattern takes the standard error of
    the same damper fitted to the equation residual (as stage 6 does)."""
    key = kind.fitted.name
    if kind.refit is Refit.DAMPING_PATTERN and not std.get(key):
        same = [c for c in stages.screening.candidates
                if c.mechanism == kind.name and c.location == loc and c.std.get(key)]
        if same:
            std = {key: float(max(same, key=lambda c: c.explained).std[key])}
    params, std = kind.in_lab_terms(params, std, loc, stages.model.nominal)
    return Named(kind.name, loc, params, std)
