"""Fit a real rig's MuJoCo twin to recorded trials by re-simulation, with or without physics beyond it.

The twin (:class:`~momentid.twin.fitted_rig.FittedRig`: stated floor masses, a full stiffness matrix, modal
damping, records of the registry's real-rig kinds in chosen storeys (``joint_friction``, ``cubic_spring``,
``quadratic_damping``: MJCF-only; ``bouc_wen``: its compiled law; no Python in the loop), one gain and clock
offset per floor sensor) is fitted by output error: every training trial is re-simulated through MuJoCo
under its recorded table acceleration, read by the sensors, and the residual of each trial is scaled by
that trial's signal so that the fit minimises the sum of the trials' squared NRMSE (every amplitude counts alike; one
parameter set explains them all).  The optimiser is scipy's trust-region least squares; the Jacobian's
physical columns are forward differences, all compiled once and re-simulated in one batched rollout per
trial (:func:`~momentid.lab.resim.simulate`; a linear twin as MuJoCo's own step map,
:mod:`momentid.lab.linear_replay`); the sensors' columns are exact (no re-simulation).

Every NRMSE is :func:`~momentid.twin.replay.nrmse` over the floor channels after the trial's
quiet lead-in.  A trial's low-energy tail (after :data:`FIT_ENERGY` of its floor signal's energy) is not
re-simulated while fitting; held-out trials are always simulated whole.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.fft
import scipy.optimize
from threadpoolctl import threadpool_limits

from momentid.errors import IdentificationError
from momentid.lab import resim
from momentid.lab.sensors import gain_and_delay, padded_length
from momentid.mechanisms import joint_friction as jf
from momentid.mechanisms import registry
from momentid.twin.fitted_rig import (FIT_ENERGY, REFERENCE_DRIFT, FittedRig, Trial, friction_records, friction_start,
                                      joint_tendon_stiffness, mechanism_start, storey_levels, trial, twin_modes)
from momentid.twin.replay import nrmse as replay_nrmse

__all__ = ["FittedRig", "friction_records", "Trial", "FitResult", "trial", "fit_twin", "predict", "nrmse",
           "sensor_jacobian", "FIT_ENERGY", "friction_start", "mechanism_start", "storey_levels", "twin_modes",
           "joint_tendon_stiffness", "workers", "each", "motion_scale"]

#: Seconds of a trial's quiet lead-in simulated before its shaking starts (the rest is the floors at rest).
LEAD_IN_MARGIN = 1.0
#: Forward-difference step, relative to each parameter's typical size.
DIFF_STEP = 1e-3
#: Optimiser's evaluation cap per fit (each evaluation re-simulates the training trials once).
MAX_NFEV = 40
#: Bounds of the friction parameters in the fit: stiffness lost at REFERENCE_DRIFT (N/m), slip drift (m),
#: exponent.
FRICTION_BOUNDS = ((1e-3, 300.0), (2e-4, 0.05), (-0.9, 1.0))
#: Bounds of the modal damping ratios and the sensors' log-gains and clock offsets (s).
DAMPING_BOUNDS = (-0.01, 0.1)
GAIN_BOUNDS = (-0.2, 0.2)
OFFSET_BOUNDS = (-0.02, 0.02)
_INVALID = 10.0     # residual of a parameter set whose stiffness is not positive definite


@dataclass(frozen=True)
class FitResult:
    """A twin fitted by re-simulation.

    Attributes
    ----------
    model : RigModel
    trials : tuple of str
        The trials it was fitted to.
    nrmse : dict
        Each training trial's NRMSE (whole trial).
    cost : float
        Sum of the training trials' squared NRMSE over the fitted spans.
    nfev : int
    """

    model: FittedRig
    trials: tuple
    nrmse: dict
    cost: float
    nfev: int


class _JointCodec:
    """A ``joint_friction`` record's three fitted numbers: log of the stiffness its secant has lost at
    :data:`REFERENCE_DRIFT`, log slip drift, exponent.  Below the slip drift a joint's loss grows as a power
    of the drift, so its stiffness and slip drift are nearly interchangeable; the loss at a drift the rig
    reaches is what the trials determine."""

    size = 3

    def pack(self, p: dict) -> list:
        lost = p["stiffness"] * jf.lost_fraction(REFERENCE_DRIFT, p["slip_drift"], p["exponent"])
        return [np.log(lost), np.log(p["slip_drift"]), p["exponent"]]

    def unpack(self, x) -> dict:
        slip, chi = float(np.exp(x[1])), float(x[2])
        return {"stiffness": float(np.exp(x[0])) / jf.lost_fraction(REFERENCE_DRIFT, slip, chi), "slip_drift": slip,
                "exponent": chi}

    def bounds(self):
        # (the first bound is on the stiffness lost at REFERENCE_DRIFT, N/m)
        return ([np.log(FRICTION_BOUNDS[0][0]), np.log(FRICTION_BOUNDS[1][0]), FRICTION_BOUNDS[2][0]],
                [np.log(FRICTION_BOUNDS[0][1]), np.log(FRICTION_BOUNDS[1][1]), FRICTION_BOUNDS[2][1]])

    def scale(self, p: dict) -> list:
        return [1.0, 1.0, 1.0]

    def share(self, p: dict, weight: float) -> dict:
        return {**p, "stiffness": p["stiffness"] * weight}


class _ParamCodec:
    """Any other real-rig kind's fitted numbers: each parameter over its scale, within the bounds and from
    the start its kind declares for the storey (:meth:`~momentid.mechanisms.base.MechanismKind.twin_parameters`)."""

    def __init__(self, kind, spec: dict):
        self.names = [p.name for p in kind.params]
        self.spec = spec
        self.size = len(self.names)

    def pack(self, p: dict) -> list:
        return [p[n] / self.spec[n][0] for n in self.names]

    def unpack(self, x) -> dict:
        return {n: float(v * self.spec[n][0]) for n, v in zip(self.names, x)}

    def bounds(self):
        return ([self.spec[n][2] / self.spec[n][0] for n in self.names],
                [self.spec[n][3] / self.spec[n][0] for n in self.names])

    def scale(self, p: dict) -> list:
        return [1.0] * self.size

    def share(self, p: dict, weight: float) -> dict:
        return dict(p)


def _codec(kind_name: str, level):
    if kind_name == "joint_friction":
        return _JointCodec()
    kind = registry.get(kind_name)
    return _ParamCodec(kind, kind.twin_parameters(*level))


class _Layout:
    """The parameter vector: K's upper triangle (N/m), damping ratios, each mechanism record's numbers
    (:class:`_JointCodec`, :class:`_ParamCodec`), then log-gains and clock offsets of the sensors, then the
    gains of the table's other motions the twin is driven by (``motion_scale``: their typical sizes).
    ``shared`` (records of one kind): one block of numbers for every record, a joint in each storey as
    stiff as the first's times the ratio of their storeys' stiffness in the template (one law, fewer
    parameters)."""

    def __init__(self, template: FittedRig, shared: bool = False, levels: dict | None = None,
                 motion_scale: np.ndarray | None = None, fit_motion: bool = True):
        self.template = template
        self.d = template.storeys
        self.records = tuple(template.friction)
        kinds = {m.type for m in self.records}
        self.shared = bool(shared) and len(self.records) > 1 and len(kinds) == 1
        self.codecs = [_codec(m.type, (levels or {}).get(m.location))
                       for m in self.records[:1 if self.shared else len(self.records)]]
        # shared: each storey's joint stiffness relative to the first's, as the start's storeys' stiffness
        K0 = np.asarray(template.stiffness)
        tendon = [joint_tendon_stiffness(K0, m) for m in self.records] if self.shared else []
        self.weights = [t / tendon[0] for t in tendon]
        self.iu = np.triu_indices(self.d)
        mech = sum(c.size for c in self.codecs)
        self.n_phys = len(self.iu[0]) + self.d + mech
        # each parameter's typical size, for the difference steps: K's entries (N/m), damping ratios,
        # the mechanisms' numbers, the sensors' log-gains and clock offsets (s)
        K = np.abs(K0)
        own = [c.scale(dict(m.parameters)) for c, m in zip(self.codecs, self.records)]
        self.scale = np.concatenate([np.maximum(K[self.iu], 0.01 * K.max()), np.full(self.d, 0.01),
                                     np.ravel(np.concatenate(own)) if own else np.zeros(0), np.full(self.d, 0.01),
                                     np.full(self.d, 1e-3)])
        # the table motions' gains last: each one's typical size makes its motion as large as the shaking
        self.k = len(template.table_motion) if fit_motion else 0       # else the template's gains, held
        self.scale = np.concatenate([self.scale, np.ones(self.k) if motion_scale is None else motion_scale[:self.k]])
        assert self.scale.size == self.n_phys + 2 * self.d + self.k

    def pack(self, model: FittedRig) -> np.ndarray:
        parts = [np.asarray(model.stiffness)[self.iu], np.asarray(model.damping_ratio)]
        for codec, m in zip(self.codecs, model.friction):
            parts.append(codec.pack(dict(m.parameters)))
        parts += [np.log(model.gain), model.offset, np.asarray(model.table_gains)[:self.k]]
        return np.concatenate([np.ravel(np.asarray(p, float)) for p in parts])

    def unpack(self, theta) -> FittedRig:
        d, k = self.d, len(self.iu[0])
        K = np.zeros((d, d))
        K[self.iu] = theta[:k]
        K = K + K.T - np.diag(np.diag(K))
        zeta = np.asarray(theta[k:k + d])
        i = k + d
        params = []
        for codec in self.codecs:
            params.append(codec.unpack(theta[i:i + codec.size]))
            i += codec.size
        if self.shared:       # one law in every place (a joint's stiffness in proportion to its storey's)
            params = [self.codecs[0].share(params[0], w) for w in self.weights]
        records = tuple(replace(m, parameters=tuple(p.items())) for m, p in zip(self.records, params))
        return replace(self.template, stiffness=K, damping_ratio=zeta, friction=records,
                       gain=np.exp(theta[i:i + d]), offset=np.asarray(theta[i + d:i + 2 * d]),
                       table_gains=np.asarray(theta[i + 2 * d:i + 2 * d + self.k]) if self.k
                       else self.template.table_gains)

    def bounds(self):
        k = len(self.iu[0])
        lo = [-np.inf] * k + [DAMPING_BOUNDS[0]] * self.d
        hi = [np.inf] * k + [DAMPING_BOUNDS[1]] * self.d
        for codec in self.codecs:
            low, high = codec.bounds()
            lo += list(low)
            hi += list(high)
        lo += [GAIN_BOUNDS[0]] * self.d + [OFFSET_BOUNDS[0]] * self.d + [-np.inf] * self.k
        hi += [GAIN_BOUNDS[1]] * self.d + [OFFSET_BOUNDS[1]] * self.d + [np.inf] * self.k
        return np.array(lo), np.array(hi)


def _valid(model: FittedRig) -> bool:
    K = np.asarray(model.stiffness)
    if np.any(np.linalg.eigvalsh(K) <= 0):
        return False
    return all(dict(m.parameters)["stiffness"] < joint_tendon_stiffness(K, m) for m in model.friction
               if m.type == "joint_friction")


def workers() -> int:
    """Threads the fits run side by side (:data:`~momentid.lab.resim.ROLLOUT_THREADS`, else one per core):
    MuJoCo's rollout releases the GIL, so trials and fits simulated on threads share the cores."""
    return max(1, resim.ROLLOUT_THREADS or os.cpu_count() or 1)


