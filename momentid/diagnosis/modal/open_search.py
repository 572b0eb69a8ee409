"""The open search on recordings without added mass: a nonlinear restoring law on one mode.

When the linear modal model of :mod:`momentid.diagnosis.modal.path` misses a held-out run, one mode is
given a restoring force beyond ``k eta + c eta'`` from the function library's terms
(:func:`momentid.mechanisms.data_driven.term_signal`: quadratic and cubic stiffness, quadratic
damping, friction, two-sided gaps and one-sided stops; not the hysteretic state or the stiffness
switch), and the held-out run is replayed with it.  Steps:

1. **Modal coordinates** from the floor accelerations: with the fitted residues ``R`` (modes x
   floors), ``a - z'' = eta'' R`` once each floor sensor's fitted gain and clock offset are undone, so
   ``eta'' = (a - z'') R^+``; ``eta'`` and ``eta`` are its integrals in the frequency domain above
   :data:`HIGH_PASS_OVER_MODE_1` x the first mode (below it a double integral is sensor drift).
2. **Selection** by the equation error, on every mode: ``-(eta'' + z'') = k eta + c eta' + sum
   theta_i g_i`` is linear in the coefficients; every signal is band-passed to the mode's band and
   :data:`EDGE_PERIODS` are dropped at each run's ends; terms join one at a time while each lowers the
   leave-one-run-out error by :data:`MIN_GAIN` (cheap: per-run normal equations).  A dissipative
   term (friction, quadratic damping) whose coefficient comes out negative feeds energy in: it is
   rejected.  The mode whose law lowers the error most is kept.
3. **Output-error refinement** of that law and of the linear baseline (``k``, ``c`` alone) on the
   training runs: Levenberg-Marquardt, every parameter set and every run simulated in one batch
   (exact first-order hold of the linear part, the nonlinear force by a predictor-corrector step);
   the law from two starts (the equation error's coefficients and the linear model), its dissipative
   terms kept positive.
4. **Held-out check**: the held-out run replayed with the law on that mode (the others linear); the
   law *beats the linear model* when it lowers the held-out NRMSE by :data:`MIN_HELD_OUT_GAIN` below
   both the linear model's and the refitted baseline's.  Either way the result is reported, with its
   numbers; the verdict does not change.
"""
from __future__ import annotations

from collections.abc import Sequence
import math
from dataclasses import dataclass, field
import os
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg

from momentid.core.series import Experiment
from momentid.diagnosis.modal import check as mc
from momentid.diagnosis.function_library import DELTA_FRACTIONS, SIGN_SCALE, Column
from momentid.estimation.linear import discretize, outputs, simulate_linear
from momentid.lab.sensors import gain_and_delay
from momentid.mechanisms.data_driven import TERMS, term_signal

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["ModalDiscovery", "discover_modal", "plot_modal_discovered", "modal_discovered_figure",
           "HIGH_PASS_OVER_MODE_1", "MIN_GAIN", "MAX_TERMS", "MIN_HELD_OUT_GAIN", "ITERATIONS", "DISSIPATIVE",
           "MODAL_UNITS"]

#: The integrals of ``eta''`` keep frequencies above this multiple of the first mode (below it a
#: double integral of sensor noise and offsets is all drift).
HIGH_PASS_OVER_MODE_1 = 0.3
#: A term joins the law only if it lowers the leave-one-run-out equation error by this share ...
MIN_GAIN = 0.05
#: ... and a law holds at most this many terms beyond ``k`` and ``c`` (a few runs support no more).
MAX_TERMS = 2
#: The law beats the linear model when its held-out NRMSE is this share below the linear model's.
MIN_HELD_OUT_GAIN = 0.05
#: Levenberg-Marquardt iterations of the output-error refinement (each: one batched simulation of every
#: parameter set on every training run); the relative finite-difference step of its Jacobian; the
#: Levenberg-Marquardt damping's start and its factors after a rejected / accepted step.
ITERATIONS = 10
JACOBIAN_STEP = 1e-3
DAMPING_START, DAMPING_UP, DAMPING_DOWN = 1e-3, 10.0, 3.0
#: A step changes no scaled parameter by more than this (an e-fold of k, c or a dissipative term; a
#: term's coefficient by its unit: a force as large as the whole restoring force).
STEP_LIMIT = 1.0
#: A dissipative term's output-error refinement starts at least at this share of its unit (its
#: coefficient is refined as a logarithm, which cannot start at zero).
DISSIPATIVE_START = 1e-3
#: A simulation whose modal displacement exceeds this multiple of the training runs' peak diverged.
DIVERGED = 1e3
#: The equation error drops this many periods of the high-pass frequency at each end of a run (the
#: frequency-domain integrals and band-pass of a record that stops while moving err there).
EDGE_PERIODS = 2.0
#: Terms that only dissipate energy when their coefficient is positive.
DISSIPATIVE = ("v_abs_v", "sign_v")
#: Terms that scale the mode's velocity (their effect is compared with the linear damping force).
VELOCITY_TERMS = ("v", "v_abs_v", "sign_v")
#: Units of each term's coefficient on the modal coordinate (force per unit modal mass, m/s^2).
MODAL_UNITS = {"x": "1/s^2", "v": "1/s", "x_abs_x": "1/(m s^2)", "x3": "1/(m^2 s^2)", "v_abs_v": "1/m",
               "sign_v": "m/s^2", "dead_zone": "1/s^2", "gap_pos": "1/s^2", "gap_neg": "1/s^2"}
