"""A sensor channel with an offset: it reads the true signal plus ``bias``."""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import Param, SensorFault, one_coefficient
from momentid.mechanisms.registry import register

__all__ = ["SensorBias"]


@register
class SensorBias(SensorFault):
    name = "sensor_bias"
    fitted = Param("bias", "channel unit", "constant offset of the reading", example=0.01)
    setting = fitted
    summary = "x(t) + bias recorded as x(t)"

    def distort(self, time, x, params):
        return x + params["bias"]

    def correct(self, time, x, params):
        return x - params["bias"]

    def channel_signature(self, signals, group, floor):
        # An offset b on a_j leaves -(m_j + dm_j) b on floor j; on q_j, -K[:, j] b on every floor.
        j, ones = floor, np.ones(len(signals.a))
        if group == "a":
            return signals.floor_columns((signals.masses[j] + signals.added_mass[:, j]) * ones, j), [], \
                one_coefficient("bias")
        return np.outer(ones, signals.K[:, j]), [], one_coefficient("bias")

    def replay_column(self, sim, sim_rate, step):
        return -step, one_coefficient("bias")
