"""Re-simulation of a real rig under recorded table motions: many models at once, no Python in the loop.

A real rig's identified stiffness is a full symmetric matrix (its floors rotate and its columns bend,
so floors two apart are coupled), its damping is modal (:func:`modal_damping`), and what it leaves out
is physics such as joint friction (:mod:`momentid.mechanisms.joint_friction`).  Such a rig is a
:class:`~momentid.lab.rig_model.RigModel` (:meth:`~momentid.lab.rig_model.RigModel.from_matrices`: any
symmetric K and C carried exactly by fixed tendons), built by the lab's one builder
(:func:`momentid.lab.rig.build_spec`) with the implicitfast integrator and accelerometers only
(:func:`build_spec`); a storey's joint friction rides on the tendon of its place (``storey<s>``), which
its kind's ``storey_tendon`` hook changes (joint friction: it keeps ``k - stiffness``).

:func:`simulate` rolls out many such models at once (``mujoco.rollout``, one thread per core, no
Python in the loop) under a recorded table acceleration, held piecewise linear between samples (the
``table`` actuator's control is its rate), and returns the floors' absolute accelerations at the
samples, as ideal sensors read them (the sensors' gains and clock offsets are applied by the caller).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Sequence
import math
import os

import mujoco
import numpy as np
from mujoco import rollout as _rollout
from numpy.typing import ArrayLike

from momentid.core import counters
from momentid.errors import ModelError, SimulationError
from momentid import mechanisms as registry
from momentid.lab import native_forces
from momentid.lab import rig as lab_rig
from momentid.lab.rig_model import RigModel
from momentid.lab.tendons import pair_coefficient

__all__ = ["build_spec", "compile_models", "simulate", "modal_damping", "TIMESTEP_PER_SAMPLE", "substeps_for",
           "STOREY_HEIGHT", "BASE_MASS"]

#: Integrator steps per recorded sample of a 120 Hz recording (4.2 ms steps, within
#: joint_friction.MAX_TIMESTEP); :func:`substeps_for` gives any rate's.
TIMESTEP_PER_SAMPLE = 2
#: Rollout threads when a call does not say (None: one per core); a caller running several fits side by
#: side on forked processes sets it to 1.
ROLLOUT_THREADS: int | None = None
#: Steps per rollout call: bounds the state buffer (batch x steps x state) to tens of MB.
_CHUNK_STEPS = 4096
#: Storey height (m) of a re-simulated rig's drawn floors; what a storey kind's tendon hook is told (joint
#: friction ignores it).
STOREY_HEIGHT = 0.15
#: The table's platen (kg) of a re-simulated rig: its base motion is the recorded one, whatever it weighs.
BASE_MASS = 1.0


def modal_damping(masses: ArrayLike, K: np.ndarray, zeta: ArrayLike) -> np.ndarray:
    """``C = M Phi diag(2 zeta w) Phi^T M`` (N s/m): the classical damping whose modes are those of
    (M, K) with damping ratios ``zeta`` (ascending frequency order), shape (d, d)."""
    m_half = np.sqrt(np.asarray(masses, float))
    w2, psi = np.linalg.eigh(K / m_half[:, None] / m_half[None, :])
    if np.any(w2 <= 0):
        raise ModelError(f"stiffness matrix with eigenvalues {w2.tolist()}: expected positive definite")
    S = m_half[:, None] * psi
    return S @ np.diag(2.0 * np.asarray(zeta, float) * np.sqrt(w2)) @ S.T


def build_spec(rig: RigModel, timestep: float, name: str = "rig_twin") -> mujoco.MjSpec:
    """The MJCF of ``rig`` as the re-simulation runs it (:func:`momentid.lab.rig.build_spec`: integrator
    ``implicitfast`` at ``timestep`` (s), the table and floor accelerometers only), whose written MJCF keeps
    the bodies' masses (stock MuJoCo needs them).  A rig with a force whose state MuJoCo integrates
    (Bouc-Wen's hysteretic drift) runs RK4: under implicitfast the state, stepped by explicit Euler, lags
    the drift by a step, and the force on that lag is a negative damping of ``(1 - alpha) k dt``, several
    times a lightly damped storey's own (the twin diverged)."""
    stateful = any(registry.get(m.type).has_state(dict(m.parameters)) for m in rig.mechanisms)
    integrator = mujoco.mjtIntegrator.mjINT_RK4 if stateful else mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec = lab_rig.build_spec(rig, timestep=timestep, name=name, integrator=integrator,
                              sensors=("zdd", "a"))
    spec.compiler.saveinertial = True
    return spec


def compile_models(rigs: Iterable[RigModel], timestep: float) -> list[mujoco.MjModel]:
    """Compiled ``mujoco.MjModel`` of each :class:`~momentid.lab.rig_model.RigModel` (all of one layout: the
    same tendons and mechanisms' places), by :func:`build_spec`; a rig's callback forces (Bouc-Wen's, with
    its state) loaded as the native callbacks' program (:mod:`~momentid.lab.native_forces`), a kind that
    takes a share of its storey's stiffness taking it from the rig's ``K``.

    Raises
    ------
    ModelError
        A callback force with no native law (the re-simulation runs no Python in MuJoCo's step).
    """
    out = []
    for r in rigs:
        model = lab_rig.compile_model(build_spec(r, timestep))
        if any(registry.get(m.type).callback for m in r.mechanisms):
            storeys = [pair_coefficient(r.K, s - 1, s) for s in range(1, r.storeys + 1)]
            if not native_forces.load_program(model, r.mechanisms, storeys):
                raise ModelError(f"mechanisms {[m.type for m in r.mechanisms]}: a callback force without a native "
                                 f"law (numba) cannot be re-simulated; expected kinds whose laws compile")
        out.append(model)
    return out


def _programs(models: Sequence[mujoco.MjModel]) -> bool:
    """Whether any of ``models`` carries native callback forces."""
    return any(m.nnumeric and m.numeric(0).name == native_forces.PROGRAM for m in models)


def substeps_for(dt: float) -> int:
    """Integrator steps per sample interval ``dt`` (s): the fewest that keep the step within
    :data:`momentid.mechanisms.joint_friction.MAX_TIMESTEP` (the step the joints' sliders are tested at):
    2 at 120 and 200 Hz, 3 at 100 Hz, 4 at 60 Hz, 1 from 240 Hz."""
    from momentid.mechanisms.joint_friction import MAX_TIMESTEP

    return max(1, math.ceil(dt / MAX_TIMESTEP - 1e-9))


def simulate(models: Iterable[mujoco.MjModel], zdd: np.ndarray, dt: float, substeps: int = TIMESTEP_PER_SAMPLE,
             threads: int | None = None, linear: bool = False) -> np.ndarray:
    """Floor absolute accelerations of compiled twins driven by a recorded table acceleration.

    Parameters
    ----------
    models : sequence of mujoco.MjModel
        From :func:`compile_models`, one layout, timestep ``dt / substeps``.
    zdd : ndarray, shape (n,) or (len(models), n)
        Table acceleration (m/s^2) at the samples, one for every model or one per model; the floors start
        at rest on the table.
    dt : float
        Sample interval (s).
    threads : int, optional
        Rollout threads (default: :data:`ROLLOUT_THREADS`, else the machine's cores; at most one per model).
    linear : bool
        The models are linear twins (no mechanism): replayed as MuJoCo's own step map
        (:mod:`momentid.lab.linear_replay`: the same readings to round-off, about 50x faster); a model that
        is not linear raises :class:`~momentid.errors.ModelError`.  Twins whose only nonlinear forces are
        compiled laws (Bouc-Wen's, under RK4) replay in compiled code whatever ``linear`` says
        (:mod:`momentid.lab.native_replay`: the same readings to round-off), and so do twins whose only
        nonlinearities are their joints' friction loss and their tendons' polynomial springs and dampers
        (:mod:`momentid.lab.step_replay`); the choice is :func:`momentid.lab.compiled_paths.compiled_path`'s.

    Returns
    -------
    ndarray, shape (len(models), n, d)
        Floor accelerations (m/s^2) at the samples, as ideal sensors read them.
    """
    models = list(models)
    counters.add(counters.REPLAYS, len(models))
    first = models[0]
    if abs(first.opt.timestep * substeps - dt) > 1e-5 * dt:     # an MJCF prints the step to 6 digits
        raise SimulationError(f"model timestep {first.opt.timestep} s: expected the sample interval {dt} s / "
                              f"{substeps}")
    d = sum(1 for j in range(first.njnt) if first.joint(j).name.startswith("q"))
    layout = lab_rig.sensor_layout(first)
    index = np.array([layout[f"a{i + 1}"] for i in range(d)])
    drives = np.atleast_2d(np.asarray(zdd, float))
    if drives.shape[0] not in (1, len(models)):
        raise ValueError(f"{drives.shape[0]} table drives for {len(models)} models: expected one, or one per model")
    n = drives.shape[1]
    jerk = np.repeat(np.diff(drives, axis=1) / dt, substeps, axis=1)
    jerk = np.concatenate([jerk, np.zeros((jerk.shape[0], 1))], axis=1)   # one step more: the last sensors
    if linear:
        from momentid.lab import linear_replay

        if drives.shape[0] == 1:
            out = linear_replay.simulate(models, jerk[0], float(drives[0, 0]), index, substeps)
        else:
            out = np.concatenate([linear_replay.simulate([m], j, float(z[0]), index, substeps)
                                  for m, j, z in zip(models, jerk, drives)])
        return _finite(out)
    nthread = max(1, min(threads or ROLLOUT_THREADS or os.cpu_count() or 1, len(models)))
    from momentid.lab.compiled_paths import compiled_path
    from momentid.lab.replay_batch import replay_batch

    path = compiled_path(models)           # compiled laws, or friction rows and polynomial tendons: no MuJoCo
    if path is not None:                   # in the loop
        return _finite(replay_batch(models, jerk, drives[:, 0], index, substeps, nthread, path))
    datas = [mujoco.MjData(first) for _ in range(nthread)]
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = []
    for k, m in enumerate(models):
        data = mujoco.MjData(m)
        data.act[0] = drives[k if drives.shape[0] > 1 else 0, 0]
        s = np.empty(mujoco.mj_stateSize(m, full))
        mujoco.mj_getState(m, data, s, full)
        states.append(s)
    state = np.array(states)
    out = np.empty((len(models), n, d))
    steps = jerk.shape[1]
    chunk = substeps * max(1, _CHUNK_STEPS // substeps)
    control = np.zeros((jerk.shape[0], steps, first.nu))   # the table's jerk; a force's state actuator takes none
    control[:, :, 0] = jerk
    with native_forces.installed() if _programs(models) else contextlib.nullcontext():
        for start in range(0, steps, chunk):
            stop = min(steps, start + chunk)
            st, sensors = _rollout.rollout(models, datas, state, control[:, start:stop])
            rows = sensors[:, ::substeps][:, :, index]
            out[:, start // substeps:start // substeps + rows.shape[1]] = rows
            state = st[:, -1]
    return _finite(out)


def _finite(out: np.ndarray) -> np.ndarray:
    """``out``, unless a simulation diverged (:class:`~momentid.errors.SimulationError`)."""
    if not np.all(np.isfinite(out)):
        raise SimulationError("the twin's simulation diverged (non-finite accelerations): expected a smaller "
                              "timestep or physical parameters")
    return out
