"""Simulate the added-mass runs of a scenario on the MuJoCo rig.

The base follows the prescribed ground motion exactly: MuJoCo's RK4
integrator calls the control callback at every stage with ``d.time`` set to
the stage time, and the callback sets the table motor's force to the value
that makes the base acceleration equal ``z''(t)`` at that instant::

    qacc = M^-1 (qfrc_passive - qfrc_bias + e_0 f)   =>   f = (z'' - [M^-1 r]_0) / [M^-1]_00

(``M`` is constant: every joint is a slide along x).  ``z''`` is precomputed on
the half-step grid that RK4's stages visit, so the callback is a lookup and
one dot product.  Each run is a freshly compiled model (``mujoco.MjSpec``).
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import Callable, Iterator

import mujoco
import numpy as np

from . import model as rig
from .data import Experiment, RunData
from .errors import SimulationError
from .excitation import GroundMotion, ground_motion
from .scenario import BandLimitedNoise, Run, Scenario, Sensors, public_text
from .sensors import measure

__all__ = ["simulate_run", "simulate", "run_experiment", "ground_motion_of"]


@contextlib.contextmanager
def _control_callback(callback) -> Iterator[None]:
    """Install a global MuJoCo control callback and restore the old one."""
    previous = mujoco.get_mjcb_control()
    mujoco.set_mjcb_control(callback)
    try:
        yield
    finally:
        mujoco.set_mjcb_control(previous)


def ground_motion_of(scenario: Scenario) -> GroundMotion:
    """The table motion of ``scenario`` (shared by all its runs)."""
    return ground_motion(scenario.excitation, scenario.duration)


class _TableDrive:
    """Control callback that makes the base joint follow ``z''(t)`` exactly."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, motion: GroundMotion,
                 n_steps: int, mechanisms=()):
        h = model.opt.timestep
        self.nonlinear = tuple(m for m in mechanisms if m.type in ("coulomb_friction", "cubic_stiffness"))
        d = sum(1 for j in range(model.njnt) if model.joint(j).name.startswith("q"))
        self.floor_dofs = np.array([model.jnt_dofadr[model.joint(f"q{i + 1}").id] for i in range(d)])
        self.per_half_step = 2.0 / h
        stage_times = np.arange(2 * n_steps + 3) * (h / 2)
        self.zdd = np.ascontiguousarray(motion.acceleration(stage_times), dtype=float)
        full = np.zeros((model.nv, model.nv))
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, full)
        inv = np.linalg.inv(full)
        self.scale = 1.0 / inv[0, 0]
        self.row = inv[0] * self.scale

    def __call__(self, model, data) -> None:
        k = int(data.time * self.per_half_step + 0.5)
        if self.nonlinear:   # storey forces the MJCF cannot express, applied to the floor joints
            q = data.qpos[self.floor_dofs]
            v = data.qvel[self.floor_dofs]
            f = rig.storey_forces(self.nonlinear, rig.drifts(q), rig.drifts(v))
            data.qfrc_applied[self.floor_dofs] = rig.storey_to_floor(f)
        data.ctrl[0] = self.zdd[k] * self.scale - self.row @ (data.qfrc_passive - data.qfrc_bias
                                                              + data.qfrc_applied)


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
        (:func:`momentid.sensors.measure`); with ideal sensors, exactly
        ``n = scenario.n_samples`` samples at ``t = k / sample_rate``.
        ``meta['model_xml']`` holds the MJCF.
    """
    motion = motion if motion is not None else ground_motion_of(scenario)
    if scenario.tracking is not None:
        motion = _with_tracking_error(scenario, run, motion)
    spec = rig.build_spec(scenario.structure, run.added_mass, timestep=scenario.timestep,
                          name=f"{scenario.name}_{run.name}", mechanisms=scenario.truth)
    model = rig.compile_model(spec)
    data = mujoco.MjData(model)
    n, sub = scenario.n_samples, scenario.substeps
    drive = _TableDrive(model, data, motion, n * sub, scenario.truth)
    mujoco.mj_resetData(model, data)
    data.qpos[0] = float(motion.displacement(0.0))
    data.qvel[0] = float(motion.velocity(0.0))

    d = scenario.structure.storeys
    channels = Sensors().channels(d)     # every channel, exact; the sensor model picks and degrades
    layout = rig.sensor_layout(model)
    index = np.array([layout[c] for c in channels])
    out = np.empty((n, len(channels)))
    report_every = max(1, n // 50)
    with _control_callback(drive):
        for k in range(n):
            mujoco.mj_step(model, data)
            out[k] = data.sensordata[index]   # the state at t_k (start of the step)
            for _ in range(sub - 1):
                mujoco.mj_step(model, data)
            if progress is not None and (k + 1) % report_every == 0:
                progress(report_every)
    if progress is not None:
        progress(n % report_every)
    _check_run(model, data, out, scenario, run)
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


def _check_run(model, data, out, scenario: Scenario, run: Run) -> None:
    warnings = [(mujoco.mjtWarning(i).name, int(w.number)) for i, w in enumerate(data.warning)
                if w.number > 0]
    if warnings:
        raise SimulationError(
            f"{scenario.source}: run {run.name!r}: MuJoCo warnings {warnings}: expected none "
            f"(check masses, stiffnesses and the sample rate)"
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
    from .analytic import modal_properties
    s = scenario.structure
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


def _parallel_runs(scenario: Scenario, motion: GroundMotion, workers: int) -> Iterator[RunData]:
    """Simulate the runs in ``workers`` forked processes; yield them in run order.

    The workers are forked with the scenario and motion as initializer
    arguments (inherited, not pickled) and run exactly :func:`simulate_run`,
    so the numbers equal the serial path's bit for bit.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                               initializer=_set_forked_job, initargs=(scenario, motion))
    try:
        futures = [pool.submit(_simulate_forked, i) for i in range(len(scenario.runs))]
        for future in futures:
            yield future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


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
        per available core.  Results are identical to the serial path and
        come back in run order.
    """
    _stability_check(scenario)
    motion = ground_motion_of(scenario)
    n_workers = _worker_count(workers, len(scenario.runs))
    runs = []
    with _progress_bar(scenario.n_samples * len(scenario.runs), progress, scenario.name) as bar:
        if n_workers > 1:
            results = _parallel_runs(scenario, motion, n_workers)
        else:
            results = (simulate_run(scenario, run, motion, progress=bar.update)
                       for run in scenario.runs)
        try:
            for run in scenario.runs:
                bar.set_postfix_str(run.name)
                result = next(results)
                if n_workers > 1:
                    bar.update(scenario.n_samples)
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


def run_experiment(scenario: Scenario, path, *, progress: bool = False,
                   workers: int | None = 1) -> Experiment:
    """Simulate every run and record it to the MCAP file ``path``.

    Each run is written and flushed as soon as it completes (in run order),
    so a crash keeps every completed run readable.  ``workers`` as in
    :func:`simulate`.
    """
    from .recording import RecordingWriter

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


class _SampledMotion:
    """A table motion known only by its acceleration samples (linear between them)."""

    def __init__(self, t: np.ndarray, zdd: np.ndarray):
        self.t, self.zdd = t, zdd

    def acceleration(self, t):
        return np.interp(t, self.t, self.zdd, right=self.zdd[-1])

    def displacement(self, t):
        return np.zeros_like(np.asarray(t, float))

    def velocity(self, t):
        return np.zeros_like(np.asarray(t, float))


def replay(structure, mechanisms, run: RunData, zdd: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Replay a recorded run's table acceleration through a MuJoCo model.

    Parameters
    ----------
    structure : Structure
        The model (e.g. identified) to replay.
    mechanisms : sequence of Mechanism
        Physics added to the linear model (see :func:`momentid.model.build_spec`).
    run : RunData
        Supplies the clock, the added masses and (unless ``zdd`` is given) the
        measured base acceleration ``zdd``.

    Returns
    -------
    dict
        ``'a'``, ``'q'``, ``'v'``: simulated floor channels, each (n, d); the
        floors start at rest relative to the table.
    """
    zdd = run["zdd"] if zdd is None else zdd
    h = 1.0 / run.sample_rate
    spec = rig.build_spec(structure, run.added_mass, timestep=h, name="replay", mechanisms=mechanisms)
    model = rig.compile_model(spec)
    data = mujoco.MjData(model)
    n = run.n_samples
    drive = _TableDrive(model, data, _SampledMotion(run.time - run.time[0], zdd), n, mechanisms)
    mujoco.mj_resetData(model, data)
    layout = rig.sensor_layout(model)
    d = structure.storeys
    names = [f"{g}{i + 1}" for g in ("a", "q", "v") for i in range(d)]
    index = np.array([layout[c] for c in names])
    out = np.empty((n, len(names)))
    with _control_callback(drive):
        for k in range(n):
            mujoco.mj_step(model, data)
            out[k] = data.sensordata[index]
    return {g: out[:, i * d:(i + 1) * d] for i, g in enumerate(("a", "q", "v"))}
