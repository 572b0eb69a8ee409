"""The calibrated twin as an MJCF model, built through ``mujoco.MjSpec`` on the rig of ``models/``.

:func:`twin_spec` builds the identified rig (:meth:`~momentid.twin.parameters.TwinParameters.rig`) with
the lab's one builder, :func:`momentid.lab.rig.build_spec` (the table on its slide joint driven by the
table command, every floor a child of the table on its own slide joint, K and C as fixed tendons), then
adds its extra modes and sensors.  The twin holds:

* **K and C exactly**: the storey tendons and, where the identified matrices are not tridiagonal,
  link tendons between farther levels (:func:`momentid.lab.tendons.tendon_layout`); the floor
  joints carry no damping of their own (except ``mu dm`` of an added mass, added-mass path);
* **extra modes**: one oscillator per mode on its own slide joint on the table
  (``extra_mode<e>``, spring ``m w^2`` and damper ``2 zeta w m`` for a body of the mean floor mass),
  so that its coordinate obeys ``eta'' + 2 zeta w eta' + w^2 eta = -z''``;
* **sensors, natively**: MuJoCo 4.0 sensors keep a history (``nsample``) and read it ``delay``
  seconds late (interpolated: :data:`LINEAR`, :data:`CUBIC`), which carries each floor sensor's clock offset.  The
  history cannot read less than one step late, and its cubic interpolation needs two steps behind it, so
  every sensor reads at least :data:`MIN_LATENCY_STEPS` steps late: the table sensor ``zdd`` reads a
  latency ``L`` late and floor sensor ``j`` ``L + clock_offset_j`` (``L``, whole steps, is as few as keep
  every delay at that floor).  A replay drives the table ``L`` ahead of the recording, so that the twin's
  sensors read on the recording's clock (:mod:`momentid.twin.replay`).  Gains and biases have no
  native sensor attribute: they are custom numeric data (``sensor_gain``, ``sensor_bias``, ``extra_mode_residues``)
  applied by momentid's sensor model, ``reading_j = gain_j (a_j + sum_e R_ej (a<j>_mode<e> - zdd_a<j>)) + bias_j``
  (the last two: the extra mode's oscillator and the table read at floor sensor j's delay).

Integration: RK4 at :func:`substeps` steps per sample, chosen so that RK4's own damping of the highest
mode stays below :data:`NUMERICAL_DAMPING_FRACTION` of the lightest damping ratio and its frequency
error below :data:`FREQUENCY_ERROR`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from momentid.errors import ModelError
from momentid.lab import rig
from momentid.twin.parameters import SensorModel, TwinParameters

__all__ = ["Timing", "timing", "substeps", "latency", "twin_spec", "sensor_names", "MIN_LATENCY_STEPS",
           "NUMERICAL_DAMPING_FRACTION", "FREQUENCY_ERROR", "MAX_SUBSTEPS", "LINEAR", "CUBIC"]

#: Fewest steps a twin sensor reads late: MuJoCo's history holds past steps only, and its cubic
#: interpolation needs a stored step on each side of the instant it reads (measured: below two
#: steps its error is ~1e-2 of the signal, from two steps on ~1e-4 at w h = 0.2).
MIN_LATENCY_STEPS = 2
#: RK4 damps an undamped oscillator by ``(w h)^5 / 144`` of critical per step: kept below this fraction
#: of the lightest mode's damping ratio (1 %: the twin's damping is the identified one to 1 %).
NUMERICAL_DAMPING_FRACTION = 0.01
#: RK4's relative frequency error ``(w h)^4 / 120``, kept below this (a hundredth of a percent).
FREQUENCY_ERROR = 1e-4
#: Most RK4 steps per sample; a rig that needs more (damping ratios below ~1e-6) is refused.
MAX_SUBSTEPS = 64
#: ``interp`` values of MuJoCo's history interpolation (0 is the zero-order hold).  The table's
#: acceleration is the drive, straight between RK4 steps: read linearly, exactly.  A floor's absolute
#: acceleration ``-M^-1 (K q + C q')`` is smooth (the drive's kinks cancel in it): read by cubics.
LINEAR, CUBIC = 1, 2
#: History samples kept beyond the longest delay (the cubic interpolation's two neighbours and slack).
_HISTORY_MARGIN = 4


@dataclass(frozen=True)
class Timing:
    """Sample rate of the recording and RK4 steps per sample."""

    sample_rate: float
    substeps: int

    @property
    def timestep(self) -> float:
        """RK4 step (s)."""
        return 1.0 / (self.sample_rate * self.substeps)


def _modes(params: TwinParameters):
    """Angular frequencies (rad/s) and damping ratios of the twin's storey and extra modes."""
    from momentid.core.analytic import modal_properties

    modes = modal_properties(np.diag(params.masses), params.C, params.K)
    w = np.concatenate([2 * np.pi * modes.frequency, [2 * np.pi * e.frequency for e in params.extra_modes]])
    z = np.concatenate([modes.damping_ratio, [e.damping_ratio for e in params.extra_modes]])
    return w, z


