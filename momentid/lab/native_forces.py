"""The callback kinds' forces in MuJoCo's step as native code: no Python in a rollout.

:class:`~momentid.lab.simulation.CallbackForces` applies the forces the MJCF cannot express from a
Python control callback, about four times a step under RK4: more time than MuJoCo's own step.  Here the
same forces run as two C functions compiled by numba and installed as MuJoCo's control and
actuator-dynamics callbacks (``mujoco.set_mjcb_control`` takes a C function pointer):

- each model carries its own **program**, the custom numeric :data:`PROGRAM` that
  :func:`momentid.lab.rig.build_spec` adds to a rig with callback forces (:func:`program_size` entries)
  and :func:`load_program` fills once compiled: per force, the address of its kind's compiled law
  (:mod:`momentid.mechanisms.native`), the dofs of its link's upper and lower floors, its state's
  activation address and actuator, and the law's parameter vector.  So one installed callback serves
  every model at once, each reading its own forces: many models on ``mujoco.rollout``'s threads;
- the ``control`` callback writes, at every call, each force across its link into ``qfrc_applied`` (on the upper
  floor's dof against the stretch, on the lower one's with it), as the Python callback does;
  the ``act_dyn`` callback returns a force's state rate for its state actuator.

The callbacks read ``mjModel`` and ``mjData`` through their C layout, taken from MuJoCo's own
description of its structs (``mujoco.introspect``) and checked against a live model and data before
first use (:func:`available`); where numba or that check fails, or a kind has no native law, the
simulator keeps the Python callback.  Compiled once (:mod:`momentid.lab.native_dispatch`), then loaded from
numba's on-disk cache, as the laws are.
"""

from __future__ import annotations

import contextlib
import ctypes
import threading
from collections.abc import Iterable, Iterator, Sequence

import mujoco
import numpy as np

from momentid import mechanisms as registry
from momentid.core.structure import Mechanism

__all__ = ["PROGRAM", "HEADER", "ENABLED", "program_size", "add_program", "available", "load_program", "installed",
           "state_actuator", "applies", "threadable", "plain"]

#: Name of the custom numeric holding a model's forces for the native callbacks.
PROGRAM = "momentid_forces"
#: Entries before each force's parameters: law address, rate address (0: none), upper dof, lower dof
#: (-1: the table), activation address (-1: no state), state actuator (-1), number of parameters.
HEADER = 7
#: Use the native callbacks where they are available (tests set it False to run the Python callback).
ENABLED = True


def state_actuator(k: int) -> str:
    """Name of the actuator holding the internal state of the ``k``-th (0-based) stateful mechanism."""
    return f"state{k + 1}"


def program_size(mechanisms: Iterable[Mechanism]) -> int:
    """Entries of the program of ``mechanisms`` (0 without a callback force): a count, then per force
    :data:`HEADER` entries and its parameters."""
    sizes = [HEADER + len(registry.get(m.type).params) + registry.get(m.type).needs_stiffness
             for m in mechanisms if registry.get(m.type).callback]
    return 1 + sum(sizes) if sizes else 0


def add_program(spec: mujoco.MjSpec, mechanisms: Iterable[Mechanism]) -> None:
    """Add the (empty) program of ``mechanisms``' callback forces to ``spec``: the first custom numeric."""
    size = program_size(mechanisms)
    if size:
        spec.add_numeric(name=PROGRAM, data=[0.0] * size)