def each(fn: Callable[[Any], Any], items: Iterable[Any]) -> list:
    """``[fn(x) for x in items]``, on up to :func:`workers` threads (results in ``items``' order)."""
    items = list(items)
    if len(items) < 2 or workers() < 2:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(min(workers(), len(items))) as pool:
        return list(pool.map(fn, items))


def _steps(substeps: int | None, dt: float) -> int:
    """Integrator steps per sample: ``substeps``, else :func:`~momentid.lab.resim.substeps_for` of ``dt``."""
    return resim.substeps_for(dt) if substeps is None else int(substeps)


def _simulate(models, tr: Trial, whole: bool, substeps: int | None, compiled=None,
              threads: int | None = None, linear: bool | None = None, drives: np.ndarray | None = None) -> np.ndarray:
    """Floor accelerations (len(models), stop, d) of ``models`` (one table drive,
    :meth:`~momentid.twin.fitted_rig.FittedRig.drive`) on ``tr``; the quiet lead-in, where the
    floors ride the table at rest, is not simulated (the floors read the table's acceleration) but for
    its last :data:`LEAD_IN_MARGIN` seconds.  ``compiled``: the models already compiled at ``tr``'s step.
    ``linear``: replay as linear twins (:mod:`momentid.lab.linear_replay`; default: when no model has a
    mechanism), else by ``mujoco.rollout``.  ``drives`` (len(models), n): one table drive per model instead."""
    substeps = _steps(substeps, tr.dt)
    stop = len(tr.zdd) if whole else tr.fit_stop
    first = max(0, tr.start - int(round(LEAD_IN_MARGIN / tr.dt)))
    compiled = resim.compile_models([m.rig() for m in models], tr.dt / substeps) if compiled is None else compiled
    if drives is None:
        drives = models[0].drive(tr)[None, :]
        if any(not np.array_equal(m.table_gains, models[0].table_gains) for m in models[1:]):
            raise ValueError("models simulated together share the table's drive: expected the same table gains")
    out = np.empty((len(compiled), stop, tr.a.shape[1]))
    out[:, :first] = drives[:, :first, None]
    out[:, first:] = resim.simulate(compiled, drives[:, first:stop], tr.dt, substeps, threads=threads,
                                    linear=not any(m.friction for m in models) if linear is None else linear)
    return out


