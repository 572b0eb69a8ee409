"""The shake-table rig as a MuJoCo model, built through ``mujoco.MjSpec``.

Layout ("star"): a ``base`` body on a slide joint ``base_x`` carries every
floor as a direct child on its own slide joint ``q<i>``, so a floor joint's
position is its displacement *relative to the base*.  The storeys are fixed
tendons ``storey<i> = q_i - q_(i-1)`` (``q_0 = 0``) with stiffness ``k_i`` and
damping ``kappa k_i``: they carry ``K`` and ``kappa K`` exactly.  The floor
joints' own damping ``mu (m_i + dm_i)`` carries ``mu (M + dM)``.  An added
mass is a body welded to its floor (``added<i>``).

The table drive runs inside MuJoCo, with no Python in the loop: the actuator
``table`` is an integrator whose activation is the commanded table
acceleration (its control is the jerk, held over a step, so the command is
piecewise linear in time and exact at every RK4 stage), and its gear is the
base's inertia.  The base joint carries an armature of
``TABLE_INERTIA_RATIO`` times the rig's mass, so the structure's reaction
moves the table acceleration off its command by about ``1 /
TABLE_INERTIA_RATIO`` (a stiff servo table).

``models/shear_building/`` holds the paper's rig written out by
:func:`build_spec`; the README there gives the derivation.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
import contextlib
from dataclasses import replace

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from momentid import mechanisms as registry
from momentid.errors import ModelError
from momentid.core.structure import Mechanism, Structure
from momentid.mechanisms.base import drifts, storey_to_floor
from momentid.mechanisms.coulomb_friction import FRICTION_SMOOTHING
from momentid.mechanisms.place import Place, Target
from momentid.lab.native_forces import add_program, state_actuator
from momentid.lab.rig_model import RigModel
from momentid.lab.tendons import put_tendon

__all__ = ["build_spec", "compile_model", "sensor_layout", "callback_forces", "storey_to_floor", "drifts",
           "FRICTION_SMOOTHING", "TABLE_INERTIA_RATIO", "needs_callback", "CALLBACK_MECHANISMS", "stateful",
           "state_actuator", "mujoco_warnings_counted_not_printed", "add_elements", "empty_spec", "RigModel",
           "SENSOR_GROUPS"]

_PLATEN = (0.6, 0.4, 0.025)      # base half-sizes (m), drawing only
_SLAB = (0.25, 0.2, 0.01)        # floor slab half-sizes (m), drawing only
_MAX_STOREYS = 200


def _inertia(mass: float, half: tuple[float, float, float]) -> list[float]:
    """Box inertia; only needed to make the body valid (slide joints only)."""
    x, y, z = (2 * h for h in half)
    return [mass / 12 * (y * y + z * z), mass / 12 * (x * x + z * z), mass / 12 * (x * x + y * y)]


#: Base armature / rig mass: the structure's reaction changes the table's
#: acceleration by about its inverse (1e-10 relative, below RK4's error).
TABLE_INERTIA_RATIO = 1e10

#: Forces the MJCF cannot express, which the simulator applies in a control callback: the kinds
#: registered when this module was imported that declare ``callback`` (for messages; code asks
#: the registry, :func:`needs_callback`, so that a kind added later counts too).
CALLBACK_MECHANISMS = tuple(kind.name for kind in registry.REGISTRY.values() if kind.callback)


def needs_callback(mechanisms: Iterable[Mechanism]) -> bool:
    """True when ``mechanisms`` include forces the MJCF cannot express."""
    return any(registry.get(m.type).callback for m in mechanisms)


#: Length of an actuator's ``gainprm`` (all zero on a state actuator: it exerts no force).
_GAIN_PARAMETERS = 10


def stateful(mechanisms: Iterable[Mechanism]) -> tuple[Mechanism, ...]:
    """The ``mechanisms`` whose force has an internal state (in order): each gets a state actuator."""
    return tuple(m for m in mechanisms if registry.get(m.type).has_state(dict(m.parameters)))


#: The rig's sensors by group, in the order they are added: the table's acceleration, displacement and
#: velocity, then every floor's absolute acceleration, displacement and velocity relative to the table.
SENSOR_GROUPS = ("zdd", "z", "zd", "a", "q", "v")


def build_spec(rig: RigModel | Structure, added_mass: ArrayLike | None = None, *, timestep: float = 1e-3,
               name: str = "shear_building", mechanisms: Sequence[Mechanism] = (),
               integrator: mujoco.mjtIntegrator = mujoco.mjtIntegrator.mjINT_RK4,
               sensors: tuple[str, ...] = SENSOR_GROUPS) -> mujoco.MjSpec:
    """Build the MJCF specification of a rig for one run: the one builder of every rig momentid simulates.

    Parameters
    ----------
    rig : RigModel or Structure
        The rig (:class:`~momentid.lab.rig_model.RigModel`: masses, tendons, joint damping, added masses,
        mechanisms), or a shear building, whose rig is ``RigModel.shear(rig, added_mass, mechanisms)``.
    added_mass : array_like, shape (d,), optional
        With a Structure: masses bolted to floors 1..d in this run (kg); zeros by default.
    timestep : float
        Integrator step (s).
    name : str
        The MJCF model name.
    mechanisms : sequence of Mechanism
        With a Structure: physics beyond the linear model (a scenario's ``[truth]``), each of a kind
        registered in :mod:`momentid.mechanisms`.  A kind changes the MJCF through its hooks
        (``storey_tendon``: the storey tendon's stiffness and damping, e.g. ``extra_damper``,
        ``p_delta``; ``added_mass_body``: the added mass's body, e.g. ``flexible_added_mass``;
        ``elements``: bodies, joints and tendons of its own at its place, e.g. ``joint_friction``,
        ``tuned_mass_damper``); the
        ``callback`` kinds' forces across their place (a storey, a floor against the table, two
        floors) are applied by the simulator in a control callback (:func:`callback_forces`,
        :func:`needs_callback`); a force with memory (``has_state``) keeps its state in the activation
        of a force-free actuator (:func:`state_actuator`).
    integrator : mujoco.mjtIntegrator
        RK4 (the lab, the twin) or implicitfast (the re-simulation of a fitted rig, :mod:`momentid.lab.resim`).
    sensors : tuple of str
        The sensor groups of :data:`SENSOR_GROUPS` to add, in that order.

    Returns
    -------
    mujoco.MjSpec
        Compile it with :func:`compile_model` (or ``spec.compile()``).

    Raises
    ------
    ModelError
        A number of storeys outside 1..200, a non-positive timestep, invalid added masses or mechanism
        records, or added masses and mechanisms given beside a RigModel (which holds its own).
    """
    if isinstance(rig, RigModel):
        if added_mass is not None or mechanisms:
            raise ModelError("build_spec: a RigModel holds its added masses and mechanisms: expected neither "
                             "beside it")
        model = rig
    else:
        model = RigModel.shear(rig, added_mass, mechanisms)
    d = model.storeys
    if not 1 <= d <= _MAX_STOREYS:
        raise ModelError(f"structure has {d} storeys: expected 1..{_MAX_STOREYS}")
    if not timestep > 0:
        raise ModelError(f"timestep = {timestep!r}: expected a positive number of seconds")
    for mech in model.mechanisms:
        registry.validate(mech, d)
    spec = empty_spec(name, timestep, integrator)
    add_program(spec, model.mechanisms)   # the callback forces' program for the native callbacks
    base, table = _base(spec, model)
    floors = _floors(spec, model, base)
    _tendons(spec, model)
    add_elements(spec, model.mechanisms, [base] + floors, timestep)
    _actuators(spec, model, table.armature + model.base_mass)
    _sensors(spec, d, sensors)
    return spec


def _base(spec: mujoco.MjSpec, model: RigModel):
    """The table's platen on its slide joint ``base_x``, with the armature of a stiff servo table."""
    base = spec.worldbody.add_body(name="base", pos=[0, 0, _PLATEN[2]])
    base.mass = model.base_mass
    base.inertia = _inertia(model.base_mass, _PLATEN)
    table = base.add_joint(name="base_x", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
    rig_mass = model.base_mass + float(np.sum(model.masses)) + float(np.sum(model.added_mass))
    table.armature = TABLE_INERTIA_RATIO * rig_mass
    base.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=list(_PLATEN), rgba=[0.35, 0.35, 0.4, 1],
                  contype=0, conaffinity=0)
    base.add_site(name="base_imu", pos=[0, 0, 0])
    return base, table


