"""A twin whose step is linear but for its sliders' friction loss and its tendons' polynomial springs and
dampers (joint friction, a cubic spring, quadratic damping), replayed in compiled code: the same readings as
MuJoCo's own steps to round-off, several times faster.

A real rig's twin under ``implicitfast`` is springs and dampers on tendons and the table driven by its jerk
actuator, plus what its physics adds: joint friction's Iwan sliders, whose friction loss is a constraint row
each (:mod:`momentid.mechanisms.joint_friction`, solved by PGS), or a polynomial stiffness or damping on a
storey tendon (:mod:`momentid.mechanisms.cubic_spring`, :mod:`momentid.mechanisms.quadratic_damping`).
MuJoCo treats a constraint force as any other generalized force in the implicit update and integrates a
tendon's spring explicitly, so given those forces ``g`` (the rows' forces, then the polynomial part of each
such tendon's force) the step is linear:

    x+ = A x + b u + F g,        y = y0 + C x + d u + G g,

with ``x`` the positions, velocities and activation, ``u`` the table's jerk and ``y`` the sensors read in
the step.  Each slider's constraint is a row of its own: the sliders' mass matrix is diagonal (each one's
inertia is its joint's armature on a body of token mass; :func:`check` measures the coupling), so the dual
problem PGS solves splits row by row and its solution is exact in one sweep,

    f = clip(-(a0 + B v) / (A_ii + R_i), -F_i, F_i),     a0 = P x + p u,

``a0`` the slider's unconstrained acceleration, ``v`` its velocity, ``B`` the reference acceleration's
damping (MuJoCo's ``efc_KBIP``), ``A_ii + R_i`` the row's regularised inverse inertia (``efc_AR``), ``F_i``
its friction loss.  A fixed tendon of length ``L = l + Lx x`` stretched ``D = L - L0`` from its spring's
length, moving at ``V``, adds ``-(k2 D^2 + k3 D^3 + b2 V |V| + b3 V^3)`` (its ``stiffnesspoly`` and
``dampingpoly``: MuJoCo's laws).  implicitfast also puts the dampers' slope into its update's matrix: a
diagonal term on the dofs they span, which the loop carries by Woodbury (:func:`_implicit`).  :func:`maps`
reads the maps by centred differences of ``mj_step`` and ``mj_forward`` of a copy without those nonlinear
terms (exact to round-off for a linear map; ``g`` put in as applied forces) and ``B, A_ii + R_i`` off
``mj_forward`` of the model itself; :func:`replay` steps them in a numba loop.  It reads what
``mujoco.rollout`` reads to 3e-11 of the signal over the flexible rig's 12 000-sample Northridge with joint
friction, 3e-13 with quadratic damping (``tests/test_step_replay.py``; stick-slip switches amplify
round-off, so not to 1e-15).

A model with none of them is linear, and replays so under any integrator (a lab rig's RK4).  Anything else
nonlinear (compiled laws, limits, contacts, tendon friction loss, a damper across dofs the implicit update
couples), those nonlinearities under another integrator than implicitfast, friction rows under another solver,
or rows that couple, is refused (:func:`check`): the replay is then ``mujoco.rollout``'s.
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

__all__ = ["check", "applies", "StepMaps", "maps", "replay", "ENABLED", "MAX_COUPLING", "NEGLIGIBLE"]

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


def _polynomial_tendons(model: mujoco.MjModel) -> np.ndarray:
    """The tendons with a polynomial spring or damper."""
    return np.flatnonzero(np.any(np.hstack([model.tendon_stiffnesspoly, model.tendon_dampingpoly]) != 0, axis=1))


def _linear_part(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of ``model`` without its dofs' friction loss and its tendons' polynomial springs and dampers."""
    free = copy.copy(model)
    free.dof_frictionloss[:] = 0.0
    free.tendon_stiffnesspoly[:] = 0.0
    free.tendon_dampingpoly[:] = 0.0
    return free


def _coupled_dampers(model: mujoco.MjModel) -> bool:
    """Whether a tendon's polynomial damper spans two dofs whose entry implicitfast's derivative keeps (its
    sparsity: a dof and its ancestors).  The derivative of a damper across sibling dofs (a storey's floors)
    keeps only its diagonal, which :func:`_implicit` carries."""
    pattern = {(i, int(model.D_colind[model.D_rowadr[i] + k])) for i in range(model.nv)
               for k in range(model.D_rownnz[i])}
    for t in np.flatnonzero(np.any(model.tendon_dampingpoly != 0, axis=1)):
        adr = model.tendon_adr[t]
        touched = {int(model.jnt_dofadr[model.wrap_objid[w]]) for w in range(adr, adr + model.tendon_num[t])}
        if any(i != j and (i, j) in pattern for i in touched for j in touched):
            return True
    return False


