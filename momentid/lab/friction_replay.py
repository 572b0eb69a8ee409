"""A twin whose only nonlinearity is friction loss on its joints (the Iwan sliders of joint friction), replayed
in compiled code: the same readings as MuJoCo's own steps to round-off, several times faster.

A real rig's twin with joint friction (:mod:`momentid.mechanisms.joint_friction`) is linear but for its
sliders' friction-loss constraints: springs and dampers on tendons, the table driven by its jerk actuator,
the ``implicitfast`` integrator, the PGS solver.  Given the sliders' constraint forces ``f`` (generalized
forces on their dofs) its step is linear:

    x+ = A x + b u + F f,        y = y0 + C x + d u + G f,

with ``x`` the positions, velocities and activation, ``u`` the table's jerk and ``y`` the sensors read in
the step; MuJoCo treats a constraint force as any other generalized force in the implicit update.  Each
slider's constraint is a row of its own: the sliders' mass matrix is diagonal (each one's inertia is its
joint's armature on a body of token mass; :func:`check` measures the coupling), so the dual problem PGS
solves splits row by row and its solution is exact in one sweep,

    f = clip(-(a0 + B v) / (A_ii + R_i), -F_i, F_i),     a0 = P x + p u,

``a0`` the slider's unconstrained acceleration, ``v`` its velocity, ``B`` the reference acceleration's
damping (MuJoCo's ``efc_KBIP``), ``A_ii + R_i`` the row's regularised inverse inertia (``efc_AR``), ``F_i``
its friction loss.  :func:`maps` reads ``A, b, F, C, d, G, P, p`` by centred differences of ``mj_step`` and
``mj_forward`` of a copy without friction loss (exact to round-off for a linear map) and ``B, A_ii + R_i``
off ``mj_forward`` of the model itself; :func:`replay` steps them in a numba loop.  It reads what
``mujoco.rollout`` reads to 1e-11 of the signal over the flexible rig's 12 000-sample Northridge
(``tests/test_friction_replay.py``; stick-slip switches amplify round-off, so not to 1e-15).

Anything else nonlinear (compiled laws, polynomial springs, limits, contacts, tendon friction loss), another
integrator or solver, or sliders whose rows couple, is refused (:func:`check`): the replay is then
``mujoco.rollout``'s.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numba
import numpy as np

from momentid.core.compiled import disk_cached
from momentid.errors import ModelError
from momentid.lab import native_forces
from momentid.lab.linear_replay import FD_EPS, nonlinear_elements
from momentid.lab.replay_batch import accepts

__all__ = ["check", "applies", "FrictionMaps", "maps", "replay", "ENABLED", "MAX_COUPLING", "NEGLIGIBLE"]

#: Replay such twins in compiled code (tests set it False to compare with ``mujoco.rollout``).
ENABLED = True
#: Largest coupling between two friction rows, relative to the smallest row's own inverse inertia, for which
#: the row-by-row solution is taken for PGS's.  The sliders' rows couple through their bodies' token mass
#: (1e-9 kg) only: 1e-13 of it at the fit's start, 1e-10 to 4e-6 where a fit makes a storey's joint weak
#: (10 to 0.05 N/m on the flexible rig's twin), where the replay still read the rollout to 2.7e-11.
MAX_COUPLING = 1e-6
#: An entry of the step maps within this share of its row's largest is round-off of the centred differences
#: and left out of the replay (:func:`_sparse`): on the flexible rig's twin the replay then reads the
#: rollout to 5e-12 against 1.2e-11 with them, at a third of the multiplies; 1e-13 would drop real ones
#: (1e-9 off).
NEGLIGIBLE = 1e-15


def _rows(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """The dofs of ``data``'s constraint rows, all of them friction loss on a dof (else empty)."""
    if data.nefc and np.all(data.efc_type == mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF):
        return np.asarray(data.efc_id, int).copy()
    return np.zeros(0, int)