def substeps(params: TwinParameters, sample_rate: float) -> int:
    """RK4 steps per sample that integrate every mode of ``params`` to the module's accuracy.

    Raises
    ------
    ModelError
        A mode without positive damping, or one that needs more than :data:`MAX_SUBSTEPS`.
    """
    w, z = _modes(params)
    if not np.all(np.isfinite(w)) or np.any(z <= 0) or not np.all(np.isfinite(z)):
        raise ModelError(f"the twin's modes have damping ratios {np.round(z, 6).tolist()}: expected every one "
                         f"positive (a passive rig)")
    theta = min((144 * NUMERICAL_DAMPING_FRACTION * float(np.min(z))) ** 0.2, (120 * FREQUENCY_ERROR) ** 0.25)
    n = max(1, math.ceil(float(np.max(w)) / sample_rate / theta))
    if n > MAX_SUBSTEPS:
        raise ModelError(f"the twin needs {n} RK4 steps per sample at {sample_rate:g} Hz (top mode "
                         f"{np.max(w) / (2 * np.pi):.4g} Hz, lightest damping ratio {np.min(z):.3g}): expected "
                         f"at most {MAX_SUBSTEPS}")
    return n


def timing(params: TwinParameters, sample_rate: float) -> Timing:
    """:class:`Timing` of a replay at ``sample_rate`` (Hz)."""
    if not (math.isfinite(sample_rate) and sample_rate > 0):
        raise ModelError(f"sample rate {sample_rate!r} Hz: expected a positive number")
    return Timing(float(sample_rate), substeps(params, sample_rate))


def latency(sensors: SensorModel, step: float) -> float:
    """Delay (s) of the table sensor: the fewest whole steps of ``step`` seconds that keep every floor
    sensor's delay at :data:`MIN_LATENCY_STEPS` steps or more.  Whole steps: the drive, advanced by
    it, then bends at the recording's samples exactly where the RK4 steps start."""
    ahead = max(0.0, -float(np.min(sensors.clock_offset)))
    return (MIN_LATENCY_STEPS + math.ceil(ahead / step - 1e-9)) * step


def sensor_names(d: int, n_extra: int) -> dict:
    """Sensor names of a twin: ``zdd``, ``a<j>``, ``q<j>``, and per floor ``zdd_a<j>`` and
    ``a<j>_mode<e>`` when it has extra modes."""
    floors = [f"a{j + 1}" for j in range(d)]
    return {"table": "zdd", "floors": floors, "q": [f"q{j + 1}" for j in range(d)],
            "table_at_floor": [f"zdd_a{j + 1}" for j in range(d)] if n_extra else [],
            "extra": [[f"a{j + 1}_mode{e + 1}" for e in range(n_extra)] for j in range(d)] if n_extra else []}


def _delayed(sensor, delay: float, step: float, interp: int) -> None:
    sensor.delay = float(delay)
    sensor.nsample = int(math.ceil(delay / step)) + _HISTORY_MARGIN
    sensor.interp = interp


