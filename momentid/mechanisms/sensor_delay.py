"""A sensor channel read late: its clock is ``delay`` seconds behind the others."""

from __future__ import annotations

from typing import Any

import numpy as np

from momentid.mechanisms.base import EquationSignals, Param, SensorFault, SensorStage, ToParams, one_coefficient
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

    def distort(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """The signal read ``delay`` (s) late: cubic interpolation, held before the first sample."""
        # The true signal read late: cubic interpolation, held before the first sample.
        delay = params["delay"]
        if delay == 0:
            return x
        from scipy.interpolate import CubicSpline
        return CubicSpline(time, x)(np.clip(time - delay, time[0], time[-1]))

    def correct(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """The reading ``delay`` (s) earlier: linear interpolation, held after the last sample."""
        return np.interp(time + params["delay"], time, x)

    def channel_signature(self, signals: EquationSignals, group: str, floor: int
                          ) -> tuple[np.ndarray, list[np.ndarray], ToParams] | None:
        """``-delay`` times the channel's rate through its term of the equations (the floor's inertia for
        ``a_j``, the K column for ``q_j``).
        """
        # Late by tau: the reading is x - tau x', so the residual holds -tau x' through the channel's
        # term of the equations (the floor's inertia for a_j, the K column for q_j).
        j = floor
        if group == "a":
            inertia = signals.masses[j] + signals.added_mass[:, j]
            return signals.floor_columns(-inertia * signals.jerk[:, j], j), [], one_coefficient("delay")
        return -np.outer(signals.v[:, j], signals.K[:, j]), [], one_coefficient("delay")

    def replay_column(self, sim: np.ndarray, sim_rate: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, ToParams]:
        """On the table channel: the replay's rate."""
        return sim_rate, one_coefficient("delay")

    def from_kinematic(self, fit: Any) -> tuple[dict, dict, float]:
        """The kinematic fit's delay alone, its standard error and the share it explains."""
        return {"delay": fit.delay_only}, {"delay": fit.delay_std}, fit.explained["delay"]
