"""Stage 5 of the added-mass diagnosis: every registered mechanism's signature, fitted where it could be.

Each kind of :mod:`momentid.mechanisms` states its signature in the floor-force residual
(:meth:`~momentid.mechanisms.base.MechanismKind.screen_equation`); its coefficients are fitted by
least squares together with the linear confounds the identified model may already have absorbed,
on half of the data (alternate time blocks), and scored on the other half by the share of the
*excess over noise* it explains.  Faults of the table channel show only in replays driven by it
(:func:`screen_replay`); a flexibly attached mass is tested by replay too
(:func:`screen_attachment`); a linear damper hides in the identified C, so it is also tested on
the identified matrices (:func:`damping_pattern`).  Every kind is screened at every place of its
target (:meth:`~momentid.mechanisms.base.MechanismKind.places`), links first.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
import enum
import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from momentid import mechanisms
from momentid.core.series import RunData
from momentid.diagnosis.added_mass.kinematic_check import ROUND_OFF
from momentid.diagnosis.added_mass.residuals import (ResidualRow, blocks, replay_noise, replay_outputs)
from momentid.estimation.reconstruct import Prefilter, band_filter
from momentid.diagnosis.thresholds import EXCESS, NOTHING_TO_EXPLAIN
from momentid.errors import IdentificationError
from momentid.estimation.identification import damping_models
from momentid.estimation.identified import Identification
from momentid.estimation.linear import discretize, outputs, simulate_linear
from momentid.mechanisms.base import EquationSignals, MechanismKind, Refit, Screened, drifts
from momentid.mechanisms.place import Place, Target

__all__ = ["Domain", "Candidate", "ReplayResiduals", "DampingPattern", "screen_equation", "screen_replay",
           "screen_attachment", "damping_pattern", "signature_columns", "remaining_excess", "pattern_fit",
           "screening_order", "linear_springs_left", "screen_storeys", "storey_shear"]

#: Attachment frequencies tried by replay: from just above the top mode ...
ATTACHMENT_LOW_OVER_TOP_MODE = 1.1
#: ... to the lower of 0.4 x the sample rate (the band's ceiling) and 20 x the top mode (an
#: attachment that stiff moves with its floor) ...
ATTACHMENT_HIGH_OVER_SAMPLE_RATE = 0.4
ATTACHMENT_HIGH_OVER_TOP_MODE = 20.0
#: ... in this many log-spaced points, at this damping ratio; the best is then refined.
ATTACHMENT_GRID_POINTS = 28
ATTACHMENT_DAMPING_RATIO = 0.05
#: The damping-pattern test runs when the Rayleigh model of the identified C is rejected (p-value
#: below this) and misses by more than this share of C's norm.
RAYLEIGH_P_VALUE = 1e-3
RAYLEIGH_MISFIT = 0.02


class Domain(str, enum.Enum):
    """Where a candidate was screened (its ``domain`` in ``report.json``)."""

    EQUATION = "equation"                    # floor-force residual of the identified model
    NOMINAL = "equation (nominal model)"     # floor-force residual of the lab's nominal model
    REPLAY = "replay"                        # replay residual (driven by the recorded table channel)
    SENSORS = "sensors"                      # the channels checked against each other
    PARAMETERS = "parameters"                # the pattern of the identified matrices

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class Candidate:
    """One fitted candidate mechanism: a kind at a place, its fitted parameters and standard errors,
    the share of the excess residual it explains on held-out blocks, and where it was screened."""

    kind: MechanismKind
    place: Place
    parameters: dict
    std: dict
    explained: float
    domain: Domain

    @property
    def mechanism(self) -> str:
        """The kind's name."""
        return self.kind.name

    @property
    def location(self) -> dict:
        """The place as a record's location (``{"storey": 2}``, ...)."""
        return self.place.location

    def same_as(self, other: Candidate) -> bool:
        """The same kind at the same place (whatever the fit)."""
        return self.kind is other.kind and self.place == other.place

    def to_dict(self) -> dict:
        """An entry of ``report.json``'s ``candidates``."""
        return {"mechanism": self.mechanism, "location": self.location, "parameters": self.parameters,
                "std": self.std, "explained": self.explained, "domain": self.domain}


