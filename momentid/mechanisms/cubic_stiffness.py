"""Cubic stiffness of a storey: a force ``k3 x^3`` on its drift ``x`` (k3 > 0 hardens, < 0 softens)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from momentid.mechanisms.base import (EquationSignals, Fitter, MechanismKind, Param, Refit, Screened, Signal, Target,
                                      one_coefficient)
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.place import Place
from momentid.mechanisms.registry import register
from momentid.mechanisms.sizing import ResimulatedForce

__all__ = ["CubicStiffness"]


def _native_force(p, x, v, t, s):
    return p[0] * x * x * x


@register
class CubicStiffness(ResimulatedForce, MechanismKind):
    name = "cubic_stiffness"
    target = Target.STOREY
    params = (Param("k3", "N/m^3", "cubic stiffness, + hardening / - softening", example=3.5e7),)
    fitted = params[0]
    callback = True
    refit = Refit.RESIMULATE
    summary = "k3 x^3 across a storey (x: drift)"

    def storey_force(self, params: dict, drift: Signal, drift_velocity: Signal, time: float,
                     stiffness: float | None) -> Signal:
        """``k3 x^3`` (N)."""
        return params["k3"] * drift * drift * drift

    def link_law(self, params: dict, place: Place, stiffness: float | None) -> Callable[..., float]:
        """The storey force on floats, with the same arithmetic and no call."""
        k3 = params["k3"]   # storey_force on floats, without its call
        return lambda x, v, t: k3 * x * x * x

    def native_law(self) -> NativeLaw:
        """The compiled force."""
        return NativeLaw(_native_force)

    def screen_equation(self, signals: EquationSignals, fit: Fitter, place: Place) -> list[Screened]:
        """The stretch cubed, a spring and a dashpot at ``place`` the confounds."""
        return fit([signals.columns(signals.stretch(place) ** 3, place)], signals.linear_confounds(place), place,
                   one_coefficient("k3"))

    def force_signal(self, params: dict, stretch: np.ndarray, rate: np.ndarray, weight_above: float) -> np.ndarray:
        """``stretch ** 3`` (m^3): the force (n,) per unit ``k3``."""
        return stretch ** 3
