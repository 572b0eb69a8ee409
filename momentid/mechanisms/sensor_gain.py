"""A sensor channel with the wrong sensitivity: it reads ``gain`` times the true signal."""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import MechanismKind, Param, Refit, Target
from momentid.mechanisms.registry import register

__all__ = ["SensorGain"]


def _from_equation(c, e):
    """Gain of a channel whose reading r = g x leaves (1 - 1/g) r in the residual: c = 1 - 1/g."""
    return {"gain": float(1 / (1 - c[0]))}, {"gain": float(e[0] / (1 - c[0]) ** 2)}


def _from_replay(c, e):
    """Gain of the table channel: a replay driven by g z'' misses (1/g - 1) of it: c = 1/g - 1."""
    return {"gain": float(1 / (1 + c[0]))}, {"gain": float(e[0] / (1 + c[0]) ** 2)}


@register
class SensorGain(MechanismKind):
    name = "sensor_gain"
    target = Target.CHANNEL
    fitted = Param("gain", "1", "reading / true signal", example=1.05)
    refit = Refit.CORRECT_DATA
    kinematic = True
    summary = "gain x(t) recorded as x(t)"

    def distort(self, time, x, params):
        return params["gain"] * x

    def correct(self, time, x, params):
        return x / params["gain"]

    def screen_equation(self, signals, fit, index):
        j, dm, a = index, signals.added_mass[:, index], signals.a[:, index]
        out = []
        if np.any(dm > 0):   # a floor accelerometer's gain is separable from the mass only with added mass
            out += fit([signals.floor_columns(dm * a, j)], [signals.floor_columns(a, j)], {"channel": f"a{j + 1}"},
                       _from_equation)
        column = np.outer(signals.q[:, j], signals.K[:, j]) + np.outer(signals.v[:, j], signals.C[:, j])
        out += fit([column], [], {"channel": f"q{j + 1}"}, _from_equation)
        return out

    def replay_column(self, sim, sim_rate, step):
        return sim, _from_replay
