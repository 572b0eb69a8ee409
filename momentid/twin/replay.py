"""Replay a recorded trial through the MuJoCo twin and score it.

The table is driven by the recorded table acceleration: the table actuator of
:mod:`momentid.lab.rig` integrates a jerk held over each RK4 step, so the commanded acceleration is
the recording's samples joined by straight lines (first-order hold, the modal identification's own
assumption), exact at every RK4 stage.  The command runs the twin's sensor latency ``L`` ahead of
the recording (see :mod:`momentid.twin.spec`), so the twin's delayed sensors read on the
recording's clock: its table sensor reproduces the recorded table acceleration.  The floors start at
rest on the table (the recordings start with a quiet lead-in), and the sensors' histories empty: for
the first latency (a few milliseconds) they read 0.  Nothing is integrated outside
MuJoCo, and what MuJoCo integrates cannot drift: the floors' coordinates are relative to the table
and held by the storeys' springs; the table's own position, which a biased acceleration would carry
away, enters no force and no reading.

Score: ``NRMSE = sqrt(sum_j |a_j - a_j,twin|^2 / sum_j |a_j - mean_j|^2)`` over the floor sensors and
the samples after the quiet lead-in (the definition of :mod:`momentid.diagnosis.modal.check`), with
one constant per sensor fitted (its bias); beside it, the NRMSE the sensors' noise alone leaves
(levels from :func:`momentid.estimation.noise.estimate_noise`): the floor sensors' own, and the table
sensor's, which drives the twin and reaches the floors through it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout
from numpy.typing import ArrayLike

from momentid.core.series import RunData
from momentid.errors import SimulationError
from momentid.estimation.noise import estimate_noise, quiet_lead_in
from momentid.lab import rig
from momentid.twin.parameters import SensorModel, TwinParameters
from momentid.twin.spec import Timing, sensor_names, timing as make_timing, twin_spec

__all__ = ["Replay", "roll", "floor_readings", "replay_run", "nrmse", "transfer", "table_noise_gain", "CHUNK_STEPS"]

#: RK4 steps per ``mujoco.rollout`` call: memory stays bounded on long records.
CHUNK_STEPS = 200_000


@dataclass(frozen=True)
class Replay:
    """One trial replayed through the twin.

    Attributes
    ----------
    run : str
    time : ndarray, shape (n,)
        Seconds from the run's first sample.
    recorded, twin : ndarray, shape (n, d)
        Floor sensors' readings (m/s^2): recorded, and the twin's through its sensor model.
    table : ndarray, shape (n,)
        The twin's table sensor (m/s^2): the recorded table acceleration, read back.
    q : ndarray, shape (n, d)
        The twin's floor displacements relative to the table (m), true (no sensor delay).
    start : int
        First sample scored (after the quiet lead-in).
    sensors : SensorModel
        The floor sensors used, with the fitted bias.
    calibrated : bool
        The run was one of the identification's (its own sensor calibration), else nominal sensors.
    nrmse : float
        Over every floor sensor (1 = 100 %).
    nrmse_floors : ndarray, shape (d,)
        Per floor sensor.
    noise_nrmse : float
        What the sensors' noise alone leaves: a perfect twin's expected NRMSE.
    """

    run: str
    time: np.ndarray
    recorded: np.ndarray
    twin: np.ndarray
    table: np.ndarray
    q: np.ndarray
    start: int
    sensors: SensorModel
    calibrated: bool
    nrmse: float
    nrmse_floors: np.ndarray
    noise_nrmse: float

    def to_dict(self) -> dict:
        """The trial's scores as a JSON-ready dict (NRMSE as fractions; the sensors it was replayed with)."""
        return {"run": self.run, "calibration": self.calibrated, "nrmse": self.nrmse,
                "nrmse_per_floor": self.nrmse_floors.tolist(), "noise_nrmse": self.noise_nrmse,
                "samples": int(self.time.size), "scored_from_s": float(self.time[self.start]),
                "sensors": "calibrated on this trial" if self.calibrated else "nominal (the calibrated runs' mean)",
                "sensor_model": self.sensors.to_dict()}


def nrmse(measured: np.ndarray, model: np.ndarray, axis: int | None = None) -> np.ndarray | float:
    """``sqrt(sum |measured - model|^2 / sum |measured - mean|^2)`` over ``axis`` (all by default)."""
    centred = measured - measured.mean(axis=0)
    return np.sqrt(np.sum((measured - model) ** 2, axis=axis) / np.sum(centred ** 2, axis=axis))


