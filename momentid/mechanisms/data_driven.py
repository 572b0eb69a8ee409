"""A force discovered from the data: a sparse sum of terms of one storey's drift, or of one floor's
displacement against the table (the diagnosis's open search, :mod:`momentid.diagnosis.added_mass.open_search`).

The force (N, positive resists ``x``) is ``sum_i c_i phi_i(x, v, t, z)`` over the terms of
:data:`TERMS`, with ``x`` the storey drift or floor displacement (m), ``v`` its rate (m/s), ``t``
the time since the run started (s) and ``z`` a Bouc-Wen hysteretic state driven by ``v`` (m; the
simulator integrates it, :meth:`~momentid.mechanisms.base.MechanismKind.has_state`).  A record
carries every term's coefficient ``c_<term>`` (0: absent) and shape parameters, so the same law
is evaluated on arrays by the function library and on floats by the simulator's callback.

Truth only: the diagnosis builds these records itself, it never names them as a verdict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from momentid.mechanisms.base import MechanismKind, Param, Signal, Target
from momentid.mechanisms.bouc_wen import bouc_wen_rate
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.registry import register

__all__ = ["Term", "TERMS", "HYSTERETIC_BETA", "term_signal", "law", "DataDrivenStorey", "DataDrivenFloor"]

#: The hysteretic term's Bouc-Wen ``beta`` (``gamma = 1 - beta``): symmetric loops that soften with
#: the amplitude (the shape the open search tries; yield drift and exponent are searched on a grid).
HYSTERETIC_BETA = 0.5


@dataclass(frozen=True)
class Term:
    """One term of the function library: its name, the unit of its coefficient, the signal in words,
    and its shape parameters (a gap, a yield drift, a switch time)."""

    name: str
    unit: str
    meaning: str
    shapes: tuple[Param, ...] = ()

    @property
    def coefficient(self) -> str:
        """The record's parameter holding this term's coefficient."""
        return f"c_{self.name}"


def _shape(name: str, unit: str, meaning: str, example: float, low: float = 0.0, low_open: bool = True) -> Param:
    return Param(name, unit, meaning, low=low, low_open=low_open, example=example)


#: The terms a discovered force may combine.
TERMS = (
    Term("x", "N/m", "x (a linear spring)"),
    Term("v", "N s/m", "v (a linear dashpot)"),
    Term("x_abs_x", "N/m^2", "x |x| (quadratic stiffening or softening)"),
    Term("x3", "N/m^3", "x^3 (cubic stiffening or softening)"),
    Term("v_abs_v", "N s^2/m^2", "v |v| (quadratic damping)"),
    Term("sign_v", "N", "tanh(v / v_s) (friction)",
         (_shape("sign_v_scale", "m/s", "velocity scale of the smoothed sign", 1e-3),)),
    Term("dead_zone", "N/m", "sign(x) max(|x| - delta, 0) (a two-sided gap)",
         (_shape("dead_zone_delta", "m", "half-width of the gap", 1e-3, low_open=False),)),
    Term("gap_pos", "N/m", "max(x - delta, 0) (a stop on the + side)",
         (_shape("gap_pos_delta", "m", "distance to the stop", 1e-3, low_open=False),)),
    Term("gap_neg", "N/m", "min(x + delta, 0) (a stop on the - side)",
         (_shape("gap_neg_delta", "m", "distance to the stop", 1e-3, low_open=False),)),
    Term("hysteretic", "N/m", "z, a Bouc-Wen hysteretic drift (hysteresis)",
         (_shape("hysteretic_yield", "m", "yield drift where z saturates", 1e-3),
          Param("hysteretic_exponent", "1", "sharpness of the yield", low=1.0, high=10.0, example=2.0))),
    Term("switch", "N/m", "x H(t - t0) (a stiffness change at t0)",
         (_shape("switch_time", "s", "time of the change, from the start of each run", 5.0, low_open=False),)),
)

_BY_NAME = {t.name: t for t in TERMS}

#: Example coefficients (the registry's tests build a record of examples): a cubic stiffening of the
#: size ``cubic_stiffness``'s example, every other term absent.
_EXAMPLES = {"x3": 3.5e7}


#: Each term's signal ``(params, x, v, time, state)`` -> force per unit coefficient; floats or arrays.
_SIGNALS = {
    "x": lambda p, x, v, time, state: x,
    "v": lambda p, x, v, time, state: v,
    "x_abs_x": lambda p, x, v, time, state: x * abs(x),
    "x3": lambda p, x, v, time, state: x ** 3,
    "v_abs_v": lambda p, x, v, time, state: v * abs(v),
    "sign_v": lambda p, x, v, time, state: np.tanh(v / p["sign_v_scale"]),
    "dead_zone": lambda p, x, v, time, state: np.sign(x) * np.maximum(abs(x) - p["dead_zone_delta"], 0.0),
    "gap_pos": lambda p, x, v, time, state: np.maximum(x - p["gap_pos_delta"], 0.0),
    "gap_neg": lambda p, x, v, time, state: np.minimum(x + p["gap_neg_delta"], 0.0),
    "hysteretic": lambda p, x, v, time, state: state,
    "switch": lambda p, x, v, time, state: x * (np.asarray(time) >= p["switch_time"]),
}


def _above(u: float) -> float:
    """``np.maximum(u, 0.0)`` of a float, bit for bit (numpy returns its second argument for equal
    values, so +0.0 for -0.0, and a NaN of either)."""
    return u if u > 0.0 or u != u else 0.0


def _below(u: float) -> float:
    """``np.minimum(u, 0.0)`` of a float, bit for bit."""
    return u if u < 0.0 or u != u else 0.0


def _sign(u: float) -> float:
    """``np.sign(u)`` of a float, bit for bit (+0.0 for either zero, NaN for NaN)."""
    return 1.0 if u > 0.0 else -1.0 if u < 0.0 else 0.0 if u == 0.0 else u


#: The signals of :data:`_SIGNALS` that call numpy, on floats: the simulator's callback evaluates
#: them four times a step, where numpy's call on a scalar costs more than the arithmetic.
_FLOAT_SIGNALS = dict(_SIGNALS, **{
    "dead_zone": lambda p, x, v, time, state: _sign(x) * _above(abs(x) - p["dead_zone_delta"]),
    "gap_pos": lambda p, x, v, time, state: _above(x - p["gap_pos_delta"]),
    "gap_neg": lambda p, x, v, time, state: _below(x + p["gap_neg_delta"]),
    "switch": lambda p, x, v, time, state: x * (1.0 if time >= p["switch_time"] else 0.0),
})


def term_signal(name: str, params: dict, x: Signal, v: Signal, time: Signal, state: Signal = 0.0) -> Signal:
    """The signal of term ``name`` (its force per unit coefficient) at ``x`` (m), ``v`` (m/s), ``time``
    (s) and hysteretic state ``state`` (m), with the record's shape parameters; floats or arrays."""
    if name not in _SIGNALS:
        raise KeyError(f"unknown term {name!r}: expected one of {', '.join(_BY_NAME)}")
    return _SIGNALS[name](params, x, v, time, state)


