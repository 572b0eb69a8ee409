"""The numba parts of :mod:`momentid.lab.native_forces`: the two dispatching callbacks, compiled with
numba's disk cache where one can be written (:func:`momentid.core.compiled.disk_cached`); and the RK4 loop of
:mod:`momentid.lab.native_replay`, which calls the same compiled laws through the same program.

Imported only when a model first needs its callback forces natively (numba is then loaded).  Everything
a callback calls is a module-level numba function, and the callbacks close over plain integers only:
the byte offsets of the ``mjModel`` and ``mjData`` fields they read, found and checked by
:mod:`momentid.lab.native_forces`.  numba keys its on-disk cache on the closure's values, so a MuJoCo
whose structs are laid out differently compiles afresh, and the same one loads the callbacks from the
cache (about 2 s saved a process on 2 cores).
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import carray, types
from numba.core import cgutils
from numba.core.ccallback import CFunc
from numba.extending import intrinsic

from momentid.core.compiled import disk_cached

__all__ = ["control_callback", "act_dyn_callback", "rk4_replay"]


@intrinsic
def _pointer(typingctx, address):
    """An address (int64) as a pointer."""
    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)
    return types.voidptr(types.int64), codegen


@intrinsic
def _call_force(typingctx, fn, p, x, v, t, s):
    """A compiled force law at address ``fn`` called with its parameters at address ``p``."""
    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        fnty = ir.FunctionType(double, [cgutils.voidptr_t, double, double, double, double])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()),
                            [builder.inttoptr(args[1], cgutils.voidptr_t)] + list(args[2:]))
    f8 = types.float64
    return f8(types.int64, types.int64, f8, f8, f8, f8), codegen


@intrinsic
def _call_rate(typingctx, fn, p, s, x, v):
    """A compiled state rate at address ``fn`` called with its parameters at address ``p``."""
    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        fnty = ir.FunctionType(double, [cgutils.voidptr_t, double, double, double])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()),
                            [builder.inttoptr(args[1], cgutils.voidptr_t)] + list(args[2:]))
    f8 = types.float64
    return f8(types.int64, types.int64, f8, f8, f8), codegen


@disk_cached(numba.njit, inline="always")
def _word(address):
    """The 8-byte word at ``address``."""
    return carray(_pointer(address), 1, np.int64)[0]


@disk_cached(numba.njit, inline="always")
def _program(m, m_numadr, m_numdata):
    """Address of the model's program (its first numeric), the model's fields at these offsets."""
    return _word(m + m_numdata) + 8 * np.int64(carray(_pointer(_word(m + m_numadr)), 1, np.int32)[0])


@disk_cached(numba.njit, inline="always")
def _stretch(prog, k, qpos, qvel):
    """The stretch and its rate of the link of the force at entry ``k`` of the program ``prog``."""
    top, below = np.int64(prog[k + 2]), np.int64(prog[k + 3])
    x, v = qpos[top], qvel[top]
    if below >= 0:
        x -= qpos[below]
        v -= qvel[below]
    return x, v


def control_callback(offsets: dict[str, int], header: int) -> CFunc:
    """The control callback: every force of the model's program into ``qfrc_applied``."""
    d_time, d_qpos, d_qvel, d_act, d_qfrc = (int(offsets[f"d_{f}"]) for f in ("time", "qpos", "qvel", "act",
                                                                               "qfrc_applied"))
    m_nnumeric, m_numadr, m_numdata = (int(offsets[k]) for k in ("m_nnumeric", "m_numeric_adr",
                                                                  "m_numeric_data"))
    HEADER = int(header)

    @disk_cached(numba.cfunc, types.void(types.int64, types.int64))
    def control(m, d):
        if carray(_pointer(m + m_nnumeric), 1, np.int64)[0] < 1:
            return   # a model with no callback force, rolled out on another thread meanwhile: nothing to push
        base = _program(m, m_numadr, m_numdata)
        n = np.int64(carray(_pointer(base), 1, np.float64)[0])
        size = 1
        for _ in range(n):   # the program's length
            size += HEADER + np.int64(carray(_pointer(base + 8 * (size + 6)), 1, np.float64)[0])
        prog = carray(_pointer(base), size, np.float64)
        nv, k = 1, 1
        for _ in range(n):   # the dofs the forces push: the arrays' length read
            nv = max(nv, 1 + np.int64(prog[k + 2]), 1 + np.int64(prog[k + 3]))
            k += HEADER + np.int64(prog[k + 6])
        qpos = carray(_pointer(_word(d + d_qpos)), nv, np.float64)
        qvel = carray(_pointer(_word(d + d_qvel)), nv, np.float64)
        out = carray(_pointer(_word(d + d_qfrc)), nv, np.float64)
        act_base = _word(d + d_act)
        t = carray(_pointer(d + d_time), 1, np.float64)[0]
        k = 1
        for _ in range(n):   # the floors the forces push start from 0
            out[np.int64(prog[k + 2])] = 0.0
            if prog[k + 3] >= 0.0:
                out[np.int64(prog[k + 3])] = 0.0
            k += HEADER + np.int64(prog[k + 6])
        k = 1
        for _ in range(n):
            x, v = _stretch(prog, k, qpos, qvel)
            adr = np.int64(prog[k + 4])
            s = carray(_pointer(act_base + 8 * adr), 1, np.float64)[0] if adr >= 0 else 0.0
            f = _call_force(np.int64(prog[k]), base + 8 * (k + HEADER), x, v, t, s)
            out[np.int64(prog[k + 2])] -= f          # the link resists its stretch on its upper floor ...
            if prog[k + 3] >= 0.0:
                out[np.int64(prog[k + 3])] += f      # ... and on its lower one
            k += HEADER + np.int64(prog[k + 6])

    return control


