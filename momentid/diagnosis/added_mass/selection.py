"""Stages 5 and 6 of the added-mass diagnosis: which candidate to name, then the choice by re-simulation.

:func:`screen` gathers the screened candidates of every domain; :func:`choose` picks the verdict
(a mechanism, ``unexplained`` or ``none``) from them; :func:`select` re-simulates the plausible
candidates on the training runs, keeps the one that replays best, sizes it, and demotes it to
``unexplained`` when its augmented model removes too little of the misfit.  What it tried and why
it decided is a :class:`Selection` (``report.json``'s ``selection``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from momentid import mechanisms
from momentid.core.structure import Mechanism, Structure
from momentid.diagnosis.added_mass.locate import Localisation
from momentid.diagnosis.added_mass.resimulation import Augmented, ForceRefit, Refitter
from momentid.diagnosis.added_mass.residuals import EquationResiduals, LinearModel
from momentid.diagnosis.added_mass.screening import (Candidate, DampingPattern, Domain, ReplayResiduals,
                                                     damping_pattern, screen_attachment, screen_equation, screen_replay,
                                                     screening_order)
from momentid.diagnosis.added_mass.sensor_faults import SensorCheck
from momentid.diagnosis.thresholds import ACCEPTED, EXCESS, EXPLAINED
from momentid.diagnosis.verdict import Verdict
from momentid.core.processes import run_forked
from momentid.mechanisms.base import MechanismKind, Refit
from momentid.mechanisms.place import Place, Target

__all__ = ["Screening", "Choice", "Tried", "Partial", "Step", "OutsideLibrary", "Selection", "Finding", "screen",
           "choose", "select", "explained_share", "SHORTLIST_SIZE", "SHORTLIST_FLOOR", "EARNS"]

#: Re-simulated at most: the chosen candidate and the best of up to 3 other kinds of physics ...
SHORTLIST_SIZE = 4
#: ... each explaining at least this share of the excess in screening.
SHORTLIST_FLOOR = 0.15
#: A further mechanism of a compound diagnosis must remove at least this share of the training
#: replays' misfit above noise that the model without it leaves (half: it does more than any
#: one-parameter fit of noise can).
EARNS = 0.5


@dataclass(frozen=True)
class Screening:
    """Stage 5: the screened candidates.

    Attributes
    ----------
    candidates : tuple of Candidate
        Every physical candidate of every domain (and the sensor check's), for the report.
    pool : tuple of Candidate
        Those the verdict may name, given which residuals show a mismatch.
    pattern : DampingPattern or None
        A physical dashpot read from the identified C.
    pattern_info : dict
        The damping-pattern fits (reported as ``parameter_pattern``, even when rejected).
    replay : ReplayResiduals
        The replay residual's excess per channel and the table-channel faults.
    """

    candidates: tuple[Candidate, ...]
    pool: tuple[Candidate, ...]
    pattern: DampingPattern | None
    pattern_info: dict
    replay: ReplayResiduals


@dataclass(frozen=True)
class Choice:
    """The verdict of screening; ``candidate`` is set for ``Verdict.MECHANISM`` only."""

    verdict: Verdict
    candidate: Candidate | None
    location: dict


@dataclass(frozen=True)
class Tried:
    """A candidate re-simulated at stage 6: its augmented model and the training runs' mean NRMSE
    through it."""

    candidate: Candidate
    augmented: Augmented
    nrmse: float

    def to_dict(self) -> dict:
        """The candidate tried and its training NRMSE."""
        return {"mechanism": self.candidate.mechanism, "location": self.candidate.location, "nrmse": self.nrmse}


@dataclass(frozen=True)
class Partial:
    """The best candidate of a stage-6 ``unexplained``: it removed too little of the misfit alone.

    ``parameters``: its size in the lab's terms; ``augmented``: its augmented model as built.
    """

    candidate: Candidate
    parameters: dict
    augmented: Augmented

    def to_dict(self) -> dict:
        """The candidate that explains part of the mismatch, with its parameters."""
        return {"mechanism": self.candidate.mechanism, "location": self.candidate.location,
                "parameters": self.parameters}


@dataclass(frozen=True)
class Step:
    """A further mechanism tried by a compound diagnosis: the training runs' NRMSE before and with it,
    the noise's, and the share of the misfit above noise it removes.  A ``retest``: a mechanism
    named, tested again once the others are in the model (``before``: the model without it;
    ``screening_explained`` None)."""

    mechanism: str
    location: dict
    screening_explained: float | None
    before: float
    after: float
    noise: float
    explained: float
    retest: bool = False

    @property
    def earned(self) -> bool:
        """It removes at least :data:`EARNS` of the misfit above noise."""
        return self.explained >= EARNS

    def to_dict(self) -> dict:
        """The step of a compound diagnosis as ``report.json`` states it (NRMSE as fractions)."""
        out = {"mechanism": self.mechanism, "location": self.location,
               "screening_explained": self.screening_explained, "training_nrmse_before": self.before,
               "training_nrmse_with": self.after, "training_nrmse_noise": self.noise, "explained": self.explained,
               "earns_above": EARNS, "earned": self.earned}
        if self.retest:
            del out["screening_explained"]
            out["retest"] = True
        return out


@dataclass(frozen=True)
class OutsideLibrary:
    """A force outside the library that replays the training runs better than the physics the library
    named (:func:`~momentid.diagnosis.added_mass.open_search.challenge`): what was named, and the training runs'
    NRMSE through the named model, the discovered force's model and noise alone, with the share of
    the named model's misfit above noise the force removes."""

    mechanism: str
    location: dict
    named: float
    discovered: float
    noise: float
    explained: float

    def to_dict(self) -> dict:
        """The named physics and the discovered force's training NRMSE, against the noise's."""
        return {"named": [self.mechanism, self.location], "training_nrmse_named": self.named,
                "training_nrmse_discovered": self.discovered, "training_nrmse_noise": self.noise,
                "explained": self.explained}


@dataclass(frozen=True)
class Selection:
    """How a diagnosis chose (``report.json``'s ``selection``; None and empty fields are left out).

    Attributes
    ----------
    linear : float or None
        Training runs' mean NRMSE through the linear model.
    tried : tuple of Tried
        The shortlist re-simulated at stage 6.
    augmented, noise : float or None
        Training NRMSE through the chosen model, and what sensor noise alone leaves.
    explained : float or None
        The share of the misfit above noise the chosen model removes (accepted above ``ACCEPTED``).
    partial : Partial or None
        The best candidate of an ``unexplained`` verdict.
    steps : tuple of Step, or None
        Each further mechanism a compound diagnosis tried (None: none was looked for).
    joint, joint_explained : float or None
        Training NRMSE through the joint model of several mechanisms, and the share it removes.
    after_correction : Selection or None
        The selection on the recordings with a sensor fault undone.
    outside_library : OutsideLibrary or None
        The physics named here, beaten by a force outside the library (the verdict is then
        ``unexplained``).
    """

    linear: float | None = None
    tried: tuple[Tried, ...] = ()
    augmented: float | None = None
    noise: float | None = None
    explained: float | None = None
    partial: Partial | None = None
    steps: tuple[Step, ...] | None = None
    joint: float | None = None
    joint_explained: float | None = None
    after_correction: Selection | None = None
    outside_library: OutsideLibrary | None = None

    def to_dict(self) -> dict:
        """The selection as ``report.json``'s ``selection`` (NRMSE as fractions; absent parts None)."""
        out = {"training_nrmse_linear": self.linear,
               "training_nrmse": [t.to_dict() for t in self.tried] if self.tried else None,
               "training_nrmse_augmented": self.augmented, "training_nrmse_noise": self.noise,
               "explained": self.explained, "accepted_above": ACCEPTED if self.explained is not None else None,
               "partial": self.partial.to_dict() if self.partial else None,
               "compound": [s.to_dict() for s in self.steps] if self.steps is not None else None,
               "training_nrmse_joint": self.joint, "joint_explained": self.joint_explained,
               "after_correction": self.after_correction.to_dict() if self.after_correction else None,
               "outside_library": self.outside_library.to_dict() if self.outside_library else None}
        return {k: v for k, v in out.items() if v is not None}


@dataclass(frozen=True)
class Finding:
    """Stage 6: the verdict, with the mechanism it names (``kind`` at ``place``), sized, and its model.

    ``location`` is the mechanism's place, or where an ``unexplained`` mismatch is.  ``refit`` and
    ``corrected`` are the augmented model's errors-in-variables refit and corrected identification
    (:class:`~momentid.diagnosis.added_mass.resimulation.Augmented`), which a compound diagnosis continues from.
    """

    verdict: Verdict
    kind: MechanismKind | None
    place: Place | None
    location: dict
    parameters: dict
    std: dict
    structure: Structure
    records: tuple[Mechanism, ...]
    selection: Selection = field(default_factory=Selection)
    refit: ForceRefit | None = None
    corrected: object | None = None

    @property
    def mechanism(self) -> str:
        """The verdict in ``report.json``'s words: the mechanism's name, ``none`` or ``unexplained``."""
        return self.kind.name if self.kind is not None else self.verdict.value


def _physical(c: Candidate) -> bool:
    """A passive rig: no negative damper, friction or weight (cubic stiffness may soften)."""
    return c.kind.physical(c.parameters)


def screen(model: LinearModel, residuals: EquationResiduals, sensors: SensorCheck) -> Screening:
    """Stage 5: screen every mechanism in every domain; keep the physical candidates."""
    d, result, band, f_top = model.storeys, model.result, model.band, model.f_top
    has_nominal = model.nominal_result is not None
    domains = [(result, residuals.rows, Domain.EQUATION)]
    if residuals.nominal_rows is not None:
        domains.append((model.nominal_result, residuals.nominal_rows, Domain.NOMINAL))
    # An attachment's equation signature is a grid over frequencies (most of the time): its own job.
    kinds = mechanisms.library()
    groups = [[k for k in kinds if k.refit is not Refit.ATTACHMENT], [k for k in kinds if k.refit is Refit.ATTACHMENT]]
    jobs = [lambda r=r, rows=rows, domain=domain, group=group: screen_equation(r, rows, residuals.noise_floor, f_top,
                                                                               domain, kinds=group)
            for r, rows, domain in domains for group in groups]
    # A flexibly attached mass, by replay: of the nominal model when the lab states one (the identified
    # model has partly absorbed the attachment in the runs that carry it), else of the identified one.
    jobs.append(lambda: screen_attachment(model.nominal_result if has_nominal else result, model.train.runs, d, band,
                                          f_top))
    # Replay residuals (table accelerometer effects).  The floor equations do not involve the table
    # accelerometer, so when the nominal model explains them, it is the fair model to replay (a fit
    # driven by a faulty base channel has partly absorbed the fault).
    jobs.append(lambda: screen_replay(model.nominal_result if has_nominal and not residuals.nominal_mismatch
                                      else result, model.train.runs, d, band))
    *equation, attachment, replay = run_forked(lambda job: job(), jobs)   # independent: on the workers
    order = {pair: i for i, pair in enumerate(screening_order(kinds, d))}
    candidates = []
    for i in range(len(domains)):   # each domain's candidates in screening order, as one screen gives them
        candidates += sorted(equation[2 * i] + equation[2 * i + 1], key=lambda c: order[(c.kind, c.place)])
    candidates += list(replay.candidates) + attachment
    pattern = damping_pattern(result, d)
    pattern_info = pattern.info if pattern else {}
    if pattern and not _physical(pattern.candidate):   # a negative damper is no explanation
        pattern = None
    if pattern:
        candidates.append(pattern.candidate)
    candidates = [c for c in candidates if _physical(c) and not sensors.rules_out(c)]
    if sensors.candidate is not None:
        candidates.append(sensors.candidate)
    if sensors.fault is not None:
        # One channel contradicts the others: a sensor fault, which also disturbs every model-based
        # residual (so those cannot be trusted to name the physics).
        pool = [sensors.fault]
    elif has_nominal and not residuals.nominal_mismatch and replay.mismatch:
        # Floors obey the nominal equations, yet replays from the table channel miss: the table channel.
        pool = [c for c in candidates if c.domain == Domain.REPLAY]
    else:
        pool = [c for c in candidates
                if (c.domain == Domain.EQUATION and residuals.mismatch)
                or (c.domain == Domain.REPLAY and replay.mismatch)
                or (c.domain == Domain.NOMINAL and residuals.nominal_mismatch)]
    return Screening(tuple(candidates), tuple(pool), pattern, pattern_info, replay)


def choose(screening: Screening, residuals: EquationResiduals, where: Localisation) -> Choice:
    """The verdict of screening: the candidate that explains most of the excess, if enough."""
    best = max(screening.pool, key=lambda c: c.explained) if screening.pool else None
    if best is not None and best.explained >= EXPLAINED:
        return Choice(Verdict.MECHANISM, best, best.location)
    if screening.pattern:
        # A linear damper leaves no residual (the identified C absorbs it): the pattern decides.
        return Choice(Verdict.MECHANISM, screening.pattern.candidate, screening.pattern.candidate.location)
    excess_eq, excess_rep = residuals.excess, screening.replay.excess
    if not (residuals.mismatch or screening.replay.mismatch):
        return Choice(Verdict.NONE, None, {})
    if where.storeys[f"storey{where.storey}"] > EXCESS and (residuals.mismatch or residuals.nominal_mismatch):
        place = Place(Target.STOREY, where.storey)     # the storey whose shear residual stands out
    elif max(excess_rep.values(), default=0) > max(excess_eq.values()):
        place = Place(Target.CHANNEL, max(excess_rep, key=excess_rep.get))
    else:
        place = Place(Target.FLOOR, int(max(excess_eq, key=excess_eq.get)[len("floor"):]))
    return Choice(Verdict.UNEXPLAINED, None, place.location)


def _shortlist(pool, chosen: Candidate) -> list[Candidate]:
    """The screened candidates worth re-simulating: the chosen one and the best candidate of each
    other kind of physics that explains at least ``SHORTLIST_FLOOR`` of the excess (up to
    ``SHORTLIST_SIZE`` in all; one per kind, so that a kind which screens well at several places
    cannot crowd the others out).  Sensor faults are sized on corrected data, not re-simulated."""
    out, kinds = [chosen], {chosen.kind}
    for c in sorted(pool, key=lambda c: -c.explained):
        if c.kind in kinds or c.explained < SHORTLIST_FLOOR or c.kind.refit is Refit.CORRECT_DATA:
            continue
        kinds.add(c.kind)
        out.append(c)
        if len(out) == SHORTLIST_SIZE:
            break
    return out


def explained_share(before: float, after: float, noise: float) -> float:
    """Share of the misfit power above the noise that a model removes (NRMSEs in, 1 = all)."""
    excess = before ** 2 - noise ** 2
    if excess <= 0:
        return 1.0
    return float(1.0 - max(after ** 2 - noise ** 2, 0.0) / excess)


def _tried(refitter: Refitter, c: Candidate) -> Tried:
    """``c``'s augmented model and its training score (one job of stage 6's shortlist)."""
    augmented = refitter.augment(c.kind, c.place, c.parameters, c.std)
    return Tried(c, augmented, refitter.score(augmented))


def select(model: LinearModel, choice: Choice, screening: Screening, refitter: Refitter, where: Localisation,
           *, replay: bool) -> Finding:
    """Stage 6: re-simulate the shortlist, size the winner, accept it or call the mismatch unexplained."""
    chosen, loc, selection, built = choice.candidate, choice.location, Selection(), None
    if chosen is not None and chosen.domain != Domain.SENSORS and replay:
        # Screening ranks signatures on residuals; the choice among the plausible ones is made by
        # re-simulation: each augmented model replays the training runs, and the lowest NRMSE wins.
        extra = [screening.pattern.candidate] if screening.pattern else []
        shortlist = _shortlist(list(screening.pool) + extra, chosen)
        if len(shortlist) > 1:
            base = refitter.linear_score()
            tried = run_forked(lambda c: _tried(refitter, c), shortlist)
            for t in tried:
                refitter.remember(t.augmented, t.nrmse)
            best = min(tried, key=lambda t: t.nrmse)
            selection = Selection(linear=base, tried=tuple(tried))
            chosen, loc, built = best.candidate, best.candidate.location, best.augmented
    if chosen is None:
        return Finding(choice.verdict, None, None, loc, {}, {}, refitter.linear_structure, (), selection)
    kind, place = chosen.kind, chosen.place
    built = built or refitter.augment(kind, place, chosen.parameters, chosen.std)
    params, std = built.parameters, built.std
    if kind.refit is Refit.DAMPING_PATTERN and not std:
        # From the damping pattern of the identified C: take the standard error of the same damper
        # fitted to the equation residual (noise only, given the linear model).
        key = kind.fitted.name
        same = [c for c in screening.candidates if c.same_as(chosen) and c.std.get(key)]
        if same:
            std = {key: float(max(same, key=lambda c: c.explained).std[key])}
    params, std = kind.in_lab_terms(params, std, place, model.nominal)   # p_delta: 1 = the full weight above
    augmented = replace(built, parameters=params, std=std)
    finding = Finding(Verdict.MECHANISM, kind, place, loc, params, std, augmented.structure, augmented.records,
                      selection, built.refit, built.corrected)
    if not replay:
        return finding
    # Does the augmented model explain the mismatch?  Re-simulate the training runs: it must remove at
    # least ACCEPTED of the misfit above the noise, else the best candidate is only partial.
    linear, after, noise = refitter.linear_score(), refitter.score(augmented), refitter.noise_nrmse()
    share = explained_share(linear, after, noise)
    selection = replace(selection, linear=linear, augmented=after, noise=noise, explained=share)
    if share >= ACCEPTED:
        return replace(finding, selection=selection)
    if where.storeys[f"storey{where.storey}"] > EXCESS:   # where the residual says, not the guess
        loc = Place(Target.STOREY, where.storey).location
    return Finding(Verdict.UNEXPLAINED, None, None, loc, {}, {}, refitter.linear_structure, (),
                   replace(selection, partial=Partial(chosen, params, built)))