#: Samples drawn in ``discovered.png``.
PLOT_POINTS = 4000
_MEANING = {t.name: t.meaning for t in TERMS}


@dataclass(frozen=True)
class ModalDiscovery:
    """A mode's restoring law found by :func:`discover_modal` (``report.json``'s ``discovered``).

    Attributes
    ----------
    location : dict
        ``{"mode": m}`` (1-based) and the worst floor sensor of the held-out misfit.
    description : str
        The law in words.
    terms : tuple of dict
        ``term``, ``meaning``, ``coefficient``, ``unit`` and shape parameters; ``x`` and ``v`` are the
        law's linear stiffness (1/s^2) and damping (1/s).
    nrmse_before, nrmse_after : float
        Held-out floor-acceleration NRMSE of the linear model and with the law.
    beats_linear : bool
        ``nrmse_after`` is :data:`MIN_HELD_OUT_GAIN` below the linear model's and the refitted baseline's.
    checks : dict
        Equation errors of the selection, training NRMSE of the baseline and the law, held-out NRMSE
        of the refitted baseline.
    plot : dict
        ``eta`` (m), ``measured`` and ``law`` (m/s^2): the restoring force per unit modal mass beyond
        the law's linear ``k eta + c eta'``, from the data and from the law's terms.
    """

    location: dict
    description: str
    terms: tuple
    nrmse_before: float
    nrmse_after: float
    beats_linear: bool
    checks: dict
    plot: dict = field(repr=False)

    def draw(self, path: str | os.PathLike) -> None:
        """``discovered.png`` at ``path``: :func:`plot_modal_discovered`."""
        plot_modal_discovered(self, path)

    def to_dict(self) -> dict:
        """The discovery as ``report.json`` states it: the mode and sensor, the law in words and terms, the NRMSE,
        the checks.
        """
        return {"location": self.location, "description": self.description, "terms": list(self.terms),
                "nrmse_before": self.nrmse_before, "nrmse_after": self.nrmse_after,
                "beats_linear": self.beats_linear, **self.checks}


@dataclass(frozen=True)
class _Training:
    """The training runs seen from mode ``m``: equation-error rows and output-error targets."""

    x: list            # eta (n_r,) per run, after its lead-in (m)
    v: list            # eta' (m/s)
    y: list            # -(eta'' + z'') (m/s^2)
    zdd: list          # table acceleration (N_r,), whole run (m/s^2)
    target: list       # mode m's share of the floor accelerations the other modes leave, whole run
    start: list        # first active sample of each run
    untouched: float   # floor misfit power mode m cannot change (m^2/s^4 summed)
    power: float       # floor signal power (NRMSE denominator)
    weight: float      # |R_m|^2: floor misfit power per unit modal misfit power


def _integrals(x: np.ndarray, dt: float, f_low: float) -> tuple[np.ndarray, np.ndarray]:
    """First and second integrals of ``x`` (n,) above ``f_low`` Hz (frequency domain, zero-padded)."""
    n = x.size
    spectrum = np.fft.rfft(x, 2 * n)
    f = np.fft.rfftfreq(2 * n, dt)
    keep = f >= f_low
    inverse = np.where(keep, 1.0 / np.where(keep, 2j * np.pi * f, 1.0), 0.0)
    return np.fft.irfft(spectrum * inverse, 2 * n)[:n], np.fft.irfft(spectrum * inverse ** 2, 2 * n)[:n]


