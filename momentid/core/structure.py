"""Core types of a shear building: its parameters and the extra physics a rig may carry.

This module parses nothing: the scenario parser (:mod:`momentid.lab.scenario`),
the recording reader and the importers build these records from their files.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike

from momentid.core import analytic

__all__ = ["Structure", "Mechanism", "LabStatement", "DEFAULT_BASE_MASS"]

#: Mass (kg) of the shake-table platen when a scenario states none: heavy
#: against the paper's ~40 kg model, as a real table is.
DEFAULT_BASE_MASS = 100.0


@dataclass(frozen=True)
class Structure:
    """A shear building; floor 1 is the lowest, storey i joins floor i-1 and i.

    Attributes
    ----------
    masses : tuple of float, length d
        Floor masses (kg).
    storey_stiffness : tuple of float, length d
        Storey stiffnesses (N/m).
    storey_heights : tuple of float, length d
        Storey heights (m); used for drawing and gravity effects only.
    rayleigh_mu, rayleigh_kappa : float
        ``C = mu M + kappa K`` (1/s and s).
    base_mass : float
        Mass of the shake-table platen (kg); it does not enter the
        identification because the base motion is prescribed.
    """

    masses: tuple[float, ...]
    storey_stiffness: tuple[float, ...]
    storey_heights: tuple[float, ...]
    rayleigh_mu: float
    rayleigh_kappa: float
    base_mass: float = DEFAULT_BASE_MASS

    @property
    def storeys(self) -> int:
        """Number of storeys (and floors) ``d``."""
        return len(self.masses)

    def mass_matrix(self) -> np.ndarray:
        """``M``, shape (d, d), kg."""
        return np.diag(self.masses)

    def stiffness_matrix(self) -> np.ndarray:
        """``K``, shape (d, d), N/m."""
        return analytic.shear_stiffness(self.storey_stiffness)

    def damping_matrix(self, added_mass: ArrayLike | None = None) -> np.ndarray:
        """``C = mu (M + dM) + kappa K``, shape (d, d), N*s/m."""
        M = self.mass_matrix()
        if added_mass is not None:
            M = M + np.diag(added_mass)
        return self.rayleigh_mu * M + self.rayleigh_kappa * self.stiffness_matrix()

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict (tuples as lists); :meth:`from_dict` reads it back."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: dict) -> Structure:
        """The structure of a :meth:`to_dict` dict (``base_mass`` defaults when absent)."""
        return cls(
            masses=tuple(float(x) for x in data["masses"]),
            storey_stiffness=tuple(float(x) for x in data["storey_stiffness"]),
            storey_heights=tuple(float(x) for x in data["storey_heights"]),
            rayleigh_mu=float(data["rayleigh_mu"]),
            rayleigh_kappa=float(data["rayleigh_kappa"]),
            base_mass=float(data.get("base_mass", DEFAULT_BASE_MASS)),
        )


@dataclass(frozen=True)
class Mechanism:
    """One piece of physics beyond the linear model: its kind (:mod:`momentid.mechanisms`), where it
    sits (a storey or floor number, 1 = lowest, or two floor numbers; the kind's
    :class:`~momentid.mechanisms.place.Place` reads it) and its parameters."""

    type: str
    location: int | tuple[int, int]
    parameters: tuple[tuple[str, float], ...]

    def get(self, name: str) -> float:
        """The value of parameter ``name`` (a ``KeyError`` when the mechanism has none)."""
        return dict(self.parameters)[name]


@dataclass(frozen=True)
class LabStatement:
    """What a lab states about its rig and instruments when it has no full nominal model.

    A real lab often knows its floor masses (it weighed the blocks) but not the
    stiffness or damping it is trying to measure.  Identification uses the stated
    masses to put K and C in SI units; without them results are mass-normalised.

    Attributes
    ----------
    storeys : int
        Number of storeys d.
    masses : tuple of float, length d, or None
        Stated floor masses (kg), floor 1 first; None when the lab states none.
    storey_heights : tuple of float, length d, or None
        Storey heights (m), for drawing; None when not stated.
    noise : tuple of (str, float)
        Stated noise standard deviation per channel group (``"zdd"``, ``"a"``, ...),
        in that group's SI unit; empty when the lab states none.
    """

    storeys: int
    masses: tuple[float, ...] | None = None
    storey_heights: tuple[float, ...] | None = None
    noise: tuple[tuple[str, float], ...] = ()