def _ctype(t):
    """The ctypes type of a type of ``mujoco.introspect`` (a struct's field)."""
    from mujoco.introspect import ast_nodes as ast, structs

    scalars = {"int": ctypes.c_int, "mjtNum": ctypes.c_double, "mjtSize": ctypes.c_int64,
               "size_t": ctypes.c_size_t, "uintptr_t": ctypes.c_size_t, "mjtBool": ctypes.c_ubyte,
               "mjtByte": ctypes.c_ubyte, "float": ctypes.c_float, "uint64_t": ctypes.c_uint64,
               "char": ctypes.c_char, "unsigned char": ctypes.c_ubyte, "double": ctypes.c_double}
    if isinstance(t, ast.PointerType):
        return ctypes.c_void_p
    if isinstance(t, ast.ArrayType):
        out = _ctype(t.inner_type)
        for n in reversed(t.extents):
            out = out * n
        return out
    fields = t.fields if isinstance(t, ast.AnonymousStructDecl) else None
    if fields is None:
        name = t.name if isinstance(t, ast.ValueType) else t
        if name in scalars:
            return scalars[name]
        fields = structs.STRUCTS[name].fields
    return type("s", (ctypes.Structure,), {"_fields_": [(f.name, _ctype(f.type)) for f in fields]})


def _offsets() -> dict[str, int] | None:
    """Byte offsets of the fields the callbacks read in ``mjModel`` and ``mjData``, checked against a live
    model and data (None when they do not match)."""
    try:
        model_t, data_t = _ctype("mjModel"), _ctype("mjData")
    except Exception:   # noqa: BLE001 - a MuJoCo whose description this reader does not know
        return None
    out = {f"d_{f}": getattr(data_t, f).offset for f in ("time", "qpos", "qvel", "act", "qfrc_applied")}
    out.update({f"m_{f}": getattr(model_t, f).offset for f in ("nnumeric", "numeric_adr", "numeric_data")})
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(mass=1.0, inertia=[1.0, 1.0, 1.0])
    body.add_joint(name="j", type=mujoco.mjtJoint.mjJNT_SLIDE)
    spec.add_actuator(target="j", trntype=mujoco.mjtTrn.mjTRN_JOINT, dyntype=mujoco.mjtDyn.mjDYN_INTEGRATOR)
    spec.add_numeric(name="probe", data=[1.0, 2.0])
    model = spec.compile()
    data = mujoco.MjData(model)
    data.time = 1234.5

    def at(address: int, offset: int, kind) -> float:
        return kind.from_address(address + offset).value

    pointers = {"d_qpos": data.qpos, "d_qvel": data.qvel, "d_act": data.act, "d_qfrc_applied": data.qfrc_applied}
    ok = all(at(data._address, out[k], ctypes.c_size_t) == a.ctypes.data for k, a in pointers.items())
    ok &= at(data._address, out["d_time"], ctypes.c_double) == 1234.5
    ok &= at(model._address, out["m_nnumeric"], ctypes.c_int64) == model.nnumeric
    ok &= at(model._address, out["m_numeric_adr"], ctypes.c_size_t) == model.numeric_adr.ctypes.data
    ok &= at(model._address, out["m_numeric_data"], ctypes.c_size_t) == model.numeric_data.ctypes.data
    return out if ok else None


_CALLBACKS: list = []   # [(control, act_dyn)] once compiled, [None] when unavailable


def _compile():
    """The control and act_dyn callbacks (numba ``cfunc``, cached on disk), or None when they cannot be
    built here."""
    try:
        from momentid.lab import native_dispatch as native   # numba's and llvmlite's parts imported
    except ImportError:
        return None
    offsets = _offsets()
    if offsets is None:
        return None
    return native.control_callback(offsets, HEADER), native.act_dyn_callback(offsets, HEADER)


def _callbacks():
    if not _CALLBACKS:
        _CALLBACKS.append(_compile())
    return _CALLBACKS[0]


def available() -> bool:
    """True when the native callbacks can run here (numba importable, MuJoCo's layout as described)."""
    return ENABLED and _callbacks() is not None


