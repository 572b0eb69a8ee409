"""A linear twin's replay as MuJoCo's own step map, in compiled code: the same accelerations, many times faster.

A twin with no mechanism (:class:`~momentid.lab.rig_model.RigModel` of springs and dampers on tendons, the
table driven by its jerk actuator, the ``implicitfast`` integrator) has a step that is linear in its state
and control: ``x' = A x + B u`` and sensors ``y = y0 + C x + D u``, with ``x`` the state's deviation from the
model's rest (a tangent vector: positions, velocities, activation) and ``u`` the control.  MuJoCo's
``mjd_transitionFD`` gives A, B, C and D; for a linear step its centred differences are exact to
round-off, so the replay (:func:`simulate`) reads what ``mujoco.rollout`` reads (2.5e-13 of the signal on the
flexible rig's Northridge; tested on both shipped rigs' twins) in a fraction of the time (the twin's linear
refit of three trials: 324 replays in 0.2 s where the rollouts took 10.4 s): a few multiply-adds per step
in a numba loop, no model data, no collision or constraint pipeline.

A model with anything that makes its step nonlinear (a mechanism's extra actuators or activations, a
plugin, joint or tendon friction loss, limits, contacts) is refused (:func:`check_linear`): its replay is
:func:`momentid.lab.resim.simulate`'s.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numba
import numpy as np

from momentid.core.compiled import disk_cached
from momentid.errors import ModelError

__all__ = ["check_linear", "nonlinear_elements", "state_space", "simulate", "FD_EPS"]

#: Perturbation of ``mjd_transitionFD`` (centred): for a linear step any small one is exact to round-off.
FD_EPS = 1e-6
#: Model fields of MuJoCo's nonlinear passive elements (a cubic spring and a quadratic damper are a
#: tendon's polynomial coefficients): any nonzero entry makes the step nonlinear.
_NONLINEAR = ("tendon_stiffnesspoly", "tendon_dampingpoly", "jnt_stiffnesspoly", "dof_dampingpoly",
              "actuator_dampingpoly", "tendon_springyield", "jnt_springyield", "nplastic")


def nonlinear_elements(model: mujoco.MjModel) -> list[str]:
    """What in ``model`` besides its actuators makes a step nonlinear, in words (empty: nothing).

    Parameters
    ----------
    model : mujoco.MjModel
        A compiled twin.

    Returns
    -------
    list of str
        Plugins or equality constraints, friction loss, polynomial or yielding springs and dampers, limits,
        colliding geoms: each present one.
    """
    why = []
    if model.nplugin or model.neq:
        why.append(f"{model.nplugin} plugins and {model.neq} equality constraints")
    if np.any(model.dof_frictionloss) or np.any(model.tendon_frictionloss):
        why.append("friction loss")
    if any(np.any(getattr(model, name, 0)) for name in _NONLINEAR):
        why.append("polynomial springs or dampers, or yielding springs")
    if np.any(model.jnt_limited) or np.any(model.tendon_limited):
        why.append("limits")
    if np.any(model.geom_contype) or np.any(model.geom_conaffinity):
        why.append("colliding geoms")
    return why


def check_linear(model: mujoco.MjModel) -> None:
    """Raise :class:`~momentid.errors.ModelError` unless ``model``'s step is linear in its state and control.

    Parameters
    ----------
    model : mujoco.MjModel
        A compiled twin (:func:`momentid.lab.resim.compile_models`).
    """
    why = []
    if model.nu != 1 or model.na != 1:
        why.append(f"{model.nu} actuators and {model.na} activations (the table's jerk actuator alone is linear)")
    why += nonlinear_elements(model)
    if why:
        raise ModelError(f"the twin's model has {', '.join(why)}: expected a linear twin (its replay is "
                         f"momentid.lab.resim.simulate's)")


def state_space(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The step map of a linear twin about its rest.

    Parameters
    ----------
    model : mujoco.MjModel
        A compiled twin whose step is linear (:func:`check_linear`).

    Returns
    -------
    A : ndarray, shape (nx, nx)
        ``nx = 2 nv + na``: the next state's deviation per the state's.
    B : ndarray, shape (nx, nu)
        Per control.
    C : ndarray, shape (nsensordata, nx)
        The sensors (read in the step, before it integrates) per the state's deviation.
    D : ndarray, shape (nsensordata, nu)
        Per control.
    y0 : ndarray, shape (nsensordata,)
        The sensors at rest (gravity on the accelerometers' vertical axes).
    """
    check_linear(model)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    y0 = data.sensordata.copy()        # before mjd_transitionFD, which leaves its last perturbation's
    nx = 2 * model.nv + model.na
    A, B = np.zeros((nx, nx)), np.zeros((nx, model.nu))
    C, D = np.zeros((model.nsensordata, nx)), np.zeros((model.nsensordata, model.nu))
    mujoco.mjd_transitionFD(model, data, FD_EPS, 1, A, B, C, D)
    return A, B, C, D, y0


