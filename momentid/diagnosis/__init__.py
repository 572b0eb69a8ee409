"""Diagnosis: what physics the linear model leaves out, where, and how much.

:func:`~momentid.diagnosis.pipeline.diagnose` runs the stages, one module each:

- :mod:`~momentid.diagnosis.residuals`: the linear model and its equation residual (stages 1-2);
- :mod:`~momentid.diagnosis.sensor_check` (on :mod:`~momentid.diagnosis.consistency`): the sensors
  checked against each other, model-free (stage 3);
- :mod:`~momentid.diagnosis.locate`: where (storey, run, time, amplitude, band) the misfit lives (4);
- :mod:`~momentid.diagnosis.screening`: every registered mechanism's signature fitted (5);
- :mod:`~momentid.diagnosis.refit` and :mod:`~momentid.diagnosis.selection`: the candidates re-simulated,
  the best sized and accepted or not (6);
- :mod:`~momentid.diagnosis.report`: the :class:`Diagnosis` record and its report folder (7);
- :mod:`~momentid.diagnosis.thresholds`: the decision thresholds every stage shares.

The mechanisms themselves live in :mod:`momentid.mechanisms`, one module per kind.
"""

from momentid.diagnosis.pipeline import Diagnosis, diagnose, write_report

__all__ = ["Diagnosis", "diagnose", "write_report"]
