"""A linear viscous damper across one storey, beyond the Rayleigh damping."""

from __future__ import annotations

from momentid.core.structure import Mechanism
from momentid.mechanisms.base import (EquationSignals, Fitter, MechanismKind, Param, Refit, Screened, Target,
                                      one_coefficient)
from momentid.mechanisms.place import Place
from momentid.mechanisms.registry import register
from momentid.mechanisms.sizing import Dashpot

__all__ = ["ExtraDamper"]


@register
class ExtraDamper(Dashpot, MechanismKind):
    name = "extra_damper"
    target = Target.STOREY
    params = (Param("c", "N*s/m", "viscous damper across the storey", low=0.0, low_open=True, example=3.0),)
    fitted = params[0]
    refit = Refit.DAMPING_PATTERN
    summary = "c v across a storey (v: drift velocity), in the storey tendon's damping"

    def storey_tendon(self, mech: Mechanism, stiffness: float, damping: float, weight_above: float,
                      height: float) -> tuple[float, float]:
        """The storey tendon's damping plus ``c`` (N s/m); its stiffness unchanged."""
        return stiffness, damping + mech.get("c")

    def screen_equation(self, signals: EquationSignals, fit: Fitter, place: Place) -> list[Screened]:
        """The stretch rate, the stretch the confound."""
        # A linear damper hides in an identified C: screened against the drift alone (the damping
        # pattern of the identified C is the diagnosis's other test of it).
        return fit([signals.columns(signals.stretch_rate(place), place)],
                   [signals.columns(signals.stretch(place), place)], place, one_coefficient("c"))