@dataclass(frozen=True)
class ReplayResiduals:
    """The replay residual of the floor accelerometers (driven by the recorded table channel).

    ``excess``: per channel, residual RMS / noise-only RMS; ``candidates``: table-channel faults.
    """

    excess: dict
    candidates: tuple[Candidate, ...]

    @property
    def mismatch(self) -> bool:
        """Whether some channel's replay residual exceeds ``EXCESS`` times its noise."""
        return max(self.excess.values(), default=0) > EXCESS


@dataclass(frozen=True)
class DampingPattern:
    """A dashpot read from the identified C (``candidate``) and the fits behind it (``info``, reported
    as ``parameter_pattern``)."""

    candidate: Candidate
    info: dict


@dataclass(frozen=True)
class _Fixed:
    """Confound columns fitted with every candidate of one residual (the signatures of mechanisms already
    found), cut to the train and test blocks once, with their products among themselves and with the
    target (itself cut once: ``y_train``, ``y_test``): a candidate's fit then multiplies only its own few
    columns over the samples.  ``finite``: the columns and the target are."""

    train: np.ndarray
    test: np.ndarray
    G: np.ndarray
    H: np.ndarray
    g: np.ndarray
    h: np.ndarray
    y_train: np.ndarray
    y_test: np.ndarray
    finite: bool

    @classmethod
    def of(cls, columns: list[np.ndarray], target: np.ndarray, train: np.ndarray, test: np.ndarray) -> _Fixed:
        """The fixed columns (n,) each, the target (n,) and the block masks (n,)."""
        E = np.column_stack(columns) if columns else np.empty((len(target), 0))
        Etr, Ete, ytr, yte = E[train], E[test], target[train], target[test]
        return cls(Etr, Ete, Etr.T @ Etr, Ete.T @ Ete, Etr.T @ ytr, Ete.T @ yte, ytr, yte,
                   bool(np.all(np.isfinite(E)) and np.all(np.isfinite(target))))


def _products(A: np.ndarray, y: np.ndarray, E: np.ndarray, EE: np.ndarray, Ey: np.ndarray):
    """Gram matrix and target products of the columns ``[A, E]`` (on one block), ``E``'s own given."""
    AE = A.T @ E
    return np.block([[A.T @ A, AE], [AE.T, EE]]), np.concatenate([A.T @ y, Ey]), float(y @ y)


