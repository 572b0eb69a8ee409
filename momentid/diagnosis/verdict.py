"""The verdict of a diagnosis, and one named mechanism: the words every stage and report share."""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["Verdict", "Named"]


class Verdict(enum.Enum):
    """What a diagnosis concludes (``report.json``'s ``mechanism`` is ``none``, ``unexplained``,
    ``another_rig_state`` or the named mechanism)."""

    NONE = "none"                    # the linear model explains the recordings to the noise level
    UNEXPLAINED = "unexplained"      # a mismatch no candidate of the library explains
    MECHANISM = "mechanism"          # a named mechanism
    #: The held-out trial is of another rig state than the training trials (another day, sensors or
    #: joints re-mounted: :mod:`momentid.estimation.rig_state`): its misfit is not evidence of physics.
    ANOTHER_RIG_STATE = "another_rig_state"


@dataclass(frozen=True)
class Named:
    """One named mechanism: ``report.json``'s ``mechanisms`` entry (parameters in the lab's terms).

    ``mechanism`` is a kind of :mod:`momentid.mechanisms` (or, for recordings without added mass,
    ``amplitude_dependence``); ``location`` its place (:attr:`~momentid.mechanisms.place.Place.location`).
    """

    mechanism: str
    location: dict
    parameters: dict
    std: dict

    def to_dict(self) -> dict:
        """The named mechanism, its place, parameters and standard errors."""
        return {"mechanism": self.mechanism, "location": self.location, "parameters": self.parameters,
                "std": self.std}