def law(params: dict, x: Signal, v: Signal, time: Signal, state: Signal = 0.0) -> Signal:
    """The discovered force (N, positive resists ``x``): the sum of the record's terms; floats or arrays."""
    return _summed(params, [(params[t.coefficient], _SIGNALS[t.name]) for t in TERMS], x, v, time, state)


def _summed(params: dict, active, x, v, time, state):
    """``sum c signal(x, v, time, state)`` over ``active`` ((coefficient, signal) pairs, in
    :data:`TERMS`' order; those of coefficient 0 are skipped)."""
    total = 0.0 * x
    for c, signal in active:
        if c != 0.0:
            total = total + c * signal(params, x, v, time, state)
    return float(total) if isinstance(x, float) else total


_PARAMS = tuple(p for t in TERMS for p in (Param(t.coefficient, t.unit, f"coefficient of {t.meaning}",
                                                 example=_EXAMPLES.get(t.name, 0.0)),) + t.shapes)
_AT = {p.name: i for i, p in enumerate(_PARAMS)}   # a parameter's place in the native law's vector
(_X, _V, _XAX, _X3, _VAV, _SV, _SVS, _DZ, _DZD, _GP, _GPD, _GN, _GND, _HY, _HYY, _HYN, _SW, _SWT) = (
    _AT[n] for n in ("c_x", "c_v", "c_x_abs_x", "c_x3", "c_v_abs_v", "c_sign_v", "sign_v_scale", "c_dead_zone",
                     "dead_zone_delta", "c_gap_pos", "gap_pos_delta", "c_gap_neg", "gap_neg_delta", "c_hysteretic",
                     "hysteretic_yield", "hysteretic_exponent", "c_switch", "switch_time"))