def _fit(columns: list[np.ndarray], confounds: list[np.ndarray], target: np.ndarray, train, test,
         noise_rss_test: float, fixed: _Fixed | None = None):
    """LS of ``target`` on signature + confound columns (then the ``fixed`` ones) on ``train``; score on ``test``.

    A handful of columns over many samples: solved through the (scaled) normal equations of each
    half, so every sum of squares below is a quadratic form of small Gram matrices.  Returns
    (coefficients, standard errors, share explained) of the signature columns, or None when a
    column is zero, or a column or the target is not finite (a replay of an unstable identified model
    that overflowed: nothing to fit).  ``fixed``, when given, was built on this ``target`` and these
    blocks (:meth:`_Fixed.of`), and the target is read from it.
    """
    fixed = _Fixed.of([], target, train, test) if fixed is None else fixed
    A = np.column_stack(columns + confounds)
    if not (fixed.finite and np.all(np.isfinite(A))):
        return None
    G, g, yy = _products(A[train], fixed.y_train, fixed.train, fixed.G, fixed.g)
    H, h, zz = _products(A[test], fixed.y_test, fixed.test, fixed.H, fixed.h)
    scale = np.sqrt(np.diag(G))
    if np.any(scale == 0):
        return None
    G, H = G / np.outer(scale, scale), H / np.outer(scale, scale)
    g, h = g / scale, h / scale
    k = len(columns)

    def solve(idx):
        return np.linalg.lstsq(G[np.ix_(idx, idx)], g[idx], rcond=1e-12)[0]

    def test_rss(idx, c):
        return max(zz - 2 * float(c @ h[idx]) + float(c @ H[np.ix_(idx, idx)] @ c), 0.0)

    every = np.arange(G.shape[0])
    coef = solve(every)
    after = test_rss(every, coef)
    # Confounds alone: the part of the improvement that needs no mechanism.
    base = test_rss(every[k:], solve(every[k:])) if G.shape[0] > k else zz
    if base <= NOTHING_TO_EXPLAIN * noise_rss_test:
        return coef[:k] / scale[:k], np.zeros(k), 0.0
    explained = (base - after) / (base - noise_rss_test)
    rss = max(yy - 2 * float(coef @ g) + float(coef @ G @ coef), 0.0)
    dof = max(int(train.sum()) - G.shape[0], 1)
    cov = np.linalg.pinv(G) * (rss / dof)
    # A signature nearly collinear with its confounds (a tuned-mass damper's body tuned far above the motion
    # moves with its floor) leaves a variance of round-off size, of either sign: no variance is below 0.
    return coef[:k] / scale[:k], np.sqrt(np.maximum(np.diag(cov)[:k], 0.0)) / scale[:k], float(explained)


def _fitter(target: np.ndarray, train: np.ndarray, test: np.ndarray, noise_rss: float, extra=()):
    """The :data:`~momentid.mechanisms.base.Fitter` of one residual (n, d) and its block masks (n,).

    ``extra``: columns (n, d) fitted with every signature as further confounds (the signatures of
    mechanisms already found: each candidate is then scored on what they leave).
    """
    d = target.shape[1]
    train_d, test_d, y = np.repeat(train, d), np.repeat(test, d), target.ravel()
    fixed = _Fixed.of([c.ravel() for c in extra], y, train_d, test_d)

    def fit(columns, confounds, place, to_params) -> list[Screened]:
        res = _fit([c.ravel() for c in columns], [c.ravel() for c in confounds], y, train_d, test_d, noise_rss,
                   fixed)
        if res is None:
            return []
        coef, std, explained = res
        params, pstd = to_params(coef, std)
        return [Screened(place, params, pstd, explained)]
    return fit


def _attachment_response(fs: float):
    def response(a_j, frequency, damping_ratio):
        w = 2 * np.pi * frequency
        osc = discretize(np.eye(1), np.eye(1) * 2 * damping_ratio * w, np.eye(1) * w * w, 1 / fs)
        return outputs(osc, simulate_linear(osc, a_j))["a"][:, 0]
    return response


def _equation_signals(result, rows: tuple[ResidualRow, ...], f_top: float) -> EquationSignals:
    """The training rows' band-limited signals, stacked, with the model ``result``'s matrices."""
    fs = rows[0].run.sample_rate
    a, v, q = (np.concatenate([r.signals[g] for r in rows]) for g in ("a", "v", "q"))
    dm = np.concatenate([np.broadcast_to(r.run.added_mass, r.signals["a"].shape) for r in rows])
    return EquationSignals(a=a, v=v, q=q, added_mass=dm, drift=drifts(q), drift_velocity=drifts(v),
                           jerk=np.gradient(a, 1 / fs, axis=0), masses=np.diag(result.M), C=result.C,
                           K=result.K, sample_rate=fs, f_top=f_top, attachment_response=_attachment_response(fs))


def signature_columns(kind: MechanismKind, signals: EquationSignals, place: Place) -> list[np.ndarray]:
    """The columns (n, d each) ``kind`` fits at ``place``: its signature and the linear confounds it is
    fitted with, as its :meth:`~momentid.mechanisms.base.MechanismKind.screen_equation` passes them."""
    taken: list[np.ndarray] = []

    def capture(columns, confounds, where, to_params):
        if where == place:
            taken.extend(list(columns) + list(confounds))
        return []
    kind.screen_equation(signals, capture, place)
    return taken