def _compiled_by_step(models, trials, substeps: int | None) -> dict:
    """``models`` compiled once per distinct sample interval of ``trials`` (the trials of one recording
    share it): ``{dt: [MjModel]}``."""
    rigs = [m.rig() for m in models]
    return {dt: resim.compile_models(rigs, dt / _steps(substeps, dt)) for dt in {t.dt for t in trials}}


def _residual(model: FittedRig, a: np.ndarray, tr: Trial) -> np.ndarray:
    """The fit's residual on ``tr`` of floor accelerations ``a`` (stop, d) read by ``model``'s sensors;
    ``a`` of shape (k, stop, d), k simulations read by the same sensors: (k, rows) in one transform."""
    read = gain_and_delay(a, model.gain, model.offset, tr.dt)
    stop = a.shape[-2]
    out = (tr.a[tr.start:stop] - read[..., tr.start:stop, :]) / tr.norm
    return out.reshape(*a.shape[:-2], -1)


def sensor_jacobian(model: FittedRig, a: np.ndarray, tr: Trial) -> np.ndarray:
    """Exact derivatives of the fit's residual on ``tr`` with respect to the sensors' log-gains and clock
    offsets: a reading ``g_j a_j(t - tau_j)`` changes by itself per unit of ``log g_j`` and by minus its
    time derivative (taken in the frequency domain, as the delay is) per second of ``tau_j``.

    Parameters
    ----------
    model : RigModel
        Its ``gain`` and ``offset`` (s) are the sensors'.
    a : ndarray, shape (stop, d)
        The model's floor accelerations (m/s^2) on ``tr`` as ideal sensors read them.
    tr : Trial

    Returns
    -------
    ndarray, shape ((stop - tr.start) * d, 2 d)
        Rows as the residual's (time-major, then channel); columns: the d log-gains, then the d offsets
        (residual per second).
    """
    d, stop = a.shape[1], a.shape[0]
    n = a.shape[0]
    length = padded_length(n)
    w = 2 * np.pi * scipy.fft.rfftfreq(length, tr.dt)[:, None]
    spectrum = scipy.fft.rfft(a, length, axis=0) * np.asarray(model.gain)[None, :] * np.exp(-1j * w * model.offset)
    read = scipy.fft.irfft(spectrum, length, axis=0)[:n]                # gain_and_delay(a, gain, offset, dt)
    rate = scipy.fft.irfft(1j * w * spectrum, length, axis=0)[:n]       # its time derivative
    rows = stop - tr.start
    J = np.zeros((rows, d, 2 * d))
    for j in range(d):
        J[:, j, j] = -read[tr.start:stop, j] / tr.norm
        J[:, j, d + j] = rate[tr.start:stop, j] / tr.norm
    return J.reshape(rows * d, 2 * d)