def _native_force(p, x, v, t, s):
    """:func:`law` on floats as native code (:mod:`momentid.mechanisms.native`): every term of a coefficient
    other than 0, in :data:`TERMS`' order."""
    f = 0.0
    if p[_X] != 0.0:
        f += p[_X] * x
    if p[_V] != 0.0:
        f += p[_V] * v
    if p[_XAX] != 0.0:
        f += p[_XAX] * (x * abs(x))
    if p[_X3] != 0.0:
        f += p[_X3] * (x * x * x)
    if p[_VAV] != 0.0:
        f += p[_VAV] * (v * abs(v))
    if p[_SV] != 0.0:
        f += p[_SV] * math.tanh(v / p[_SVS])
    if p[_DZ] != 0.0:
        beyond = abs(x) - p[_DZD]
        if beyond > 0.0:
            f += p[_DZ] * (beyond if x > 0.0 else -beyond if x < 0.0 else 0.0)
    if p[_GP] != 0.0 and x - p[_GPD] > 0.0:
        f += p[_GP] * (x - p[_GPD])
    if p[_GN] != 0.0 and x + p[_GND] < 0.0:
        f += p[_GN] * (x + p[_GND])
    if p[_HY] != 0.0:
        f += p[_HY] * s
    if p[_SW] != 0.0 and t >= p[_SWT]:
        f += p[_SW] * x
    return f


def _native_rate(p, s, x, v):
    u = math.pow(abs(s / p[_HYY]), p[_HYN])
    w = v * s
    sign = 1.0 if w > 0.0 else -1.0 if w < 0.0 else 0.0
    return v * (1.0 - u * (HYSTERETIC_BETA * sign + (1.0 - HYSTERETIC_BETA)))


class _DataDriven(MechanismKind):
    params = _PARAMS
    truth_only = True
    open_search = True
    callback = True

    def has_state(self, params):
        return params["c_hysteretic"] != 0.0

    def link_law(self, params, place, stiffness):
        active = [(params[t.coefficient], _FLOAT_SIGNALS[t.name]) for t in TERMS if params[t.coefficient] != 0.0]
        return lambda x, v, t, state=0.0: _summed(params, active, x, v, t, state)

    def state_rate(self, params, state, displacement, velocity):
        return bouc_wen_rate(state, velocity, params["hysteretic_yield"], params["hysteretic_exponent"],
                             HYSTERETIC_BETA)

    def native_law(self):
        return NativeLaw(_native_force, _native_rate)

    def storey_force(self, params, drift, drift_velocity, time, stiffness, state=0.0):
        return law(params, drift, drift_velocity, time, state)

    def floor_force(self, params, displacement, velocity, time, stiffness, state=0.0):
        return law(params, displacement, velocity, time, state)


@register
class DataDrivenStorey(_DataDriven):
    name = "data_driven_storey"
    target = Target.STOREY
    summary = "a discovered storey force: sum of terms of the drift x, its rate v, time and a hysteretic state"


@register
class DataDrivenFloor(_DataDriven):
    name = "data_driven_floor"
    target = Target.FLOOR_TABLE
    summary = "a discovered force between a floor and the table: sum of terms of its displacement x, v, ..."