def screening_order(kinds: Iterable[MechanismKind], storeys: int) -> list[tuple[MechanismKind, Place]]:
    """Every (kind, place) of ``kinds`` in a rig of ``storeys`` storeys, in the order screening visits
    them: storeys first, then the other places, each floor from the lowest up, the kinds in turn."""
    pairs = [(kind, place) for kind in kinds for place in kind.places(storeys)]
    return sorted(pairs, key=lambda kp: (kp[1].target is not Target.STOREY, kp[1].level))


def screen_equation(result: Identification, rows: tuple[ResidualRow, ...], noise_floor: np.ndarray, f_top: float,
                    domain: Domain, found: Sequence[tuple[MechanismKind, Place]] = (),
                    kinds: Iterable[MechanismKind] | None = None) -> list[Candidate]:
    """Candidates whose signature lives in the floor-force residual ``rows`` of the model ``result``.

    ``found``: (kind, place) of mechanisms already found; their columns are fitted with every
    candidate (:func:`signature_columns`), which is scored on what they leave, and they are not
    candidates again.  ``kinds``: the kinds screened (default: the library).
    """
    fs = rows[0].run.sample_rate
    train = np.concatenate([blocks(r.signals["a"].shape[0], fs)[0] for r in rows])
    test = ~train
    target = np.concatenate([r.residual for r in rows])                     # (N, d)
    noise_rss = float(np.sum(noise_floor ** 2)) * int(test.sum())
    signals = _equation_signals(result, rows, f_top)
    extra = [c for kind, place in found for c in signature_columns(kind, signals, place)]
    fit = _fitter(target, train, test, noise_rss, extra)
    kinds = mechanisms.library() if kinds is None else kinds
    done = set(found)
    return [Candidate(kind, s.place, s.parameters, s.std, s.explained, domain)
            for kind, place in screening_order(kinds, signals.storeys)
            for s in kind.screen_equation(signals, fit, place) if (kind, s.place) not in done]


def remaining_excess(result: Identification, rows: tuple[ResidualRow, ...], noise_floor: np.ndarray, f_top: float,
                     found: Sequence[tuple[MechanismKind, Place]]) -> np.ndarray:
    """Per floor (d,): RMS of the residual ``rows`` on the held-out blocks once the columns of the
    mechanisms ``found`` ((kind, place) each) are fitted on the others, over the noise-only RMS.

    The equation residual's excess given what is already found: near 1 when nothing is left.
    """
    return _excess_left(rows, noise_floor, _found_columns(result, rows, f_top, found)[1])


def _found_columns(result: Identification, rows: tuple[ResidualRow, ...], f_top: float,
                   found: Sequence[tuple[MechanismKind, Place]]) -> tuple[EquationSignals, list[np.ndarray]]:
    """The rows' equation signals and the signature columns (N, d) each of the mechanisms ``found``."""
    signals = _equation_signals(result, rows, f_top)
    return signals, [c for kind, place in found for c in signature_columns(kind, signals, place)]