def _unlike(model: mujoco.MjModel) -> list[str]:
    """What in ``model`` this replay cannot carry, in words (empty: nothing)."""
    why = []
    inputs = np.any(model.dof_frictionloss) or _polynomial_tendons(model).size
    if inputs and model.opt.integrator != mujoco.mjtIntegrator.mjINT_IMPLICITFAST:      # a linear step: any
        why.append(f"friction loss or polynomial tendons under integrator "
                   f"{mujoco.mjtIntegrator(model.opt.integrator).name}")
    if model.nu != 1 or model.na != 1:
        why.append(f"{model.nu} actuators and {model.na} activations (the table's jerk actuator alone)")
    if model.nnumeric and model.numeric(0).name == native_forces.PROGRAM:
        why.append("compiled force laws")
    if model.nq != model.nv or np.any(model.qpos0 != 0):
        why.append("joints other than slides at rest at 0")
    if np.any(model.tendon_frictionloss):
        why.append("tendon friction loss")
    why += nonlinear_elements(_linear_part(model))
    for t in _polynomial_tendons(model):
        wraps = model.wrap_type[model.tendon_adr[t]:model.tendon_adr[t] + model.tendon_num[t]]
        lengths = model.tendon_lengthspring[t]
        if np.any(wraps != mujoco.mjtWrap.mjWRAP_JOINT) or lengths[0] != lengths[1]:
            why.append(f"a polynomial spring or damper on tendon {t} that is not fixed, or has a dead band")
    if _coupled_dampers(model):
        why.append("a polynomial damper across dofs that implicitfast's update couples")
    if np.any(model.dof_frictionloss) and (model.opt.solver != mujoco.mjtSolver.mjSOL_PGS
                                           or model.opt.noslip_iterations):
        why.append("friction loss under a solver other than PGS (or noslip iterations)")
    if model.opt.disableflags & (mujoco.mjtDisableBit.mjDSBL_CONSTRAINT | mujoco.mjtDisableBit.mjDSBL_FRICTIONLOSS):
        why.append("its friction loss disabled")
    return why


def check(model: mujoco.MjModel) -> None:
    """Raise :class:`~momentid.errors.ModelError` unless ``model``'s only nonlinearities are its dofs' friction
    loss (under PGS, each row uncoupled from the others) and its fixed tendons' polynomial springs and dampers,
    under implicitfast, or it has none (module docstring).

    Parameters
    ----------
    model : mujoco.MjModel
        A compiled twin (:func:`momentid.lab.resim.compile_models`).
    """
    why = _unlike(model)
    if not why and np.any(model.dof_frictionloss):
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
        raise ModelError(f"the twin's model has {', '.join(why)}: expected a linear model, or an implicitfast twin "
                         f"whose only nonlinearities are its sliders' friction loss and its fixed tendons' "
                         f"polynomial springs and dampers (its replay is mujoco.rollout's)")


def applies(models: Sequence[mujoco.MjModel]) -> bool:
    """True when every one of ``models`` passes :func:`check` (and :data:`ENABLED`)."""
    return ENABLED and accepts(check, models)


