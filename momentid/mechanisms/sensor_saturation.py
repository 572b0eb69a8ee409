"""A sensor channel that saturates: beyond its range, its reading is held at +/- ``level``.

A fault that cannot be undone (the clipped peaks are lost), and one the recorded channel shows by
itself: flat runs at its extreme, entered by a step (:func:`momentid.core.clipping.find_clipping`), which
the recorded runs' checks used only to refuse.  The diagnosis reads them as this kind's finding, names it
at its channel with the level, and replays the model with the channel's reading clipped.
"""

from __future__ import annotations

import numpy as np

from momentid.core.clipping import find_clipping
from momentid.core.series import RunData
from momentid.errors import ModelError
from momentid.mechanisms.base import Param, SensorFault, SensorStage
from momentid.mechanisms.registry import register

__all__ = ["SensorSaturation"]


@register
class SensorSaturation(SensorFault):
    name = "sensor_saturation"
    fitted = Param("level", "channel unit", "full scale of the reading: held at +/- level beyond it", low=0.0,
                   low_open=True, example=3.0)
    setting = Param("saturation", "channel unit", "full scale of the channel's reading (+/-)", low=0.0,
                    low_open=True, example=0.5)
    stage = SensorStage.RANGE
    reversible = False
    summary = "x(t) held at +/- level beyond it, recorded as x(t) (a transducer's range)"

    def distort(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """``x`` clipped at ``-level`` and ``+level``."""
        return np.clip(x, -params["level"], params["level"])

    def correct(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """Refused (:class:`~momentid.errors.ModelError`): the clipped peaks are lost."""
        raise ModelError(f"{self.name}: the clipped peaks are lost: the fault cannot be undone")

    def inspect(self, run: RunData, channel: str) -> tuple[dict, float] | None:
        """The clipping level the channel shows (:func:`~momentid.core.clipping.find_clipping`) and the share of
        its samples clipped, or None.
        """
        found = find_clipping(np.asarray(run[channel], float))
        if found is None:
            return None
        return {"level": found.level}, found.samples / run.n_samples