def _extra_modes(spec: mujoco.MjSpec, params: TwinParameters) -> None:
    base = spec.body("base")
    mass = float(np.mean(params.masses))
    for e, mode in enumerate(params.extra_modes):
        w = 2 * np.pi * mode.frequency
        body = base.add_body(name=f"extra_mode{e + 1}", pos=[0.0, -0.5, 0.05])
        body.mass = mass
        body.inertia = [mass * 1e-3] * 3            # slide joint only: any valid inertia
        joint = body.add_joint(name=f"eta{e + 1}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
        joint.stiffness = [mass * w ** 2, 0.0, 0.0]
        joint.damping = [2 * mode.damping_ratio * w * mass, 0.0, 0.0]
        body.add_site(name=f"extra_mode{e + 1}_imu", pos=[0, 0, 0])


def _sensors(spec: mujoco.MjSpec, params: TwinParameters, sensors: SensorModel, step: float) -> float:
    """Delays on the table and floor sensors (and the extra modes' readings); returns the latency."""
    lag = latency(sensors, step)
    _delayed(spec.sensor("zdd"), lag, step, LINEAR)
    site, acc = mujoco.mjtObj.mjOBJ_SITE, mujoco.mjtSensor.mjSENS_ACCELEROMETER
    for j in range(params.storeys):
        delay = lag + float(sensors.clock_offset[j])
        _delayed(spec.sensor(f"a{j + 1}"), delay, step, CUBIC)
        if params.extra_modes:
            _delayed(spec.add_sensor(name=f"zdd_a{j + 1}", type=acc, objname="base_imu", objtype=site), delay, step,
                     LINEAR)
        for e in range(len(params.extra_modes)):
            _delayed(spec.add_sensor(name=f"a{j + 1}_mode{e + 1}", type=acc, objname=f"extra_mode{e + 1}_imu",
                                     objtype=site), delay, step, CUBIC)
    return lag


def _custom(spec: mujoco.MjSpec, params: TwinParameters, sensors: SensorModel, lag: float) -> None:
    spec.add_numeric(name="sensor_gain", data=sensors.gain.tolist())
    spec.add_numeric(name="sensor_bias", data=sensors.bias.tolist())
    spec.add_numeric(name="sensor_clock_offset", data=sensors.clock_offset.tolist())
    spec.add_numeric(name="sensor_latency", data=[lag])
    if params.extra_modes:
        spec.add_numeric(name="extra_mode_residues",
                         data=np.concatenate([e.residues for e in params.extra_modes]).tolist())
    spec.add_text(name="sensor_model", data=(
        "floor sensor j reads sensor_gain[j] * (a<j> + sum over extra modes e of residue[e, j] * (a<j>_mode<e> - "
        "zdd_a<j>)) + sensor_bias[j], m/s^2; every sensor reads sensor_latency s late (a<j> another "
        "sensor_clock_offset[j] s): drive the table sensor_latency s ahead to read on the table's clock"))
    if params.mass_normalised:
        spec.add_text(name="mass_note", data="mass-normalised twin: 1 kg floors, K and C per kilogram of floor")


def twin_spec(params: TwinParameters, step: float, *, sensors: SensorModel | None = None,
              added_mass: ArrayLike | None = None,
              name: str = "twin") -> mujoco.MjSpec:
    """The MJCF twin of ``params`` with the floor sensors ``sensors`` (default: the nominal ones).

    Edit the returned spec (add a mechanism's tendons, actuators, bodies) before compiling it with
    :func:`momentid.lab.rig.compile_model`.

    Parameters
    ----------
    params : TwinParameters
    step : float
        RK4 step (s), e.g. :attr:`Timing.timestep`.
    sensors : SensorModel, optional
        Whose clock offsets the sensors' delays carry, and whose gains and biases the custom data hold.
    added_mass : array_like, shape (d,), optional
        Masses bolted to the floors (kg) in the run to replay; their joint damping ``mu dm`` with the
        added-mass path's ``mu``.
    name : str
        The MJCF model name.

    Returns
    -------
    mujoco.MjSpec
    """
    sensors = params.nominal if sensors is None else sensors
    spec = rig.build_spec(params.rig(added_mass), timestep=step, name=name)
    _extra_modes(spec, params)
    lag = _sensors(spec, params, sensors, step)
    _custom(spec, params, sensors, lag)
    spec.compiler.saveinertial = True            # the MJCF written keeps the bodies' inertials
    return spec


def model_matrices(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mass, damping and stiffness matrices of the floors of a compiled twin, read back from MuJoCo.

    ``M``: the floor block of MuJoCo's joint-space inertia; ``K`` and ``C``: every tendon's
    ``stiffness c c^T`` and ``damping c c^T`` (``c`` its coefficients on the floor joints) plus the
    floor joints' own damping.  The check that a written MJCF holds the identified rig.

    Parameters
    ----------
    model : mujoco.MjModel
        A compiled twin (joints ``q1..qd``).

    Returns
    -------
    M, C, K : ndarray, shape (d, d)
        kg, N s/m, N/m.
    """
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    d = sum(1 for j in range(model.njnt) if model.joint(j).name.startswith("q"))
    dofs = np.array([int(model.jnt_dofadr[model.joint(f"q{i + 1}").id]) for i in range(d)])
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    J = np.zeros((model.ntendon, d))               # fixed tendons: a coefficient per wrapped joint
    for t in range(model.ntendon):
        for w in range(model.tendon_adr[t], model.tendon_adr[t] + model.tendon_num[t]):
            dof = int(model.jnt_dofadr[model.wrap_objid[w]])
            if dof in dofs:
                J[t, int(np.flatnonzero(dofs == dof)[0])] = model.wrap_prm[w]
    K = J.T @ (model.tendon_stiffness[:, None] * J)
    C = J.T @ (model.tendon_damping[:, None] * J) + np.diag(model.dof_damping[dofs])
    return full[np.ix_(dofs, dofs)], C, K