def _floors(spec: mujoco.MjSpec, model: RigModel, base) -> list:
    """Every floor a child of the table on its own slide joint ``q<i>``, an added mass welded to it
    (``added<i>``, changed by the ``added_mass_body`` hook of a mechanism at that floor)."""
    height = _PLATEN[2]
    floors = []
    dm = model.added_mass
    for i in range(model.storeys):
        height += model.storey_heights[i]
        m_i = float(model.masses[i])
        floor = base.add_body(name=f"floor{i + 1}", pos=[0, 0, height - _PLATEN[2]])
        floor.mass = m_i
        floor.inertia = _inertia(m_i, _SLAB)
        joint = floor.add_joint(name=f"q{i + 1}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
        joint.damping = [float(model.joint_damping[i]), 0.0, 0.0]
        floor.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=list(_SLAB),
                       rgba=[0.8, 0.6, 0.3, 1], contype=0, conaffinity=0)
        floor.add_site(name=f"floor{i + 1}_imu", pos=[0, 0, 0])
        floors.append(floor)
        if dm[i] > 0:
            extra = floor.add_body(name=f"added{i + 1}", pos=[0, 0, _SLAB[2] + 0.02])
            extra.mass = dm[i]
            extra.inertia = _inertia(dm[i], (0.05, 0.05, 0.02))
            for mech in model.mechanisms:
                kind = registry.get(mech.type)
                if kind.place(mech.location) == Place(Target.FLOOR, i + 1):
                    kind.added_mass_body(mech, extra, dm[i])
            extra.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.05, 0.05, 0.02],
                           rgba=[0.2, 0.4, 0.8, 1], contype=0, conaffinity=0)
    return floors


