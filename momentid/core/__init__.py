"""Core types and closed-form physics, shared by every layer; nothing here reads a file.

- :mod:`~momentid.core.analytic`: stiffness matrix, Rayleigh coefficients, modes.
- :mod:`~momentid.core.structure`: :class:`Structure` (M, K, Rayleigh C of a shear building) and
  :class:`Mechanism` (one piece of physics beyond the linear model).
- :mod:`~momentid.core.series`: :class:`RunData` (one run's channels, time-first) and
  :class:`Experiment` (the runs of one campaign).
"""

from momentid.core.analytic import Modes, modal_properties, rayleigh_coefficients, shear_stiffness
from momentid.core.structure import LabStatement, Mechanism, Structure
from momentid.core.series import UNITS, Experiment, RunData, channel_unit, json_safe

__all__ = [
    "Modes", "modal_properties", "rayleigh_coefficients", "shear_stiffness",
    "LabStatement", "Mechanism", "Structure",
    "UNITS", "Experiment", "RunData", "channel_unit", "json_safe",
]