@dataclass(frozen=True)
class StepMaps:
    """The step of a twin given its nonlinear forces ``g`` (module docstring): ``nf`` friction rows, then ``nt``
    polynomial tendons; ``k`` readings.

    Attributes
    ----------
    A : ndarray, shape (nx, nx)
        Next state per state (``nx = 2 nv + na``).
    b : ndarray, shape (nx,)
        Next state per jerk.
    F : ndarray, shape (nx, nf + nt)
        Next state per force (N): each friction row's, then each tendon's polynomial part.
    C, d, G : ndarray, shapes (k, nx), (k,), (k, nf + nt)
        The readings per state, jerk and force; ``y0`` (k,) at rest.
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
    Lx, stretch : ndarray, shapes (nt, nx), (nt,)
        Each polynomial tendon's stretch ``D = stretch + Lx x`` (m) from its spring's length; its velocity is
        ``V = Lx[:, :nv] v`` (a fixed tendon's Jacobian is that of its length).
    poly : ndarray, shape (nt, 4)
        Its ``k2`` (N/m^2), ``k3`` (N/m^3), ``b2`` (N s^2/m^2), ``b3`` (N s^3/m^3): the force
        ``-(k2 D^2 + k3 D^3 + b2 V |V| + b3 V^3)``.
    damped : ndarray of int, shape (nd,)
        The dofs the polynomial dampers span.
    Fd : ndarray, shape (nx, nd)
        Next state per unit generalized force (N) on each of them (:func:`_implicit`).
    J2 : ndarray, shape (nt, nd)
        The square of each tendon's Jacobian entry on each of them.
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
    Lx: np.ndarray
    stretch: np.ndarray
    poly: np.ndarray
    damped: np.ndarray
    Fd: np.ndarray
    J2: np.ndarray


def _friction_rows(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(dofs, B, A_ii + R_i)`` of ``model``'s friction rows at rest (empty without any)."""
    if not np.any(model.dof_frictionloss):
        return np.zeros(0, int), np.zeros(0), np.zeros(0)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    dofs = _rows(model, data)
    return dofs, data.efc_KBIP[:, 1].copy(), np.diag(data.efc_AR.reshape(dofs.size, dofs.size)).copy()


def maps(model: mujoco.MjModel, rows: np.ndarray | None = None) -> StepMaps:
    """The step maps of a twin that passes :func:`check` (module docstring).

    Parameters
    ----------
    model : mujoco.MjModel
        A twin that passes :func:`check`.
    rows : ndarray of int, shape (k,), optional
        The sensordata entries read (default: all ``nsensordata``).

    Returns
    -------
    StepMaps
    """
    check(model)
    dofs, damping, inverse_inertia = _friction_rows(model)
    tendons = _polynomial_tendons(model)
    free = _linear_part(model)                 # no constraints, no polynomials: the step with g as applied forces
    fd = mujoco.MjData(free)
    nv, nx, nf, nt = model.nv, 2 * model.nv + model.na, dofs.size, tendons.size
    spread = np.zeros((nv, nf + nt + nv))      # generalized force per unit of each g: the row's dof, ...
    spread[dofs, np.arange(nf)] = 1.0
    spread[:, nf + nt:] = np.eye(nv)           # (and per unit on each dof, for the dampers' implicit share)

    def at(x, u, g):              # (next state, readings, the rows' unconstrained accelerations, tendon lengths)
        fd.qpos[:], fd.qvel[:], fd.act[:] = x[:nv], x[nv:2 * nv], x[2 * nv:]
        fd.ctrl[:] = 0.0
        fd.ctrl[0] = u
        fd.qfrc_applied[:] = spread @ g
        fd.time = 0.0
        mujoco.mj_forward(free, fd)
        acc, length = fd.qacc_smooth[dofs].copy(), fd.ten_length[tendons].copy()
        mujoco.mj_step(free, fd)
        return np.concatenate([fd.qpos, fd.qvel, fd.act]), fd.sensordata.copy(), acc, length

    def centred(x, u, g, direction):
        plus, minus = at(*direction(FD_EPS, x, u, g)), at(*direction(-FD_EPS, x, u, g))
        return [(p - m) / (2 * FD_EPS) for p, m in zip(plus, minus)]

    x0, g0 = np.zeros(nx), np.zeros(nf + nt + nv)
    _, y0, _, rest = at(x0, 0.0, g0)
    A, C, P, Lx = np.zeros((nx, nx)), np.zeros((y0.size, nx)), np.zeros((nf, nx)), np.zeros((nt, nx))
    for j in range(nx):
        A[:, j], C[:, j], P[:, j], Lx[:, j] = centred(x0, 0.0, g0, lambda e, x, u, g: (x + e * np.eye(nx)[j], u, g))
    b, d, p, _ = centred(x0, 0.0, g0, lambda e, x, u, g: (x, u + e, g))
    spread[:, nf:nf + nt] = Lx[:, :nv].T      # ... and the tendon's Jacobian (a fixed tendon's: constant)
    F, G = np.zeros((nx, nf + nt + nv)), np.zeros((y0.size, nf + nt + nv))
    for j in range(nf + nt + nv):
        F[:, j], G[:, j], _, _ = centred(x0, 0.0, g0, lambda e, x, u, g: (x, u, g + e * np.eye(g0.size)[j]))
    rows = np.arange(y0.size) if rows is None else np.asarray(rows, int)
    poly = np.hstack([model.tendon_stiffnesspoly[tendons], model.tendon_dampingpoly[tendons]])
    damped = np.flatnonzero(np.any(Lx[poly[:, 2:].any(axis=1), :nv] != 0, axis=0))
    return StepMaps(A, b, F[:, :nf + nt], C[rows], d[rows], G[rows, :nf + nt], y0[rows], P, p, damping,
                    inverse_inertia, model.dof_frictionloss[dofs].copy(), nv + dofs, Lx,
                    rest - model.tendon_lengthspring[tendons, 0], poly, damped, F[:, nf + nt + damped],
                    Lx[:, damped] ** 2)


