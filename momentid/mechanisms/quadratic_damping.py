"""Quadratic (aerodynamic or turbulent) damping across a storey: a force ``c2 v |v|`` against the storey's
drift velocity ``v``, MuJoCo's own polynomial damping of the storey tendon (its second coefficient), so
that the MJCF carries it and no Python runs in the loop.  Its equivalent viscous damping grows with the
velocity amplitude (``8 c2 V / (3 pi)`` per cycle of amplitude ``V``).

The real rig's twin fits it by re-simulation (:mod:`momentid.twin.fit`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from momentid.core.structure import Mechanism
from momentid.mechanisms.base import MechanismKind, Param, Target
from momentid.mechanisms.place import Place
from momentid.mechanisms.registry import register

if TYPE_CHECKING:
    import mujoco

__all__ = ["QuadraticDamping", "START_SHARE"]

#: The fit starts where the quadratic damper, at the trials' peak drift velocity, is this share of the
#: storey's viscous damping (the twin's viscous damping keeps the rest).
START_SHARE = 0.5


@register
class QuadraticDamping(MechanismKind):
    name = "quadratic_damping"
    target = Target.STOREY
    params = (Param("c2", "N s^2/m^2", "quadratic damping across the storey (force c2 v |v|)", low=0.0,
                    example=50.0),)
    truth_only = True
    real_rig = True
    mjcf_elements = True
    summary = "c2 v |v| across a storey (v: drift velocity), MuJoCo's polynomial tendon damping"

    def elements(self, spec: mujoco.MjSpec, mech: Mechanism, place: Place, bodies: Sequence[mujoco.MjsBody],
                 timestep: float) -> dict[int, float]:
        """The quadratic term ``c2`` in the storey tendon's polynomial damping; no element of its own."""
        tendon = spec.tendon(f"storey{place.index}")
        tendon.damping = [tendon.damping[0], float(mech.get("c2")), 0.0]
        return {}

    def twin_parameters(self, stiffness: float, damping: float, drift: float, velocity: float) -> dict:
        """``c2`` in units of the one as strong as the viscous damping at the peak velocity, searched from
        ``START_SHARE`` of it up to 1000 times it.
        """
        unit = max(damping, 1e-9) / velocity            # c2 as strong as the viscous damping at the peak velocity
        return {"c2": (unit, START_SHARE * unit, 0.0, 1e3 * unit)}

    def describe(self, place: Place, params: dict, std: dict) -> str:
        """Quadratic damping with its ``c2`` (N s^2/m^2)."""
        return f"Quadratic damping at {place.words}: c2 = {params['c2']:.4g} N s^2/m^2 (force c2 v |v|)."
