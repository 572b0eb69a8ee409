"""How a kind sizes a screened candidate: each kind brings its own
(:meth:`~momentid.mechanisms.base.MechanismKind.size`).

The diagnosis hands a kind a :class:`Sizer` (its re-simulation of the training runs:
:class:`momentid.diagnosis.added_mass.resimulation.Refitter`) and the screened parameters; the kind returns the model it
is sized on and its parameters (:class:`Sized`).  The usual ways, one mix-in class each, which a kind
names among its bases (a kind with a way of its own overrides :meth:`size`, as
:mod:`~momentid.mechanisms.tuned_mass_damper` does):

- :class:`ResimulatedForce`: a nonlinear force at a link, refitted by errors-in-variables together
  with the linear model, then its size searched by re-simulation;
- :class:`Attachment`: a change of the rig the identified model partly absorbed, kept on the lab's
  nominal model;
- :class:`Dashpot`: a linear term the identified C holds, read from its pattern;
- :func:`size_correction`: a sensor fault undone on the recordings, which are then re-identified
  (:class:`~momentid.mechanisms.base.SensorFault`).

This module imports nothing of the diagnosis: what a kind needs of it is in :class:`Sizer`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from collections.abc import Sequence
from typing import Any, Protocol

from momentid.core.structure import Structure
from momentid.mechanisms.place import Place

__all__ = ["Sizer", "Sized", "ResimulatedForce", "Attachment", "Dashpot", "size_correction"]


class Sizer(Protocol):
    """What sizing asks of the diagnosis's re-simulation of the training runs.

    A ``kind`` is a :class:`~momentid.mechanisms.base.MechanismKind` (this module, imported by that one,
    cannot name it); an ``entry`` is what :meth:`entry` returns, opaque here.
    """

    #: The identified linear model as a structure, and the lab's nominal one (None when not stated).
    linear_structure: Structure
    nominal: Structure | None
    #: Noise-free recordings (no errors-in-variables refit needed).
    ideal: bool
    #: The damping-pattern fit of the identified C (its ``candidate`` and ``info``), or None.
    pattern: object

    def entry(self, kind: Any, place: Place, params: dict) -> object:
        """The mechanism ``kind`` at ``place`` with ``params``, as the other methods take it."""

    def structure_of(self, result: Any) -> Structure:
        """An identification (of the refit, or of corrected runs) as a structure."""

    def refit_forces(self, entries: list[object]) -> Any:
        """The errors-in-variables refit of the linear model with these forces at links (its ``result``,
        and per entry ``parameters`` and ``std``), or None when the runs do not allow one."""

    def better_of(self, structures: Sequence[Structure], entries: list[object]) -> Structure:
        """Of ``structures``, the one that with ``entries`` replays the training runs best."""

    def resimulate(self, structure: Structure, entry: object) -> tuple[dict, dict]:
        """The size of ``entry``'s fitted coefficient searched by re-simulation on ``structure``:
        (parameters, standard errors)."""

    def search(self, structure: Structure, entry: object, names: tuple[str, ...]) -> tuple[dict, dict]:
        """The parameters ``names`` of ``entry`` searched together by re-simulation on ``structure``:
        (parameters, standard errors)."""

    def identify_corrected(self, kind: Any, place: Place, params: dict) -> Any:
        """The linear identification of the training runs with the sensor fault ``kind`` at ``place`` undone."""


@dataclass(frozen=True)
class Sized:
    """A sized candidate: the structure its model sits on, its parameters and their standard errors;
    ``refit``: the errors-in-variables refit behind it (a resimulated force's), ``corrected``: the linear
    model identified on the corrected runs (a sensor fault's)."""

    structure: Structure
    parameters: dict
    std: dict
    refit: object | None = None
    corrected: object | None = None


class ResimulatedForce:
    """Sized as a nonlinear force at a link: refitted by errors-in-variables with the linear model, then
    its size searched by re-simulation (the kind states its :meth:`force_signal` and ``fitted``)."""

    def size(self, sizer: Sizer, place: Place, params: dict, std: dict) -> Sized:
        """Refitted with the linear model by errors-in-variables, then sized by re-simulation on the refitted
        or the nominal model, whichever replays better (noise-free runs: the screened size, on the linear
        model)."""
        structure, refit = sizer.linear_structure, None
        if sizer.ideal:
            return Sized(structure, params, std)
        refit = sizer.refit_forces([sizer.entry(self, place, params)])
        if refit is not None:
            params, std = refit.parameters[0], refit.std[0]
            structure = sizer.structure_of(refit.result)
        # The force's size by re-simulation, on the refitted linear model and on the nominal one
        # (a friction that sticks a storey leaves the linear fit poorly determined); the pair that
        # replays best wins.
        bases = [structure] + ([sizer.nominal] if sizer.nominal is not None else [])
        structure = sizer.better_of(bases, [sizer.entry(self, place, params)])
        params, sim_std = sizer.resimulate(structure, sizer.entry(self, place, params))
        # the search's std is conditional on the linear model; the refit's marginal std carries
        # the linear model's own uncertainty: report both, in quadrature
        std = {k: float(math.hypot(v, std.get(k, 0.0))) for k, v in sim_std.items()}
        return Sized(structure, params, std, refit)


class Attachment:
    """Sized on the lab's nominal model: found by replaying it (the identified one has absorbed part of
    the attachment's dynamics in the runs that carry it)."""

    def size(self, sizer: Sizer, place: Place, params: dict, std: dict) -> Sized:
        """The screened parameters, on the lab's nominal model (the identified one without it)."""
        structure = sizer.nominal if sizer.nominal is not None else sizer.linear_structure
        return Sized(structure, params, std)


class Dashpot:
    """Sized from the damping pattern of the identified C: Rayleigh part and the dashpot, when the
    pattern fit found this dashpot, else the nominal Rayleigh coefficients."""

    def size(self, sizer: Sizer, place: Place, params: dict, std: dict) -> Sized:
        """The coefficient read from the identified C's damping pattern when the pattern names this kind at
        ``place`` (else the screened one), on the linear model with the pattern's Rayleigh terms (else the
        nominal model's, else its own); the nominal model instead when that replays better."""
        structure, nominal, pattern = sizer.linear_structure, sizer.nominal, sizer.pattern
        if pattern and pattern.candidate.kind is self and pattern.candidate.place == place:
            a_, b_, c_ = pattern.info["coefficients"]
            params = {self.fitted.name: float(c_)}
        elif nominal is not None:
            a_, b_ = nominal.rayleigh_mu, nominal.rayleigh_kappa
        else:
            a_, b_ = structure.rayleigh_mu, structure.rayleigh_kappa
        structure = replace(structure, rayleigh_mu=max(a_, 0.0), rayleigh_kappa=max(b_, 0.0))
        if nominal is not None:   # the lab's own model with the damper may replay better
            structure = sizer.better_of((structure, nominal), [sizer.entry(self, place, params)])
        return Sized(structure, params, std)


def size_correction(kind: Any, sizer: Sizer, place: Place, params: dict, std: dict) -> Sized:
    """A sensor fault's sizing: the linear model identified on the training runs with the fault undone
    (and the lab's own model, when it replays the corrected runs better)."""
    corrected = sizer.identify_corrected(kind, place, params)
    structure = sizer.structure_of(corrected)
    if sizer.nominal is not None:   # the corrected data may fit the lab's own model better
        structure = sizer.better_of((structure, sizer.nominal), [sizer.entry(kind, place, params)])
    return Sized(structure, params, std, corrected=corrected)
