"""Diagnosis: what physics the linear model leaves out, where, and how much.

:func:`~momentid.diagnosis.pipeline.diagnose` runs the stages, one module each:

- :mod:`~momentid.diagnosis.residuals`: the linear model and its equation residual (stages 1-2);
- :mod:`~momentid.diagnosis.sensor_check` (on :mod:`~momentid.diagnosis.consistency`): the sensors
  checked against each other, model-free (stage 3);
- :mod:`~momentid.diagnosis.locate`: where (storey, run, time, amplitude, band) the misfit lives (4);
- :mod:`~momentid.diagnosis.screening`: every registered mechanism's signature fitted (5);
- :mod:`~momentid.diagnosis.refit`, :mod:`~momentid.diagnosis.replay` and
  :mod:`~momentid.diagnosis.selection`: the candidates re-simulated, the best sized and accepted or
  not (6); :mod:`~momentid.diagnosis.compound`: further mechanisms (6b);
- :mod:`~momentid.diagnosis.result` and :mod:`~momentid.diagnosis.verdict`: the :class:`Diagnosis`
  every recording gets, its :class:`Verdict`; each path's evidence in words
  (:mod:`~momentid.diagnosis.added_mass_words`, :mod:`~momentid.diagnosis.modal_words`,
  :mod:`~momentid.diagnosis.twin_words`); :mod:`~momentid.diagnosis.report`: the report folder (7);
- :mod:`~momentid.diagnosis.twin_diagnose` (with :mod:`~momentid.estimation.rig_state`,
  :mod:`~momentid.twin.fit` and :mod:`~momentid.diagnosis.twin_folds`): recordings without added mass, with
  stated floor masses and three trials or more, on the rig's MuJoCo twin (the same result);
- :mod:`~momentid.diagnosis.real`: the other recordings without added mass (the modal path, the same
  result);
- :mod:`~momentid.diagnosis.thresholds`: the decision thresholds every stage shares.

The mechanisms themselves live in :mod:`momentid.mechanisms`, one module per kind; the stages know
them by their contract (where they act, their signatures), never by name.
"""

from momentid.diagnosis.pipeline import Diagnosis, diagnose, write_report
from momentid.diagnosis.verdict import Verdict

__all__ = ["Diagnosis", "Verdict", "diagnose", "write_report"]
