"""A sensor channel read late: its clock is ``delay`` seconds behind the others."""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import Param, SensorFault, SensorStage, one_coefficient
from momentid.mechanisms.registry import register

__all__ = ["SensorDelay"]


@register
class SensorDelay(SensorFault):
    name = "sensor_delay"
    fitted = Param("delay", "s", "how late the channel reads (+ = late)", example=0.01)
    setting = Param("clock_offset", "s", "how late the channel's clock reads (+ = late)", example=0.01)
    stage = SensorStage.SIGNAL
    kinematic = True
    summary = "x(t - delay) recorded as x(t)"

    def distort(self, time, x, params):
        # The true signal read late: cubic interpolation, held before the first sample.
        delay = params["delay"]
        if delay == 0:
            return x
        from scipy.interpolate import CubicSpline
        return CubicSpline(time, x)(np.clip(time - delay, time[0], time[-1]))

    def correct(self, time, x, params):
        return np.interp(time + params["delay"], time, x)

    def channel_signature(self, signals, group, floor):
        # Late by tau: the reading is x - tau x', so the residual holds -tau x' through the channel's
        # term of the equations (the floor's inertia for a_j, the K column for q_j).
        j = floor
        if group == "a":
            inertia = signals.masses[j] + signals.added_mass[:, j]
            return signals.floor_columns(-inertia * signals.jerk[:, j], j), [], one_coefficient("delay")
        return -np.outer(signals.v[:, j], signals.K[:, j]), [], one_coefficient("delay")

    def replay_column(self, sim, sim_rate, step):
        return sim_rate, one_coefficient("delay")

    def from_kinematic(self, fit):
        return {"delay": fit.delay_only}, {"delay": fit.delay_std}, fit.explained["delay"]
