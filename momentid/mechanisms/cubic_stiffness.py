"""Cubic stiffness of a storey: a force ``k3 x^3`` on its drift ``x`` (k3 > 0 hardens, < 0 softens)."""

from __future__ import annotations

from momentid.mechanisms.base import MechanismKind, Param, Refit, Target, one_coefficient
from momentid.mechanisms.native import NativeLaw
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

    def storey_force(self, params, drift, drift_velocity, time, stiffness):
        return params["k3"] * drift * drift * drift

    def link_law(self, params, place, stiffness):
        k3 = params["k3"]   # storey_force on floats, without its call
        return lambda x, v, t: k3 * x * x * x

    def native_law(self):
        return NativeLaw(_native_force)

    def screen_equation(self, signals, fit, place):
        return fit([signals.columns(signals.stretch(place) ** 3, place)], signals.linear_confounds(place), place,
                   one_coefficient("k3"))

    def force_signal(self, params, stretch, rate, weight_above):
        return stretch ** 3