def check(model: mujoco.MjModel) -> None:
    """Raise :class:`~momentid.errors.ModelError` unless ``model`` is an implicitfast twin under PGS whose only
    nonlinearity is its dofs' friction loss, each row uncoupled from the others (module docstring).

    Parameters
    ----------
    model : mujoco.MjModel
        A compiled twin (:func:`momentid.lab.resim.compile_models`).
    """
    why = []
    if model.opt.integrator != mujoco.mjtIntegrator.mjINT_IMPLICITFAST:
        why.append(f"integrator {mujoco.mjtIntegrator(model.opt.integrator).name}")
    if model.opt.solver != mujoco.mjtSolver.mjSOL_PGS or model.opt.noslip_iterations:
        why.append("a solver other than PGS (or noslip iterations)")
    if model.opt.disableflags & (mujoco.mjtDisableBit.mjDSBL_CONSTRAINT | mujoco.mjtDisableBit.mjDSBL_FRICTIONLOSS):
        why.append("its friction loss disabled")
    if model.nu != 1 or model.na != 1:
        why.append(f"{model.nu} actuators and {model.na} activations (the table's jerk actuator alone)")
    if model.nnumeric and model.numeric(0).name == native_forces.PROGRAM:
        why.append("compiled force laws")
    if model.nq != model.nv or np.any(model.qpos0 != 0):
        why.append("joints other than slides at rest at 0")
    if np.any(model.tendon_frictionloss):
        why.append("tendon friction loss")
    why += [w for w in nonlinear_elements(model) if w != "friction loss"]
    if not np.any(model.dof_frictionloss):
        why.append("no friction loss")
    elif not why:
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        dofs = _rows(model, data)
        if dofs.size != np.count_nonzero(model.dof_frictionloss):
            why.append("constraint rows other than the dofs' friction loss")
        else:
            AR = data.efc_AR.reshape(dofs.size, dofs.size)
            off = np.abs(AR - np.diag(np.diag(AR))).max(initial=0.0) / np.min(np.diag(AR))
            if off > MAX_COUPLING:
                why.append(f"friction rows coupled by {off:.3g} of their inertia (at most {MAX_COUPLING:g})")
    if why:
        raise ModelError(f"the twin's model has {', '.join(why)}: expected an implicitfast twin under PGS whose "
                         f"only nonlinearity is its sliders' friction loss (its replay is mujoco.rollout's)")


def applies(models: Sequence[mujoco.MjModel]) -> bool:
    """True when every one of ``models`` passes :func:`check` (and :data:`ENABLED`)."""
    return ENABLED and accepts(check, models)


@dataclass(frozen=True)
class FrictionMaps:
    """The step of a friction twin given its sliders' forces (module docstring), for ``k`` readings.

    Attributes
    ----------
    A : ndarray, shape (nx, nx)
        Next state per state (``nx = 2 nv + na``).
    b : ndarray, shape (nx,)
        Next state per jerk.
    F : ndarray, shape (nx, nf)
        Next state per friction force (N), one column per friction row.
    C, d, G : ndarray, shapes (k, nx), (k,), (k, nf)
        The readings per state, jerk and friction force; ``y0`` (k,) at rest.
    P, p : ndarray, shapes (nf, nx), (nf,)
        The sliders' unconstrained accelerations per state and jerk.
    damping : ndarray, shape (nf,)
        ``B`` of each row's reference acceleration ``-B v`` (1/s).
    inverse_inertia : ndarray, shape (nf,)
        ``A_ii + R_i`` (1/kg).
    limit : ndarray, shape (nf,)
        Each row's friction loss (N).
    velocity : ndarray of int, shape (nf,)
        Each row's velocity's index in the state.
    """

    A: np.ndarray
    b: np.ndarray
    F: np.ndarray
    C: np.ndarray
    d: np.ndarray
    G: np.ndarray
    y0: np.ndarray
    P: np.ndarray
    p: np.ndarray
    damping: np.ndarray
    inverse_inertia: np.ndarray
    limit: np.ndarray
    velocity: np.ndarray


def maps(model: mujoco.MjModel, rows: np.ndarray | None = None) -> FrictionMaps:
    """The step maps of a friction twin (module docstring).

    Parameters
    ----------
    model : mujoco.MjModel
        A twin that passes :func:`check`.
    rows : ndarray of int, shape (k,), optional
        The sensordata entries read (default: all ``nsensordata``).

    Returns
    -------
    FrictionMaps
    """
    check(model)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    dofs = _rows(model, data)
    damping, inverse_inertia = data.efc_KBIP[:, 1].copy(), np.diag(data.efc_AR.reshape(dofs.size, dofs.size)).copy()
    free = copy.copy(model)
    free.dof_frictionloss[:] = 0.0                     # no constraints: the step with f as applied forces
    fd = mujoco.MjData(free)
    nv, nx, nf = model.nv, 2 * model.nv + model.na, dofs.size

    def at(x, u, f):              # (next state, readings, unconstrained accelerations of the rows)
        fd.qpos[:], fd.qvel[:], fd.act[:] = x[:nv], x[nv:2 * nv], x[2 * nv:]
        fd.ctrl[:] = 0.0
        fd.ctrl[0] = u
        fd.qfrc_applied[:] = 0.0
        fd.qfrc_applied[dofs] = f
        fd.time = 0.0
        mujoco.mj_forward(free, fd)
        acc = fd.qacc_smooth[dofs].copy()
        mujoco.mj_step(free, fd)
        return np.concatenate([fd.qpos, fd.qvel, fd.act]), fd.sensordata.copy(), acc

    def centred(x, u, f, direction):
        plus, minus = at(*direction(FD_EPS, x, u, f)), at(*direction(-FD_EPS, x, u, f))
        return [(p - m) / (2 * FD_EPS) for p, m in zip(plus, minus)]

    x0, f0 = np.zeros(nx), np.zeros(nf)
    _, y0, _ = at(x0, 0.0, f0)
    A, C, P = np.zeros((nx, nx)), np.zeros((y0.size, nx)), np.zeros((nf, nx))
    for j in range(nx):
        A[:, j], C[:, j], P[:, j] = centred(x0, 0.0, f0, lambda e, x, u, f: (x + e * np.eye(nx)[j], u, f))
    b, d, p = centred(x0, 0.0, f0, lambda e, x, u, f: (x, u + e, f))
    F, G = np.zeros((nx, nf)), np.zeros((y0.size, nf))
    for j in range(nf):
        F[:, j], G[:, j], _ = centred(x0, 0.0, f0, lambda e, x, u, f: (x, u, f + e * np.eye(nf)[j]))
    rows = np.arange(y0.size) if rows is None else np.asarray(rows, int)
    return FrictionMaps(A, b, F, C[rows], d[rows], G[rows], y0[rows], P, p, damping, inverse_inertia,
                        model.dof_frictionloss[dofs].copy(), nv + dofs)