def _tendons(spec: mujoco.MjSpec, model: RigModel) -> None:
    """The rig's tendons, each storey's changed by the ``storey_tendon`` hooks of its mechanisms."""
    d, dm = model.storeys, model.added_mass
    for t in model.tendons:
        k, c = t.stiffness, t.damping
        if t.upper == t.lower + 1:
            i = t.lower
            for mech in model.mechanisms:
                kind = registry.get(mech.type)
                if kind.place(mech.location) == Place(Target.STOREY, i + 1):
                    above = sum(model.masses[j] + dm[j] for j in range(i, d))
                    k, c = kind.storey_tendon(mech, k, c, above, model.storey_heights[i])
        put_tendon(spec, replace(t, stiffness=k, damping=c))


def _actuators(spec: mujoco.MjSpec, model: RigModel, gear: float) -> None:
    """The table drive (``table``: act = commanded table acceleration, m/s^2; ctrl = its rate, m/s^3;
    force = inertia x act) and one force-free actuator per force with memory, whose activation holds
    its state (its rate is the simulator's act_dyn callback's; RK4 integrates it with the motion)."""
    spec.add_actuator(name="table", target="base_x", trntype=mujoco.mjtTrn.mjTRN_JOINT,
                      dyntype=mujoco.mjtDyn.mjDYN_INTEGRATOR, gear=[gear, 0, 0, 0, 0, 0],
                      ctrllimited=mujoco.mjtLimited.mjLIMITED_FALSE,
                      actlimited=mujoco.mjtLimited.mjLIMITED_FALSE)
    for k, mech in enumerate(stateful(model.mechanisms)):
        floor = registry.get(mech.type).place(mech.location).level
        spec.add_actuator(name=state_actuator(k), target=f"q{floor}", trntype=mujoco.mjtTrn.mjTRN_JOINT,
                          dyntype=mujoco.mjtDyn.mjDYN_USER, gainprm=[0.0] * _GAIN_PARAMETERS,
                          ctrllimited=mujoco.mjtLimited.mjLIMITED_FALSE,
                          actlimited=mujoco.mjtLimited.mjLIMITED_FALSE)


def _sensors(spec: mujoco.MjSpec, d: int, groups: tuple[str, ...]) -> None:
    """The sensor ``groups`` (of :data:`SENSOR_GROUPS`, in its order): ``zdd``, ``z``, ``zd`` on the table,
    ``a<i>``, ``q<i>``, ``v<i>`` on every floor."""
    unknown = set(groups) - set(SENSOR_GROUPS)
    if unknown:
        raise ModelError(f"sensor groups {sorted(unknown)}: expected some of {', '.join(SENSOR_GROUPS)}")
    site, joint = mujoco.mjtObj.mjOBJ_SITE, mujoco.mjtObj.mjOBJ_JOINT
    acc, pos, vel = (mujoco.mjtSensor.mjSENS_ACCELEROMETER, mujoco.mjtSensor.mjSENS_JOINTPOS,
                     mujoco.mjtSensor.mjSENS_JOINTVEL)
    table = {"zdd": (acc, "base_imu", site), "z": (pos, "base_x", joint), "zd": (vel, "base_x", joint)}
    floor = {"a": (acc, "floor{}_imu", site), "q": (pos, "q{}", joint), "v": (vel, "q{}", joint)}
    for group in SENSOR_GROUPS:
        if group not in groups:
            continue
        if group in table:
            kind, target, objtype = table[group]
            spec.add_sensor(name=group, type=kind, objname=target, objtype=objtype)
            continue
        kind, target, objtype = floor[group]
        for i in range(d):
            spec.add_sensor(name=f"{group}{i + 1}", type=kind, objname=target.format(i + 1), objtype=objtype)


def empty_spec(name: str, timestep: float, integrator: mujoco.mjtIntegrator) -> mujoco.MjSpec:
    """A spec with no bodies yet: stated inertias, ``timestep`` (s), ``integrator``, no contacts."""
    spec = mujoco.MjSpec()
    spec.modelname = name
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.timestep = timestep
    spec.option.integrator = integrator
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return spec