def simulate(models: Sequence[mujoco.MjModel], jerk: np.ndarray, act0: float, rows: np.ndarray,
             substeps: int) -> np.ndarray:
    """Sensor readings of linear twins under a table jerk, one reading per sample.

    Parameters
    ----------
    models : sequence of mujoco.MjModel
        Linear twins (:func:`check_linear`), one layout.
    jerk : ndarray, shape (n_steps,)
        The table actuator's control at each integrator step (m/s^3).
    act0 : float
        The table's acceleration (m/s^2) at the start (the actuator's activation); the rest at rest.
    rows : ndarray of int, shape (k,)
        The sensordata entries read.
    substeps : int
        Integrator steps per sample: readings at steps 0, ``substeps``, ...

    Returns
    -------
    ndarray, shape (len(models), ceil(n_steps / substeps), k)
        The readings, as ``mujoco.rollout`` returns them at those steps.
    """
    maps = [state_space(m) for m in models]
    act = 2 * models[0].nv if maps else 0
    jerk = np.ascontiguousarray(jerk, float)
    n_out = -(-jerk.size // substeps)
    out = np.empty((len(maps), n_out, len(rows)))
    held = _held(jerk, substeps)
    for k, (A, B, C, D, y0) in enumerate(maps):
        x0 = np.zeros(A.shape[0])
        x0[act] = act0
        b, control, steps = np.ascontiguousarray(B[:, 0]), jerk, substeps
        if held is not None:                 # one map per sample: substeps times fewer multiplies
            A, b, control, steps = *_lifted(A, b, substeps), held, 1
        _run(A, b, np.ascontiguousarray(C[rows]), np.ascontiguousarray(D[rows, 0]), np.ascontiguousarray(y0[rows]),
             x0, control, steps, out[k])
    return out


def _held(jerk: np.ndarray, substeps: int) -> np.ndarray | None:
    """The control per sample when it is held over each sample's ``substeps`` (more than one) steps (as
    :func:`momentid.lab.resim.simulate` drives the table: one jerk per sample interval), else None."""
    if substeps < 2 or not jerk.size:
        return None
    n_out = -(-jerk.size // substeps)
    blocks = np.concatenate([jerk, np.full(n_out * substeps - jerk.size, jerk[-1])]).reshape(n_out, substeps)
    return np.ascontiguousarray(blocks[:, 0]) if np.all(blocks == blocks[:, :1]) else None


def _lifted(A: np.ndarray, b: np.ndarray, substeps: int) -> tuple[np.ndarray, np.ndarray]:
    """The step map over ``substeps`` steps under a held control: ``x <- A^s x + (A^(s-1) + ... + 1) b u``
    (the same map as stepping ``substeps`` times, to round-off; one multiply per sample, not per step)."""
    lifted, gain = np.eye(A.shape[0]), np.zeros_like(b)
    for _ in range(substeps):
        gain = A @ gain + b
        lifted = A @ lifted
    return np.ascontiguousarray(lifted), np.ascontiguousarray(gain)


@disk_cached(numba.njit, nogil=True)
def _run(A, b, C, d, y0, x, jerk, substeps, out):     # pragma: no cover  (compiled; its results are tested)
    """The replay loop: readings ``out[row] = y0 + C x + d u`` at every ``substeps``-th step, ``x = A x + b u``."""
    nx, k = x.size, y0.size
    nxt = np.empty(nx)
    for step in range(jerk.size):
        u = jerk[step]
        if step % substeps == 0:
            row = step // substeps
            for i in range(k):
                s = y0[i] + d[i] * u
                for j in range(nx):
                    s += C[i, j] * x[j]
                out[row, i] = s
        for i in range(nx):
            s = b[i] * u
            for j in range(nx):
                s += A[i, j] * x[j]
            nxt[i] = s
        x[:] = nxt
