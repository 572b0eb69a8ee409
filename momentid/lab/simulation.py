"""Simulate the added-mass runs of a scenario on the MuJoCo rig.

The table drive runs inside MuJoCo (see :mod:`momentid.lab.rig`): the table
actuator integrates the commanded jerk, so its activation, the commanded table
acceleration, is linear between steps and RK4 evaluates it exactly at every
stage.  A run is then an open-loop ``mujoco.rollout`` of a freshly compiled
model (``mujoco.MjSpec``) whose control sequence is the jerk
``(z''(t_(k+1)) - z''(t_k)) / h``: no Python runs inside the step, and the
table's acceleration equals the prescribed ``z''(t_k)`` at every step (to
``1 / TABLE_INERTIA_RATIO``) and is linear in between.  Only the nonlinear
storey forces of hidden physics (friction, cubic stiffness) need a Python
control callback.  Runs are rolled out in chunks, so memory stays bounded and
progress is reported as they go.
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from collections.abc import Callable, Iterator, Sequence
import os

import mujoco
import numpy as np
from mujoco import rollout as _rollout

from momentid import mechanisms as mechanisms_registry
from momentid.lab import native_forces, rig
from momentid.io.plausible import implausible
from momentid.core import counters
from momentid.core.series import Experiment, RunData
from momentid.core.structure import Mechanism, Structure
from momentid.errors import SimulationError
from momentid.lab.excitation import GroundMotion, ground_motion
from momentid.lab.scenario import BandLimitedNoise, Run, Scenario, Sensors, public_text
from momentid.lab.sensors import measure

__all__ = ["simulate_run", "simulate", "run_experiment", "ground_motion_of", "replay", "CallbackForces",
           "initial_state", "table_jerk"]

_CHUNK_STEPS = 50_000   # steps per rollout call: bounded memory, progress between calls


@contextlib.contextmanager
def _control_callback(callback, act_dyn=None) -> Iterator[None]:
    """Install global MuJoCo control (and, if given, actuator dynamics) callbacks; restore the old ones."""
    previous, previous_dyn = mujoco.get_mjcb_control(), mujoco.get_mjcb_act_dyn()
    mujoco.set_mjcb_control(callback)
    if act_dyn is not None:
        mujoco.set_mjcb_act_dyn(act_dyn)
    try:
        yield
    finally:
        mujoco.set_mjcb_control(previous)
        if act_dyn is not None:
            mujoco.set_mjcb_act_dyn(previous_dyn)


def ground_motion_of(scenario: Scenario) -> GroundMotion:
    """The table motion of ``scenario`` (shared by all its runs)."""
    return ground_motion(scenario.excitation, scenario.duration)


class CallbackForces:
    """Control callback applying the forces of ``mechanisms`` that the MJCF cannot express
    (:func:`momentid.lab.rig.callback_forces`) to the floor joints at every RK4 stage, and act_dyn
    callback returning the rates of their internal states (:meth:`state_rate`).

    Called about 4 times a step, most of a replay's time, so it works on Python floats: each
    mechanism's place (a storey, a floor against the table, two floors) is read from its upper floor's
    joint and its lower one's (none for the table) and pushes on both, with its kind's law on floats
    (:meth:`~momentid.mechanisms.base.MechanismKind.link_law`: the registered
    :meth:`~momentid.mechanisms.base.MechanismKind.storey_force` for a storey,
    :meth:`~momentid.mechanisms.base.MechanismKind.floor_force` for another link; the same that
    :func:`~momentid.lab.rig.callback_forces` applies to arrays).  The floors' forces are summed in a
    list and written to the floors they push.  A force with memory reads its state from its
    actuator's activation (:func:`momentid.lab.rig.state_actuator`), the trial value of the RK4 stage.

    Parameters
    ----------
    model : mujoco.MjModel
        The rig built with ``mechanisms`` (:func:`momentid.lab.rig.build_spec`).
    mechanisms : sequence of Mechanism
        The rig's mechanisms (those that are not ``callback`` kinds are left to the MJCF).
    structure : Structure, optional
        The storey stiffnesses a ``needs_stiffness`` kind takes its fraction of.
    """

    def __init__(self, model: mujoco.MjModel, mechanisms, structure=None):
        self.mechanisms = tuple(m for m in mechanisms if mechanisms_registry.get(m.type).callback)
        d = sum(1 for j in range(model.njnt) if model.joint(j).name.startswith("q"))
        # The floor joints' dofs: one after another, unless a body on a floor below the top has a joint of
        # its own (an attachment's), whose dof then sits between its floor's and the next floor's.
        dofs = [int(model.jnt_dofadr[model.joint(f"q{i + 1}").id]) for i in range(d)]
        self._floors = np.array(dofs)
        self.terms = []   # (law on floats, upper dof, lower dof or -1, activation address or -1)
        self.rates: dict[int, tuple] = {}   # state actuator id -> (rate law, top, below, params, act address)
        for m in self.mechanisms:
            kind = mechanisms_registry.get(m.type)
            place = kind.place(m.location)
            lower, upper = place.nodes
            top, below = dofs[upper - 1], (dofs[lower - 1] if lower > 0 else -1)   # -1: against the table
            k = structure.storey_stiffness[upper - 1] if structure is not None and kind.needs_stiffness else None
            if kind.needs_stiffness and k is None:
                raise SimulationError(f"{m.type} needs the structure's storey stiffnesses")
            p, adr = dict(m.parameters), -1
            if kind.has_state(p):
                act = model.actuator(rig.state_actuator(len(self.rates)))
                adr = int(model.actuator_actadr[act.id])
                self.rates[act.id] = (kind.state_rate, top, below, p, adr)
            self.terms.append((kind.link_law(p, place, k), top, below, adr))
        self._pushed = sorted({i for _, top, below, _ in self.terms for i in (top, below) if i >= 0})
        self._n_dofs = model.nv
        self._bound = None   # (data, its qpos, qvel, qfrc_applied, act): the arrays of the last data seen

    def _bind(self, data) -> tuple:
        """(data, its qpos, qvel, qfrc_applied, act): the arrays of ``data``, made once per data (a
        rollout calls with one data throughout)."""
        bound = self._bound
        if bound is None or bound[0] is not data:
            bound = self._bound = (data, data.qpos, data.qvel, data.qfrc_applied, data.act)
            data.qfrc_applied[self._floors] = 0.0   # floors no force pushes stay at 0
        return bound

    def __call__(self, model, data) -> None:
        _, qpos, qvel, out, act = self._bind(data)
        q, v, t = qpos.tolist(), qvel.tolist(), data.time
        forces = [0.0] * self._n_dofs       # by dof
        for law, top, below, adr in self.terms:
            if below >= 0:
                x, xd = q[top] - q[below], v[top] - v[below]
            else:
                x, xd = q[top], v[top]
            f = law(x, xd, t) if adr < 0 else law(x, xd, t, state=float(act[adr]))
            forces[top] -= f                # the link resists its stretch on its upper floor ...
            if below >= 0:                  # ... and on its lower one
                forces[below] += f
        for i in self._pushed:
            out[i] = forces[i]

    def state_rate(self, model: mujoco.MjModel, data: mujoco.MjData, actuator: int) -> float:
        """``mjcb_act_dyn``: the rate of a state actuator's activation (a force's internal state)."""
        rate, top, below, p, adr = self.rates[actuator]
        _, qpos, qvel, _, act = self._bind(data)
        x = qpos[top] - (qpos[below] if below >= 0 else 0.0)
        v = qvel[top] - (qvel[below] if below >= 0 else 0.0)
        return float(rate(p, float(act[adr]), float(x), float(v)))


def initial_state(model: mujoco.MjModel, z: float, zd: float, zdd: float) -> np.ndarray:
    """Full physics state (``mjSTATE_FULLPHYSICS``, shape (nstate,)) at t = 0 of a rig built by
    :func:`momentid.lab.rig.build_spec`: floors at rest on the table, the table at displacement ``z``
    (m), velocity ``zd`` (m/s) and commanded acceleration ``zdd`` (m/s^2)."""
    data = mujoco.MjData(model)
    data.qpos[0], data.qvel[0], data.act[0] = z, zd, zdd
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty(mujoco.mj_stateSize(model, full))
    mujoco.mj_getState(model, data, state, full)
    return state


def table_jerk(nodes: np.ndarray, h: float) -> np.ndarray:
    """The table actuator's control sequence (n_steps,) (m/s^3): the rate of the acceleration command
    ``nodes`` (n_steps + 1,) (m/s^2, at every step's start and the last one's end) over each step of
    ``h`` seconds."""
    return np.ascontiguousarray(np.diff(nodes) / h)


def _roll(model: mujoco.MjModel, state: np.ndarray, jerk: np.ndarray, every: int, index: np.ndarray,
          *, mechanisms=(), structure=None, progress: Callable[[int], None] | None = None
          ) -> tuple[np.ndarray, list[tuple[str, int]]]:
    """Roll ``model`` out from ``state`` under the table jerk sequence.

    Parameters
    ----------
    state : ndarray, shape (nstate,)
        ``mjSTATE_FULLPHYSICS`` state at the start.
    jerk : ndarray, shape (n_steps,)
        Control of each step (m/s^3).
    every : int
        Keep the sensors of every ``every``-th step (the substeps per sample).
    index : ndarray of int
        Columns of ``sensordata`` to keep.

    Returns
    -------
    out : ndarray, shape (n_steps // every, len(index))
        Sensor values of the state at the start of each kept step.
    warnings : list of (name, count)
        MuJoCo warnings raised during the rollout.
    """
    n_steps = len(jerk)
    out = np.empty((n_steps // every, len(index)))
    data = mujoco.MjData(model)
    chunk = every * max(1, _CHUNK_STEPS // every)
    callback = act_dyn = None
    if rig.needs_callback(mechanisms):
        native = native_forces.load_program(model, mechanisms,
                                            structure.storey_stiffness if structure is not None else None)
        callback = None if native else CallbackForces(model, mechanisms, structure)
        act_dyn = callback.state_rate if callback is not None and callback.rates else None
    # the table's jerk drives actuator 0; state actuators (forces with memory) take no control
    control = jerk[:, None] if model.nu == 1 else np.column_stack([jerk] + [np.zeros(n_steps)] * (model.nu - 1))
    warnings: dict[str, int] = {}
    if not rig.needs_callback(mechanisms):
        callbacks = native_forces.plain()
    elif callback is None:
        callbacks = native_forces.installed()
    else:
        callbacks = _control_callback(callback, act_dyn)
    with callbacks:
        for start in range(0, n_steps, chunk):
            stop = min(n_steps, start + chunk)
            states, sensors = _rollout.rollout(model, data, state[None], control[None, start:stop])
            out[start // every:stop // every] = sensors[0, ::every][:, index]
            state = states[0, -1]
            for i, w in enumerate(data.warning):
                if w.number > 0:
                    name = mujoco.mjtWarning(i).name
                    warnings[name] = warnings.get(name, 0) + int(w.number)
            if progress is not None:
                progress((stop - start) // every)
    return out, sorted(warnings.items())


def simulate_run(scenario: Scenario, run: Run, motion: GroundMotion | None = None,
                 *, progress: Callable[[int], None] | None = None) -> RunData:
    """Simulate one run and return its sensor channels.

    Parameters
    ----------
    scenario : Scenario
    run : Run
        The added masses of this run.
    motion : GroundMotion, optional
        Precomputed table motion (computed from the scenario when omitted).
    progress : callable, optional
        Called with the number of samples done since the last call.

    Returns
    -------
    RunData
        The channels of ``scenario.sensors`` as its instruments record them
        (:func:`momentid.lab.sensors.measure`); with ideal sensors, exactly
        ``n = scenario.n_samples`` samples at ``t = k / sample_rate``.
        ``meta['model_xml']`` holds the MJCF.
    """
    motion = motion if motion is not None else ground_motion_of(scenario)
    if scenario.tracking is not None:
        motion = _with_tracking_error(scenario, run, motion)
    spec = rig.build_spec(scenario.structure, run.added_mass, timestep=scenario.timestep,
                          name=f"{scenario.name}_{run.name}", mechanisms=scenario.truth)
    model = rig.compile_model(spec)
    n, sub, h = scenario.n_samples, scenario.substeps, scenario.timestep
    nodes = np.asarray(motion.acceleration(np.arange(n * sub + 1) * h), float)
    state = initial_state(model, float(motion.displacement(0.0)), float(motion.velocity(0.0)), nodes[0])

    channels = Sensors().channels(scenario.structure.storeys)   # every channel, exact; the sensor model degrades
    layout = rig.sensor_layout(model)
    index = np.array([layout[c] for c in channels])
    out, warnings = _roll(model, state, table_jerk(nodes, h), sub, index, mechanisms=scenario.truth,
                          structure=scenario.structure, progress=progress)
    _check_run(warnings, out, scenario, run)
    if scenario.truth:   # the recording must not reveal the hidden physics: attach the nominal rig
        spec = rig.build_spec(scenario.structure, run.added_mass, timestep=scenario.timestep,
                              name=f"{scenario.name}_{run.name}")
    spec.compiler.saveinertial = True
    true = RunData(
        name=run.name,
        added_mass=np.asarray(run.added_mass, float),
        time=np.arange(n) / scenario.sample_rate,
        channels=channels,
        values=out,
        meta={"model_xml": spec.to_xml()},
    )
    return measure(true, scenario.sensors, seed=scenario.seed, run_index=_run_index(scenario, run))


class _SumMotion:
    """The sum of table motions (nominal + this run's tracking error)."""

    def __init__(self, *parts):
        self.parts = parts

    def displacement(self, t):
        return sum(p.displacement(t) for p in self.parts)

    def velocity(self, t):
        return sum(p.velocity(t) for p in self.parts)

    def acceleration(self, t):
        return sum(p.acceleration(t) for p in self.parts)


def _with_tracking_error(scenario: Scenario, run: Run, motion: GroundMotion) -> _SumMotion:
    """Nominal motion plus a seeded servo error of its own for this run."""
    t = np.arange(scenario.n_samples) / scenario.sample_rate
    rms = float(np.sqrt(np.mean(motion.acceleration(t) ** 2)))
    seed = int(np.random.SeedSequence([scenario.seed, _run_index(scenario, run), 7919]).generate_state(1)[0])
    error = ground_motion(BandLimitedNoise(rms=scenario.tracking.error * rms, band=scenario.tracking.band,
                                           seed=seed, taper=min(1.0, scenario.duration / 4)),
                          scenario.duration)
    return _SumMotion(motion, error)


def _run_index(scenario: Scenario, run: Run) -> int:
    for i, r in enumerate(scenario.runs):
        if r.name == run.name:
            return i
    return len(scenario.runs)


def _check_run(warnings, out, scenario: Scenario, run: Run) -> None:
    if warnings:
        raise SimulationError(
            f"{scenario.source}: run {run.name!r}: MuJoCo warnings {warnings}: expected none "
            f"(check masses, stiffnesses, the excitation's amplitude and frequencies, and the sample rate)"
        )
    if not np.all(np.isfinite(out)):
        bad = int(np.argmax(~np.all(np.isfinite(out), axis=1)))
        raise SimulationError(
            f"{scenario.source}: run {run.name!r}: the simulation diverged at t = "
            f"{bad / scenario.sample_rate:.4g} s: expected finite responses (raise sample_rate "
            f"or simulation.substeps)"
        )


def _stability_check(scenario: Scenario) -> None:
    """Refuse steps that RK4 cannot integrate stably for this structure."""
    from momentid.core.analytic import modal_properties
    s = scenario.structure
    wrong = implausible(s)   # a Scenario built in code, past the reader's ranges: its matrices would overflow
    if wrong is not None:
        raise SimulationError(f"{scenario.source}: structure.{wrong} (momentid.io.plausible)")
    f_max = float(modal_properties(s.mass_matrix(), s.damping_matrix(), s.stiffness_matrix()).frequency.max())
    w_h = 2 * math.pi * f_max * scenario.timestep
    if w_h > 1.0:   # RK4 is stable to w h ~ 2.8; past 1 it is not accurate either
        raise SimulationError(
            f"{scenario.source}: highest natural frequency {f_max:.4g} Hz needs a step below "
            f"{1.0 / (2 * math.pi * f_max):.3g} s, got {scenario.timestep:.3g} s: raise "
            f"'scenario.sample_rate' or 'simulation.substeps'"
        )


def _progress_bar(total: int, enabled: bool, desc: str):
    from tqdm import tqdm
    return tqdm(total=total, unit="sample", unit_scale=True, desc=desc, disable=not enabled,
                leave=False, dynamic_ncols=True)


def available_cores() -> int:
    """CPU cores this process may run on."""
    import os
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _worker_count(workers: int | None, n_runs: int) -> int:
    import multiprocessing
    if workers is None:
        workers = available_cores()
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise SimulationError(f"workers = {workers!r}: expected an int >= 1 (or None for one per core)")
    if "fork" not in multiprocessing.get_all_start_methods():
        return 1  # pragma: no cover - Windows: no fork, simulate in this process
    return min(workers, n_runs)


_FORKED_JOB: tuple | None = None   # (scenario, motion) in a simulation worker process


def _set_forked_job(scenario: Scenario, motion: GroundMotion) -> None:
    global _FORKED_JOB
    _FORKED_JOB = (scenario, motion)


def _simulate_forked(index: int) -> RunData:
    scenario, motion = _FORKED_JOB
    return simulate_run(scenario, scenario.runs[index], motion)


def _parallel_runs(scenario: Scenario, motion: GroundMotion, workers: int,
                   progress: Callable[[int], None]) -> Iterator[RunData]:
    """Simulate the runs ``workers`` at a time; yield them in run order.

    A linear rig, or one whose callback forces run as native code
    (:func:`momentid.lab.native_forces.applies`), has no Python inside the
    step and ``mujoco.rollout`` releases the GIL, so the runs go to threads.
    A rig with Python callback physics is GIL-bound; its runs go to forked
    processes that inherit the scenario and motion (not pickled).  Either way each run is exactly
    :func:`simulate_run`, so the numbers equal the serial path's bit for bit.
    """
    from concurrent.futures import ThreadPoolExecutor

    from momentid.core.processes import forked_pool

    forked = rig.needs_callback(scenario.truth) and not native_forces.applies(scenario.truth)
    with contextlib.ExitStack() as stack:
        if forked:   # workers that die with this process, killed when it is interrupted
            pool = stack.enter_context(forked_pool(workers, _set_forked_job, (scenario, motion)))
            futures = [pool.submit(_simulate_forked, i) for i in range(len(scenario.runs))]
        else:   # threads report their progress as they go
            pool = ThreadPoolExecutor(max_workers=workers)
            stack.callback(pool.shutdown, wait=True, cancel_futures=True)
            futures = [pool.submit(simulate_run, scenario, run, motion, progress=progress)
                       for run in scenario.runs]
        for future in futures:
            result = future.result()
            if forked:
                progress(scenario.n_samples)
            yield result


#: Float arrays of a run's length held per channel at the peak of a simulation: the recorded
#: channels, the sensor model's working copies (noise, faults, resampling) and the kept run.
_ARRAYS_PER_CHANNEL = 4
#: Float arrays of the finer step grid held for the table motion (position, velocity,
#: acceleration and jerk nodes) and for the rollout's state and sensor chunks.
_ARRAYS_PER_STEP = 8


def _memory_check(scenario: Scenario) -> None:
    """Refuse, before any work, a scenario whose arrays cannot fit in memory."""
    from momentid.core.resources import require_memory

    n = float(scenario.duration) * scenario.sample_rate + 1
    channels = len(scenario.sensors.channels(scenario.structure.storeys))
    needed = 8.0 * n * (channels * _ARRAYS_PER_CHANNEL * len(scenario.runs)
                        + scenario.substeps * _ARRAYS_PER_STEP)
    require_memory(needed, f"{scenario.source}: simulation of scenario {scenario.name!r} "
                   f"({len(scenario.runs)} runs x {n:.3g} samples x {channels} channels)",
                   "lower 'scenario.sample_rate' or 'scenario.duration', or record fewer channels")


def simulate(scenario: Scenario, *, progress: bool = False,
             on_run: Callable[[RunData], None] | None = None,
             workers: int | None = 1) -> Experiment:
    """Simulate every run of ``scenario``.

    Parameters
    ----------
    scenario : Scenario
    progress : bool
        Show a progress bar on stderr.
    on_run : callable, optional
        Called with each completed run, in run order (e.g. to write it to a
        recording before the next one is collected).
    workers : int, optional
        Processes simulating runs at once: the runs are independent, so they
        are spread over forked worker processes (at most one per run).
        ``1`` (default) simulates in this process, ``None`` uses one process
        per available core (threads for a linear rig, forked processes when
        hidden physics needs a Python callback).  Results are identical to
        the serial path and come back in run order.
    """
    _memory_check(scenario)
    _stability_check(scenario)
    motion = ground_motion_of(scenario)
    n_workers = _worker_count(workers, len(scenario.runs))
    runs = []
    with _progress_bar(scenario.n_samples * len(scenario.runs), progress, scenario.name) as bar:
        if n_workers > 1:
            results = _parallel_runs(scenario, motion, n_workers, bar.update)
        else:
            results = (simulate_run(scenario, run, motion, progress=bar.update)
                       for run in scenario.runs)
        try:
            for run in scenario.runs:
                bar.set_postfix_str(run.name)
                result = next(results)
                if on_run is not None:
                    on_run(result)
                runs.append(result)
        finally:
            results.close()   # stops the workers when on_run fails or we are interrupted
    return Experiment(
        runs=tuple(runs),
        structure=scenario.structure,
        scenario=scenario.summary(),
        scenario_text=public_text(scenario.text),
        source="<simulation>",
    )


def run_experiment(scenario: Scenario, path: str | os.PathLike, *, progress: bool = False,
                   workers: int | None = 1) -> Experiment:
    """Simulate every run and record it to the MCAP file ``path``.

    Each run is written and flushed as soon as it completes (in run order),
    so a crash keeps every completed run readable.

    Parameters
    ----------
    scenario : Scenario
    path : str or Path
        The MCAP file to write (parent folders are created).
    progress : bool
        Show a progress bar on stderr.
    workers : int, optional
        As in :func:`simulate`.

    Returns
    -------
    Experiment
        The recorded runs, time-first ``(n_samples, n_channels)``, SI units.
    """
    from momentid.io.recording import RecordingWriter

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with RecordingWriter(path, structure=scenario.structure, scenario=scenario.summary(),
                         scenario_text=public_text(scenario.text)) as writer:
        experiment = simulate(
            scenario, progress=progress, workers=workers,
            on_run=lambda r: writer.write_run(r, model_xml=r.meta.get("model_xml")),
        )
    return Experiment(
        runs=experiment.runs, structure=experiment.structure, scenario=experiment.scenario,
        scenario_text=experiment.scenario_text, source=str(path),
    )


def _compiled_replay(model: mujoco.MjModel, nodes: np.ndarray, h: float, index: np.ndarray, mechanisms, structure
                     ) -> tuple[np.ndarray, list[tuple[str, int]]] | None:
    """:func:`_roll`'s readings of ``model`` from rest, and its warnings, by a compiled replay that steps it as
    MuJoCo does (:func:`momentid.lab.compiled_paths.compiled_path`: its callback forces' compiled laws under RK4,
    or a linear step), else None."""
    from momentid.lab.compiled_paths import compiled_path

    if rig.needs_callback(mechanisms) and not native_forces.load_program(
            model, mechanisms, structure.storey_stiffness if structure is not None else None):
        return None
    path = compiled_path([model])
    if path is None:
        return None
    x = np.zeros(2 * model.nv + model.na)
    x[2 * model.nv + int(model.actuator_actadr[0])] = nodes[0]
    out = np.empty((len(nodes) - 1, len(index)))
    resets = path(model, index, 1, x, table_jerk(nodes, h), out)
    return out, [("mjWARN_BADQACC", resets)] if resets else []


def replay(structure: Structure, mechanisms: Sequence[Mechanism], run: RunData, zdd: np.ndarray | None = None
           ) -> dict[str, np.ndarray]:
    """Replay a recorded run's table acceleration through a MuJoCo model.

    The table follows the samples of ``zdd``, linear between them (one step
    per sample).  Stepped in compiled code as MuJoCo steps it where a compiled
    path carries the model (:mod:`momentid.lab.compiled_paths`), else rolled out.

    Parameters
    ----------
    structure : Structure
        The model (e.g. identified) to replay.
    mechanisms : sequence of Mechanism
        Physics added to the linear model (see :func:`momentid.lab.rig.build_spec`).
    run : RunData
        Supplies the clock, the added masses and (unless ``zdd`` is given) the
        measured base acceleration ``zdd``.

    Returns
    -------
    dict
        ``'a'``, ``'q'``, ``'v'``: simulated floor channels, each (n, d); the
        floors start at rest relative to the table.

    Raises
    ------
    SimulationError
        On any MuJoCo warning or a diverging response.
    """
    zdd = np.asarray(run["zdd"] if zdd is None else zdd, float)
    h = 1.0 / run.sample_rate
    counters.add(counters.REPLAYS)
    spec = rig.build_spec(structure, run.added_mass, timestep=h, name="replay", mechanisms=mechanisms)
    model = rig.compile_model(spec)
    layout = rig.sensor_layout(model)
    d = structure.storeys
    names = [f"{g}{i + 1}" for g in ("a", "q", "v") for i in range(d)]
    index = np.array([layout[c] for c in names])
    nodes = np.append(zdd, zdd[-1])            # the table holds its last acceleration
    compiled = _compiled_replay(model, nodes, h, index, mechanisms, structure)
    if compiled is not None:
        out, warnings = compiled
    else:
        with rig.mujoco_warnings_counted_not_printed():   # a trial model may go unstable: an answer
            out, warnings = _roll(model, initial_state(model, 0.0, 0.0, nodes[0]), table_jerk(nodes, h), 1, index,
                                  mechanisms=mechanisms, structure=structure)
    if warnings or not np.all(np.isfinite(out)):
        raise SimulationError(
            f"replay of run {run.name!r}: MuJoCo warnings {warnings} or a diverging response: expected "
            f"a stable model (check the replayed parameters and mechanisms)"
        )
    return {g: out[:, i * d:(i + 1) * d] for i, g in enumerate(("a", "q", "v"))}
