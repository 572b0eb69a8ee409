"""A floor pounding against a stop fixed to the table, on the + side, across a gap.

The stop sits ``gap`` beyond the floor's rest position (displacement relative to the table, + side
only: a one-sided stop).  In contact, the stop pushes back with a spring ``stiffness`` on the
penetration and a dashpot ``damping`` on the floor's velocity; it only pushes (the force is
clipped at zero when the floor pulls away faster than the spring relaxes).

Truth only: hidden scenarios carry it to test the diagnosis's open search (physics outside the
library, :mod:`momentid.diagnosis.added_mass.open_search`).
"""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import MechanismKind, Param, Signal, Target
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.registry import register

__all__ = ["Pounding"]


def _native_force(p, x, v, t, s):
    penetration = x - p[0]
    if penetration <= 0.0:
        return 0.0
    return max(p[1] * penetration + p[2] * v, 0.0)


@register
class Pounding(MechanismKind):
    name = "pounding"
    target = Target.FLOOR_TABLE
    params = (Param("gap", "m", "distance from the floor's rest position to the stop (+ side)", low=0.0,
                    low_open=True, example=0.001),
              Param("stiffness", "N/m", "contact spring of the stop", low=0.0, low_open=True, example=2e4),
              Param("damping", "N s/m", "contact dashpot of the stop", low=0.0, example=0.0))
    truth_only = True
    callback = True
    summary = "max(stiffness (q - gap) + damping q', 0) on a floor beyond q = gap (q: floor vs. table)"

    def floor_force(self, params: dict, displacement: Signal, velocity: Signal, time: float,
                    stiffness: float | None) -> Signal:
        """``max(k penetration + c v, 0)`` beyond the gap, 0 within it (N)."""
        penetration = displacement - params["gap"]
        if isinstance(penetration, float):
            if penetration <= 0.0:
                return 0.0
            return max(params["stiffness"] * penetration + params["damping"] * velocity, 0.0)
        push = params["stiffness"] * penetration + params["damping"] * velocity
        return np.where(penetration > 0, np.maximum(push, 0.0), 0.0)

    def native_law(self) -> NativeLaw:
        """The compiled force."""
        return NativeLaw(_native_force)
