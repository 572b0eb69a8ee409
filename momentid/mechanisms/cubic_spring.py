"""Cubic hardening or softening of a storey as MuJoCo's own polynomial spring: the storey tendon's force
``k x + k3 x^3`` (``x``: the storey's drift; ``k3 > 0`` hardens, ``< 0`` softens), the tendon's third
stiffness coefficient, so that the MJCF carries it and no Python runs in the loop.

The real rig's twin fits it by re-simulation (:mod:`momentid.twin.fit`); ``cubic_stiffness`` is the same
law as a simulator callback, for the lab's hidden scenarios.
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

__all__ = ["CubicSpring", "SOFTEST", "HARDEST"]

#: Bounds of ``3 k3 x^2 / k`` at the training trials' peak drift ``x`` (the storey's tangent stiffness change
#: there): a softening spring keeps a positive tangent stiffness up to twice that drift (``1 + 4 x -0.25 =
#: 0``), so that a held-out trial shaking up to twice as hard replays stable (a softening law whose tangent
#: vanishes just beyond the fitted drifts snaps through on the first harder trial; the shipped rigs soften
#: by a few % of their stiffness); a hardening one may up to treble it.
SOFTEST, HARDEST = -0.25, 3.0


@register
class CubicSpring(MechanismKind):
    name = "cubic_spring"
    target = Target.STOREY
    params = (Param("k3", "N/m^3", "cubic stiffness of the storey tendon, + hardening / - softening", example=3.5e7),)
    truth_only = True
    real_rig = True
    mjcf_elements = True
    summary = "k3 x^3 across a storey (x: drift), MuJoCo's polynomial tendon spring"

    def elements(self, spec: mujoco.MjSpec, mech: Mechanism, place: Place, bodies: Sequence[mujoco.MjsBody],
                 timestep: float) -> dict[int, float]:
        """The cubic term ``k3`` in the storey tendon's polynomial stiffness; no element of its own."""
        tendon = spec.tendon(f"storey{place.index}")
        tendon.stiffness = [tendon.stiffness[0], 0.0, float(mech.get("k3"))]
        return {}

    def twin_parameters(self, stiffness: float, damping: float, drift: float, velocity: float) -> dict:
        """``k3`` in units of the cubic that changes the tangent stiffness by ``stiffness`` at the peak drift,
        searched from 0 within ``SOFTEST`` to ``HARDEST`` of it.
        """
        unit = stiffness / (3.0 * drift * drift)         # k3 that changes the tangent stiffness by k at the peak
        return {"k3": (unit, 0.0, SOFTEST * unit, HARDEST * unit)}

    def describe(self, place: Place, params: dict, std: dict) -> str:
        """A hardening or softening cubic spring, with its ``k3`` (N/m^3)."""
        return (f"{'Hardening' if params['k3'] > 0 else 'Softening'} cubic spring at {place.words}: "
                f"k3 = {params['k3']:.4g} N/m^3.")
