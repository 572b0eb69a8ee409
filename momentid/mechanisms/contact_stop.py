"""A floor in contact with stops fixed to the table: on the + side, the - side, or both, across gaps.

A stop sits ``gap_pos`` beyond the floor's rest position on the + side (displacement relative to the
table) and one ``gap_neg`` beyond it on the - side; a gap of 0 means no stop on that side.  In
contact, a stop pushes back with a spring ``stiffness`` on the penetration and a dashpot ``damping``
on the floor's velocity; it only pushes (its force is clipped at zero when the floor pulls away
faster than the spring relaxes).  ``pounding`` is the one-sided case on the + side.

Truth only: hidden scenarios carry it to test the diagnosis's open search (physics outside the
library, :mod:`momentid.diagnosis.added_mass.open_search`).
"""

from __future__ import annotations

import numpy as np

from momentid.core.structure import Mechanism
from momentid.errors import ModelError
from momentid.mechanisms.base import MechanismKind, Param, Signal
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.place import Target
from momentid.mechanisms.registry import register

__all__ = ["ContactStop"]


def _push(penetration, velocity, stiffness: float, damping: float):
    """Force (N, >= 0) of one stop at ``penetration`` (m, > 0 in contact) closing at ``velocity`` (m/s)."""
    if isinstance(penetration, float):
        return max(stiffness * penetration + damping * velocity, 0.0) if penetration > 0.0 else 0.0
    return np.where(penetration > 0, np.maximum(stiffness * penetration + damping * velocity, 0.0), 0.0)


def _native_force(p, x, v, t, s):
    gap_pos, gap_neg, k, c = p[0], p[1], p[2], p[3]
    force = 0.0
    if gap_pos > 0.0 and x - gap_pos > 0.0:
        force += max(k * (x - gap_pos) + c * v, 0.0)
    if gap_neg > 0.0 and -x - gap_neg > 0.0:
        force -= max(k * (-x - gap_neg) - c * v, 0.0)
    return force


@register
class ContactStop(MechanismKind):
    name = "contact_stop"
    target = Target.FLOOR_TABLE
    params = (Param("gap_pos", "m", "distance from the floor's rest position to the stop on the + side "
                    "(0: no stop there)", low=0.0, example=0.001),
              Param("gap_neg", "m", "distance from the floor's rest position to the stop on the - side "
                    "(0: no stop there)", low=0.0, example=0.0),
              Param("stiffness", "N/m", "contact spring of each stop", low=0.0, low_open=True, example=2e4),
              Param("damping", "N s/m", "contact dashpot of each stop", low=0.0, example=0.0))
    truth_only = True
    callback = True
    summary = ("stops on a floor beyond q = +gap_pos and q = -gap_neg (q: floor vs. table), each pushing back "
               "max(stiffness x penetration + damping x closing speed, 0)")

    def validate(self, mech: Mechanism, storeys: int) -> None:
        """The record's checks of every kind, and a stop on at least one side (a gap > 0)."""
        super().validate(mech, storeys)
        p = dict(mech.parameters)
        if p["gap_pos"] == 0.0 and p["gap_neg"] == 0.0:
            raise ModelError(f"mechanism {self.name!r}: gap_pos = gap_neg = 0, expected a stop on at least one "
                             f"side (a gap > 0 in m)")

    def floor_force(self, params: dict, displacement: Signal, velocity: Signal, time: float,
                    stiffness: float | None) -> Signal:
        """The stops' force (N): each stop the floor has passed pushes back ``max(k penetration + c closing
        speed, 0)``."""
        k, c = params["stiffness"], params["damping"]
        force = 0.0 * displacement
        if params["gap_pos"] > 0.0:
            force = force + _push(displacement - params["gap_pos"], velocity, k, c)
        if params["gap_neg"] > 0.0:
            force = force - _push(-displacement - params["gap_neg"], -velocity, k, c)
        return force

    def native_law(self) -> NativeLaw:
        """The compiled force."""
        return NativeLaw(_native_force)