class _Problem:
    """Residual and Jacobian of the output-error fit, sharing the simulations of the current point."""

    def __init__(self, layout: _Layout, trials, substeps: int | None, max_nfev: int):
        self.layout, self.trials, self.substeps = layout, tuple(trials), substeps
        self.sizes = [(t.fit_stop - t.start) * layout.d for t in self.trials]
        self.cache_key, self.cache = None, None
        self.nsim = 0
        self.max_nfev, self.nfev, self.last_jacobian = max_nfev, 0, None

    def evaluate(self, theta):
        """The residual as the optimiser asks for it (counted against ``max_nfev``)."""
        self.nfev += 1
        return self.residual(theta)

    def _point(self, theta):
        """The simulations (per trial) and the residual at ``theta``, each trial on its own thread
        (computed once per point)."""
        key = theta.tobytes()
        if key != self.cache_key:
            model = self.layout.unpack(theta)
            if _valid(model):
                compiled = _compiled_by_step([model], self.trials, self.substeps)

                def one(t):
                    a = _simulate([model], t, False, self.substeps, compiled[t.dt], threads=1)[0]
                    return a, _residual(model, a, t)

                sims, residuals = zip(*each(one, self.trials))
                self.cache = list(sims), np.concatenate(residuals)
            else:
                self.cache = None, np.full(sum(self.sizes), _INVALID)
            self.cache_key = key
            self.nsim += 1
        return self.cache

    def sims(self, theta):
        """The floor accelerations (per trial) at ``theta``, or None where the model is not valid."""
        return self._point(theta)[0]

    def residual(self, theta):
        """The fit's residual at ``theta`` (every trial's rows, in order)."""
        return self._point(theta)[1].copy()

    def jacobian(self, theta):
        if self.nfev >= self.max_nfev and self.last_jacobian is not None:
            # scipy's trust-region loop takes the Jacobian of its last accepted point even when its
            # evaluations are spent and it stops without using it: re-simulating it would be wasted
            return self.last_jacobian
        self.last_jacobian = self._jacobian(theta)
        return self.last_jacobian

    def _jacobian(self, theta):
        base = self.residual(theta)
        sims = self.sims(theta)
        n = theta.size
        J = np.zeros((base.size, n))
        if sims is None:
            return J
        lo, hi = self.layout.bounds()
        steps = np.empty(n)
        perturbed = []
        for i in range(self.layout.n_phys):
            h = DIFF_STEP * self.layout.scale[i]
            if theta[i] + h > hi[i]:
                h = -h
            steps[i] = h
            t = theta.copy()
            t[i] += h
            perturbed.append(t)
        phys = [self.layout.unpack(perturbed[i]) for i in range(self.layout.n_phys)]
        ok = [_valid(m) for m in phys]
        valid = [m for m, v in zip(phys, ok) if v]
        compiled = _compiled_by_step(valid, self.trials, self.substeps) if valid else {}
        model = self.layout.unpack(theta)
        point = _compiled_by_step([model], self.trials, self.substeps) if self.layout.k else {}
        columns = np.flatnonzero(ok)
        rows = np.cumsum([0, *self.sizes])
        # linear twins replay one step map per trial: the trials run side by side; a mechanism's twins
        # (compiled loops or MuJoCo's rollouts) spread the batch's models over threads instead
        linear = not any(m.friction for m in valid)

        def block(k):                  # trial k's rows: the perturbed models read by the point's own sensors
            t, rows_k = self.trials[k], slice(rows[k], rows[k + 1])
            if columns.size:
                run = _simulate(valid, t, False, self.substeps, compiled[t.dt], threads=1 if linear else None)
                J[rows_k, columns] = ((_residual(model, run, t) - base[rows_k]) / steps[columns, None]).T
            sensors = self.layout.n_phys + 2 * self.layout.d
            J[rows_k, self.layout.n_phys:sensors] = sensor_jacobian(model, sims[k], t)
            if self.layout.k:          # the point's model, each motion's drive nudged: one rollout of them all
                h = DIFF_STEP * self.layout.scale[sensors:]
                motion = t.motion[:, [t.motion_channels.index(c) for c in model.table_motion]]
                drives = model.drive(t)[None, :] + (h[:, None] * motion.T)
                run = _simulate([model] * len(h), t, False, self.substeps, point[t.dt] * len(h),
                                threads=1 if linear else None, drives=drives)
                J[rows_k, sensors:] = ((_residual(model, run, t) - base[rows_k]) / h[:, None]).T

        if linear:
            each(block, range(len(self.trials)))
        else:
            for k in range(len(self.trials)):
                block(k)
        self.nsim += 1
        return J


