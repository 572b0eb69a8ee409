"""Stages 4b and 6 of the diagnosis: which candidate to name, then the choice by re-simulation.

:func:`screen` gathers the screened candidates of every domain; :func:`choose` picks the verdict
(a mechanism, ``unexplained`` or ``none``) from them; :func:`select` re-simulates the plausible
candidates on the training runs, keeps the one that replays best, sizes it, and demotes it to
``unexplained`` when its augmented model removes too little of the misfit.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from momentid.core.structure import Mechanism, Structure
from momentid.diagnosis.locate import Localisation
from momentid.diagnosis.refit import Augmented, Refitter, kind_of
from momentid.diagnosis.residuals import EquationResiduals, LinearModel
from momentid.diagnosis.screening import (Candidate, DampingPattern, Domain, ReplayResiduals, damping_pattern,
                                          screen_attachment, screen_equation, screen_replay)
from momentid.diagnosis.sensor_check import SensorCheck
from momentid.diagnosis.thresholds import ACCEPTED, EXCESS, EXPLAINED
from momentid.diagnosis.workers import run_forked
from momentid.mechanisms.base import Refit

__all__ = ["Verdict", "Screening", "Choice", "Finding", "screen", "choose", "select", "explained_share"]

#: Re-simulated at most: the chosen candidate and the best of up to 3 other kinds of physics ...
SHORTLIST_SIZE = 4
#: ... each explaining at least this share of the excess in screening.
SHORTLIST_FLOOR = 0.15


class Verdict(enum.Enum):
    NONE = "none"                    # the linear model explains the recordings to the noise level
    UNEXPLAINED = "unexplained"      # a mismatch no candidate of the library explains
    MECHANISM = "mechanism"          # a named mechanism of the library


@dataclass(frozen=True)
class Screening:
    """Stage 4: the screened candidates.

    Attributes
    ----------
    candidates : tuple of Candidate
        Every physical candidate of every domain (and the sensor check's), for the report.
    pool : tuple of Candidate
        Those the verdict may name, given which residuals show a mismatch.
    pattern : DampingPattern or None
        A physical storey damper read from the identified C.
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
class Finding:
    """Stage 6: the diagnosed mechanism (or ``none`` / ``unexplained``), sized, with its model.

    ``selection`` holds the training-run NRMSE of each re-simulated candidate and the acceptance
    test (``report.json``'s ``selection``).
    """

    mechanism: str
    location: dict
    parameters: dict
    std: dict
    structure: Structure
    records: tuple[Mechanism, ...]
    selection: dict


def _physical(c: Candidate) -> bool:
    """A passive rig: no negative damper, friction or weight (cubic stiffness may soften)."""
    kind = kind_of(c.mechanism)
    return kind is None or kind.physical(c.parameters)


def screen(model: LinearModel, residuals: EquationResiduals, sensors: SensorCheck) -> Screening:
    """Stage 4: screen every mechanism in every domain; keep the physical candidates."""
    d, result, band, f_top = model.storeys, model.result, model.band, model.f_top
    candidates = screen_equation(result, residuals.rows, residuals.noise_floor, f_top, Domain.EQUATION)
    if residuals.nominal_rows is not None:
        candidates += screen_equation(model.nominal_result, residuals.nominal_rows, residuals.noise_floor, f_top,
                                      Domain.NOMINAL)
    # Replay residuals (table accelerometer effects).  The floor equations do not involve the table
    # accelerometer, so when the nominal model explains them, it is the fair model to replay (a fit
    # driven by a faulty base channel has partly absorbed the fault).
    has_nominal = model.nominal_result is not None
    replay = screen_replay(model.nominal_result if has_nominal and not residuals.nominal_mismatch else result,
                           model.train.runs, d, band)
    candidates += replay.candidates
    # A flexibly attached mass, by replay: of the nominal model when the lab states one (the identified
    # model has partly absorbed the attachment in the runs that carry it), else of the identified one.
    candidates += screen_attachment(model.nominal_result if has_nominal else result, model.train.runs, d, band,
                                    f_top)
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
        location = {"storey": where.storey}     # the storey whose shear residual stands out
    elif max(excess_rep.values(), default=0) > max(excess_eq.values()):
        location = {"channel": max(excess_rep, key=excess_rep.get)}
    else:
        location = {"floor": int(max(excess_eq, key=excess_eq.get)[len("floor"):])}
    return Choice(Verdict.UNEXPLAINED, None, location)


def _shortlist(pool, chosen: Candidate) -> list[Candidate]:
    """The screened candidates worth re-simulating: the chosen one and the best candidate of each
    other kind of physics that explains at least ``SHORTLIST_FLOOR`` of the excess (up to
    ``SHORTLIST_SIZE`` in all; one per kind, so that a kind which screens well at several places
    cannot crowd the others out).  Sensor faults are sized on corrected data, not re-simulated."""
    out, kinds = [chosen], {chosen.mechanism}
    for c in sorted(pool, key=lambda c: -c.explained):
        kind = kind_of(c.mechanism)
        if c.mechanism in kinds or c.explained < SHORTLIST_FLOOR or kind.refit is Refit.CORRECT_DATA:
            continue
        kinds.add(c.mechanism)
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


def select(model: LinearModel, choice: Choice, screening: Screening, refitter: Refitter, where: Localisation,
           *, replay: bool) -> Finding:
    """Stage 6: re-simulate the shortlist, size the winner, accept it or call the mismatch unexplained."""
    mech = choice.candidate.mechanism if choice.candidate else choice.verdict.value
    loc = choice.location
    params, std = (choice.candidate.parameters, choice.candidate.std) if choice.candidate else ({}, {})
    selection: dict = {}
    if choice.candidate is not None and choice.candidate.domain != Domain.SENSORS and replay:
        # Screening ranks signatures on residuals; the choice among the plausible ones is made by
        # re-simulation: each augmented model replays the training runs, and the lowest NRMSE wins.
        extra = [screening.pattern.candidate] if screening.pattern else []
        shortlist = _shortlist(list(screening.pool) + extra, choice.candidate)
        if len(shortlist) > 1:
            base = refitter.linear_score()
            scores = run_forked(lambda c: refitter.score(refitter.augment(c.mechanism, c.location, c.parameters,
                                                                          c.std), c.mechanism, c.location),
                                shortlist, refitter)
            scored = list(zip(scores, shortlist))
            _, best = min(scored, key=lambda x: x[0])
            selection = {"training_nrmse_linear": base,
                         "training_nrmse": [{"mechanism": c.mechanism, "location": c.location, "nrmse": nrmse}
                                            for nrmse, c in scored]}
            mech, loc, params, std = best.mechanism, best.location, best.parameters, best.std
    augmented = refitter.augment(mech, loc, params, std)
    params, std = augmented.parameters, augmented.std
    kind = kind_of(mech)
    if kind is not None and kind.refit is Refit.DAMPING_PATTERN and not std:
        # From the damping pattern of the identified C: take the standard error of the same damper
        # fitted to the equation residual (noise only, given the linear model).
        key = kind.fitted.name
        same = [c for c in screening.candidates if c.mechanism == mech and c.location == loc and c.std.get(key)]
        if same:
            std = {key: float(max(same, key=lambda c: c.explained).std[key])}
    if kind is not None:   # in the lab's terms (p_delta: 1 = the full weight above)
        params, std = kind.in_lab_terms(params, std, loc, model.nominal)
    augmented = replace(augmented, parameters=params, std=std)
    if replay and kind is not None:
        # Does the augmented model explain the mismatch?  Re-simulate the training runs: it must remove
        # at least ACCEPTED of the misfit above the noise, else the best candidate is only partial.
        linear, after, noise = refitter.linear_score(), refitter.score(augmented, mech, loc), refitter.noise_nrmse()
        share = explained_share(linear, after, noise)
        selection.update({"training_nrmse_linear": linear, "training_nrmse_augmented": after,
                          "training_nrmse_noise": noise, "explained": share, "accepted_above": ACCEPTED})
        if share < ACCEPTED:
            selection["partial"] = {"mechanism": mech, "location": loc, "parameters": params}
            mech, params, std = Verdict.UNEXPLAINED.value, {}, {}
            augmented = Augmented(refitter.linear_structure, {}, {}, ())
            if where.storeys[f"storey{where.storey}"] > EXCESS:   # where the residual says, not the guess
                loc = {"storey": where.storey}
    return Finding(mech, loc, params, std, augmented.structure, augmented.records, selection)