def _initial_state(model: mujoco.MjModel, acceleration: float) -> np.ndarray:
    """Full physics state at rest on a table accelerating at ``acceleration`` (the drive's activation)."""
    data = mujoco.MjData(model)
    data.act[0] = acceleration
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty(mujoco.mj_stateSize(model, full))
    mujoco.mj_getState(model, data, state, full)
    return state


def _command(zdd: np.ndarray, timing: Timing, lag: float) -> np.ndarray:
    """Table acceleration command at every RK4 step node: the recording ``lag`` seconds ahead,
    linear between samples, held at its last value past the end."""
    n = zdd.shape[0]
    t_step = np.arange(n * timing.substeps + 1) * timing.timestep + lag
    return np.interp(t_step, np.arange(n) / timing.sample_rate, zdd)


def roll(model: mujoco.MjModel, zdd: np.ndarray, timing: Timing, names: Sequence[str]) -> dict:
    """Drive ``model`` (a compiled twin) with the table acceleration ``zdd`` and read sensors.

    Parameters
    ----------
    model : mujoco.MjModel
        From :func:`momentid.twin.spec.twin_spec` (possibly edited); its ``zdd`` sensor's delay is the
        latency the drive runs ahead.
    zdd : ndarray, shape (n,)
        Recorded table acceleration (m/s^2), at ``timing.sample_rate``.
    timing : Timing
    names : sequence of str
        Sensors to return (first component of each).

    Returns
    -------
    dict of str to ndarray, shape (n,)
        Each sensor at the recording's sample instants.

    Raises
    ------
    SimulationError
        MuJoCo warned or the response diverged.
    """
    layout = rig.sensor_layout(model)
    index = np.array([layout[c] for c in names])
    lag = float(model.sensor_delay[model.sensor("zdd").id])
    nodes = _command(np.asarray(zdd, float), timing, lag)
    jerk = np.diff(nodes) / timing.timestep
    n_steps, every = jerk.size, timing.substeps
    control = np.zeros((n_steps, model.nu))
    control[:, 0] = jerk          # actuator 0 drives the table; any others (a mechanism's state) take none
    out = np.empty((n_steps // every, index.size))
    data = mujoco.MjData(model)
    state = _initial_state(model, nodes[0])
    chunk = every * max(1, CHUNK_STEPS // every)
    warned = []
    for start in range(0, n_steps, chunk):
        stop = min(n_steps, start + chunk)
        states, sensors = rollout.rollout(model, data, state[None], control[None, start:stop])
        # sensors[k] is read from the state at the start of step k (time k h): sample i is step i * every
        out[start // every:stop // every] = sensors[0, ::every][:, index]
        state = states[0, -1]
        warned += [mujoco.mjtWarning(i).name for i, w in enumerate(data.warning) if w.number > 0]
    if warned or not np.all(np.isfinite(out)):
        raise SimulationError(f"twin replay: MuJoCo warnings {sorted(set(warned))} or a diverging response: "
                              f"expected a stable model")
    return {name: out[:, k] for k, name in enumerate(names)}


def floor_readings(raw: dict, params: TwinParameters, sensors: SensorModel) -> np.ndarray:
    """The floor sensors' readings of the twin (m/s^2), shape (n, d), from :func:`roll`'s sensors,
    through ``sensors`` (gain, bias) and the extra modes' residues."""
    names = sensor_names(params.storeys, len(params.extra_modes))
    a = np.column_stack([raw[c] for c in names["floors"]])
    for j in range(params.storeys):
        for e, mode in enumerate(params.extra_modes):
            a[:, j] += mode.residues[j] * (raw[names["extra"][j][e]] - raw[names["table_at_floor"][j]])
    return a * sensors.gain[None, :] + sensors.bias[None, :]


def table_noise_gain(params: TwinParameters, sensors: SensorModel, sample_rate: float) -> np.ndarray:
    """Variance of each floor sensor's twin reading per unit variance of white noise on the table
    sensor that drives it: ``(2 / fs) int_0^(fs/2) |H_j(f)|^2 df`` (``H`` of :func:`transfer`), on a
    grid a tenth of the narrowest half-power bandwidth fine.

    Returns
    -------
    ndarray, shape (d,)
    """
    from momentid.core.analytic import modal_properties

    modes = modal_properties(np.diag(params.masses), params.C, params.K)
    widths = [*(modes.damping_ratio * modes.frequency), *(e.damping_ratio * e.frequency for e in params.extra_modes)]
    step = max(min(widths) / 10, 1e-4 * sample_rate)
    f = np.arange(0.0, sample_rate / 2, step)
    power = np.abs(transfer(params, f, sensors)) ** 2
    return 2.0 / sample_rate * np.trapezoid(power, f, axis=0)


def _noise_nrmse(run: RunData, recorded: np.ndarray, start: int, stated, params: TwinParameters,
                 sensors: SensorModel) -> float:
    """Expected NRMSE of a perfect twin: the floor sensors' own noise, plus the table sensor's noise
    that drives the twin and reaches its floors through the rig (:func:`table_noise_gain`)."""
    sigma = estimate_noise(run, stated=stated).sigma
    d = recorded.shape[1]
    through = sigma["zdd"] ** 2 * table_noise_gain(params, sensors, run.sample_rate)
    power = (recorded.shape[0] - start) * sum(sigma[f"a{j + 1}"] ** 2 + through[j] for j in range(d))
    scored = recorded[start:]
    return float(np.sqrt(power / np.sum((scored - scored.mean(axis=0)) ** 2)))


def replay_run(params: TwinParameters, run: RunData, *, model: mujoco.MjModel | None = None,
               stated_noise: dict | None = None) -> Replay:
    """Replay ``run`` through the twin of ``params`` and score it.

    Parameters
    ----------
    params : TwinParameters
    run : RunData
        With ``zdd`` and ``a1..ad`` (m/s^2), uniformly sampled.
    model : mujoco.MjModel, optional
        A twin compiled from :func:`momentid.twin.spec.twin_spec` for this run's sensors (edited, say,
        with a mechanism), at :func:`momentid.twin.spec.timing`'s step; default: built here.  MuJoCo
        integrates whatever the MJCF holds (tendons, joints, actuators with their dynamics); no Python
        callback is installed.
    stated_noise : dict, optional
        The lab's stated noise levels (``experiment.statement.noise``).

    Returns
    -------
    Replay
    """
    d = params.storeys
    sensors = params.sensors_of(run.name)
    t = make_timing(params, run.sample_rate)
    if model is None:
        spec = twin_spec(params, t.timestep, sensors=sensors, added_mass=run.added_mass, name=f"twin_{run.name}")
        model = rig.compile_model(spec)
    names = sensor_names(d, len(params.extra_modes))
    wanted = (["zdd"] + names["floors"] + names["q"] + names["table_at_floor"]
              + [c for row in names["extra"] for c in row])
    raw = roll(model, run["zdd"], t, wanted)
    recorded = run.group("a", d)
    start = quiet_lead_in(run)
    unbiased = floor_readings(raw, params, sensors.with_bias(np.zeros(d)))
    bias = np.mean(recorded[start:] - unbiased[start:], axis=0)      # least-squares constant per sensor
    sensors = sensors.with_bias(bias)
    twin = unbiased + bias[None, :]
    return Replay(run=run.name, time=np.arange(run.n_samples) / t.sample_rate, recorded=recorded, twin=twin,
                  table=raw["zdd"], q=np.column_stack([raw[c] for c in names["q"]]), start=start, sensors=sensors,
                  calibrated=run.name in params.sensors, nrmse=float(nrmse(recorded[start:], twin[start:])),
                  nrmse_floors=nrmse(recorded[start:], twin[start:], axis=0),
                  noise_nrmse=_noise_nrmse(run, recorded, start, stated_noise, params, sensors))


def transfer(params: TwinParameters, frequency: ArrayLike, sensors: SensorModel | None = None) -> np.ndarray:
    """The twin's table-to-floor-sensor transfer ``a_j / z''`` at ``frequency`` (Hz).

    ``1 + w^2 (K - w^2 M + i w C)^-1 M 1`` for the floors, plus each extra mode's
    ``R_j w^2 / (w_e^2 - w^2 + 2 i zeta_e w_e w)``, times each sensor's ``gain exp(-i w offset)``.

    Parameters
    ----------
    params : TwinParameters
    frequency : array_like, shape (nf,)
        Hz.
    sensors : SensorModel, optional
        Default: the nominal sensors.

    Returns
    -------
    ndarray, shape (nf, d), complex
    """
    sensors = params.nominal if sensors is None else sensors
    w = 2 * np.pi * np.asarray(frequency, float)
    M = np.diag(params.masses)
    dynamic = params.K[None] - w[:, None, None] ** 2 * M[None] + 1j * w[:, None, None] * params.C[None]
    rhs = np.broadcast_to((M @ np.ones(params.storeys))[None, :, None], (w.size, params.storeys, 1))
    out = 1 + w[:, None] ** 2 * np.linalg.solve(dynamic, rhs)[:, :, 0]
    for mode in params.extra_modes:
        we = 2 * np.pi * mode.frequency
        out = out + mode.residues[None, :] * (w ** 2 / (we ** 2 - w ** 2 + 2j * mode.damping_ratio * we * w))[:, None]
    return out * sensors.gain[None, :] * np.exp(-1j * w[:, None] * sensors.clock_offset[None, :])
