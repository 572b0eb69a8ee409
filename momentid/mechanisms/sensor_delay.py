"""A sensor channel read late: its clock is ``delay`` seconds behind the others."""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import MechanismKind, Param, Refit, Target, one_coefficient
from momentid.mechanisms.registry import register

__all__ = ["SensorDelay"]


@register
class SensorDelay(MechanismKind):
    name = "sensor_delay"
    target = Target.CHANNEL
    fitted = Param("delay", "s", "how late the channel reads (+ = late)", example=0.01)
    refit = Refit.CORRECT_DATA
    kinematic = True
    summary = "x(t - delay) recorded as x(t)"

    def distort(self, time, x, params):
        return np.interp(time - params["delay"], time, x)

    def correct(self, time, x, params):
        return np.interp(time + params["delay"], time, x)

    def screen_equation(self, signals, fit, index):
        # Late by tau: the reading is x - tau x', so the residual holds -tau x' through the channel's
        # term of the equations (the floor's inertia for a_j, the K and C columns for q_j).
        j = index
        inertia = signals.masses[j] + signals.added_mass[:, j]
        out = fit([signals.floor_columns(-inertia * signals.jerk[:, j], j)], [], {"channel": f"a{j + 1}"},
                  one_coefficient("delay"))
        out += fit([-np.outer(signals.v[:, j], signals.K[:, j])], [], {"channel": f"q{j + 1}"},
                   one_coefficient("delay"))
        return out

    def replay_column(self, sim, sim_rate, step):
        return sim_rate, lambda c, e: ({"delay": float(c[0])}, {"delay": float(e[0])})
