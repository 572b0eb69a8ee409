"""What a step of a compound diagnosis (:mod:`~momentid.diagnosis.added_mass.compound`) screens: the library
on what the mechanisms found leave, in the equation residuals of the identified and the nominal
model (each storey kind also on its own storey's shear residual, where a mechanism found elsewhere
leaves nothing: :func:`~momentid.diagnosis.added_mass.screening.screen_storeys`), and the damping pattern of C
refitted with the forces found; and which candidates of it are re-simulated (:func:`shortlist`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace

from momentid import mechanisms
from momentid.diagnosis.added_mass.resimulation import ForceRefit
from momentid.diagnosis.added_mass.augmented import Entry, identified_structure
from momentid.diagnosis.added_mass.screening import (Candidate, Domain, damping_pattern, linear_springs_left,
                                                     remaining_excess, screen_equation, screen_storeys)
from momentid.diagnosis.added_mass.selection import SHORTLIST_FLOOR
from momentid.diagnosis.added_mass.stages import Stages
from momentid.diagnosis.thresholds import EXCESS
from momentid.estimation.identified import Identification
from momentid.mechanisms.base import Refit
from momentid.mechanisms.place import Target

__all__ = ["candidates", "shortlist", "force_entries", "refitted", "elastic", "STEP_SHORTLIST"]

#: Candidates re-simulated per step: the best of each kind, by the share of the remaining excess they
#: explain, up to this many (the replay test, ``EARNS``, decides among them).
STEP_SHORTLIST = 3


def candidates(stages: Stages, entries: Sequence[Entry]) -> list[Candidate]:
    """The library screened on what the mechanisms of ``entries`` leave in the equation residual,
    in the domains (identified, nominal model) where an excess is left; best first."""
    model, residuals = stages.model, stages.residuals
    # A sensor fault is undone on the data, not fitted; an attachment's equation signature is a grid
    # over frequencies, not a few columns: neither is carried as columns, and an attachment is not
    # screened again (its replay screening, stage 5, is its test; the grid would cost most of the time).
    found = [(e.kind, e.place) for e in entries
             if e.kind.target is not Target.CHANNEL and e.kind.refit is not Refit.ATTACHMENT]
    storey_kinds = [k for k in mechanisms.library() if k.refit is Refit.RESIMULATE]
    domains = [(model.result, residuals.rows, Domain.EQUATION)]
    if residuals.nominal_rows is not None:
        domains.append((model.nominal_result, residuals.nominal_rows, Domain.NOMINAL))
    out = []
    for result, rows, domain in domains:
        if remaining_excess(result, rows, residuals.noise_floor, model.f_top, found).max() > EXCESS:
            cands = screen_equation(result, rows, residuals.noise_floor, model.f_top, domain, found,
                                    kinds=[k for k in mechanisms.library() if k.refit is not Refit.ATTACHMENT])
            if domain is Domain.NOMINAL and found:   # P-Delta scored by what the lab's model leaves there
                cands += linear_springs_left(result, rows, residuals.noise_floor, model.f_top, found, cands)
            if found:   # ... and every storey kind by what is left in its own storey's shear
                cands += screen_storeys(result, rows, model.f_top, domain, found, kinds=storey_kinds)
            out += cands
    # A linear damper leaves no residual: the pattern of C shows it, once C is refitted with the forces
    # found (unmodelled, they distort the identified C).
    refit = refitted(stages, entries)
    pattern = damping_pattern(elastic(stages, entries, refit.result if refit else model.result), model.storeys)
    if pattern is not None:
        out.append(pattern.candidate)
    done = {(e.kind, e.place) for e in entries}
    out = [c for c in out if (c.kind, c.place) not in done and c.kind.physical(c.parameters)
           and c.kind.refit is not Refit.CORRECT_DATA]
    return sorted(out, key=lambda c: -c.explained)


def shortlist(candidates: list[Candidate]) -> list[Candidate]:
    """The best candidate of each kind that explains at least ``SHORTLIST_FLOOR`` of what is left (and
    the damping pattern), up to ``STEP_SHORTLIST``, and beside a dashpot of the damping pattern the
    best dissipative force at its link: the replay decides among them.

    Not ``EXPLAINED``: with a mechanism in the model, what is left is partly that mechanism's own
    misfit (friction's signature, a smoothed sign of noisy drift velocities, leaves part of a
    friction force in the residual), so a second mechanism that is really there may explain well
    under half of it in screening and still halve the replays' misfit.  And a friction the identified
    C has taken in as an equivalent viscous damping leaves little in the residual at all: the
    pattern shows a damper where it is.
    """
    out, kinds = [], set()
    for c in candidates:
        if c.kind in kinds or (c.domain is not Domain.PARAMETERS and c.explained < SHORTLIST_FLOOR):
            continue
        kinds.add(c.kind)
        out.append(c)
    out = out[:STEP_SHORTLIST]
    for damper in [c for c in out if c.domain is Domain.PARAMETERS]:
        rivals = [c for c in candidates if c.place.target.link and c.place.nodes == damper.place.nodes
                  and c.kind not in kinds and c.kind.dissipative and c.kind.refit is Refit.RESIMULATE]
        if rivals:
            kinds.add(rivals[0].kind)
            out.append(rivals[0])
    return out


def force_entries(stages: Stages, entries: Iterable[Entry]) -> list[Entry]:
    """The forces (``RESIMULATE`` kinds) of ``entries`` the errors-in-variables refit takes as inputs
    (none for noise-free data, identified by the plain equation error)."""
    return [] if stages.model.ideal else [e for e in entries if e.kind.refit is Refit.RESIMULATE]


def refitted(stages: Stages, entries: Iterable[Entry]) -> ForceRefit | None:
    """The linear model refitted by errors-in-variables with the forces of ``entries`` as inputs; None
    when there are none (or noise-free data, or runs the refit cannot use)."""
    forces = force_entries(stages, entries)
    return stages.refitter.refit_forces(forces) if forces else None


def elastic(stages: Stages, entries: Iterable[Entry], result: Identification) -> Identification:
    """``result`` with its stiffness matrix as the storeys' elastic one, the one Rayleigh damping is
    proportional to: without what the mechanisms of ``entries`` take from it in the model (P-Delta's
    loss to the floors' own weight, which an identified K holds)."""
    structure = identified_structure(result, stages.model.nominal)
    for kind, place, params in entries:
        structure = kind.replay_structure(structure, place, params, True)
    return replace(result, K=structure.stiffness_matrix())