def replay(model: mujoco.MjModel, rows: np.ndarray, substeps: int, x: np.ndarray, control: np.ndarray,
           out: np.ndarray) -> None:
    """Replay one friction twin (module docstring) from state ``x`` under the table's jerk.

    The :class:`~momentid.lab.replay_batch.Replay` of :func:`~momentid.lab.replay_batch.replay_batch` (its
    parameters): ``model`` passes :func:`check`; ``x`` (2 nv + na,) the state, ``control`` (n_steps,) the jerk
    (m/s^3), ``out`` (ceil(n_steps / substeps), k) the readings of sensordata ``rows``, written.
    """
    mp = maps(model, rows)
    _run(*_sparse(np.hstack([mp.A, mp.F])), mp.b, *_sparse(mp.P), mp.p, np.hstack([mp.C, mp.G]), mp.d, mp.y0,
         mp.damping, mp.inverse_inertia, mp.limit, mp.velocity, model.nv, x, control, substeps, out)


def _sparse(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``matrix`` (rows, columns) in compressed rows ``(start, column, value)``, its entries within
    :data:`NEGLIGIBLE` of their row's largest left out: the centred differences' round-off in the entries that
    are zero (about two thirds of a joint-friction twin's), whose sum the replay would otherwise carry."""
    keep = np.abs(matrix) > NEGLIGIBLE * np.abs(matrix).max(axis=1, keepdims=True)
    start = np.concatenate([[0], np.cumsum(keep.sum(axis=1))]).astype(np.int64)
    column = np.nonzero(keep)[1].astype(np.int64)
    return start, column, np.ascontiguousarray(matrix[keep])


@disk_cached(numba.njit, nogil=True)
def _run(w_start, w_column, w_value, b, p_start, p_column, p_value, p, CG, d, y0, damping, inverse_inertia,
         limit, velocity, nv, x, jerk, substeps, out):     # pragma: no cover  (compiled; its results are tested)
    """The replay loop on ``z = [x; f]``: the rows' forces ``f``, the readings ``y0 + d u + [C G] z`` at every
    ``substeps``-th step, the next state ``W z + b u`` (``W = [A F]`` and ``P`` in compressed rows,
    :func:`_sparse`).  A position or velocity MuJoCo calls bad (NaN, or beyond 1e10) resets the twin to rest
    as ``mj_step`` does."""
    nx, nf, k = x.size, limit.size, y0.size
    z = np.empty(nx + nf)
    nxt = np.empty(nx)
    for step in range(jerk.size):
        u = jerk[step]
        for i in range(2 * nv):
            if not abs(x[i]) <= 1e10:
                x[:] = 0.0
                u = 0.0
                break
        z[:nx] = x
        for r in range(nf):
            a = p[r] * u + damping[r] * x[velocity[r]]
            for e in range(p_start[r], p_start[r + 1]):
                a += p_value[e] * x[p_column[e]]
            z[nx + r] = min(max(-a / inverse_inertia[r], -limit[r]), limit[r])
        if step % substeps == 0:
            for i in range(k):
                out[step // substeps, i] = y0[i] + d[i] * u + np.dot(CG[i], z)
        for i in range(nx):
            s = b[i] * u
            for e in range(w_start[i], w_start[i + 1]):
                s += w_value[e] * z[w_column[e]]
            nxt[i] = s
        x[:] = nxt