def replay(model: mujoco.MjModel, rows: np.ndarray, substeps: int, x: np.ndarray, control: np.ndarray,
           out: np.ndarray) -> int:
    """Replay one twin (module docstring) from state ``x`` under the table's jerk.

    The :class:`~momentid.lab.replay_batch.Replay` of :func:`~momentid.lab.replay_batch.replay_batch` (its
    parameters): ``model`` passes :func:`check`; ``x`` (2 nv + na,) the state, ``control`` (n_steps,) the jerk
    (m/s^3), ``out`` (ceil(n_steps / substeps), k) the readings of sensordata ``rows``, written; returns the
    number of resets.
    """
    mp = maps(model, rows)
    return int(_run(*_sparse(np.hstack([mp.A, mp.F])), mp.b, *_sparse(mp.P), mp.p, np.hstack([mp.C, mp.G]), mp.d,
                    mp.y0, mp.damping, mp.inverse_inertia, mp.limit, mp.velocity, np.ascontiguousarray(mp.Lx),
                    mp.stretch, mp.poly, mp.damped, np.ascontiguousarray(mp.Fd), np.ascontiguousarray(mp.J2), model.nv,
                    model.opt.timestep, x, control, substeps, out))


def _sparse(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``matrix`` (rows, columns) in compressed rows ``(start, column, value)``, its entries within
    :data:`NEGLIGIBLE` of their row's largest left out: the centred differences' round-off in the entries that
    are zero (about two thirds of a joint-friction twin's), whose sum the replay would otherwise carry."""
    keep = np.abs(matrix) > NEGLIGIBLE * np.abs(matrix).max(axis=1, keepdims=True)
    start = np.concatenate([[0], np.cumsum(keep.sum(axis=1))]).astype(np.int64)
    column = np.nonzero(keep)[1].astype(np.int64)
    return start, column, np.ascontiguousarray(matrix[keep])


@disk_cached(numba.njit, inline="always")
def _dot(a, b, start, stop):   # pragma: no cover  (compiled; tested)
    """``sum(a[i] * b[start + i] for i < stop - start)``: a short dot product without BLAS's call overhead."""
    s = 0.0
    for i in range(stop - start):
        s += a[i] * b[start + i]
    return s


@disk_cached(numba.njit, inline="always")
def _forces(x, u, z, p_start, p_column, p_value, p, damping, inverse_inertia, limit, velocity, Lx, stretch,
            poly):   # pragma: no cover  (compiled; tested)
    """``z = [x; g]``: the friction rows' forces, then the polynomial tendons' (module docstring)."""
    nx, nf = x.size, limit.size
    z[:nx] = x
    for r in range(nf):
        a = p[r] * u + damping[r] * x[velocity[r]]
        for e in range(p_start[r], p_start[r + 1]):
            a += p_value[e] * x[p_column[e]]
        z[nx + r] = min(max(-a / inverse_inertia[r], -limit[r]), limit[r])
    nv = (nx - 1) // 2
    for t in range(stretch.size):
        D = stretch[t] + _dot(Lx[t], x, 0, nx)
        V = _dot(Lx[t], x, nv, 2 * nv)
        z[nx + nf + t] = -(poly[t, 0] * D * D + poly[t, 1] * D * D * D
                           + poly[t, 2] * V * abs(V) + poly[t, 3] * V * V * V)


@disk_cached(numba.njit, inline="always")
def _next(z, u, w_start, w_column, w_value, b, nxt):   # pragma: no cover  (compiled; tested)
    """``nxt = W z + b u``."""
    for i in range(nxt.size):
        s = b[i] * u
        for e in range(w_start[i], w_start[i + 1]):
            s += w_value[e] * z[w_column[e]]
        nxt[i] = s


@disk_cached(numba.njit, inline="always")
def _implicit(x, nxt, Lx, poly, damped, Fd, J2, work, rhs):   # pragma: no cover  (compiled; tested)
    """Correct ``nxt``, the step without the polynomial dampers' share of implicitfast's matrix, for it.
    MuJoCo's update solves ``(M - h D + h diag(e)) dv = h f`` with ``e_j = sum_t s_t J_tj^2`` on the dampers'
    dofs, ``s_t = 2 b2 |V_t| + 3 b3 V_t^2`` each damper's slope at the step's start (implicitfast keeps the
    derivative's entries on its sparsity only: a storey's floors are siblings, so its diagonal).  By Woodbury
    ``dv`` is the step's ``dv0`` less ``Fd w``, ``(I + diag(e) Wd) w = diag(e) dv0`` on those dofs with ``Wd``
    ``Fd``'s velocity rows of them, and the positions follow the velocities: ``nxt -= Fd w``."""
    nt, nd, nx = J2.shape[0], J2.shape[1], x.size
    nv = (nx - 1) // 2
    if nd == 0:
        return
    for j in range(nd):
        rhs[j] = 0.0
    for t in range(nt):
        V = _dot(Lx[t], x, nv, 2 * nv)
        slope = 2.0 * poly[t, 2] * abs(V) + 3.0 * poly[t, 3] * V * V
        for j in range(nd):
            rhs[j] += slope * J2[t, j]          # e_j for now
    for r in range(nd):
        for c in range(nd):
            work[r, c] = (1.0 if r == c else 0.0) + rhs[r] * Fd[nv + damped[r], c]
        rhs[r] *= nxt[nv + damped[r]] - x[nv + damped[r]]
    for c in range(nd):                  # Gauss without pivots: I + E Wd is similar to I + E^1/2 Wd E^1/2 (SPD)
        for r in range(c + 1, nd):
            factor = work[r, c] / work[c, c]
            for j in range(c, nd):
                work[r, j] -= factor * work[c, j]
            rhs[r] -= factor * rhs[c]
    for c in range(nd - 1, -1, -1):
        for j in range(c + 1, nd):
            rhs[c] -= work[c, j] * rhs[j]
        rhs[c] /= work[c, c]
    for i in range(nx):
        nxt[i] -= _dot(Fd[i], rhs, 0, nd)


@disk_cached(numba.njit, nogil=True)
def _run(w_start, w_column, w_value, b, p_start, p_column, p_value, p, CG, d, y0, damping, inverse_inertia,
         limit, velocity, Lx, stretch, poly, damped, Fd, J2, nv, h, x, jerk, substeps,
         out):   # pragma: no cover  (compiled; tested)
    """The replay loop on ``z = [x; g]`` (:func:`_forces`): the readings ``y0 + d u + [C G] z`` at every
    ``substeps``-th step, the next state ``W z + b u`` (``W = [A F]`` and ``P`` in compressed rows,
    :func:`_sparse`) with the polynomial dampers' implicit share (:func:`_implicit`).  As ``mj_step`` does, a
    position or velocity that is NaN or beyond 1e10 resets the twin to rest (control 0 for the step), and so
    does an acceleration beyond 1e10 (here the step's velocity change over ``h``, MuJoCo's reads its ``qacc``:
    the same step but where the implicit update's share decides), after which the step's readings are those
    at rest.  Returns the number of resets."""
    nx, k, nt = x.size, y0.size, stretch.size
    resets = 0
    z = np.empty(nx + limit.size + nt)
    nxt = np.empty(nx)
    work, rhs = np.empty((damped.size, damped.size)), np.empty(damped.size)
    for step in range(jerk.size):
        u = jerk[step]
        for i in range(2 * nv):
            if not abs(x[i]) <= 1e10:
                x[:] = 0.0
                u = 0.0
                resets += 1
                break
        _forces(x, u, z, p_start, p_column, p_value, p, damping, inverse_inertia, limit, velocity, Lx, stretch, poly)
        _next(z, u, w_start, w_column, w_value, b, nxt)
        _implicit(x, nxt, Lx, poly, damped, Fd, J2, work, rhs)
        for i in range(nv, 2 * nv):
            if not abs(nxt[i] - x[i]) <= 1e10 * h:
                x[:] = 0.0
                u = 0.0
                resets += 1
                _forces(x, u, z, p_start, p_column, p_value, p, damping, inverse_inertia, limit, velocity, Lx,
                        stretch, poly)
                _next(z, u, w_start, w_column, w_value, b, nxt)
                break
        if step % substeps == 0:
            for i in range(k):
                out[step // substeps, i] = y0[i] + d[i] * u + _dot(CG[i], z, 0, z.size)
        x[:] = nxt
    return resets
