"""Stage 3 of the added-mass diagnosis: the sensors checked against each other, whatever the structure does.

A floor accelerometer must read the table acceleration plus the floor displacement's second
derivative (``a_j = zdd + q_j''``, :func:`~momentid.diagnosis.added_mass.kinematic_check.kinematic_check`).  One
channel that contradicts the others is a sensor fault, which also disturbs every model-based
residual; consistent channels rule out a gain or a clock offset on any of them.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from momentid import mechanisms
from momentid.diagnosis.added_mass.kinematic_check import KinematicCheck, kinematic_check
from momentid.diagnosis.added_mass.residuals import LinearModel
from momentid.diagnosis.added_mass.screening import Candidate, Domain
from momentid.diagnosis.thresholds import EXPLAINED
from momentid.mechanisms.place import Place, Target

__all__ = ["SensorCheck", "check_sensors"]

#: Fits of the kinematic check listed in the report.
REPORTED_FITS = 3


@dataclass(frozen=True)
class SensorCheck:
    """Result of :func:`check_sensors`.

    Attributes
    ----------
    check : KinematicCheck or None
        The kinematic check (None when the channels it needs were not recorded).
    candidate : Candidate or None
        Its best single-channel fit when the channels disagree.
    fault : Candidate or None
        ``candidate`` when it explains the disagreement (at least ``EXPLAINED`` of it): a
        conclusive sensor fault.  Else the channels disagree but no single channel's gain or delay
        says why (several faults, or noise that is not white), and the model-based screening decides.
    """

    check: KinematicCheck | None
    candidate: Candidate | None
    fault: Candidate | None

    @property
    def consistent(self) -> bool:
        """Whether the kinematic check ran and found every channel consistent."""
        return self.check is not None and self.check.consistent

    def rules_out(self, candidate: Candidate) -> bool:
        """Consistent channels rule out the sensor faults the check tests."""
        return self.consistent and candidate.kind.kinematic

    def to_dict(self) -> dict:
        """``sensor_check`` of ``report.json`` (empty without a check)."""
        kin = self.check
        if kin is None:
            return {}
        return {"relation": "a_j = zdd + q_j''", "band_hz": list(kin.band), "excess": kin.excess,
                "consistent": kin.consistent, "fits": [asdict(f) for f in kin.fits[:REPORTED_FITS]]}


def check_sensors(model: LinearModel) -> SensorCheck:
    """Stage 3: check the training runs' channels against each other.

    When they disagree, the channel whose fit removes most of the disagreement is read as each sensor
    fault the check tests (``kinematic`` kinds, :meth:`~momentid.mechanisms.base.MechanismKind.from_kinematic`);
    the one that explains most is the candidate (the first registered on a tie).
    """
    kin = kinematic_check(model.train.runs, model.storeys, model.f_top)
    if kin is None or kin.consistent or not kin.fits:
        return SensorCheck(kin, None, None)
    fit, place = kin.fits[0], Place(Target.CHANNEL, kin.fits[0].channel)
    readings = [(kind, kind.from_kinematic(fit)) for kind in mechanisms.library() if kind.kinematic]
    kind, (params, std, explained) = max(readings, key=lambda r: r[1][2])
    candidate = Candidate(kind, place, params, std, explained, Domain.SENSORS)
    return SensorCheck(kin, candidate, candidate if explained >= EXPLAINED else None)