def fit_twin(trials: Sequence[Trial], start: FittedRig, *, substeps: int | None = None,
             max_nfev: int = MAX_NFEV, shared: bool = False, fit_motion: bool = True) -> FitResult:
    """Fit ``start`` (its friction storeys fixed, their values the start) to ``trials`` together.

    Parameters
    ----------
    trials : sequence of Trial
    start : RigModel
        Starting point; its ``friction`` records say which storeys carry joint friction.
    shared : bool
        One joint's parameters for every friction storey (the first storey's start), instead of one set
        per storey.
    fit_motion : bool
        Fit the gains of the table motions ``start`` is driven by (``start.table_motion``); False: hold
        ``start``'s.

    Raises
    ------
    IdentificationError
        The start is not a valid model (stiffness not positive definite, friction stiffer than its storey).
    """
    trials = tuple(trials)
    if not _valid(start):
        raise IdentificationError(f"fit start of trials {[t.name for t in trials]}: stiffness not positive definite "
                                  f"or a joint stiffer than its storey: {start.to_dict()}")
    layout = _Layout(start, shared, storey_levels(start, trials), motion_scale(start, trials), fit_motion)
    problem = _Problem(layout, trials, substeps, max_nfev)
    lo, hi = layout.bounds()
    theta0 = np.clip(layout.pack(start), lo + 1e-9, hi - 1e-9)
    # one BLAS thread: the trials replay on threads of their own, and BLAS threads spinning after the
    # trust region's SVD took their cores (the shipped rig's refit: 1.3-1.7 s with them, 1.0 s without)
    with threadpool_limits(limits=1, user_api="blas"):
        result = scipy.optimize.least_squares(problem.evaluate, theta0, jac=problem.jacobian, bounds=(lo, hi),
                                              method="trf", x_scale="jac", max_nfev=max_nfev, ftol=1e-6, xtol=1e-8)
    model = layout.unpack(result.x)
    return FitResult(model=model, trials=tuple(t.name for t in trials),
                     nrmse=dict(zip([t.name for t in trials], each(lambda t: nrmse(model, t, substeps), trials))),
                     cost=float(2 * result.cost), nfev=int(problem.nsim))