def add_elements(spec: mujoco.MjSpec, mechanisms: Iterable[Mechanism], bodies: Sequence[mujoco.MjsBody],
                 timestep: float) -> None:
    """Add the MJCF elements the ``mjcf_elements`` kinds among ``mechanisms`` build at their places
    (:meth:`~momentid.mechanisms.base.MechanismKind.elements`: ``joint_friction``'s sliders across a
    storey, ``tuned_mass_damper``'s body hung on a floor) to ``spec``.

    ``bodies`` are the base and the floors, in order (``bodies[i]`` is below storey ``i + 1``); the floor
    joints are ``q<i>``.  The mass a kind's elements take off a floor (it says which) is taken off that
    floor's own, so that the floor masses stay as stated.
    """
    for mech in mechanisms:
        kind = registry.get(mech.type)
        if not kind.mjcf_elements:
            continue
        place = kind.place(mech.location)
        for level, taken in kind.elements(spec, mech, place, bodies, timestep).items():
            if level == 0:
                continue
            body = bodies[level]
            if not body.mass > taken:
                raise ModelError(f"{mech.type} at {place.words}: its elements weigh {taken:.3g} kg, more than "
                                 f"floor {level} ({body.mass:.3g} kg): expected a smaller timestep")
            body.mass = body.mass - taken


def callback_forces(mechanisms: Iterable[Mechanism], q: np.ndarray, v: np.ndarray, time: float = 0.0,
                    structure: Structure | None = None) -> np.ndarray:
    """Floor forces (N) the MJCF cannot express: those of the ``callback`` kinds
    (:data:`CALLBACK_MECHANISMS`) without memory, each by its registered law across its place.

    Parameters
    ----------
    q, v : ndarray, shape (n, d)
        Floor displacements (m) and velocities (m/s) relative to the table.
    time : float
        Time since the run started (s), for time-dependent laws (``stiffness_loss``).
    structure : Structure, optional
        The storey stiffnesses a ``needs_stiffness`` kind takes its fraction of.

    Returns
    -------
    ndarray, shape (n, d)
        The generalised force on each floor.
    """
    q, v = np.atleast_2d(q), np.atleast_2d(v)
    f = np.zeros(np.broadcast(q, v).shape)
    for mech in mechanisms:
        kind = registry.get(mech.type)
        if not kind.callback:
            continue
        place = kind.place(mech.location)
        if kind.has_state(dict(mech.parameters)):
            raise ModelError(f"{mech.type} at {place.words} has memory: its force depends on the history of "
                             f"the motion, expected a simulation (momentid.lab.simulation)")
        if kind.needs_stiffness and structure is None:
            raise ModelError(f"{mech.type} needs the structure's storey stiffnesses")
        stiffness = structure.storey_stiffness[place.level - 1] if kind.needs_stiffness else None
        law = kind.storey_force if place.target is Target.STOREY else kind.floor_force
        f += place.columns(law(dict(mech.parameters), place.stretch(q), place.stretch(v), time, stiffness),
                           q.shape[1])
    return f


def compile_model(spec: mujoco.MjSpec) -> mujoco.MjModel:
    """Compile ``spec``; compiler errors become :class:`ModelError`.

    Parameters
    ----------
    spec : mujoco.MjSpec
        A rig built by :func:`build_spec` (or edited from one).

    Returns
    -------
    mujoco.MjModel

    Raises
    ------
    ModelError
        MuJoCo's compiler refused the spec; its message is kept.
    """
    try:
        return spec.compile()
    except Exception as exc:  # mujoco raises ValueError with the compiler's text
        text = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())   # one line
        raise ModelError(f"MuJoCo could not compile model '{spec.modelname}': {text}") from None


def sensor_layout(model: mujoco.MjModel) -> dict[str, int]:
    """Map channel name -> index into ``sensordata`` (x axis of accelerometers)."""
    out = {}
    for s in range(model.nsensor):
        out[model.sensor(s).name] = int(model.sensor_adr[s])
    return out


@contextlib.contextmanager
def mujoco_warnings_counted_not_printed() -> Iterator[None]:
    """MuJoCo prints each warning (``Nan, Inf or huge value in QPOS ...``) and appends it to
    ``MUJOCO_LOG.TXT`` in the working folder.  momentid reads the warning counters of ``MjData``
    instead and refuses the run in one line (or, replaying a trial model that goes unstable, takes
    that as an answer), so the text is dropped meanwhile (a process-wide MuJoCo setting: forked
    workers inherit it; the command line sets it for the whole command)."""
    old = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda message: None)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(old)