def _training(experiment: Experiment, linear: mc.RunsFit, train, m: int) -> _Training:
    """Mode ``m`` (0-based) of every training run, each with its own fitted sensor gains and offsets."""
    d, R = experiment.storeys, np.asarray(linear.residues, float)
    others = np.delete(np.arange(d), m)
    f_low = HIGH_PASS_OVER_MODE_1 * float(linear.frequency[0])
    rows = {key: [] for key in ("x", "v", "y", "zdd", "target", "start")}
    untouched = power = 0.0
    for i, name in enumerate(train):
        run = experiment.run(name)
        dt, start, zdd = 1.0 / run.sample_rate, mc.active_start(run), run["zdd"]
        measured = run.group("a", d)
        a = gain_and_delay(measured, linear.gain[i], linear.offset[i], dt, undo=True) - zdd[:, None]
        eta_m = (a[start:] @ np.linalg.pinv(R))[:, m]                 # the data's own eta_m''
        v, x = _integrals(eta_m, dt, f_low)
        oscillators = discretize(np.eye(d), np.diag(2 * linear.zeta * linear.omega), np.diag(linear.omega ** 2), dt)
        eta_linear = outputs(oscillators, simulate_linear(oscillators, zdd))["a"] - zdd[:, None]
        left = a - eta_linear[:, others] @ R[others]                  # what mode m should carry
        target = left @ R[m] / float(R[m] @ R[m])
        untouched += float(np.sum((left - target[:, None] * R[m][None, :])[start:] ** 2))
        power += float(np.sum((measured[start:] - measured[start:].mean(axis=0)) ** 2))
        for key, value in (("x", x), ("v", v), ("y", -(eta_m + zdd[start:])), ("zdd", zdd), ("target", target),
                           ("start", start)):
            rows[key].append(value)
    return _Training(**rows, untouched=untouched, power=power, weight=float(R[m] @ R[m]))


def _library(x: np.ndarray, v: np.ndarray) -> list[Column]:
    """The candidate terms on the stacked training rows: polynomial, velocity, friction (its smoothing
    :data:`~momentid.diagnosis.function_library.SIGN_SCALE` x RMS(eta')), gaps and stops at
    :data:`~momentid.diagnosis.function_library.DELTA_FRACTIONS` of the peak ``|eta|``."""
    peak = float(np.max(np.abs(x)))
    shapes = [("x_abs_x", {}), ("x3", {}), ("v_abs_v", {}),
              ("sign_v", {"sign_v_scale": SIGN_SCALE * float(np.sqrt(np.mean(v ** 2)))})]
    shapes += [(name, {f"{name}_delta": f * peak}) for name in ("dead_zone", "gap_pos", "gap_neg")
               for f in DELTA_FRACTIONS]
    return [Column(name, shape, term_signal(name, shape, x, v, 0.0)) for name, shape in shapes]


def _band_pass(x: np.ndarray, band: tuple[float, float], dt: float) -> np.ndarray:
    """``x`` (n, ...) keeping the frequencies in ``band`` (Hz) only (frequency domain, zero-padded)."""
    n = x.shape[0]
    f = np.fft.rfftfreq(2 * n, dt)
    keep = ((f >= band[0]) & (f < band[1])).reshape((-1,) + (1,) * (x.ndim - 1))
    return np.fft.irfft(np.fft.rfft(x, 2 * n, axis=0) * keep, 2 * n, axis=0)[:n]


def _band(frequency: np.ndarray, m: int, f_low: float) -> tuple[float, float]:
    """Mode ``m``'s band (Hz): from ``f_low`` (mode 1) or the geometric mean with the mode below, to the
    one with the mode above (the Nyquist frequency's double for the last mode)."""
    f = np.asarray(frequency, float)
    low = f_low if m == 0 else math.sqrt(f[m - 1] * f[m])
    return low, math.sqrt(f[m] * f[m + 1]) if m + 1 < f.size else math.inf


