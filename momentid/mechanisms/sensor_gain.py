"""A sensor channel with the wrong sensitivity: it reads ``gain`` times the true signal."""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import Param, SensorFault, SensorStage
from momentid.mechanisms.registry import register

__all__ = ["SensorGain"]


def _from_equation(c, e):
    """Gain of a channel whose reading r = g x leaves (1 - 1/g) r in the residual: c = 1 - 1/g."""
    return {"gain": float(1 / (1 - c[0]))}, {"gain": float(e[0] / (1 - c[0]) ** 2)}


def _from_replay(c, e):
    """Gain of the table channel: a replay driven by g z'' misses (1/g - 1) of it: c = 1/g - 1."""
    return {"gain": float(1 / (1 + c[0]))}, {"gain": float(e[0] / (1 + c[0]) ** 2)}


@register
class SensorGain(SensorFault):
    name = "sensor_gain"
    fitted = Param("gain", "1", "reading / true signal", example=1.05)
    setting = Param("gain", "1", "reading / true signal", low=0.0, low_open=True, example=1.05)
    stage = SensorStage.GAIN
    kinematic = True
    summary = "gain x(t) recorded as x(t)"

    def distort(self, time, x, params):
        return params["gain"] * x

    def correct(self, time, x, params):
        return x / params["gain"]

    def channel_signature(self, signals, group, floor):
        j = floor
        if group == "a":
            dm, a = signals.added_mass[:, j], signals.a[:, j]
            if not np.any(dm > 0):   # a floor accelerometer's gain is separable from the mass only with added mass
                return None
            return signals.floor_columns(dm * a, j), [signals.floor_columns(a, j)], _from_equation
        column = np.outer(signals.q[:, j], signals.K[:, j]) + np.outer(signals.v[:, j], signals.C[:, j])
        return column, [], _from_equation

    def replay_column(self, sim, sim_rate, step):
        return sim, _from_replay

    def from_kinematic(self, fit):
        return {"gain": fit.gain_only}, {"gain": fit.gain_std}, fit.explained["gain"]
