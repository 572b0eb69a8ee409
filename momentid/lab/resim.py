"""The MuJoCo model of a real rig identified from accelerometers, and its re-simulation under recorded
table motions.

A real rig's identified stiffness is a full symmetric matrix (its floors rotate and its columns bend,
so floors two apart are coupled), its damping is modal, and what it leaves out is physics such as
joint friction (:mod:`momentid.mechanisms.joint_friction`).  :class:`RigModel` holds such a model;
:func:`build_spec` writes it as MJCF in the rig's layout (:mod:`momentid.lab.rig`: a ``base`` body on
the slide joint ``base_x`` driven by the ``table`` integrator actuator, floors on slide joints ``q<i>``
relative to it, accelerometers ``a<i>``).  Any symmetric K and C is carried exactly by fixed tendons, laid out as
the ``momentid twin`` builder lays them (:func:`momentid.lab.tendons.tendon_layout`: ``storey<j>``
between neighbouring levels, ``link<i>_<j>`` where K or C couples levels further apart); a storey's
joint friction rides on the tendon of its place (``storey<s>``), which its kind's ``storey_tendon``
hook changes (joint friction: it keeps ``k - stiffness``).

:func:`simulate` rolls out many such models at once (``mujoco.rollout``, one thread per core, no
Python in the loop) under a recorded table acceleration, held piecewise linear between samples (the
``table`` actuator's control is its rate), and returns the floors' absolute accelerations at the
samples, as ideal sensors read them (the sensors' gains and clock offsets are applied by the caller).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace

import mujoco
import numpy as np
from mujoco import rollout as _rollout

from momentid.core.structure import Mechanism
from momentid.errors import ModelError, SimulationError
from momentid.lab import rig
from momentid.lab.tendons import put_tendon, tendon_layout
from momentid.mechanisms import registry

__all__ = ["RigModel", "build_spec", "compile_models", "simulate", "modal_damping", "friction_records",
           "TIMESTEP_PER_SAMPLE", "substeps_for"]

#: Integrator steps per recorded sample of a 120 Hz recording (4.2 ms steps, within
#: joint_friction.MAX_TIMESTEP); :func:`substeps_for` gives any rate's.
TIMESTEP_PER_SAMPLE = 2
#: Rollout threads when a call does not say (None: one per core); a caller running several fits side by
#: side on forked processes sets it to 1.
ROLLOUT_THREADS: int | None = None
#: Steps per rollout call: bounds the state buffer (batch x steps x state) to tens of MB.
_CHUNK_STEPS = 4096
_PLATEN = (0.3, 0.2, 0.01)     # drawing only (m)
_SLAB = (0.15, 0.1, 0.01)
#: Storey height (m) of the drawn floors; what a storey kind's tendon hook is told (joint friction ignores it).
_STOREY_HEIGHT = 0.15


def modal_damping(masses, K, zeta) -> np.ndarray:
    """``C = M Phi diag(2 zeta w) Phi^T M`` (N s/m): the classical damping whose modes are those of
    (M, K) with damping ratios ``zeta`` (ascending frequency order), shape (d, d)."""
    m_half = np.sqrt(np.asarray(masses, float))
    w2, psi = np.linalg.eigh(K / m_half[:, None] / m_half[None, :])
    if np.any(w2 <= 0):
        raise ModelError(f"stiffness matrix with eigenvalues {w2.tolist()}: expected positive definite")
    S = m_half[:, None] * psi
    return S @ np.diag(2.0 * np.asarray(zeta, float) * np.sqrt(w2)) @ S.T


@dataclass(frozen=True)
class RigModel:
    """A real rig as MuJoCo simulates it.

    Attributes
    ----------
    masses : ndarray, shape (d,)
        Floor masses (kg).
    stiffness : ndarray, shape (d, d)
        K (N/m) of the stuck joints (small drifts), symmetric positive definite.
    damping_ratio : ndarray, shape (d,)
        Modal viscous damping ratios (1) on the modes of (M, K), ascending frequency.
    friction : tuple of Mechanism
        ``joint_friction`` records (at most one per storey); empty: the linear twin.
    gain, offset : ndarray, shape (d,)
        Floor sensors' gains (1) and clock offsets (s, positive: the sensor lags the table's).
    """

    masses: np.ndarray
    stiffness: np.ndarray
    damping_ratio: np.ndarray
    friction: tuple = ()
    gain: np.ndarray = field(default=None)
    offset: np.ndarray = field(default=None)

    def __post_init__(self):
        d = len(self.masses)
        if self.gain is None:
            object.__setattr__(self, "gain", np.ones(d))
        if self.offset is None:
            object.__setattr__(self, "offset", np.zeros(d))

    @property
    def storeys(self) -> int:
        return len(self.masses)

    @property
    def damping(self) -> np.ndarray:
        """C (N s/m), shape (d, d)."""
        return modal_damping(self.masses, self.stiffness, self.damping_ratio)

    def linear(self) -> RigModel:
        """The same rig without its friction."""
        return replace(self, friction=())

    def to_dict(self) -> dict:
        return {"masses_kg": np.asarray(self.masses).tolist(), "stiffness_n_per_m": np.asarray(self.stiffness).tolist(),
                "damping_ratio": np.asarray(self.damping_ratio).tolist(),
                "friction": [{**registry.get(m.type).place(m.location).location, **dict(m.parameters)}
                             for m in self.friction],
                "sensor_gain": np.asarray(self.gain).tolist(), "sensor_offset_s": np.asarray(self.offset).tolist()}


def build_spec(model: RigModel, timestep: float, name: str = "rig_twin") -> mujoco.MjSpec:
    """The MJCF of ``model`` (see the module docstring); integrator ``implicitfast`` at ``timestep`` (s)."""
    d = model.storeys
    K, C = np.asarray(model.stiffness, float), model.damping
    if K.shape != (d, d) or not np.allclose(K, K.T):
        raise ModelError(f"stiffness of shape {K.shape}: expected a symmetric ({d}, {d}) matrix")
    spec = rig.empty_spec(name, timestep, mujoco.mjtIntegrator.mjINT_IMPLICITFAST)
    base = spec.worldbody.add_body(name="base", pos=[0, 0, _PLATEN[2]])
    base.mass = 1.0
    base.inertia = [0.01] * 3
    table = base.add_joint(name="base_x", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
    table.armature = rig.TABLE_INERTIA_RATIO * (1.0 + float(np.sum(model.masses)))
    base.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=list(_PLATEN), rgba=[0.35, 0.35, 0.4, 1],
                  contype=0, conaffinity=0)
    base.add_site(name="base_imu")
    floors = []
    for i in range(d):
        floor = base.add_body(name=f"floor{i + 1}", pos=[0, 0, _STOREY_HEIGHT * (i + 1)])
        floor.mass = float(model.masses[i])
        floor.inertia = [float(model.masses[i]) * 1e-3] * 3
        floor.add_joint(name=f"q{i + 1}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
        floor.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=list(_SLAB), rgba=[0.8, 0.6, 0.3, 1],
                       contype=0, conaffinity=0)
        floor.add_site(name=f"floor{i + 1}_imu")
        floors.append(floor)
    tendons = tendon_layout(K, C)             # the twin builder's tendons
    changed = {}
    for mech in model.friction:               # each storey kind changes its storey's tendon by its hook
        registry.validate(mech, d)
        kind = registry.get(mech.type)
        lower, upper = kind.place(mech.location).nodes
        t = changed.get((lower, upper)) or next(t for t in tendons if (t.lower, t.upper) == (lower, upper))
        k, c = kind.storey_tendon(mech, t.stiffness, t.damping, float(np.sum(model.masses[upper - 1:])),
                                  _STOREY_HEIGHT)
        changed[(lower, upper)] = replace(t, stiffness=k, damping=c)
    for t in tendons:
        put_tendon(spec, changed.get((t.lower, t.upper), t))
    rig.add_storey_elements(spec, model.friction, [base] + floors, timestep)
    spec.add_actuator(name="table", target="base_x", trntype=mujoco.mjtTrn.mjTRN_JOINT,
                      dyntype=mujoco.mjtDyn.mjDYN_INTEGRATOR, gear=[table.armature + base.mass, 0, 0, 0, 0, 0],
                      ctrllimited=mujoco.mjtLimited.mjLIMITED_FALSE, actlimited=mujoco.mjtLimited.mjLIMITED_FALSE)
    site = mujoco.mjtObj.mjOBJ_SITE
    spec.add_sensor(name="zdd", type=mujoco.mjtSensor.mjSENS_ACCELEROMETER, objname="base_imu", objtype=site)
    for i in range(d):
        spec.add_sensor(name=f"a{i + 1}", type=mujoco.mjtSensor.mjSENS_ACCELEROMETER, objname=f"floor{i + 1}_imu",
                        objtype=site)
    spec.compiler.saveinertial = True       # spec.to_xml() writes the bodies' masses (stock MuJoCo needs them)
    return spec


def compile_models(models, timestep: float) -> list:
    """Compiled ``mujoco.MjModel`` of each :class:`RigModel` (all of one layout: same friction storeys)."""
    return [rig.compile_model(build_spec(m, timestep)) for m in models]


def substeps_for(dt: float) -> int:
    """Integrator steps per sample interval ``dt`` (s): the fewest that keep the step within
    :data:`momentid.mechanisms.joint_friction.MAX_TIMESTEP` (the step the joints' sliders are tested at):
    2 at 120 and 200 Hz, 3 at 100 Hz, 4 at 60 Hz, 1 from 240 Hz."""
    from momentid.mechanisms.joint_friction import MAX_TIMESTEP

    return max(1, math.ceil(dt / MAX_TIMESTEP - 1e-9))


def simulate(models, zdd: np.ndarray, dt: float, substeps: int = TIMESTEP_PER_SAMPLE,
             threads: int | None = None) -> np.ndarray:
    """Floor absolute accelerations of compiled twins driven by a recorded table acceleration.

    Parameters
    ----------
    models : sequence of mujoco.MjModel
        From :func:`compile_models`, one layout, timestep ``dt / substeps``.
    zdd : ndarray, shape (n,)
        Table acceleration (m/s^2) at the samples; the floors start at rest on the table.
    dt : float
        Sample interval (s).
    threads : int, optional
        Rollout threads (default: :data:`ROLLOUT_THREADS`, else the machine's cores; at most one per model).

    Returns
    -------
    ndarray, shape (len(models), n, d)
        Floor accelerations (m/s^2) at the samples, as ideal sensors read them.
    """
    models = list(models)
    first = models[0]
    if abs(first.opt.timestep * substeps - dt) > 1e-5 * dt:     # an MJCF prints the step to 6 digits
        raise SimulationError(f"model timestep {first.opt.timestep} s: expected the sample interval {dt} s / "
                              f"{substeps}")
    d = sum(1 for j in range(first.njnt) if first.joint(j).name.startswith("q"))
    layout = rig.sensor_layout(first)
    index = np.array([layout[f"a{i + 1}"] for i in range(d)])
    n = len(zdd)
    jerk = np.repeat(np.diff(zdd) / dt, substeps)
    jerk = np.append(jerk, 0.0)                       # one step more: the last sample's sensors
    nthread = max(1, min(threads or ROLLOUT_THREADS or os.cpu_count() or 1, len(models)))
    datas = [mujoco.MjData(first) for _ in range(nthread)]
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = []
    for m in models:
        data = mujoco.MjData(m)
        data.act[0] = zdd[0]
        s = np.empty(mujoco.mj_stateSize(m, full))
        mujoco.mj_getState(m, data, s, full)
        states.append(s)
    state = np.array(states)
    out = np.empty((len(models), n, d))
    steps = len(jerk)
    chunk = substeps * max(1, _CHUNK_STEPS // substeps)
    for start in range(0, steps, chunk):
        stop = min(steps, start + chunk)
        st, sensors = _rollout.rollout(models, datas, state, jerk[None, start:stop, None])
        rows = sensors[:, ::substeps][:, :, index]
        out[:, start // substeps:start // substeps + rows.shape[1]] = rows
        state = st[:, -1]
    if not np.all(np.isfinite(out)):
        raise SimulationError("the twin's simulation diverged (non-finite accelerations): expected a smaller "
                              "timestep or physical parameters")
    return out


def friction_records(storeys, params) -> tuple:
    """``joint_friction`` records from per-storey ``params`` dicts."""
    return tuple(Mechanism("joint_friction", int(s), tuple(p.items())) for s, p in zip(storeys, params))
