"""Coulomb friction across a storey: a force of constant size opposing the storey's drift velocity."""

from __future__ import annotations

from collections.abc import Callable
import math

import numpy as np

from momentid.mechanisms.base import (EquationSignals, Fitter, MechanismKind, Param, Refit, Screened, Signal, Target,
                                      one_coefficient)
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.place import Place
from momentid.mechanisms.registry import register
from momentid.mechanisms.sizing import ResimulatedForce

__all__ = ["CoulombFriction", "FRICTION_SMOOTHING", "SCREENING_SMOOTHING", "smooth_sign"]

#: Velocity scale (m/s) of the smoothed Coulomb law ``F tanh(v / FRICTION_SMOOTHING)`` the rig
#: simulates and the refit fits: a sign function for any drift velocity the rig reaches (its
#: storeys move at cm/s), smooth enough for RK4 at a 1 ms step.
FRICTION_SMOOTHING = 5e-4

#: Screening does not use the law's scale: its drift velocities are measured, band-limited and noisy,
#: and a sharp sign of a noisy velocity flips at every zero crossing, so the screening signature is
#: ``tanh(v / (SCREENING_SMOOTHING x RMS(v)))`` (a sign for all but the slowest 5 % of the motion).
SCREENING_SMOOTHING = 0.05

#: Smoothing scale (m/s) of the screening signature when a storey does not move at all.
_STILL = 1e-9


def smooth_sign(x: Signal) -> Signal:
    """``tanh(x)`` of a float (``math.tanh``, the simulator's callback) or of an array (``np.tanh``)."""
    return math.tanh(x) if isinstance(x, float) else np.tanh(x)


def _native_force(p, x, v, t, s):
    return p[0] * math.tanh(v / FRICTION_SMOOTHING)


@register
class CoulombFriction(ResimulatedForce, MechanismKind):
    name = "coulomb_friction"
    target = Target.STOREY
    params = (Param("force", "N", "friction force, opposes the storey drift velocity", low=0.0, low_open=True,
                    example=0.3),)
    fitted = params[0]
    callback = True
    refit = Refit.RESIMULATE
    dissipative = True
    summary = "F tanh(v / FRICTION_SMOOTHING) across a storey (v: drift velocity)"

    def storey_force(self, params: dict, drift: Signal, drift_velocity: Signal, time: float,
                     stiffness: float | None) -> Signal:
        """``force tanh(drift velocity / FRICTION_SMOOTHING)`` (N)."""
        return params["force"] * smooth_sign(drift_velocity / FRICTION_SMOOTHING)

    def link_law(self, params: dict, place: Place, stiffness: float | None) -> Callable[..., float]:
        """The storey force on floats, with the same arithmetic and no calls."""
        force, tanh = params["force"], math.tanh   # storey_force on floats, without its calls
        return lambda x, v, t: force * tanh(v / FRICTION_SMOOTHING)

    def native_law(self) -> NativeLaw:
        """The compiled force."""
        return NativeLaw(_native_force)

    def screen_equation(self, signals: EquationSignals, fit: Fitter, place: Place) -> list[Screened]:
        """``tanh`` of the stretch rate over a fraction of its RMS; a spring and a dashpot at ``place`` are the
        confounds."""
        velocity = signals.stretch_rate(place)
        eps = SCREENING_SMOOTHING * float(np.sqrt(np.mean(velocity ** 2))) or _STILL
        return fit([signals.columns(np.tanh(velocity / eps), place)], signals.linear_confounds(place), place,
                   one_coefficient("force"))

    def force_signal(self, params: dict, stretch: np.ndarray, rate: np.ndarray, weight_above: float) -> np.ndarray:
        """``tanh(rate / FRICTION_SMOOTHING)``: the force (n,) per newton of friction."""
        return np.tanh(rate / FRICTION_SMOOTHING)