def load_program(model: mujoco.MjModel, mechanisms: Iterable[Mechanism],
                 storey_stiffness: Sequence[float] | None = None) -> bool:
    """Fill ``model``'s program with the callback forces of ``mechanisms`` (``storey_stiffness``: N/m per
    storey, which a ``needs_stiffness`` kind takes its fraction of).  False, the model untouched, when the
    native callbacks cannot apply them (not :func:`available`, a kind without a native law, a model
    without its program): the caller then runs the Python callback."""
    from momentid.mechanisms.native import compiled

    forces = [m for m in mechanisms if registry.get(m.type).callback]
    size = program_size(forces)
    if (not forces or not available() or model.nnumeric < 1 or model.numeric(0).name != PROGRAM
            or int(model.numeric_size[0]) != size
            or any(registry.get(m.type).native_law() is None for m in forces)):
        return False
    d = sum(1 for j in range(model.njnt) if model.joint(j).name.startswith("q"))
    dofs = [int(model.jnt_dofadr[model.joint(f"q{i + 1}").id]) for i in range(d)]
    prog, states = [float(len(forces))], 0
    for m in forces:
        kind = registry.get(m.type)
        place = kind.place(m.location)
        lower, upper = place.nodes
        p = dict(m.parameters)
        if kind.needs_stiffness and storey_stiffness is None:
            return False
        k = float(storey_stiffness[upper - 1]) if kind.needs_stiffness else None
        force, rate = compiled(kind.native_law())
        adr = act = -1
        if kind.has_state(p):
            act = model.actuator(state_actuator(states)).id
            adr, states = int(model.actuator_actadr[act]), states + 1
        values = kind.native_parameters(p, k)
        prog += [float(force.address), float(rate.address if rate is not None else 0), float(dofs[upper - 1]),
                 float(dofs[lower - 1] if lower > 0 else -1), float(adr), float(act), float(len(values))] + values
    adr = int(model.numeric_adr[0])
    model.numeric_data[adr:adr + size] = np.array(prog)
    return True


def applies(mechanisms: Iterable[Mechanism]) -> bool:
    """True when the native callbacks apply every callback force of ``mechanisms`` (so their rollouts
    need no Python: they may run on threads side by side)."""
    forces = [m for m in mechanisms if registry.get(m.type).callback]
    return available() and all(registry.get(m.type).native_law() is not None for m in forces)


def threadable(mechanisms: Sequence[Mechanism]) -> bool:
    """True when rollouts of models with ``mechanisms`` run no Python in MuJoCo's step: no callback force,
    or every one native (:func:`applies`); such rollouts may run on threads side by side, with each other
    and with those of models with no callback force (the native control callback leaves a model without a
    program alone).  A rig with no callback force loads no compiled code to answer."""
    return not any(registry.get(m.type).callback for m in mechanisms) or applies(mechanisms)


_USERS = threading.Lock(), [0, None]   # (lock, [rollouts using the callbacks, the callbacks they replaced])


@contextlib.contextmanager
def installed() -> Iterator[None]:
    """Install the native control and act_dyn callbacks (every model rolled out meanwhile must carry a
    loaded program, :func:`load_program`); restore the previous ones when the last rollout using them
    ends.  Threads may use it side by side: the callbacks read each model's own program."""
    control, act_dyn = _callbacks()
    lock, users = _USERS
    with lock:
        if users[0] == 0:
            users[1] = mujoco.get_mjcb_control(), mujoco.get_mjcb_act_dyn()
            mujoco.set_mjcb_control(control.ctypes)
            mujoco.set_mjcb_act_dyn(act_dyn.ctypes)
        users[0] += 1
    try:
        yield
    finally:
        with lock:
            users[0] -= 1
            if users[0] == 0:
                mujoco.set_mjcb_control(users[1][0])
                mujoco.set_mjcb_act_dyn(users[1][1])


@contextlib.contextmanager
def plain() -> Iterator[None]:
    """Around a rollout of a model with no callback force: no control callback of another model may act
    on it.  The native callbacks, installed meanwhile by a rollout on another thread (:func:`installed`),
    leave a model without a program alone, so they stay (removing them would leave that rollout without
    its forces); any other control callback is removed for the block and restored after."""
    lock, users = _USERS
    with lock:
        previous = mujoco.get_mjcb_control()
        keep = users[0] > 0 or previous is None
        if not keep:
            mujoco.set_mjcb_control(None)
    try:
        yield
    finally:
        if not keep:
            with lock:
                mujoco.set_mjcb_control(previous)
