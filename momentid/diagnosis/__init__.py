"""Diagnosis: what physics the linear model leaves out, where, and how much.

:func:`~momentid.diagnosis.dispatch.diagnose` asks the recorded channels first (stage 0,
:mod:`~momentid.diagnosis.data_check`: a fault a channel shows by itself), then takes the recording's path,
one subpackage each, around shared stages:

- :mod:`~momentid.diagnosis.added_mass`: a rig identified with added masses (stages 1-8 of
  ``docs/diagnosis.md``: linear model and residuals, sensors against each other, where, screening,
  choice by re-simulation, further mechanisms, report, open search);
- :mod:`~momentid.diagnosis.twin`: accelerometer-only recordings with stated floor masses and three
  trials or more, on the rig's MuJoCo twin (fitted by :mod:`momentid.twin.fit`);
- :mod:`~momentid.diagnosis.modal`: the other accelerometer-only recordings, on the modal model.

Shared by every path: :mod:`~momentid.diagnosis.result` and :mod:`~momentid.diagnosis.verdict` (the
:class:`Diagnosis` every recording gets, its :class:`Verdict`), :mod:`~momentid.diagnosis.thresholds`
(the decision thresholds), :mod:`~momentid.diagnosis.report` (the report folder) and
:mod:`~momentid.diagnosis.figures`; the open searches' :mod:`~momentid.diagnosis.function_library` and
:mod:`~momentid.diagnosis.discovered_physics` (what a discovered force is, physically).

The mechanisms themselves live in :mod:`momentid.mechanisms`, one module per kind; the stages know
them by their contract (where they act, their signatures, how they are sized), never by name.
"""

from momentid.diagnosis.dispatch import Diagnosis, diagnose, write_report
from momentid.diagnosis.verdict import Verdict

__all__ = ["Diagnosis", "Verdict", "diagnose", "write_report"]
