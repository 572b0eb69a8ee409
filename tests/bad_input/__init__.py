"""The bad-input suite (issue 12): every case is a row of a table, grouped by entry point.

``python -m tests.bad_input --summary`` runs every case and prints the count per entry point and
outcome class (the figures of docs/reliability.md); ``pytest tests/bad_input`` runs them as tests.
"""

from __future__ import annotations

from . import at2, cli, csv_import, import_faults, imu_import, recording, scenario, second_sweep, shipped_faults
from ._core import Case, Group, Observed, Outcome, check, observe

__all__ = ["CASES", "Case", "Group", "Observed", "Outcome", "check", "observe"]

#: Every case, by the module that holds it (each case names its entry point, :class:`Group`).
CASES: list[Case] = [*scenario.CASES, *at2.CASES, *csv_import.CASES, *imu_import.CASES, *recording.CASES,
                     *cli.CASES, *import_faults.CASES, *shipped_faults.CASES, *second_sweep.CASES]
