"""``momentid diagnose``: what physics the linear model leaves out, for every kind of recording.

:func:`diagnose` first asks the recorded channels what they show by themselves (stage 0:
:func:`~momentid.diagnosis.data_check.diagnose_data`, a saturated sensor), then takes the recording's
path: a rig identified with added masses (:func:`~momentid.diagnosis.added_mass.path.diagnose_added_mass`),
or, without added mass (accelerometers only), the rig's MuJoCo twin when the lab states its floor masses
and recorded three trials or more (:func:`momentid.diagnosis.twin.path.diagnose_twin`), else the modal
model (:func:`momentid.diagnosis.modal.path.diagnose_modal`).  Every path gives the same
:class:`~momentid.diagnosis.result.Diagnosis`; ``docs/diagnosis.md`` numbers the stages.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.series import Experiment
from momentid.diagnosis.added_mass.path import diagnose_added_mass
from momentid.diagnosis.data_check import diagnose_data
from momentid.diagnosis.report import write_report
from momentid.diagnosis.result import Diagnosis
from momentid.errors import MomentidError

__all__ = ["Diagnosis", "diagnose", "write_report"]


def diagnose(experiment: Experiment, *, replay: bool = True, hold_out: str | None = None) -> Diagnosis:
    """Find, name and model the physics the linear shear model leaves out.

    Parameters
    ----------
    experiment : Experiment
        At least two runs (one with added mass); with three or more, the last
        run is held out for the before/after replay.  Runs without added mass
        (accelerometer-only labs) run on the twin
        (:func:`momentid.diagnosis.twin.path.diagnose_twin`: stated floor masses and three trials or
        more), else take :func:`momentid.diagnosis.modal.path.diagnose_modal`.
    replay : bool
        Replay the held-out run through the linear and augmented MuJoCo models
        (the NRMSE figures); off only for quick screening.
    hold_out : str, optional
        Runs without added mass only: the run to hold out (default: the last; on the twin, the last
        trial of the others' rig state inside their amplitudes).

    Returns
    -------
    Diagnosis
        When a recorded channel shows a fault by itself (a saturation's clipped peaks), that fault, named
        with no model (:func:`momentid.diagnosis.data_check.diagnose_data`): the model-based stages need
        channels without it.
    """
    named = diagnose_data(experiment)   # what the channels show by themselves (a saturation) comes first
    if named is not None:
        return named
    if not any(np.any(run.added_mass) for run in experiment.runs):
        from momentid.diagnosis.twin import path as twin_diagnose
        if twin_diagnose.applies(experiment):        # stated masses, 3+ trials: on the MuJoCo twin
            with threadpool_limits(limits=1, user_api="blas"):
                return twin_diagnose.diagnose_twin(experiment, hold_out=hold_out)
        from momentid.diagnosis.modal.path import diagnose_modal
        return replace(diagnose_modal(experiment, hold_out=hold_out), notes=tuple(experiment.notes))
    if hold_out is not None:
        raise MomentidError(f"{experiment.source}: hold_out = {hold_out!r}: choosing the held-out run works for "
                            f"runs without added mass only; this experiment adds mass (its last run is held out)")
    # Thousands of small dense products (8 x 8 exponentials in the errors-in-variables refits): BLAS
    # threads only add waiting, 6x on a busy 2-core machine.
    with threadpool_limits(limits=1, user_api="blas"):
        return diagnose_added_mass(experiment, replay)
