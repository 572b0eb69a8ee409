"""P-Delta: the weight above a storey, leaning on it as it drifts, takes ``g W / h`` from its stiffness.

In a rig the loss is ``factor x g x (mass above) / height`` (1 = the full gravity effect).  The
diagnosis cannot tell the floors' own weight from the stiffness (it is the same in every run), so
it fits the part the added masses change: ``weight_per_height`` (1/m) times ``-g (added mass
above) x drift``, and reports it as ``factor`` when the lab states its storey heights.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from momentid.core.structure import Mechanism, Structure
from momentid.mechanisms.base import (EquationSignals, Fitter, GRAVITY, MechanismKind, Param, Refit, Screened, Target,
                                      one_coefficient)
from momentid.mechanisms.place import Place
from momentid.mechanisms.registry import register
from momentid.mechanisms.sizing import ResimulatedForce

__all__ = ["PDelta"]


@register
class PDelta(ResimulatedForce, MechanismKind):
    name = "p_delta"
    target = Target.STOREY
    params = (Param("factor", "1", "share of the full gravity P-Delta of the weight above", low=0.0,
                    example=1.0),)
    fitted = Param("weight_per_height", "1/m", "factor / storey height", low=0.0, low_open=True)
    refit = Refit.RESIMULATE
    linear_spring = True
    summary = "-factor g (mass above) / h x drift across a storey"

    def storey_tendon(self, mech: Mechanism, stiffness: float, damping: float, weight_above: float,
                      height: float) -> tuple[float, float]:
        """The storey's stiffness less ``factor g m / h`` (``m``: the mass above, kg; ``h``: the height, m)."""
        return stiffness - mech.get("factor") * GRAVITY * weight_above / height, damping

    def screen_equation(self, signals: EquationSignals, fit: Fitter, place: Place) -> list[Screened]:
        """``-g m x`` with ``m`` each sample's added mass above the storey (none when no run adds mass
        there: it is then the stiffness), a spring and a dashpot the confounds.
        """
        above = place.above(signals.added_mass)
        if not np.any(above > 0):   # no run adds mass above: indistinguishable from the stiffness
            return []
        drift = signals.stretch(place)
        return fit([signals.columns(-GRAVITY * above * drift, place)], signals.linear_confounds(place), place,
                   one_coefficient("weight_per_height"))

    def force_signal(self, params: dict, stretch: np.ndarray, rate: np.ndarray, weight_above: float) -> np.ndarray:
        """``-g m x`` (n,): the force per unit ``weight_per_height`` (``m``: ``weight_above``, kg)."""
        return -GRAVITY * weight_above * stretch

    def as_records(self, place: Place, params: dict) -> tuple[Mechanism, ...]:
        """One record of factor 1: the size is the storey height of :meth:`replay_structure`."""
        # Built with factor 1 on a structure whose storey height is 1 / weight_per_height.
        return (Mechanism(self.name, place.index, (("factor", 1.0),)),)

    def replay_structure(self, structure: Structure, place: Place, params: dict, static: bool) -> Structure:
        """The structure whose MJCF ``p_delta`` (factor 1) loses ``weight_per_height x g x weight
        above``: the storey's height is set to 1 / weight_per_height; with ``static`` the loss of the
        floors' own weight, which an identified stiffness already holds, is added back."""
        s = place.index - 1
        h_eff = 1.0 / params["weight_per_height"] if params["weight_per_height"] > 0 else float("inf")
        k = list(structure.storey_stiffness)
        if static:
            k[s] += GRAVITY * sum(structure.masses[s:]) / h_eff
        return replace(structure, storey_stiffness=tuple(k), storey_heights=tuple(
            h_eff if i == s else h for i, h in enumerate(structure.storey_heights)))

    def in_lab_terms(self, params: dict, std: dict, place: Place, nominal: Structure | None) -> tuple[dict, dict]:
        """With a stated storey height ``h``, also the lab's ``factor = weight_per_height h``."""
        if nominal is None:   # no stated storey height: weight_per_height it stays
            return params, std
        h = nominal.storey_heights[place.index - 1]
        params = {**params, "factor": params["weight_per_height"] * h}
        if "weight_per_height" in std:
            std = {**std, "factor": std["weight_per_height"] * h}
        return params, std
