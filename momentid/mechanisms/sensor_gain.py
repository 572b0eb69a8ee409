"""A sensor channel with the wrong sensitivity: it reads ``gain`` times the true signal."""

from __future__ import annotations

from typing import Any

import numpy as np

from momentid.mechanisms.base import EquationSignals, Param, SensorFault, SensorStage, ToParams
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

    def distort(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """``gain x``."""
        return params["gain"] * x

    def correct(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """``x / gain``."""
        return x / params["gain"]

    def channel_signature(self, signals: EquationSignals, group: str, floor: int
                          ) -> tuple[np.ndarray, list[np.ndarray], ToParams] | None:
        """On ``a_j``: ``dm_j a_j`` with ``a_j`` the confound (None without added mass there); on ``q_j``:
        its K and C columns.
        """
        j = floor
        if group == "a":
            dm, a = signals.added_mass[:, j], signals.a[:, j]
            if not np.any(dm > 0):   # a floor accelerometer's gain is separable from the mass only with added mass
                return None
            return signals.floor_columns(dm * a, j), [signals.floor_columns(a, j)], _from_equation
        column = np.outer(signals.q[:, j], signals.K[:, j]) + np.outer(signals.v[:, j], signals.C[:, j])
        return column, [], _from_equation

    def replay_column(self, sim: np.ndarray, sim_rate: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, ToParams]:
        """On the table channel: the replay itself."""
        return sim, _from_replay

    def from_kinematic(self, fit: Any) -> tuple[dict, dict, float]:
        """The kinematic fit's gain alone, its standard error and the share it explains."""
        return {"gain": fit.gain_only}, {"gain": fit.gain_std}, fit.explained["gain"]
