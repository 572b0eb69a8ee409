"""A ``callback`` kind's force law as native code: no Python in MuJoCo's step.

The simulator applies the forces the MJCF cannot express in MuJoCo's control callback, about four
times a step under RK4.  A Python callback costs more than MuJoCo's own step (``python -m benchmarks
--stages replay``); so each ``callback`` kind states its law once more as a plain function of floats
(:class:`NativeLaw`, :meth:`~momentid.mechanisms.base.MechanismKind.native_law`), which numba compiles to
a C function (:func:`compiled`), cached on disk next to the kind's module.  The lab's callback
(:mod:`momentid.lab.native_forces`) calls it through its address.

The compiled form takes the kind's parameter vector
(:meth:`~momentid.mechanisms.base.MechanismKind.native_parameters`: its ``params`` in order, then the
storey's stiffness when it ``needs_stiffness``) as a pointer ``p``:

- ``force(p, x, v, t, s)``: the force (N) resisting the link's stretch ``x`` (m) changing at ``v``
  (m/s), at time ``t`` (s) since the run started, with internal state ``s`` (0 without one): the same
  as :meth:`~momentid.mechanisms.base.MechanismKind.storey_force` /
  :meth:`~momentid.mechanisms.base.MechanismKind.floor_force` to round-off (tested,
  ``tests/test_native_forces.py``);
- ``rate(p, s, x, v)``: the state's rate, as :meth:`~momentid.mechanisms.base.MechanismKind.state_rate`.

numba is imported only when a law is first compiled: a rig with no callback force never loads it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

__all__ = ["NativeLaw", "FORCE_SIGNATURE", "RATE_SIGNATURE", "compiled", "call_force", "call_rate"]

#: C signature of a compiled force law: ``double force(double *p, double x, double v, double t, double s)``.
FORCE_SIGNATURE = "float64(CPointer(float64), float64, float64, float64, float64)"
#: C signature of a compiled state rate: ``double rate(double *p, double s, double x, double v)``.
RATE_SIGNATURE = "float64(CPointer(float64), float64, float64, float64)"


@dataclass(frozen=True)
class NativeLaw:
    """A kind's force law (and its state's rate, when the force has memory) as functions numba compiles
    (module-level functions of floats and the parameter vector ``p``, calling ``math`` only: numba
    compiles the function alone, so a helper of the package cannot be called from it)."""

    force: Callable
    rate: Callable | None = None


_COMPILED: dict[NativeLaw, tuple] = {}


def compiled(law: NativeLaw) -> tuple:
    """``(force, rate)``: the compiled C functions of ``law`` (numba ``cfunc``; ``rate`` None without
    one), compiled once a process (and cached on disk)."""
    got = _COMPILED.get(law)
    if got is None:
        import numba

        from momentid.core.compiled import disk_cached

        force = disk_cached(numba.cfunc, FORCE_SIGNATURE)(law.force)
        rate = disk_cached(numba.cfunc, RATE_SIGNATURE)(law.rate) if law.rate is not None else None
        got = _COMPILED[law] = (force, rate)
    return got


def _pointer(p):
    import ctypes

    import numpy as np

    buffer = np.ascontiguousarray(p, dtype=float)
    return buffer, buffer.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def call_force(law: NativeLaw, p: Sequence[float], x: float, v: float, t: float, s: float = 0.0) -> float:
    """The compiled force of ``law`` at one point, called through its C address (tests, checks)."""
    buffer, pointer = _pointer(p)
    return compiled(law)[0].ctypes(pointer, x, v, t, s)


def call_rate(law: NativeLaw, p: Sequence[float], s: float, x: float, v: float) -> float:
    """The compiled state rate of ``law`` at one point, called through its C address."""
    buffer, pointer = _pointer(p)
    return compiled(law)[1].ctypes(pointer, s, x, v)