class _LeaveOneRunOut:
    """Per-run normal equations of ``y`` on ``[eta, eta', library...]``, each signal band-passed to the
    mode's band (a linear filter keeps the regression's equation; it drops the other modes' share that
    residues fitted to the noise level still leak into ``eta''``): any subset's leave-one-run-out
    equation error (mean square, m^2/s^4) and its fit on every run, without re-reading the data."""

    def __init__(self, data: _Training, cols: list[Column], band: tuple[float, float], dt: float):
        bounds = np.cumsum([0] + [x.size for x in data.x])
        runs = [slice(a, b) for a, b in zip(bounds, bounds[1:])]
        X = np.column_stack([np.concatenate(data.x), np.concatenate(data.v), np.concatenate(data.y)]
                            + [c.signal for c in cols])
        edge = min(int(EDGE_PERIODS / (band[0] * dt)), min(p.stop - p.start for p in runs) // 4)
        X = np.concatenate([_band_pass(X[p], band, dt)[edge:X[p].shape[0] - edge] for p in runs])
        X, y = np.delete(X, 2, axis=1), X[:, 2]
        self.scale = np.linalg.norm(X, axis=0)
        self.scale[self.scale == 0] = 1.0
        X = X / self.scale
        bounds = np.cumsum([0] + [p.stop - p.start - 2 * edge for p in runs])
        parts = [slice(a, b) for a, b in zip(bounds, bounds[1:])]
        self.G = np.array([X[p].T @ X[p] for p in parts])
        self.g = np.array([X[p].T @ y[p] for p in parts])
        self.yy = np.array([float(y[p] @ y[p]) for p in parts])
        self.n = y.size

    def fit(self, idx: list[int], runs=None) -> np.ndarray:
        """Coefficients (in the data's units) of the columns ``idx`` fitted on ``runs`` (default: all)."""
        runs = slice(None) if runs is None else runs
        G, g = self.G[runs].sum(axis=0)[np.ix_(idx, idx)], self.g[runs].sum(axis=0)[idx]
        return np.linalg.lstsq(G, g, rcond=1e-12)[0] / self.scale[idx]

    def error(self, idx: list[int]) -> float:
        total = 0.0
        for r in range(len(self.yy)):
            c = self.fit(idx, np.arange(len(self.yy)) != r) * self.scale[idx]
            total += self.yy[r] - 2 * float(c @ self.g[r, idx]) + float(c @ self.G[r][np.ix_(idx, idx)] @ c)
        return max(total, 0.0) / self.n


def _select(loro: _LeaveOneRunOut, cols: list[Column]) -> tuple[list[int], dict]:
    """Forward selection (indices into ``cols``) and every law's leave-one-run-out error, by name."""
    chosen: list[int] = []
    best = loro.error([0, 1])
    errors = {"linear": best}
    while len(chosen) < MAX_TERMS:
        used = {cols[i].term for i in chosen}
        trials = {}
        for i, col in enumerate(cols):
            idx = [0, 1] + [2 + j for j in chosen + [i]]
            if col.term in used or any(cols[j].term in DISSIPATIVE and c < 0 for j, c in
                                       zip(chosen + [i], loro.fit(idx)[2:])):
                continue                      # a dissipative term that feeds energy in is no physics
            trials[i] = loro.error(idx)
        if not trials:
            break
        i = min(trials, key=trials.get)
        errors[" + ".join(_name(cols[j]) for j in chosen + [i])] = trials[i]
        if trials[i] > (1.0 - MIN_GAIN) * best:
            break
        chosen.append(i)
        best = trials[i]
    return chosen, errors


def _name(col: Column) -> str:
    return col.term + "".join(f" ({k} {v:.3g})" for k, v in col.shape.items())


class _Force:
    """``sum_i theta_i g_i(x, v)`` (B,) for B members at once (``theta``: (B, len(cols))), with the
    coefficients laid out once: it runs twice per simulation step."""

    def __init__(self, cols: list[Column], theta: np.ndarray):
        self.terms = [(np.ascontiguousarray(theta[:, i]), col.term, col.shape) for i, col in enumerate(cols)]

    def __call__(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        total = 0.0
        for th, term, shape in self.terms:
            total = total + th * term_signal(term, shape, x, v, 0.0)
        return total if self.terms else np.zeros_like(x)


def _hold(k: float, c: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact first-order-hold step of ``eta'' + c eta' + k eta = w``: ``s+ = Phi s + G0 w + G1 w+``."""
    aug = np.zeros((4, 4))
    aug[0, 1], aug[1, 0], aug[1, 1], aug[1, 2], aug[2, 3] = 1.0, -k, -c, 1.0, 1.0
    E = scipy.linalg.expm(aug * dt)
    return E[:2, :2], E[:2, 2] - E[:2, 3] / dt, E[:2, 3] / dt


def _simulate(k: np.ndarray, c: np.ndarray, theta: np.ndarray, cols: list[Column], zdd: np.ndarray, dt: float,
              bound: float) -> np.ndarray:
    """``eta''`` (n, B) of ``eta'' + z'' = -(k eta + c eta' + sum theta_i g_i)`` for B members at once,
    at rest at the first sample: the linear part exact (first-order hold of its input), the nonlinear
    force by a predictor-corrector step (second order).  ``k``, ``c``: (B,) (1/s^2, 1/s); ``theta``:
    (B, len(cols)); ``zdd``: (n, B) table accelerations (m/s^2).  A member whose ``|eta|`` exceeds
    ``bound`` (m) diverged: its column is NaN."""
    n, B = zdd.shape
    held = {pair: _hold(*pair, dt) for pair in set(zip(k, c))}      # members share (k, c) across runs
    steps = [held[pair] for pair in zip(k, c)]
    (p00, p01), (p10, p11) = np.array([s[0] for s in steps]).transpose(1, 2, 0)
    (a0, b0), (a1, b1) = np.array([s[1] for s in steps]).T, np.array([s[2] for s in steps]).T
    u = np.vstack([zdd, zdd[-1:]])
    drive_x, drive_v = -(a0 * u[:-1] + a1 * u[1:]), -(b0 * u[:-1] + b1 * u[1:])    # the table's share, (n, B)
    hold_x, hold_v = a0 + a1, b0 + b1                     # the force held over a step (the predictor)
    x, v = np.zeros(B), np.zeros(B)
    force = _Force(cols, theta)
    f = force(x, v)
    history = np.empty((3, n, B))                         # eta, eta', force at each sample
    diverged = np.zeros(B, bool)
    with np.errstate(over="ignore", invalid="ignore"):      # a diverging member overflows before it is caught
        for j in range(n):
            history[0, j], history[1, j], history[2, j] = x, v, f
            x, v = p00 * x + p01 * v + drive_x[j] - hold_x * f, p10 * x + p11 * v + drive_v[j] - hold_v * f
            if cols:
                correction = force(x, v) - f                     # corrector: the force at the step's end
                x, v = x - a1 * correction, v - b1 * correction
                f = force(x, v)
            if j % 256 == 0:
                bad = ~(np.abs(x) < bound)
                diverged |= bad
                x[bad], v[bad], f[bad] = 0.0, 0.0, 0.0
        out = -zdd - history[2] - k * history[0] - c * history[1]
    out[:, diverged] = np.nan
    return out


@dataclass(frozen=True)
class _Problem:
    """The output-error fit: training data, the law's columns, reference ``k``, ``c`` and term units.
    Parameters are scaled: ``log(k / k0)``, ``log(c / c0)``, each term's coefficient in its unit, a
    dissipative term's as the log (it stays positive: dissipative)."""

    data: _Training
    cols: list
    dt: float
    k0: float
    c0: float
    units: np.ndarray

    def coefficients(self, law: list[int], p: np.ndarray) -> tuple[float, float, np.ndarray]:
        """``(k, c, theta over every column)`` of scaled parameters ``p`` of the law using columns ``law``."""
        theta = np.zeros(len(self.cols))
        dissipative = np.array([self.cols[i].term in DISSIPATIVE for i in law], bool)
        theta[law] = np.where(dissipative, np.exp(np.where(dissipative, p[2:], 0.0)), p[2:]) * self.units[law]
        return self.k0 * math.exp(p[0]), self.c0 * math.exp(p[1]), theta

    def start(self, law: list[int], k: float, c: float, theta: np.ndarray) -> np.ndarray:
        """Scaled parameters of ``(k, c, theta)`` (``theta`` over the law's columns; a dissipative term's
        coefficient at least :data:`DISSIPATIVE_START` of its unit)."""
        scaled = theta / self.units[law]
        dissipative = np.array([self.cols[i].term in DISSIPATIVE for i in law], bool)
        scaled = np.where(dissipative, np.log(np.maximum(scaled, DISSIPATIVE_START)), scaled)
        return np.concatenate([[math.log(k / self.k0), math.log(c / self.c0)], scaled])

    def residuals(self, sets: list[tuple[list[int], np.ndarray]]) -> np.ndarray:
        """Output-error residuals (n_sets, N) of each parameter set on every training run, scaled so that
        a row's sum of squares is the floor-acceleration misfit power mode m adds (m^2/s^4)."""
        d = self.data
        runs, longest = len(d.zdd), max(z.size for z in d.zdd)
        zdd = np.zeros((longest, runs))
        for r, z in enumerate(d.zdd):
            zdd[:z.size, r] = z
        laws = [self.coefficients(law, p) for law, p in sets]
        k = np.repeat([w[0] for w in laws], runs)
        c = np.repeat([w[1] for w in laws], runs)
        theta = np.repeat(np.array([w[2] for w in laws]).reshape(len(sets), -1), runs, axis=0)
        bound = DIVERGED * max(float(np.max(np.abs(x))) for x in d.x)
        eta = _simulate(k, c, theta, self.cols, np.tile(zdd, (1, len(sets))), self.dt, bound)
        scale = math.sqrt(d.weight)
        return np.array([np.concatenate([scale * (eta[s:t.size, i * runs + r] - t[s:])
                                         for r, (s, t) in enumerate(zip(d.start, d.target))])
                         for i in range(len(sets))])

    def nrmse(self, cost: float) -> float:
        """Training floor-acceleration NRMSE (sensor gains and offsets undone) at output-error ``cost``."""
        return math.sqrt((self.data.untouched + cost) / self.data.power)


def _refine(problem: _Problem, laws: list[list[int]], starts: list[np.ndarray]):
    """Levenberg-Marquardt on the training runs' output error, all laws in each batched simulation.
    Returns each law's parameters and cost (sum of squared residuals), and the first law's cost at its
    start."""
    trial = [np.asarray(s, float) for s in starts]
    best = list(trial)
    cost, damping = [math.inf] * len(laws), [DAMPING_START] * len(laws)
    state = [None] * len(laws)                               # (residual, Jacobian) at best
    first = None
    for iteration in range(ITERATIONS):
        sets = [(law, p) for law, base in zip(laws, trial)
                for p in [base] + list(base + JACOBIAN_STEP * np.eye(base.size))]
        rows = problem.residuals(sets)
        at = 0
        for i, base in enumerate(trial):
            block, at = rows[at:at + base.size + 1], at + base.size + 1
            value = float(block[0] @ block[0])
            first = value if first is None else first
            J = (block[1:] - block[0]).T / JACOBIAN_STEP
            if math.isfinite(value) and value < cost[i] and np.all(np.isfinite(J)):
                best[i], cost[i], state[i] = base, value, (block[0], J)
                damping[i] /= DAMPING_DOWN
            else:
                damping[i] *= DAMPING_UP
            if state[i] is None or iteration == ITERATIONS - 1:
                continue
            r, J = state[i]
            JTJ = J.T @ J
            step = np.linalg.lstsq(JTJ + damping[i] * np.diag(np.diag(JTJ)), -J.T @ r, rcond=None)[0]
            trial[i] = best[i] + step * min(1.0, STEP_LIMIT / max(float(np.max(np.abs(step))), 1e-300))
    return best, cost, first


def _replay(linear: mc.RunsFit, m: int, eta_m: np.ndarray, gain, offset, zdd: np.ndarray, dt: float) -> np.ndarray:
    """Floor accelerations (n, d) as the sensors read them, mode ``m`` following ``eta_m''`` (n,) and the
    other modes the linear model."""
    R = np.asarray(linear.residues, float)
    others = R.copy()
    others[m] = 0.0
    return (mc.replay(linear.omega, linear.zeta, others, gain, offset, zdd, dt)
            + gain_and_delay(eta_m[:, None] * R[m][None, :], gain, offset, dt))


def _describe(mode: int, law: list[Column], k: float, c: float, theta: np.ndarray, peaks, top: float) -> str:
    """The law in words: each term's force at the training runs' peak modal displacement or velocity,
    as a share of the mode's linear spring or damping force there."""
    x_peak, v_peak = peaks
    parts = []
    for col, th in zip(law, theta):
        velocity = col.term in VELOCITY_TERMS
        at = v_peak if velocity else x_peak
        signal = [float(term_signal(col.term, col.shape, 0.0 if velocity else a, a if velocity else 0.0, 0.0))
                  for a in (at, -at)]                       # a stop on one side acts on that side only
        side = int(abs(signal[1]) > abs(signal[0]))
        share = th * signal[side] / ((c if velocity else k) * at * (1 - 2 * side))
        if velocity:
            kind = "dissipative" if th > 0 else "feeding energy in"
        else:
            kind = "stiffening" if share > 0 else "softening"
        shape = "".join(f", {key.split('_')[-1]} {1e3 * abs(top) * value:.3g} mm at the top floor"
                        for key, value in col.shape.items() if key.endswith("delta"))
        parts.append(f"{_MEANING[col.term]}{shape}: {kind}, {100 * share:+.1f} % of the mode's linear "
                     f"{'damping' if velocity else 'spring'} force at the training runs' peak "
                     f"{'velocity' if velocity else 'displacement'} (top floor {1e3 * abs(top) * at:.3g} "
                     f"{'mm/s' if velocity else 'mm'})")
    return f"mode {mode}: " + "; ".join(parts)


def _terms(law: list[Column], k: float, c: float, theta: np.ndarray) -> tuple:
    linear = [{"term": "x", "meaning": _MEANING["x"], "coefficient": k, "unit": MODAL_UNITS["x"]},
              {"term": "v", "meaning": _MEANING["v"], "coefficient": c, "unit": MODAL_UNITS["v"]}]
    return tuple(linear + [{"term": col.term, "meaning": _MEANING[col.term], "coefficient": float(th),
                            "unit": MODAL_UNITS[col.term], **col.shape} for col, th in zip(law, theta)])


def _held_out(run, d: int, linear: mc.RunsFit, m: int, law: list[Column], laws, bound: float):
    """Held-out floor-acceleration NRMSE of each of ``laws`` (``(k, c, theta)``) on mode ``m``, the other
    modes linear and the sensors the training runs' mean (NaN for a law that diverges)."""
    dt, start = 1.0 / run.sample_rate, mc.active_start(run)
    gain, offset = linear.gain.mean(axis=0), linear.offset.mean(axis=0)
    eta = _simulate(np.array([w[0] for w in laws]), np.array([w[1] for w in laws]), np.array([w[2] for w in laws]),
                    law, np.column_stack([run["zdd"]] * len(laws)), dt, bound)
    measured = run.group("a", d)[start:]
    return tuple(mc.nrmse(measured, _replay(linear, m, eta[:, i], gain, offset, run["zdd"], dt)[start:])
                 if np.all(np.isfinite(eta[:, i])) else math.nan for i in range(len(laws)))


def _search_mode(experiment: Experiment, linear: mc.RunsFit, train, m: int, dt: float):
    """Selection on mode ``m``: its data, library, ``(chosen, errors)``, the chosen law's equation error
    relative to the linear one (1 when nothing is chosen) and the normal equations."""
    data = _training(experiment, linear, train, m)
    cols = _library(np.concatenate(data.x), np.concatenate(data.v))
    f_low = HIGH_PASS_OVER_MODE_1 * float(linear.frequency[0])
    loro = _LeaveOneRunOut(data, cols, _band(linear.frequency, m, f_low), dt)
    chosen, errors = _select(loro, cols)
    law = " + ".join(_name(cols[i]) for i in chosen)
    return data, cols, (chosen, errors), errors[law] / errors["linear"] if chosen else 1.0, loro


def discover_modal(experiment: Experiment, linear: mc.RunsFit, train: Sequence[str], held: str, location: dict,
                   before: float) -> ModalDiscovery | None:
    """The open search: the mode whose law lowers the equation error most, checked on ``held`` (see the
    module docstring).

    Parameters
    ----------
    experiment : Experiment
        Runs without added mass (``zdd``, ``a1..ad`` in m/s^2).
    linear : RunsFit
        The pooled linear modal model of the training runs (per-run sensor gains and offsets in its rows).
    train : sequence of str
        Training runs (at least two), in ``linear``'s order.
    held : str
        The held-out run.
    location : dict
        Where the held-out misfit is (``sensor``: its worst floor sensor, reported with the mode).
    before : float
        The linear model's held-out NRMSE.

    Returns
    -------
    ModalDiscovery, or None when no term lowers the leave-one-run-out equation error by :data:`MIN_GAIN`
    on any mode.
    """
    dt = 1.0 / experiment.run(train[0]).sample_rate
    searches = [_search_mode(experiment, linear, train, m, dt) for m in range(experiment.storeys)]
    m = min(range(len(searches)), key=lambda i: searches[i][3])
    data, cols, (chosen, errors), _, loro = searches[m]
    if not chosen:
        return None
    x, v, y = np.concatenate(data.x), np.concatenate(data.v), np.concatenate(data.y)
    law = [cols[i] for i in chosen]
    k0, c0 = float(linear.omega[m] ** 2), float(2 * linear.zeta[m] * linear.omega[m])
    base, fitted = loro.fit([0, 1]), loro.fit([0, 1] + [2 + i for i in chosen])
    units = np.array([float(np.std(y) / max(np.std(col.signal), 1e-300)) for col in law])
    k_start, c_start = (r0 * float(np.clip((r0 + fitted[j] - base[j]) / r0, 0.5, 2.0)) for j, r0 in enumerate((k0, c0)))
    problem = _Problem(data, law, dt, k0, c0, units)
    everything = list(range(len(law)))
    # The law starts twice: from the equation error's coefficients, and from the linear model (which
    # the equation error on noisy, band-passed signals may have misled); the better one is kept.
    (p_base, *p_laws), (cost_base, *cost_laws), cost_start = _refine(
        problem, [[], everything, everything],
        [np.zeros(2), problem.start(everything, k_start, c_start, fitted[2:]),
         problem.start(everything, k0, c0, np.zeros(len(law)))])
    p_law, cost_law = min(zip(p_laws, cost_laws), key=lambda pc: pc[1])
    k, c, theta = problem.coefficients(everything, p_law)
    refitted, after = _held_out(experiment.run(held), experiment.storeys, linear, m, law,
                                [problem.coefficients([], p_base), (k, c, theta)], DIVERGED * float(np.max(np.abs(x))))
    beats = bool(after <= (1.0 - MIN_HELD_OUT_GAIN) * min(before, refitted))
    R = np.asarray(linear.residues, float)
    pick = np.linspace(0, x.size - 1, min(PLOT_POINTS, x.size)).astype(int)
    return ModalDiscovery(
        location={"mode": m + 1, "sensor": location.get("sensor")},
        description=_describe(m + 1, law, k, c, theta, (float(np.max(np.abs(x))), float(np.max(np.abs(v)))),
                              float(R[m, -1])),
        terms=_terms(law, k, c, theta), nrmse_before=before, nrmse_after=after, beats_linear=beats,
        checks={"equation_error_loro_m2_s4": errors,
                "training_nrmse": {"linear": problem.nrmse(cost_start), "linear (refitted)": problem.nrmse(cost_base),
                                   "law": problem.nrmse(cost_law)},
                "held_out_nrmse_linear_refitted": refitted},
        plot={"eta": x[pick], "measured": y[pick] - k * x[pick] - c * v[pick],
              "law": sum(th * col.signal[pick] for col, th in zip(law, theta))})


def modal_discovered_figure(discovery: ModalDiscovery) -> Figure:
    """The mode's restoring force per unit modal mass beyond the law's linear part, against its
    displacement, from the data (equation form) and from the discovered law's terms (a matplotlib figure)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    p = discovery.plot
    fig, ax = plt.subplots(figsize=(7, 5))
    ax.plot(1e3 * p["eta"], p["measured"], ".", color="0.5", ms=3,
            label="-(eta'' + z'') - (k eta + c eta'), training runs")
    ax.plot(1e3 * p["eta"], p["law"], ".", color="C3", ms=1, label="the discovered law's nonlinear terms")
    ax.set_xlabel(f"modal displacement eta of mode {discovery.location['mode']} (mm)")
    ax.set_ylabel("force per unit modal mass beyond k eta + c eta' (m/s^2)", fontsize=9)
    ax.set_title(f"mode {discovery.location['mode']}: held-out NRMSE {100 * discovery.nrmse_before:.2f} % -> "
                 f"{100 * discovery.nrmse_after:.2f} % ({'beats' if discovery.beats_linear else 'does not beat'} "
                 f"the linear model)", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_modal_discovered(discovery: ModalDiscovery, path: str | os.PathLike) -> None:
    """``discovered.png``: :func:`modal_discovered_figure` as a PNG."""
    import matplotlib.pyplot as plt

    fig = modal_discovered_figure(discovery)
    fig.savefig(path, dpi=90)
    plt.close(fig)