def motion_scale(model: FittedRig, trials: Sequence[Trial]) -> np.ndarray:
    """Per table motion of ``model`` (:attr:`~momentid.twin.fitted_rig.FittedRig.table_motion`), the gain that
    makes it as large (RMS over the ``trials``' shaking) as the table's shaking axis: the typical size of
    its gain, shape (k,).

    Raises
    ------
    IdentificationError
        A trial lacks one of the motions, or a motion never moves.
    """
    for t in trials:
        model.drive(t)                                    # raises for a trial without the motions
    shaking = np.sqrt(np.mean(np.concatenate([t.zdd[t.start:] for t in trials]) ** 2))
    out = []
    for channel in model.table_motion:
        x = np.concatenate([t.motion[t.start:, t.motion_channels.index(channel)] for t in trials])
        rms = float(np.sqrt(np.mean(x ** 2)))
        if not rms > 0:
            raise IdentificationError(f"trials {[t.name for t in trials]}: the table's {channel} never moves; "
                                      f"expected a measured motion to drive the twin by")
        out.append(shaking / rms)
    return np.array(out)


def predict(model: FittedRig, tr: Trial, substeps: int | None = None) -> np.ndarray:
    """``model``'s floor accelerations (n, d) on the whole of ``tr``, as its sensors read them."""
    a = _simulate([model], tr, True, substeps)[0]
    return gain_and_delay(a, model.gain, model.offset, tr.dt)


def nrmse(model: FittedRig, tr: Trial, substeps: int | None = None) -> float:
    """Held-out NRMSE of ``model`` on the whole of ``tr`` (floor channels, after the lead-in)."""
    return float(replay_nrmse(tr.a[tr.start:], predict(model, tr, substeps)[tr.start:]))


