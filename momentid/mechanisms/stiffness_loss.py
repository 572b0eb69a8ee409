"""A storey connection that slips: from ``time`` on it loses ``fraction`` of its stiffness.

Truth only: hidden scenarios carry it to test the diagnosis's "unexplained" verdict on physics
outside its library.
"""

from __future__ import annotations

from momentid.mechanisms.base import MechanismKind, Param, Signal, Target
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.registry import register

__all__ = ["StiffnessLoss"]


def _native_force(p, x, v, t, s):
    if t < p[1]:
        return 0.0
    return -p[0] * p[2] * x


@register
class StiffnessLoss(MechanismKind):
    name = "stiffness_loss"
    target = Target.STOREY
    params = (Param("fraction", "1", "share of the storey stiffness lost", low=0.0, high=1.0, low_open=True,
                    example=0.4),
              Param("time", "s", "when the loss starts, from the start of each run", low=0.0,
                    example=5.0))
    truth_only = True
    callback = True
    needs_stiffness = True
    summary = "-fraction k x across a storey from t = time on (k: its stiffness, x: drift)"

    def storey_force(self, params: dict, drift: Signal, drift_velocity: Signal, time: float,
                     stiffness: float | None) -> Signal:
        """``-fraction k x`` from ``time`` (s) on, 0 before (N)."""
        if time < params["time"]:
            return 0.0 * drift
        return -params["fraction"] * stiffness * drift

    def native_law(self) -> NativeLaw:
        """The compiled force."""
        return NativeLaw(_native_force)
