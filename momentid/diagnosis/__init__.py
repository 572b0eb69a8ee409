"""Diagnosis: what physics the linear model leaves out, where, and how much.

- :mod:`~momentid.diagnosis.pipeline`: :func:`diagnose` and its report.
- :mod:`~momentid.diagnosis.consistency`: sensors checked against each other, model-free.
- :mod:`~momentid.diagnosis.locate`: where (storey, run, time, amplitude, band) the misfit lives.
"""

from momentid.diagnosis.pipeline import Diagnosis, diagnose, write_report

__all__ = ["Diagnosis", "diagnose", "write_report"]
