"""The rig as MuJoCo builds it: one type for every model of a shake-table rig momentid simulates.

A :class:`RigModel` is what :func:`momentid.lab.rig.build_spec` turns into MJCF, whoever asks: the
lab's simulation of a scenario (a shear building: storey springs and Rayleigh damping), the
re-simulation of a real rig fitted to its trials (:mod:`momentid.lab.resim`: a full stiffness
matrix, modal damping, joint friction) and the calibrated twin (:mod:`momentid.twin.spec`: full K and
C, the damping an added mass brings).  It holds the floor masses, the base's, the springs and dashpots
between levels as fixed tendons (:mod:`momentid.lab.tendons`), the floor joints' own damping, the
masses bolted to the floors in the run, and the mechanisms the rig carries.

Two ways to one: :meth:`RigModel.shear` from a :class:`~momentid.core.structure.Structure` (storey
tendons of stiffness ``k_i`` and damping ``kappa k_i``, floor joints damped by ``mu (m_i + dm_i)``,
exactly as the lab always built it), :meth:`RigModel.from_matrices` from any symmetric K and C.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from momentid.core.structure import DEFAULT_BASE_MASS, Mechanism, Structure
from momentid.errors import ModelError
from momentid.lab.tendons import Tendon, tendon_layout

__all__ = ["RigModel"]


@dataclass(frozen=True)
class RigModel:
    """A shake-table rig for :func:`momentid.lab.rig.build_spec` (SI units; floor 1 is the lowest).

    Attributes
    ----------
    masses : ndarray, shape (d,)
        Floor masses (kg), without the added masses.
    tendons : tuple of Tendon
        Springs and dashpots between levels (level 0 is the table), storeys ``storey<j>`` first.
    joint_damping : ndarray, shape (d,)
        Each floor joint's own damping (N s/m), against its motion relative to the table.
    storey_heights : ndarray, shape (d,)
        Storey heights (m): where the floors are drawn, and what a storey kind's tendon hook is told.
    base_mass : float
        The table's platen (kg).
    added_mass : ndarray, shape (d,)
        Masses bolted to the floors in this run (kg).
    mechanisms : tuple of Mechanism
        Physics beyond the linear model, each of a registered kind (:mod:`momentid.mechanisms`).
    """

    masses: np.ndarray
    tendons: tuple[Tendon, ...]
    joint_damping: np.ndarray
    storey_heights: np.ndarray
    base_mass: float = DEFAULT_BASE_MASS
    added_mass: np.ndarray = field(default=None)
    mechanisms: tuple = ()

    def __post_init__(self):
        d = len(self.masses)
        if self.added_mass is None:
            object.__setattr__(self, "added_mass", np.zeros(d))

    @property
    def storeys(self) -> int:
        """Number of storeys (and floors) ``d``."""
        return len(self.masses)

    @classmethod
    def shear(cls, structure: Structure, added_mass: ArrayLike | None = None,
              mechanisms: Sequence[Mechanism] = ()) -> RigModel:
        """The shear building ``structure`` with ``added_mass`` (kg, shape (d,); none by default) and
        ``mechanisms``: storey tendons ``k_i`` and ``kappa k_i``, floor joints damped by ``mu (m_i + dm_i)``.

        Raises
        ------
        ModelError
            Added masses of the wrong shape, negative or not finite.
        """
        d = structure.storeys
        dm = np.zeros(d) if added_mass is None else np.asarray(added_mass, float)
        if dm.shape != (d,) or np.any(dm < 0) or not np.all(np.isfinite(dm)):
            raise ModelError(f"added_mass = {dm.tolist()}: expected {d} finite values >= 0 (kg)")
        mu, kappa = structure.rayleigh_mu, structure.rayleigh_kappa
        tendons = tuple(Tendon(f"storey{i + 1}", i, i + 1, k, kappa * k)
                        for i, k in enumerate(structure.storey_stiffness))
        damping = np.array([mu * (m + a) for m, a in zip(structure.masses, dm)])
        return cls(masses=np.asarray(structure.masses, float), tendons=tendons, joint_damping=damping,
                   storey_heights=np.asarray(structure.storey_heights, float), base_mass=structure.base_mass,
                   added_mass=dm, mechanisms=tuple(mechanisms))

    @classmethod
    def from_matrices(cls, masses: ArrayLike, K: ArrayLike, C: ArrayLike, storey_heights: ArrayLike, *,
                      base_mass: float = DEFAULT_BASE_MASS, joint_damping: ArrayLike | None = None,
                      added_mass: ArrayLike | None = None, mechanisms: Sequence[Mechanism] = ()) -> RigModel:
        """A rig carrying the symmetric ``K`` (N/m) and ``C`` (N s/m), each (d, d), exactly as tendons
        (:func:`~momentid.lab.tendons.tendon_layout`), with floor ``masses`` (kg, (d,)) drawn at
        ``storey_heights`` (m, (d,)); ``joint_damping`` (N s/m, (d,)) none by default.

        Raises
        ------
        ModelError
            ``K`` or ``C`` not a symmetric (d, d) matrix.
        """
        masses = np.asarray(masses, float)
        d = masses.size
        K, C = np.asarray(K, float), np.asarray(C, float)
        for name, X in (("stiffness", K), ("damping", C)):
            if X.shape != (d, d) or not np.allclose(X, X.T):
                raise ModelError(f"{name} matrix of shape {X.shape}: expected a symmetric ({d}, {d}) matrix")
        return cls(masses=masses, tendons=tendon_layout(K, C),
                   joint_damping=np.zeros(d) if joint_damping is None else np.asarray(joint_damping, float),
                   storey_heights=np.asarray(storey_heights, float), base_mass=float(base_mass),
                   added_mass=None if added_mass is None else np.asarray(added_mass, float),
                   mechanisms=tuple(mechanisms))

    @property
    def K(self) -> np.ndarray:
        """The stiffness matrix (N/m, (d, d)) the tendons carry (mechanisms aside)."""
        return self._assembled("stiffness")

    @property
    def C(self) -> np.ndarray:
        """The damping matrix (N s/m, (d, d)) the tendons and the floor joints carry (mechanisms aside)."""
        return self._assembled("damping") + np.diag(self.joint_damping)

    def _assembled(self, what: str) -> np.ndarray:
        d = self.storeys
        out = np.zeros((d, d))
        for t in self.tendons:
            w = np.zeros(d)
            w[t.upper - 1] = 1.0
            if t.lower > 0:
                w[t.lower - 1] = -1.0
            out += getattr(t, what) * np.outer(w, w)
        return out
