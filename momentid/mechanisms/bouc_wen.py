"""Bouc-Wen hysteresis in a storey (the shear-frame form of the nonlinear system identification
workshop's benchmark), in the yield-drift-normalised form.

The storey's restoring force is ``alpha k x + (1 - alpha) k z`` (``k``: the storey's linear
stiffness, ``x``: its drift) with the hysteretic drift ``z`` obeying

    z' = x' - (beta |x'| |z|^(n-1) z + gamma x' |z|^n) / x_y^n,     gamma = 1 - beta,

so that ``z`` follows ``x`` for small drifts and saturates at ``x_y`` (the yield drift): the storey
softens to ``alpha k`` beyond yield, with loops whose area grows with the drift amplitude.  The
storey tendon keeps ``k x``; the callback adds ``(1 - alpha) k (z - x)``.  ``z`` has memory: the
simulator integrates it as a MuJoCo state (:meth:`~momentid.mechanisms.base.MechanismKind.has_state`),
so every RK4 stage sees its own trial value.

Hidden scenarios carry it to test the diagnosis's open search, and a real rig's twin fits it
(``real_rig``: :meth:`BoucWen.twin_parameters`; re-simulated with its compiled law and state).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from momentid.mechanisms.base import MechanismKind, Param, Signal, Target
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.registry import register

__all__ = ["BoucWen", "bouc_wen_rate", "bouc_wen_state", "TWIN_ALPHA"]

#: A real rig's twin starts its Bouc-Wen storeys with this share of the stiffness elastic (the rest
#: hysteretic): at 1, the hysteresis would vanish and with it the fit's gradient in its other parameters.
TWIN_ALPHA = 0.9


def bouc_wen_rate(z: Signal, velocity: Signal, yield_drift: Signal, exponent: Signal, beta: float) -> Signal:
    """``z'`` (m/s) of the normalised Bouc-Wen law at state ``z`` (m) and velocity (m/s), with the yield
    drift (m), exponent and ``beta`` of the law; floats or arrays."""
    u = abs(z / yield_drift) ** exponent
    sign = np.sign(velocity * z) if isinstance(z, np.ndarray) else (velocity * z > 0) - (velocity * z < 0)
    return velocity * (1.0 - u * (beta * sign + (1.0 - beta)))


def bouc_wen_state(velocity: np.ndarray, dt: float, yield_drift: ArrayLike, exponent: ArrayLike, beta: float
                   ) -> np.ndarray:
    """The hysteretic drift ``z`` (n, k) driven by a velocity record (m/s) sampled every ``dt`` (s),
    from ``z = 0``, for ``k`` laws at once (``yield_drift``, ``exponent``: arrays (k,); ``velocity``:
    (n,) shared by all, or (n, k), one record per law).

    Heun's method (second order) on the samples: the record's own resolution, for the diagnosis's
    function library; the simulator integrates the same law with RK4 at its step.
    """
    yield_drift, exponent = np.atleast_1d(yield_drift).astype(float), np.atleast_1d(exponent).astype(float)
    z = np.zeros((len(velocity), len(yield_drift)))
    zk = np.zeros(len(yield_drift))
    for k in range(1, len(velocity)):
        v0, v1 = velocity[k - 1], velocity[k]
        r0 = bouc_wen_rate(zk, v0, yield_drift, exponent, beta)
        r1 = bouc_wen_rate(zk + dt * r0, v1, yield_drift, exponent, beta)
        zk = zk + 0.5 * dt * (r0 + r1)
        z[k] = zk
    return z


def _native_force(p, x, v, t, s):   # p: alpha, yield_drift, exponent, beta, stiffness
    return (1.0 - p[0]) * p[4] * (s - x)


def _native_rate(p, s, x, v):
    u = math.pow(abs(s / p[1]), p[2])
    w = v * s
    sign = 1.0 if w > 0.0 else -1.0 if w < 0.0 else 0.0
    return v * (1.0 - u * (p[3] * sign + (1.0 - p[3])))


@register
class BoucWen(MechanismKind):
    name = "bouc_wen"
    target = Target.STOREY
    params = (Param("alpha", "1", "post-yield stiffness over the storey's stiffness", low=0.0, high=1.0, example=0.2),
              Param("yield_drift", "m", "drift where the hysteretic part saturates", low=0.0, low_open=True,
                    example=0.002),
              Param("exponent", "1", "sharpness of the yield (n)", low=1.0, high=10.0, example=2.0),
              Param("beta", "1", "share of the loop's shape term in |x'| (gamma = 1 - beta)", low=0.0, high=1.0,
                    example=0.5))
    truth_only = True
    real_rig = True
    callback = True
    needs_stiffness = True
    summary = "alpha k x + (1 - alpha) k z across a storey, z: Bouc-Wen hysteretic drift (yield drift x_y)"

    def has_state(self, params: dict) -> bool:
        """Always: the hysteretic drift ``z`` (m) is the force's state."""
        return True

    def state_rate(self, params: dict, state: float, displacement: float, velocity: float) -> float:
        """``z'`` (m/s) of the Bouc-Wen law at the state and the drift's rate (:func:`bouc_wen_rate`)."""
        return bouc_wen_rate(state, velocity, params["yield_drift"], params["exponent"], params["beta"])

    def storey_force(self, params: dict, drift: Signal, drift_velocity: Signal, time: float,
                     stiffness: float | None, state: Signal = 0.0) -> Signal:
        """``(1 - alpha) k (z - x)`` (N): the hysteretic part, beside the storey tendon's ``k x``."""
        return (1.0 - params["alpha"]) * stiffness * (state - drift)

    def native_law(self) -> NativeLaw:
        """The compiled force and state rate."""
        return NativeLaw(_native_force, _native_rate)

    def twin_parameters(self, stiffness: float, damping: float, drift: float, velocity: float) -> dict:
        """A storey of a real rig's twin: from a tenth of the stiffness hysteretic (``alpha`` 0.9), yielding
        at the training trials' peak drift with a rounded yield (exponent 2, ``beta`` 0.5); ``alpha`` within
        0-1, the yield drift within 0.02-20 times the peak drift, the exponent within 1-10 (below the yield the
        storey keeps its stiffness: the linear twin's modes at small amplitude)."""
        return {"alpha": (1.0, TWIN_ALPHA, 0.0, 1.0), "yield_drift": (drift, drift, 0.02 * drift, 20.0 * drift),
                "exponent": (1.0, 2.0, 1.0, 10.0), "beta": (1.0, 0.5, 0.0, 1.0)}