def act_dyn_callback(offsets: dict[str, int], header: int) -> CFunc:
    """The actuator-dynamics callback: the state rate of the force whose state ``actuator`` holds."""
    d_qpos, d_qvel, d_act = (int(offsets[f"d_{f}"]) for f in ("qpos", "qvel", "act"))
    m_numadr, m_numdata = int(offsets["m_numeric_adr"]), int(offsets["m_numeric_data"])
    HEADER = int(header)

    @disk_cached(numba.cfunc, types.float64(types.int64, types.int64, types.int32))
    def act_dyn(m, d, actuator):
        base = _program(m, m_numadr, m_numdata)
        n = np.int64(carray(_pointer(base), 1, np.float64)[0])
        k = 1
        for _ in range(n):
            head = carray(_pointer(base + 8 * k), HEADER, np.float64)
            if np.int64(head[5]) == actuator:
                top, below, adr = np.int64(head[2]), np.int64(head[3]), np.int64(head[4])
                nv = 1 + max(top, below)
                qpos = carray(_pointer(_word(d + d_qpos)), nv, np.float64)
                qvel = carray(_pointer(_word(d + d_qvel)), nv, np.float64)
                x, v = qpos[top], qvel[top]
                if below >= 0:
                    x -= qpos[below]
                    v -= qvel[below]
                s = carray(_pointer(_word(d + d_act) + 8 * adr), 1, np.float64)[0]
                return _call_rate(np.int64(head[1]), base + 8 * (k + HEADER), s, x, v)
            k += HEADER + np.int64(head[6])
        return 0.0

    return act_dyn


@disk_cached(numba.njit, inline="always")
def _derivative(x, u, t, lin, prog, base, header, nv, applied, dx):   # pragma: no cover  (compiled; tested)
    """``dx``: the state's rate at ``x`` (positions, velocities, activations) under control ``u`` at time
    ``t``; ``applied``: the program's forces at ``x`` (generalised, per dof).  ``lin`` packs the linear
    part: ``[rate at rest | rate per state (nx x nx) | per control | per applied force (nx x nv)]``."""
    nx = x.size
    n = np.int64(prog[0])
    applied[:] = 0.0
    k = 1
    for _ in range(n):
        top, below, adr = np.int64(prog[k + 2]), np.int64(prog[k + 3]), np.int64(prog[k + 4])
        xs, vs = x[top], x[nv + top]
        if below >= 0:
            xs -= x[below]
            vs -= x[nv + below]
        st = x[2 * nv + adr] if adr >= 0 else 0.0
        f = _call_force(np.int64(prog[k]), base + 8 * (k + header), xs, vs, t, st)
        applied[top] -= f
        if below >= 0:
            applied[below] += f
        k += header + np.int64(prog[k + 6])
    for i in range(nx):
        s = lin[i] + lin[nx + nx * nx + i] * u
        row = nx + i * nx
        for j in range(nx):
            s += lin[row + j] * x[j]
        row = 2 * nx + nx * nx + i * nv
        for j in range(nv):
            s += lin[row + j] * applied[j]
        dx[i] = s
    k = 1
    for _ in range(n):   # a force's state: its law's rate
        adr = np.int64(prog[k + 4])
        if adr >= 0:
            top, below = np.int64(prog[k + 2]), np.int64(prog[k + 3])
            xs, vs = x[top], x[nv + top]
            if below >= 0:
                xs -= x[below]
                vs -= x[nv + below]
            dx[2 * nv + adr] = _call_rate(np.int64(prog[k + 1]), base + 8 * (k + header), x[2 * nv + adr], xs, vs)
        k += header + np.int64(prog[k + 6])


