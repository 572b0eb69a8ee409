"""A sensor channel with an offset: it reads the true signal plus ``bias``."""

from __future__ import annotations

import numpy as np

from momentid.mechanisms.base import EquationSignals, Param, SensorFault, ToParams, one_coefficient
from momentid.mechanisms.registry import register

__all__ = ["SensorBias"]


@register
class SensorBias(SensorFault):
    name = "sensor_bias"
    fitted = Param("bias", "channel unit", "constant offset of the reading", example=0.01)
    setting = fitted
    summary = "x(t) + bias recorded as x(t)"

    def distort(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """``x + bias``."""
        return x + params["bias"]

    def correct(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """``x - bias``."""
        return x - params["bias"]

    def channel_signature(self, signals: EquationSignals, group: str, floor: int
                          ) -> tuple[np.ndarray, list[np.ndarray], ToParams] | None:
        """On ``a_j``: ``-(m_j + dm_j) bias`` on floor ``j``; on ``q_j``: ``-K[:, j] bias`` on every floor."""
        # An offset b on a_j leaves -(m_j + dm_j) b on floor j; on q_j, -K[:, j] b on every floor.
        j, ones = floor, np.ones(len(signals.a))
        if group == "a":
            return signals.floor_columns((signals.masses[j] + signals.added_mass[:, j]) * ones, j), [], \
                one_coefficient("bias")
        return np.outer(ones, signals.K[:, j]), [], one_coefficient("bias")

    def replay_column(self, sim: np.ndarray, sim_rate: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, ToParams]:
        """On the table channel: minus the replay of a unit table acceleration."""
        return -step, one_coefficient("bias")
