"""A sensor channel with an offset: it reads the true signal plus ``bias``."""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import MechanismKind, Param, Refit, Target, one_coefficient
from momentid.mechanisms.registry import register

__all__ = ["SensorBias"]


@register
class SensorBias(MechanismKind):
    name = "sensor_bias"
    target = Target.CHANNEL
    fitted = Param("bias", "channel unit", "constant offset of the reading", example=0.01)
    refit = Refit.CORRECT_DATA
    summary = "x(t) + bias recorded as x(t)"

    def distort(self, time, x, params):
        return x + params["bias"]

    def correct(self, time, x, params):
        return x - params["bias"]

    def screen_equation(self, signals, fit, index):
        j = index
        ones = np.ones(len(signals.a))
        inertia = signals.masses[j] + signals.added_mass[:, j]
        out = fit([signals.floor_columns(inertia * ones, j)], [], {"channel": f"a{j + 1}"}, one_coefficient("bias"))
        out += fit([np.outer(ones, signals.K[:, j])], [], {"channel": f"q{j + 1}"}, one_coefficient("bias"))
        return out

    def replay_column(self, sim, sim_rate, step):
        return -step, one_coefficient("bias")
