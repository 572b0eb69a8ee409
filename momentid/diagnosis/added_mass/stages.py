"""Stages 1-6 of the added-mass diagnosis in one call: from an experiment to stage 6's finding.

:func:`~momentid.diagnosis.added_mass.path.diagnose_added_mass` runs them once, and again on recordings a compound
diagnosis (:mod:`~momentid.diagnosis.added_mass.compound`) asks to have corrected: each run has its own
:class:`~momentid.diagnosis.added_mass.resimulation.Refitter`, nothing is shared between them.
"""

from __future__ import annotations

from dataclasses import dataclass

from momentid.core.series import Experiment
from momentid.diagnosis.added_mass.locate import Localisation, locate
from momentid.diagnosis.added_mass.resimulation import Refitter
from momentid.diagnosis.added_mass.residuals import EquationResiduals, LinearModel, equation_residuals, fit_linear_model
from momentid.diagnosis.added_mass.selection import Finding, Screening, choose, screen, select
from momentid.diagnosis.added_mass.sensor_faults import SensorCheck, check_sensors
from momentid.estimation.identified import Identification

__all__ = ["Stages", "run_stages"]


@dataclass(frozen=True)
class Stages:
    """The results of stages 1-6 (see :mod:`momentid.diagnosis.dispatch`)."""

    model: LinearModel
    residuals: EquationResiduals
    sensors: SensorCheck
    where: Localisation
    screening: Screening
    refitter: Refitter
    found: Finding


def run_stages(experiment: Experiment, *, replay: bool, result: Identification | None = None) -> Stages:
    """Stages 1-6 on ``experiment`` (runs with added mass); ``replay``: size and accept by re-simulation;
    ``result``: the training runs' identification, when known (see :func:`fit_linear_model`)."""
    model = fit_linear_model(experiment, result)
    residuals = equation_residuals(model)
    sensors = check_sensors(model)
    where = locate(residuals.located_rows, model.storeys, (model.f_low, model.f_top))
    screening = screen(model, residuals, sensors)
    refitter = Refitter(model, screening.pattern)
    found = select(model, choose(screening, residuals, where), screening, refitter, where, replay=replay)
    return Stages(model, residuals, sensors, where, screening, refitter, found)