def _excess_left(rows: tuple[ResidualRow, ...], noise_floor: np.ndarray, columns: list[np.ndarray]) -> np.ndarray:
    """:func:`remaining_excess` once the found mechanisms' ``columns`` (N, d) each are known.  Their
    least squares goes through the scaled normal equations: a few dozen columns over the samples, whose
    Gram matrix is small (the fit's residual is what counts, not the coefficients of columns that may be
    nearly collinear)."""
    fs = rows[0].run.sample_rate
    train = np.concatenate([blocks(r.signals["a"].shape[0], fs)[0] for r in rows])
    target = np.concatenate([r.residual for r in rows])
    left = target[~train]
    if columns:
        X = np.stack(columns, axis=-1)                                        # (N, d, m)
        Xtr = X[train].reshape(-1, X.shape[-1])
        scale = np.linalg.norm(Xtr, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        Xtr = Xtr / scale
        coef = np.linalg.lstsq(Xtr.T @ Xtr, Xtr.T @ target[train].ravel(), rcond=1e-12)[0]
        left = left - X[~train] @ (coef / scale)
    return np.sqrt(np.mean(left ** 2, axis=0)) / noise_floor


def linear_springs_left(result: Identification, rows: tuple[ResidualRow, ...], noise_floor: np.ndarray,
                        f_top: float, found: Sequence[tuple[MechanismKind, Place]],
                        candidates: Iterable[Candidate]) -> list[Candidate]:
    """Candidates of ``linear_spring`` kinds (P-Delta) fitted to the nominal model's residual ``rows``,
    scored by the share of the excess the mechanisms ``found`` leave that their columns (with their
    confounds: a spring and a dashpot at the storey) remove on held-out blocks.

    Their own score leaves out what the confounds take: the storey's spring, which for a linear
    spring kind is most of it (the floors' own weight, the same in every run).  Beside a strong
    nonlinearity elsewhere, which distorts the identified model more than the added masses change
    the storey, what the lab's model leaves at that storey is the evidence; re-simulation decides.
    """
    signals, columns = _found_columns(result, rows, f_top, found)
    before = _excess_left(rows, noise_floor, columns) ** 2
    if before.max() <= EXCESS ** 2:
        return []
    out = []
    for c in candidates:
        if c.kind.linear_spring:
            after = _excess_left(rows, noise_floor, columns + signature_columns(c.kind, signals, c.place)) ** 2
            share = float(np.sum(before - after) / np.sum(np.maximum(before - 1.0, 0.0)))
            out.append(Candidate(c.kind, c.place, c.parameters, c.std, share, c.domain))
    return out


def storey_shear(x: np.ndarray) -> np.ndarray:
    """Storey shears from floor forces (..., d): ``V_s = sum over floors i >= s``.  A force across
    storey ``s`` alone shows in ``V_s`` alone (it pushes its two floors equally and oppositely)."""
    return np.cumsum(x[..., ::-1], axis=-1)[..., ::-1]


def screen_storeys(result: Identification, rows: tuple[ResidualRow, ...], f_top: float, domain: Domain,
                   found: Sequence[tuple[MechanismKind, Place]] = (),
                   kinds: Iterable[MechanismKind] | None = None) -> list[Candidate]:
    """Storey candidates scored on their own storey's shear residual, at the storeys where the
    mechanisms ``found`` leave an excess there (above ``EXCESS`` of the noise's shear).

    :func:`screen_equation` scores a candidate by the share of the whole residual's excess it
    explains; beside a mechanism whose own misfit is large (a friction that sticks, whose signature
    is a smoothed sign of noisy drift velocities), a second mechanism in another storey holds a few
    percent of that excess and is never re-simulated, though its storey's shear holds nothing else.
    Here each storey's shear is the target, the found mechanisms' columns (those acting across it)
    confounds; ``explained`` is the share of that storey's excess (re-simulation decides).
    """
    fs = rows[0].run.sample_rate
    train = np.concatenate([blocks(r.signals["a"].shape[0], fs)[0] for r in rows])
    test = ~train
    V = storey_shear(np.concatenate([r.residual for r in rows]))
    N = storey_shear(np.concatenate([r.noise for r in rows]))
    signals = _equation_signals(result, rows, f_top)
    found_columns = [storey_shear(c) for kind, place in found for c in signature_columns(kind, signals, place)]
    kinds = mechanisms.library() if kinds is None else kinds
    done, out = set(found), []
    for s in range(signals.storeys):
        noise_ms = float(np.mean(N[:, s] ** 2))
        extra = [c[:, s] for c in found_columns if np.any(c[train, s] != 0)]
        left = V[:, s]
        if extra:
            X = np.column_stack(extra)
            left = left - X @ np.linalg.lstsq(X[train], left[train], rcond=None)[0]
        if noise_ms <= 0 or np.mean(left[test] ** 2) <= EXCESS ** 2 * noise_ms:
            continue

        fixed = _Fixed.of(extra, V[:, s], train, test)

        def fit(columns, confounds, place, to_params, s=s, fixed=fixed):
            confounds = [c[:, s] for c in map(storey_shear, confounds) if np.any(c[train, s] != 0)]
            res = _fit([storey_shear(c)[:, s] for c in columns], confounds, V[:, s], train, test,
                       noise_ms * int(test.sum()), fixed)
            if res is None:
                return []
            coef, std, explained = res
            params, pstd = to_params(coef, std)
            return [Screened(place, params, pstd, explained)]
        for kind in kinds:
            for place in kind.places(signals.storeys):
                if place.target is Target.STOREY and place.level == s + 1 and (kind, place) not in done:
                    out += [Candidate(kind, sc.place, sc.parameters, sc.std, sc.explained, domain)
                            for sc in kind.screen_equation(signals, fit, place)]
    return out


def screen_replay(result: Identification, runs: Sequence[RunData], d: int, band: Prefilter) -> ReplayResiduals:
    """Table-accelerometer faults: visible only when the model is driven by the recorded base."""
    fs = runs[0].sample_rate
    target, sims, rates, steps, noise = [], [], [], [], []
    for run in runs:
        meas = band_filter(run.group("a", d), fs, band)
        sim = band_filter(replay_outputs(result, run)["a"], fs, band)
        target.append(meas - sim)
        sims.append(sim)
        rates.append(np.gradient(sim, 1 / fs, axis=0))
        steps.append(band_filter(replay_outputs(result, run, np.ones(run.n_samples))["a"], fs, band))
        noise.append(replay_noise(result, run, d, band)["a"])
    target = np.concatenate(target)
    scale = np.sqrt(np.mean(np.concatenate(sims) ** 2, axis=0))
    rms = np.sqrt(np.mean(target ** 2, axis=0))
    # Noise-free data: the floor is what the replay's straight-line table drive between samples leaves
    # open (consistency.inter_sample: h^2/12 of the replay's second derivative, by Parseval), and round-off.
    between = np.sqrt(np.mean(np.concatenate([np.diff(s, 2, axis=0) for s in sims]) ** 2, axis=0)) / 12
    floor = np.maximum.reduce([np.mean(noise, axis=0), between, ROUND_OFF * scale])
    excess = {f"a{j + 1}": float(rms[j] / floor[j]) for j in range(d)}
    train = np.concatenate([blocks(r.n_samples, fs)[0] for r in runs])
    test = ~train
    fit = _fitter(target, train, test, float(np.sum(floor ** 2)) * int(test.sum()))
    sims, rates, steps = np.concatenate(sims), np.concatenate(rates), np.concatenate(steps)
    cands = []
    table = Place(Target.CHANNEL, "zdd")
    for kind in mechanisms.library():
        signature = kind.replay_column(sims, rates, steps) if kind.target is Target.CHANNEL else None
        if signature is not None:
            column, to_params = signature
            cands += [Candidate(kind, s.place, s.parameters, s.std, s.explained, Domain.REPLAY)
                      for s in fit([column], [], table, to_params)]
    return ReplayResiduals(excess=excess, candidates=tuple(cands))


def _attachment_replay(kind, result, run, d, j, f_a, zeta):
    """Floor accelerations (n, d) of the model with ``run``'s added mass on floor j on its attachment."""
    dm = np.asarray(run.added_mass, float).copy()
    m_a = dm[j]
    dm[j] = 0.0
    # floor damping as before: mu times the floor's mass with every added mass
    M, C, K = kind.attachment_matrices(result.M + np.diag(dm),
                                       result.C + result.mu * np.diag(np.asarray(run.added_mass)),
                                       result.K, j, m_a, f_a, zeta)
    linear = discretize(M, C, K, 1 / run.sample_rate)
    return outputs(linear, simulate_linear(linear, run["zdd"]))["a"][:, :d]


def screen_attachment(result: Identification, runs: Sequence[RunData], d: int, band: Prefilter, f_top: float
                      ) -> list[Candidate]:
    """A flexibly attached added mass, tested by replay (sensor noise does not enter the signature)."""
    fs = runs[0].sample_rate
    out = []
    for kind in mechanisms.library():
        if kind.refit is not Refit.ATTACHMENT:
            continue
        found = []
        for place in kind.places(d):
            j = place.index - 1
            loaded = [r for r in runs if r.added_mass[j] > 0 and r.has("a1")]
            if not loaded:
                continue
            meas = [band_filter(r.group("a", d), fs, band) for r in loaded]
            rigid = [band_filter(replay_outputs(result, r)["a"], fs, band) for r in loaded]
            noise = sum(r.n_samples * float(np.sum(replay_noise(result, r, d, band)["a"] ** 2)) for r in loaded)
            base = sum(float(np.sum((m - y) ** 2)) for m, y in zip(meas, rigid))
            if base <= NOTHING_TO_EXPLAIN * noise:
                continue

            def rss(f_a, zeta, j=j, meas=meas, loaded=loaded):   # bound now: refined after the loop
                try:
                    return sum(float(np.sum((m - band_filter(_attachment_replay(kind, result, r, d, j, f_a, zeta),
                                                             fs, band)) ** 2)) for m, r in zip(meas, loaded))
                except IdentificationError:   # a trial attachment no sampled model can hold (too fast)
                    return math.inf

            grid = [(f_a, rss(f_a, ATTACHMENT_DAMPING_RATIO)) for f_a in np.geomspace(
                ATTACHMENT_LOW_OVER_TOP_MODE * f_top,
                min(ATTACHMENT_HIGH_OVER_SAMPLE_RATE * fs, ATTACHMENT_HIGH_OVER_TOP_MODE * f_top),
                ATTACHMENT_GRID_POINTS)]
            f_a, best = min(grid, key=lambda x: x[1])
            n_eff = sum(r.n_samples for r in loaded) * d * min(1.0, 2 * (band.high or fs / 2) / fs)
            found.append((best, place, f_a, base, noise, rss, n_eff))
        if not found:
            continue
        # The attachment's frequency and damping, refined where the grid removes the most misfit: each
        # floor is fitted on its own loaded runs, so the misfits left are sums over different runs (a
        # floor loaded in one run leaves less than the true one loaded in three) and only what each
        # removes compares (a floor's unloaded runs keep the rigid replay's misfit either way).
        _, place, f_a, base, noise, rss, n_eff = min(found, key=lambda x: x[0] - x[3])
        params, std, best = _refine_oscillator(rss, f_a, ATTACHMENT_DAMPING_RATIO, n_eff)
        out.append(Candidate(kind, place, params, std, float((base - best) / (base - noise)), Domain.REPLAY))
        for b, other, f_k, base_k, noise_k, _, _ in found:
            if other != place:
                out.append(Candidate(kind, other, {"frequency": float(f_k), "damping_ratio": ATTACHMENT_DAMPING_RATIO},
                                     {}, float((base_k - b) / (base_k - noise_k)), Domain.REPLAY))
    return out


#: Refinement of an attachment: Nelder-Mead tolerance on (log f, log zeta), evaluations allowed, the
#: largest damping ratio tried, and the steps in (log f, log zeta) of the curvature's differences.
_REFINE_XATOL, _REFINE_EVALUATIONS, _MAX_DAMPING_RATIO = 1e-3, 80, 2.0
#: Nelder-Mead stops when the misfit changes by less than this fraction of its starting value.
_REFINE_FATOL = 1e-9
_CURVATURE_STEPS = (0.002, 0.02)


def _refine_oscillator(rss, f0: float, zeta0: float, n_eff: float):
    """Least-squares (frequency, damping ratio) of an attachment from the grid's best point.

    Nelder-Mead on (log f, log zeta); standard errors from the curvature of the misfit,
    ``cov = 2 s^2 H^-1`` with ``s^2 = rss / n_eff``.  Returns (parameters, std, rss at the optimum).
    """
    def cost(x):
        return rss(math.exp(x[0]), min(math.exp(x[1]), _MAX_DAMPING_RATIO))

    x0 = np.array([math.log(f0), math.log(zeta0)])
    res = scipy.optimize.minimize(cost, x0, method="Nelder-Mead",
                                  options={"xatol": _REFINE_XATOL, "fatol": _REFINE_FATOL * cost(x0),
                                           "maxfev": _REFINE_EVALUATIONS})
    x = res.x if res.fun < cost(x0) else x0
    f, zeta = math.exp(x[0]), min(math.exp(x[1]), _MAX_DAMPING_RATIO)
    q0 = cost(x)
    h = np.array(_CURVATURE_STEPS)
    H = np.zeros((2, 2))
    for a in range(2):
        for b in range(2):
            ea, eb = np.eye(2)[a] * h[a], np.eye(2)[b] * h[b]
            H[a, b] = ((cost(x + ea + eb) - cost(x + ea - eb) - cost(x - ea + eb) + cost(x - ea - eb))
                       / (4 * h[a] * h[b]))
    std = {}
    try:
        cov = 2 * (q0 / max(n_eff - 2, 1)) * np.linalg.inv(H)
        if np.all(np.diag(cov) > 0):
            std = {"frequency": float(f * math.sqrt(cov[0, 0])), "damping_ratio": float(zeta * math.sqrt(cov[1, 1]))}
    except np.linalg.LinAlgError:
        pass
    return {"frequency": float(f), "damping_ratio": float(zeta)}, std, float(q0)


def damping_pattern(result: Identification, d: int) -> DampingPattern | None:
    """A linear dashpot hides in the identified C: look for the pattern of one, of any kind the
    library sizes by it (``Refit.DAMPING_PATTERN``) at any of its places (``C = a M + b K + c P``, ``P``
    the kind's term there, :meth:`~momentid.mechanisms.base.MechanismKind.damping_pattern`).  The place
    whose pattern fits best wins (on a tie, the first in :func:`screening_order`)."""
    kinds = [k for k in mechanisms.library() if k.refit is Refit.DAMPING_PATTERN]
    fits = {f.model: f for f in damping_models(result)}
    ray = fits["rayleigh"]
    if not kinds or not (ray.p_value < RAYLEIGH_P_VALUE and ray.misfit > RAYLEIGH_MISFIT):
        return None
    mis, coef, kind, place = min((pattern_fit(result, kind.damping_pattern(place, d)) + (kind, place)
                                  for kind, place in screening_order(kinds, d)), key=lambda x: x[0])
    cand = Candidate(kind, place, {kind.fitted.name: float(coef[2])}, {}, float(1.0 - mis / ray.misfit),
                     Domain.PARAMETERS)
    return DampingPattern(cand, {"rayleigh_misfit": ray.misfit, "rayleigh_p_value": ray.p_value,
                                 "with_damper_misfit": mis, "coefficients": [float(x) for x in coef]})


def pattern_fit(result: Identification, pattern: np.ndarray) -> tuple[float, np.ndarray]:
    """The identified C as ``a M + b K + c P`` (``pattern`` P: (d, d), a dashpot's term), least squares
    over the upper triangle.  Returns (relative misfit, (a, b, c))."""
    iu = np.triu_indices(result.storeys)
    c = result.C[iu]
    A = np.column_stack([result.M[iu], result.K[iu], pattern[iu]])
    coef, *_ = np.linalg.lstsq(A, c, rcond=None)
    return float(np.linalg.norm(c - A @ coef) / np.linalg.norm(c)), coef