@disk_cached(numba.njit, inline="always")
def _bad(x, start, stop):   # pragma: no cover  (compiled; tested)
    """MuJoCo's ``mju_isBad`` over ``x[start:stop]``: a NaN or a magnitude beyond ``mjMAXVAL`` (1e10)."""
    for i in range(start, stop):
        if not abs(x[i]) <= 1e10:
            return True
    return False


@disk_cached(numba.njit, nogil=True)
def _rk4(x, jerk, h, substeps, lin, prog, base, header, nv, sensors, out):   # pragma: no cover  (compiled; tested)
    """Classical RK4 on the rate of :func:`_derivative`; readings ``out[row] = y0 + C x + d u + G f`` before
    every ``substeps``-th step (``sensors`` packs ``[y0 | C (k x nx) | d | G (k x nv)]``).  A state or
    acceleration MuJoCo calls bad resets the model as ``mj_step`` does (``mj_resetData``: at rest, the
    table's activation, time and control at 0 for that step) and the replay goes on from rest: a diverged twin
    reads its blow-up, finite, as its rollout does (which stops stepping it meanwhile).  Returns the number of
    such resets (MuJoCo's warnings)."""
    nx, k = x.size, out.shape[1]
    resets = 0
    applied, k1, k2, k3, k4, stage = (np.empty(nv), np.empty(nx), np.empty(nx), np.empty(nx), np.empty(nx),
                                      np.empty(nx))
    t = 0.0
    for step in range(jerk.size):
        u = jerk[step]
        if _bad(x, 0, 2 * nv):           # MuJoCo's checks of positions and velocities: reset
            x[:] = 0.0
            t, u = 0.0, 0.0
            resets += 1
        _derivative(x, u, t, lin, prog, base, header, nv, applied, k1)
        if _bad(k1, nv, 2 * nv):         # and of accelerations: reset, forward again
            x[:] = 0.0
            t, u = 0.0, 0.0
            resets += 1
            _derivative(x, u, t, lin, prog, base, header, nv, applied, k1)
        if step % substeps == 0:
            row = step // substeps
            for i in range(k):
                s = sensors[i] + sensors[k + k * nx + i] * u
                for j in range(nx):
                    s += sensors[k + i * nx + j] * x[j]
                for j in range(nv):
                    s += sensors[2 * k + k * nx + i * nv + j] * applied[j]
                out[row, i] = s
        for i in range(nx):
            stage[i] = x[i] + 0.5 * h * k1[i]
        _derivative(stage, u, t + 0.5 * h, lin, prog, base, header, nv, applied, k2)
        for i in range(nx):
            stage[i] = x[i] + 0.5 * h * k2[i]
        _derivative(stage, u, t + 0.5 * h, lin, prog, base, header, nv, applied, k3)
        for i in range(nx):
            stage[i] = x[i] + h * k3[i]
        _derivative(stage, u, t + h, lin, prog, base, header, nv, applied, k4)
        for i in range(nx):
            x[i] += h * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]) / 6.0
        t += h
    return resets


def rk4_replay(x: np.ndarray, jerk: np.ndarray, h: float, substeps: int, lin: np.ndarray, prog: np.ndarray,
               header: int, nv: int, sensors: np.ndarray, out: np.ndarray) -> int:
    """Replay a model's RK4 steps from state ``x`` (modified) under the control ``jerk``, its forces the
    program ``prog``'s compiled laws (:mod:`momentid.lab.native_replay` builds the arguments).

    Parameters
    ----------
    x : ndarray, shape (nx,)
        Positions (nv), velocities (nv) and activations at the start; the end state on return.
    jerk : ndarray, shape (n_steps,)
        The control at each step.
    h : float
        The step (s).
    substeps : int
        Steps per reading.
    lin, sensors : ndarray
        The packed linear rate and readings (see :func:`_derivative` and :func:`_rk4`).
    prog : ndarray
        The model's program (:data:`momentid.lab.native_forces.PROGRAM`); it must stay alive meanwhile.
    header : int
        :data:`momentid.lab.native_forces.HEADER`.
    nv : int
        Degrees of freedom.
    out : ndarray, shape (ceil(n_steps / substeps), k)
        The readings, written.

    Returns
    -------
    int
        How many times MuJoCo's checks reset the model to rest (a position, velocity or acceleration NaN or
        beyond 1e10: each a warning of ``mj_step``).
    """
    return int(_rk4(x, jerk, float(h), int(substeps), lin, prog, np.int64(prog.ctypes.data), np.int64(header),
                    np.int64(nv), sensors, out))
