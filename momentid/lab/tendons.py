"""Any symmetric stiffness and damping matrix as fixed tendons between the rig's levels.

:func:`tendon_layout` writes K and C exactly as fixed tendons (see ``models/twin/README.md``): every
pair of levels ``i < j`` (level 0 is the table, level ``j`` floor ``j``) gets a tendon of length
``q_j - q_i`` with stiffness ``-K_ij`` (``i >= 1``) or the row sum ``sum_l K_jl`` (``i = 0``), and
damping likewise from C, so that ``sum_t k_t c_t c_t^T = K`` entry by entry.  A shear building's
tridiagonal K and C need the storey tendons only; a real rig's full matrices add link tendons.
:func:`put_tendon` writes one into a ``mujoco.MjSpec``.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["Tendon", "tendon_layout", "pair_coefficient", "put_tendon"]


@dataclass(frozen=True)
class Tendon:
    """One fixed tendon of the rig: length ``q_upper - q_lower`` (level 0 is the table).

    Attributes
    ----------
    name : str
        ``storey<j>`` when it joins neighbouring levels ``j-1`` and ``j``, else ``link<i>_<j>``.
    lower, upper : int
        Levels joined, ``0 <= lower < upper <= d``.
    stiffness : float
        N/m (negative on a link that stiffens the floors' difference less than the storeys imply).
    damping : float
        N s/m.
    """

    name: str
    lower: int
    upper: int
    stiffness: float
    damping: float


def pair_coefficient(X: np.ndarray, lower: int, upper: int) -> float:
    """The tendon coefficient between levels ``lower < upper`` that puts ``X`` together exactly."""
    if lower == 0:
        return float(np.sum(X[upper - 1]))
    return float(-X[lower - 1, upper - 1])


def tendon_layout(K: np.ndarray, C: np.ndarray) -> tuple:
    """Fixed tendons whose stiffnesses sum to ``K`` and damping to ``C`` exactly.

    Storey tendons (neighbouring levels) always; a link tendon only where K or C needs one (a
    shear building's tridiagonal K and C need none).

    Parameters
    ----------
    K, C : ndarray, shape (d, d)
        Symmetric (N/m, N s/m).

    Returns
    -------
    tuple of Tendon
        Storeys first (1..d), then links by lower level, upper level.
    """
    d = K.shape[0]
    out = [Tendon(f"storey{j}", j - 1, j, pair_coefficient(K, j - 1, j), pair_coefficient(C, j - 1, j))
           for j in range(1, d + 1)]
    for i in range(d + 1):
        for j in range(i + 2, d + 1):
            k, c = pair_coefficient(K, i, j), pair_coefficient(C, i, j)
            if k != 0.0 or c != 0.0:
                out.append(Tendon(f"link{i}_{j}", i, j, k, c))
    return tuple(out)


def put_tendon(spec: mujoco.MjSpec, t: Tendon) -> None:
    """Write one tendon of :func:`tendon_layout` into ``spec``.

    A spring-damper on ``q_upper - q_lower`` (``q_upper`` alone when ``lower`` is the table) of
    stiffness ``t.stiffness`` (N/m) and damping ``t.damping`` (N s/m), rest length 0.  The rig's own
    storey tendon of that name is reused when ``spec`` has one (``rig.build_spec``); otherwise the
    tendon is added.
    """
    tendon = spec.tendon(t.name)
    if tendon is None:
        tendon = spec.add_tendon(name=t.name)
        tendon.wrap_joint(f"q{t.upper}", 1.0)
        if t.lower > 0:
            tendon.wrap_joint(f"q{t.lower}", -1.0)
    tendon.stiffness = [t.stiffness, 0.0, 0.0]
    tendon.damping = [t.damping, 0.0, 0.0]
    tendon.springlength = [0.0, 0.0]
