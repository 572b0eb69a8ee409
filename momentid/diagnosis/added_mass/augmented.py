"""Augmented models and their replays: a linear structure with mechanisms, re-simulated in MuJoCo.

An :class:`Entry` is one mechanism of an augmented model: its kind, its place and its fitted
parameters.  :func:`joint_replay` builds the model of a structure with entries (each kind changes
the structure it sits on, :meth:`~momentid.mechanisms.base.MechanismKind.replay_structure`, and a
sensor fault is undone on the run instead) and replays a run through it; :func:`replay_check` is the
held-out run's before/after comparison every diagnosis reports.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import NamedTuple

import numpy as np

from momentid.core.analytic import shear_stiffness
from momentid.core.series import RunData
from momentid.core.structure import Mechanism, Structure
from momentid.diagnosis.added_mass.residuals import LinearModel, nrmse
from momentid.errors import SimulationError
from momentid.estimation.identified import Identification
from momentid.lab import rig
from momentid.mechanisms.base import MechanismKind
from momentid.mechanisms.place import Place, Target

__all__ = ["Entry", "records", "identified_structure", "measured_groups", "joint_replay", "replay_check",
           "MIN_STIFFNESS", "DEFAULT_STOREY_HEIGHT", "DEFAULT_BASE_MASS"]

#: A storey stiffness a linear fit left at or below zero becomes this (N/m): a valid MJCF.
MIN_STIFFNESS = 1e-9
#: Without a nominal model: storey height (m, drawing only) and platen mass (kg) of the replay model.
DEFAULT_STOREY_HEIGHT = 0.3
DEFAULT_BASE_MASS = 100.0


class Entry(NamedTuple):
    """One mechanism of an augmented model: its kind, its place and its parameters (the fitted ones)."""

    kind: MechanismKind
    place: Place
    parameters: dict

    def records(self) -> tuple[Mechanism, ...]:
        """Its model records (:meth:`~momentid.mechanisms.base.MechanismKind.as_records`)."""
        return self.kind.as_records(self.place, self.parameters)

    def key(self) -> tuple:
        """A hashable, printable identity: kind name, location and parameters."""
        return self.kind.name, self.place.location, self.parameters


def records(entries: Iterable[Entry]) -> tuple[Mechanism, ...]:
    """Every model record of ``entries`` (sensor faults have none)."""
    return tuple(r for entry in entries for r in entry.records())


def identified_structure(result: Identification, nominal: Structure | None) -> Structure:
    """An identification result as a :class:`Structure` (least-squares storey stiffnesses)."""
    d = result.storeys
    A = np.stack([shear_stiffness(np.eye(d)[s]) for s in range(d)], axis=-1).reshape(d * d, d)
    k, *_ = np.linalg.lstsq(A, result.K.ravel(), rcond=None)
    heights = nominal.storey_heights if nominal else (DEFAULT_STOREY_HEIGHT,) * d
    base = nominal.base_mass if nominal else DEFAULT_BASE_MASS
    return Structure(masses=tuple(np.diag(result.M)), storey_stiffness=tuple(np.maximum(k, MIN_STIFFNESS)),
                     storey_heights=tuple(heights), rayleigh_mu=max(result.mu, 0.0),
                     rayleigh_kappa=max(result.kappa, 0.0), base_mass=base)


def measured_groups(run: RunData, d: int) -> dict[str, np.ndarray]:
    """The floor channels a replay is compared with: ``{"a": (n, d), "q": (n, d)}``, those measured."""
    return {g: run.group(g, d) for g in ("a", "q") if run.has(f"{g}1")}


def joint_replay(structure: Structure, entries: Iterable[Entry], mechanism_records: Sequence[Mechanism], run: RunData,
                 d: int, static: bool = True) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Replay ``run`` through an augmented model: (simulated, measured-and-corrected) channels.

    ``entries``: the :class:`Entry` of each mechanism, applied in turn: its structure change
    (:meth:`~momentid.mechanisms.base.MechanismKind.replay_structure`), and for a sensor fault the
    correction of the run.  ``mechanism_records``: every mechanism's model records.  ``static``:
    whether ``structure`` already holds what the floors' own weight does to it (an identified model
    does, a nominal one does not; see ``p_delta``).
    """
    from momentid.lab.simulation import replay
    measured = measured_groups(run, d)
    for kind, place, params in entries:
        structure = kind.replay_structure(structure, place, params, static)
        if kind.target is Target.CHANNEL:
            run = kind.correct_run(run, place, params)
            measured = {g: run.group(g, d) for g in measured}
    return replay(structure, mechanism_records, run, run["zdd"]), measured


def replay_check(model: LinearModel, linear_structure: Structure, structure: Structure, entries: Sequence[Entry],
                 mechanism_records: Sequence[Mechanism]) -> tuple[float, float, dict, str]:
    """NRMSE of the evaluation run: linear model vs. augmented model, both in MuJoCo.

    ``entries``: the :class:`Entry` of every mechanism of the augmented model (sensor faults are undone
    on the run), as :func:`joint_replay` takes them; ``mechanism_records`` their model records.
    Returns (before, after, curves, augmented MJCF text).
    """
    from momentid.lab.simulation import replay
    run, d, band = model.evaluation_run, model.storeys, model.band
    static = structure != model.nominal
    fs = run.sample_rate
    measured = measured_groups(run, d)
    try:
        lin = replay(linear_structure, (), run, run["zdd"])
    except SimulationError:
        # the linear model refitted on the training runs diverges under this run's table motion (a rig
        # that changed mid-run can drive the refit's damping below zero): the identified model stands
        # for it; should that diverge too, the error says so
        lin = replay(model.nominal, (), run, run["zdd"])
    before = nrmse(lin, measured, fs, band)
    if mechanism_records or any(kind.target is Target.CHANNEL for kind, _, _ in entries):
        aug, corrected = joint_replay(structure, entries, mechanism_records, run, d, static)
        after = nrmse(aug, corrected, fs, band)
    else:
        aug, after = lin, before
    for kind, place, params in entries:
        structure = kind.replay_structure(structure, place, params, static)
    spec = rig.build_spec(structure, run.added_mass, timestep=1 / fs, name="augmented", mechanisms=mechanism_records)
    spec.compiler.saveinertial = True
    curves = {"time": run.time, "measured": measured, "linear": lin, "augmented": aug}
    return before, after, curves, spec.to_xml()
