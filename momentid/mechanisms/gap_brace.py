"""A storey brace that engages only beyond a gap: a dead-zone spring on the storey's drift.

Slack bracing (a cable or a bolted brace with oversized holes) carries no force until the storey's
drift ``x`` exceeds the slack ``gap`` either way; beyond it the brace adds its ``stiffness``:
``stiffness sign(x) max(|x| - gap, 0)``.

Truth only: hidden scenarios carry it to test the diagnosis's open search (physics outside the
library, :mod:`momentid.diagnosis.added_mass.open_search`).
"""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import MechanismKind, Param, Signal
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.place import Target
from momentid.mechanisms.registry import register

__all__ = ["GapBrace"]


def _native_force(p, x, v, t, s):
    beyond = abs(x) - p[0]
    if beyond > 0.0:
        return p[1] * (beyond if x > 0.0 else -beyond)
    return 0.0


@register
class GapBrace(MechanismKind):
    name = "gap_brace"
    target = Target.STOREY
    params = (Param("gap", "m", "slack of the brace: the drift (either way) beyond which it engages", low=0.0,
                    low_open=True, example=0.001),
              Param("stiffness", "N/m", "stiffness of the brace once engaged", low=0.0, low_open=True,
                    example=2000.0))
    truth_only = True
    callback = True
    summary = "stiffness sign(x) max(|x| - gap, 0) across a storey (x: drift): a brace engaging beyond a gap"

    def storey_force(self, params: dict, drift: Signal, drift_velocity: Signal, time: float,
                     stiffness: float | None) -> Signal:
        """``stiffness (|x| - gap)`` with the drift's sign beyond the gap, 0 within it (N)."""
        beyond = abs(drift) - params["gap"]
        if isinstance(drift, float):
            return params["stiffness"] * (beyond if drift > 0 else -beyond) if beyond > 0.0 else 0.0
        return params["stiffness"] * np.sign(drift) * np.maximum(beyond, 0.0)

    def native_law(self) -> NativeLaw:
        """The compiled force."""
        return NativeLaw(_native_force)
