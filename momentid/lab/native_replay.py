"""A twin whose only nonlinear forces are compiled laws, replayed in compiled code: the same readings as
``mujoco.rollout`` of it to round-off, without MuJoCo in the loop.

A twin that carries a force with memory (Bouc-Wen's hysteretic drift, :mod:`momentid.mechanisms.bouc_wen`)
runs MuJoCo's RK4 with the force's compiled law in the native control callback and its state's rate in the
act_dyn callback (:mod:`momentid.lab.native_forces`).  Everything else in its step is linear: the springs
and dampers on tendons, the table driven by its jerk actuator.  So its rate is

    x' = r0 + A x + b u + F f(x, t),

with ``x`` the positions, velocities and activations, ``u`` the table's jerk and ``f`` the forces the program's
laws put on the dofs (their states' rates replace those activations' rows), and its sensors
``y = y0 + C x + d u + G f``.  :func:`maps` reads ``r0, A, b, F`` and ``y0, C, d, G`` off ``mj_forward`` by
centred differences, exact to round-off for a linear map, on a copy of the model whose program is emptied (so
the callbacks, whoever installed them, add nothing); :func:`replay` steps classical RK4 on that rate in a
numba loop calling the same compiled laws through the same program (:func:`momentid.lab.native_dispatch.rk4_replay`):
MuJoCo's RK4 step, whose stages are those of the classical tableau.  A Bouc-Wen storey's rollout of the
shipped flexible rig's twin costs about 6 us a step in MuJoCo, a fraction of that here.

A model with anything else nonlinear (friction loss, polynomial springs, limits, contacts, plugins, an
actuator that pushes beyond the table's) or another integrator is refused (:func:`check`): its replay is
another path's (:mod:`momentid.lab.compiled_paths`) or ``mujoco.rollout``'s.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import mujoco
import numpy as np

from momentid.errors import ModelError
from momentid.lab import native_forces
from momentid.lab.linear_replay import FD_EPS, nonlinear_elements
from momentid.lab.replay_batch import accepts

__all__ = ["check", "applies", "maps", "replay", "ENABLED"]

#: Replay such twins in compiled code (tests set it False to compare with ``mujoco.rollout``).
ENABLED = True


def _forces(model: mujoco.MjModel) -> int:
    """The number of forces in ``model``'s loaded program (0: none)."""
    if model.nnumeric < 1 or model.numeric(0).name != native_forces.PROGRAM:
        return 0
    return int(model.numeric_data[int(model.numeric_adr[0])])


def check(model: mujoco.MjModel) -> None:
    """Raise :class:`~momentid.errors.ModelError` unless ``model`` is an RK4 twin whose only nonlinear forces
    are its loaded program's compiled laws (module docstring).

    Parameters
    ----------
    model : mujoco.MjModel
        A compiled twin (:func:`momentid.lab.resim.compile_models`).
    """
    why = []
    if model.opt.integrator != mujoco.mjtIntegrator.mjINT_RK4:
        why.append(f"integrator {mujoco.mjtIntegrator(model.opt.integrator).name}")
    if not _forces(model):
        why.append("no compiled force laws loaded")
    if model.nq != model.nv or np.any(model.qpos0 != 0):
        why.append("joints other than slides at rest at 0")
    why += nonlinear_elements(model)
    user = mujoco.mjtDyn.mjDYN_USER
    if any(model.actuator_dyntype[i] != user or np.any(model.actuator_gainprm[i]) or np.any(model.actuator_biasprm[i])
           for i in range(1, model.nu)):
        why.append("actuators that push beyond the table's")
    if why:
        raise ModelError(f"the twin's model has {', '.join(why)}: expected an RK4 twin whose only nonlinear "
                         f"forces are compiled laws (its replay is mujoco.rollout's)")


def applies(models: Sequence[mujoco.MjModel]) -> bool:
    """True when every one of ``models`` passes :func:`check` (and :data:`ENABLED`)."""
    return ENABLED and accepts(check, models)


def maps(model: mujoco.MjModel, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The linear part of ``model``'s rate and sensors (module docstring), packed for the compiled loop.

    Parameters
    ----------
    model : mujoco.MjModel
        A twin that passes :func:`check`.
    rows : ndarray of int, shape (k,), optional
        The sensordata entries read (default: all ``nsensordata``).

    Returns
    -------
    lin : ndarray, shape (nx + nx nx + nx + nx nv,)
        ``r0``, ``A`` (row-major), ``b``, ``F`` (row-major); ``nx = 2 nv + na``.
    sensors : ndarray, shape (k + k nx + k + k nv,)
        ``y0``, ``C`` (row-major), ``d``, ``G`` (row-major) of the ``k`` readings.
    """
    check(model)
    inert = copy.copy(model)
    inert.numeric_data[int(inert.numeric_adr[0])] = 0.0        # an empty program: the callbacks add nothing
    data = mujoco.MjData(inert)
    nv, na = model.nv, model.na
    nx = 2 * nv + na

    def at(x, u, applied):
        data.qpos[:], data.qvel[:], data.act[:] = x[:nv], x[nv:2 * nv], x[2 * nv:]
        data.ctrl[:] = 0.0
        data.ctrl[0] = u
        data.qfrc_applied[:] = applied
        data.time = 0.0
        mujoco.mj_forward(inert, data)
        return np.concatenate([data.qvel, data.qacc, data.act_dot]), data.sensordata.copy()

    x0, f0 = np.zeros(nx), np.zeros(nv)
    r0, y0 = at(x0, 0.0, f0)

    def centred(point):           # (rate, readings) per unit of the perturbed input
        (rp, yp), (rm, ym) = point(FD_EPS), point(-FD_EPS)
        return (rp - rm) / (2 * FD_EPS), (yp - ym) / (2 * FD_EPS)

    A, C = np.zeros((nx, nx)), np.zeros((y0.size, nx))
    for j in range(nx):
        A[:, j], C[:, j] = centred(lambda e: at(x0 + e * np.eye(nx)[j], 0.0, f0))
    b, d = centred(lambda e: at(x0, e, f0))
    F, G = np.zeros((nx, nv)), np.zeros((y0.size, nv))
    for j in range(nv):
        F[:, j], G[:, j] = centred(lambda e: at(x0, 0.0, e * np.eye(nv)[j]))
    rows = np.arange(y0.size) if rows is None else np.asarray(rows, int)
    lin = np.concatenate([r0, A.ravel(), b, F.ravel()])
    return lin, np.concatenate([y0[rows], C[rows].ravel(), d[rows], G[rows].ravel()])


def replay(model: mujoco.MjModel, rows: np.ndarray, substeps: int, x: np.ndarray, control: np.ndarray,
           out: np.ndarray) -> int:
    """Replay one twin with compiled laws (module docstring) by RK4 from state ``x`` under the table's jerk.

    The :class:`~momentid.lab.replay_batch.Replay` of :func:`~momentid.lab.replay_batch.replay_batch` (its
    parameters): ``model`` passes :func:`check`; ``x`` (2 nv + na,) the state, ``control`` (n_steps,) the jerk
    (m/s^3), ``out`` (ceil(n_steps / substeps), k) the readings of sensordata ``rows``, written; returns the
    number of resets.
    """
    from momentid.lab.native_dispatch import rk4_replay

    lin, sensors = maps(model, rows)
    adr = int(model.numeric_adr[0])
    prog = np.array(model.numeric_data[adr:adr + int(model.numeric_size[0])])
    return rk4_replay(x, control, model.opt.timestep, substeps, lin, prog, native_forces.HEADER, model.nv, sensors,
                      out)
