"""When model and recordings disagree: locate the mismatch, name the physics, add it.

Pipeline (:func:`diagnose`):

1. **Linear model** identified from the recordings themselves (``identify``,
   errors-in-variables for noisy data), beside the nominal model the lab states.
2. **Residuals** in two domains.  *Equation residual*: the force per floor
   (and storey shear) the identified linear model leaves unexplained, on
   band-limited signals, compared with what sensor noise alone leaves
   (the same propagation applied to synthetic noise of the measured levels).
   *Replay residual*: each run's measured table acceleration replayed
   through the model, compared with the recorded floor channels.
3. **Screening**: every candidate mechanism at every location is a
   parametrised force signature (or a sensor transformation); its
   coefficient is fitted by least squares together with the linear
   confounds the identified model may already have absorbed, on half of the
   data (alternate time blocks), and scored on the other half by the share of
   the *excess over noise* it explains.  A linear damper hides in the
   identified C, so ``extra_damper`` is tested on the identified matrices
   (the damping-model check) instead.
4. **Verdict**: ``none`` when residuals sit at the noise level;
   ``unexplained`` when no candidate explains most of the excess; otherwise the
   best candidate, whose augmented MuJoCo model is replayed on a held-out run
   (NRMSE before/after, on band-limited channels).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.signal

from momentid.lab import rig
from momentid.core.analytic import modal_properties, shear_stiffness
from momentid.diagnosis.consistency import kinematic_check, noise_sigma
from momentid.diagnosis.locate import locate
from momentid.core.series import Experiment, RunData, json_safe
from momentid.errors import IdentificationError, ModelError, SimulationError
from momentid.estimation.identification import damping_models, identify
from momentid.estimation.linear import discretize, outputs, simulate_linear
from momentid.estimation.reconstruct import Prefilter, prepare_run, suggest_band
from momentid.core.structure import Mechanism, Structure

__all__ = ["Candidate", "Diagnosis", "diagnose", "write_report", "MECHANISM_IDS"]

MECHANISM_IDS = ("none", "unexplained", "coulomb_friction", "cubic_stiffness", "extra_damper", "p_delta",
                 "flexible_added_mass", "sensor_delay", "sensor_gain", "sensor_bias")
#: Residual RMS above this multiple of the noise-only level counts as a mismatch.
EXCESS = 1.3
#: A candidate must explain this share of the excess (on held-out blocks) to be named.
EXPLAINED = 0.5
#: ... and its augmented model must remove this share of the training runs' replay misfit above the
#: noise (0.75: the misfit at least halves when noise is negligible).
ACCEPTED = 0.75
_BLOCK_S = 1.0


@dataclass(frozen=True)
class Candidate:
    """One fitted candidate mechanism."""

    mechanism: str
    location: dict
    parameters: dict
    std: dict
    explained: float          # share of the excess residual explained on held-out blocks
    domain: str               # "equation" or "replay"


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose` (see ``report.json`` for the serialised form)."""

    mechanism: str
    location: dict
    parameters: dict
    std: dict
    nrmse_before: float
    nrmse_after: float
    excess_equation: dict      # per floor: residual RMS / noise-only RMS
    excess_replay: dict        # per channel: replay NRMSE / noise-only NRMSE
    candidates: tuple[Candidate, ...]
    summary: str
    holdout: str
    parameter_pattern: dict = field(default_factory=dict)
    sensor_check: dict = field(default_factory=dict)   # a_j = zdd + q_j'': excess per floor, best fits
    selection: dict = field(default_factory=dict)      # training-run NRMSE of each re-simulated candidate
    localisation: dict = field(default_factory=dict)   # storey, runs, time windows, amplitude, bands, shape
    augmented_xml: str = ""
    curves: dict = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        return {
            "mechanism": self.mechanism, "location": self.location, "parameters": self.parameters,
            "std": self.std, "nrmse_before": self.nrmse_before, "nrmse_after": self.nrmse_after,
            "summary": self.summary, "holdout": self.holdout,
            "excess_equation": self.excess_equation, "excess_replay": self.excess_replay,
            "parameter_pattern": self.parameter_pattern, "sensor_check": self.sensor_check,
            "selection": self.selection, "localisation": self.localisation,
            "candidates": [asdict(c) for c in self.candidates],
        }


# ----------------------------------------------------------------------------- helpers

def _with_values(run: RunData, values: np.ndarray) -> RunData:
    return replace(run, values=values)


def _signals(run: RunData, d: int, band: Prefilter) -> dict[str, np.ndarray]:
    s = prepare_run(run, d, band)
    if "zdd" not in s and run.has("zdd"):
        s["zdd"] = run["zdd"]
    return s


def _floor_residual(result, s, dm) -> np.ndarray:
    D = np.diag(dm)
    return s["a"] @ (result.M + D).T + s["v"] @ (result.C + result.mu * D).T + s["q"] @ result.K.T


def _blocks(n: int, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Alternate blocks of ``_BLOCK_S`` seconds: (train mask, test mask)."""
    idx = (np.arange(n) / (fs * _BLOCK_S)).astype(int) % 2
    return idx == 0, idx == 1


def _fit(columns: list[np.ndarray], confounds: list[np.ndarray], target: np.ndarray, train, test,
         noise_rss_test: float):
    """LS of ``target`` on signature + confound columns on ``train``; score on ``test``.

    A handful of columns over many samples: solved through the (scaled) normal equations of each
    half, so every sum of squares below is a quadratic form of small Gram matrices.
    """
    X = np.column_stack(columns + confounds)
    Xtr, ytr, Xte, yte = X[train], target[train], X[test], target[test]
    scale = np.linalg.norm(Xtr, axis=0)
    if np.any(scale == 0):
        return None
    Xtr, Xte = Xtr / scale, Xte / scale
    G, g, yy = Xtr.T @ Xtr, Xtr.T @ ytr, float(ytr @ ytr)
    H, h, zz = Xte.T @ Xte, Xte.T @ yte, float(yte @ yte)
    k = len(columns)

    def solve(idx):
        return np.linalg.lstsq(G[np.ix_(idx, idx)], g[idx], rcond=1e-12)[0]

    def test_rss(idx, c):
        return max(zz - 2 * float(c @ h[idx]) + float(c @ H[np.ix_(idx, idx)] @ c), 0.0)

    every = np.arange(X.shape[1])
    coef = solve(every)
    after = test_rss(every, coef)
    # Confounds alone: the part of the improvement that needs no mechanism.
    base = test_rss(every[k:], solve(every[k:])) if confounds else zz
    if base <= 1.02 * noise_rss_test:
        return coef[:k] / scale[:k], np.zeros(k), 0.0   # nothing to explain
    explained = (base - after) / (base - noise_rss_test)
    rss = max(yy - 2 * float(coef @ g) + float(coef @ G @ coef), 0.0)
    dof = max(int(train.sum()) - X.shape[1], 1)
    cov = np.linalg.pinv(G) * (rss / dof)
    return coef[:k] / scale[:k], np.sqrt(np.diag(cov)[:k]) / scale[:k], float(explained)


# ----------------------------------------------------------------------------- the diagnosis

def _nominal_result(structure: Structure, like):
    """The nominal model in the shape of an identification result."""
    return replace(like, M=structure.mass_matrix(), C=structure.damping_matrix(), K=structure.stiffness_matrix(),
                   mu=structure.rayleigh_mu, kappa=structure.rayleigh_kappa, covariance=None)


def _identified_structure(result, nominal: Structure | None) -> Structure:
    d = result.storeys
    A = np.stack([shear_stiffness(np.eye(d)[s]) for s in range(d)], axis=-1).reshape(d * d, d)
    k, *_ = np.linalg.lstsq(A, result.K.ravel(), rcond=None)
    heights = nominal.storey_heights if nominal else (0.3,) * d
    base = nominal.base_mass if nominal else 100.0
    return Structure(masses=tuple(np.diag(result.M)), storey_stiffness=tuple(np.maximum(k, 1e-9)),
                     storey_heights=tuple(heights), rayleigh_mu=max(result.mu, 0.0),
                     rayleigh_kappa=max(result.kappa, 0.0), base_mass=base)


def diagnose(experiment: Experiment, *, replay: bool = True) -> Diagnosis:
    """Find, name and model the physics the linear shear model leaves out.

    Parameters
    ----------
    experiment : Experiment
        At least two runs (one with added mass); with three or more, the last
        run is held out for the before/after replay.
    replay : bool
        Replay the held-out run through the linear and augmented MuJoCo models
        (the NRMSE figures); off only for quick screening.
    """
    runs = experiment.runs
    d = experiment.storeys
    if len(runs) < 2:
        raise IdentificationError(f"{experiment.source}: diagnosis needs at least two runs, got {len(runs)}")
    hold = runs[-1] if len(runs) >= 3 else None
    train_runs = tuple(r for r in runs if r is not hold)
    train_exp = replace(experiment, runs=train_runs)
    result = identify(train_exp)
    f_top = float(result.modes().frequency.max())
    if experiment.structure is not None:   # a badly disturbed fit must not shrink the band
        s0 = experiment.structure
        f_nom = float(modal_properties(s0.mass_matrix(), s0.damping_matrix(), s0.stiffness_matrix()).frequency.max())
        f_top = max(f_top, f_nom) if np.isfinite(f_top) else f_nom
    ideal = result.estimator == "equation"
    band = Prefilter() if ideal else Prefilter(high=min(max(suggest_band(runs[0], d), 2.5 * f_top),
                                                         0.4 * runs[0].sample_rate))
    # ---- equation-domain residuals and their noise-only level
    rows = []
    for k, run in enumerate(train_runs):
        s = _signals(run, d, band)
        r = _floor_residual(result, s, run.added_mass)
        sig = noise_sigma(run)
        rng = np.random.default_rng(k)
        noise = np.column_stack([rng.standard_normal(run.n_samples) * sig[c] for c in run.channels])
        sn = _signals(_with_values(run, noise), d, band)
        rn = _floor_residual(result, sn, run.added_mass)
        rows.append((run, s, r, rn))
    rms = np.sqrt(np.mean(np.concatenate([x[2] for x in rows]) ** 2, axis=0))
    rms_noise = np.sqrt(np.mean(np.concatenate([x[3] for x in rows]) ** 2, axis=0))
    floor_scale = np.sqrt(np.mean(np.concatenate([x[1]["a"] @ result.M.T for x in rows]) ** 2, axis=0))
    noise_floor = np.maximum(rms_noise, 1e-7 * floor_scale)   # noise-free data: round-off
    excess_eq = {f"floor{j + 1}": float(rms[j] / noise_floor[j]) for j in range(d)}
    candidates = _screen_equation(result, rows, d, noise_floor, f_top)
    nom_mismatch = False
    if experiment.structure is not None:
        # The nominal model the lab states: when it is right but for the missing physics, its residual
        # is that physics alone, undisturbed by what a linear fit absorbed.
        nom = _nominal_result(experiment.structure, result)
        nrows = [(run, s, _floor_residual(nom, s, run.added_mass), rn) for run, s, _, rn in rows]
        nom_rms = np.sqrt(np.mean(np.concatenate([x[2] for x in nrows]) ** 2, axis=0))
        nom_mismatch = bool(np.max(nom_rms / noise_floor) > EXCESS)
        for c in _screen_equation(nom, nrows, d, noise_floor, f_top):
            candidates.append(replace(c, domain="equation (nominal model)"))
    # ---- where and how: the storey shear residual by storey, run, time, amplitude, band and shape
    # (the nominal model's when it shows the mismatch: nothing absorbed by a fit)
    freqs = result.modes().frequency
    f_low = float(np.min(freqs)) if np.all(np.isfinite(freqs)) else 0.5 * f_top
    where = locate(nrows if experiment.structure is not None and nom_mismatch else rows, d, (f_low, f_top))
    # ---- replay-domain residuals (table accelerometer effects). Eq. (3) does not involve the table
    # accelerometer, so when the nominal model explains the floor equations, it is the fair model
    # to replay (a fit driven by a faulty base channel has partly absorbed the fault).
    replay_model = nom if (experiment.structure is not None and not nom_mismatch) else result
    excess_rep, rep_candidates = _screen_replay(replay_model, train_runs, d, band)
    candidates += rep_candidates
    # A flexibly attached mass, by replay: of the nominal model when the lab states one (the identified
    # model has partly absorbed the attachment in the runs that carry it), else of the identified one.
    candidates += _screen_flexible(nom if experiment.structure is not None else result, train_runs, d, band,
                                   f_top)
    pattern = _damping_pattern(result, d)
    pattern_info = pattern[1] if pattern else {}
    if pattern and not _physical(pattern[0]):   # a negative damper is no explanation
        pattern = None
    if pattern:
        candidates.append(pattern[0])
    candidates = [c for c in candidates if _physical(c)]
    # ---- the sensors against each other (a_j = zdd + q_j''), whatever the structure does
    kin = kinematic_check(train_runs, d, f_top)
    if kin is not None and kin.consistent:
        # Consistent channels rule out a gain or a time shift on any of them.
        candidates = [c for c in candidates if c.mechanism not in ("sensor_gain", "sensor_delay")]
    eq_mismatch = max(excess_eq.values()) > EXCESS
    rep_mismatch = max(excess_rep.values(), default=0) > EXCESS
    sensor_fault = None
    if kin is not None and not kin.consistent:
        fit = kin.best()
        mech_k, params_k, std_k, explained_k = fit.verdict()
        sensor_fault = Candidate(mech_k, {"channel": fit.channel}, params_k, std_k, explained_k, "sensors")
        candidates.append(sensor_fault)
        if explained_k < EXPLAINED:
            # Channels disagree, but no single channel's gain or delay says why (several faults, or
            # noise that is not white): inconclusive, the model-based screening decides.
            sensor_fault = None
    if sensor_fault is not None:
        # One channel contradicts the others: a sensor fault, which also disturbs every model-based
        # residual (so those cannot be trusted to name the physics).
        pool = [sensor_fault]
    elif experiment.structure is not None and not nom_mismatch and rep_mismatch:
        # Floors obey the nominal equations, yet replays from the table channel miss: the table channel.
        pool = [c for c in candidates if c.domain == "replay"]
    else:
        pool = [c for c in candidates
                if (c.domain == "equation" and eq_mismatch) or (c.domain == "replay" and rep_mismatch)
                or (c.domain == "equation (nominal model)" and nom_mismatch)]
    best = max(pool, key=lambda c: c.explained) if pool else None
    if best is not None and best.explained >= EXPLAINED:
        chosen = best
    elif pattern:
        # A linear damper leaves no residual (the identified C absorbs it): the pattern decides.
        chosen = pattern[0]
    elif eq_mismatch or rep_mismatch:
        chosen = "unexplained"
    else:
        chosen = None
    nominal = experiment.structure
    linear_structure = _identified_structure(result, nominal)
    if chosen is None:
        mech, loc, params, std = "none", {}, {}, {}
    elif chosen == "unexplained":
        worst = max(excess_eq, key=excess_eq.get)
        if where.storeys[f"storey{where.storey}"] > EXCESS and (eq_mismatch or nom_mismatch):
            loc = {"storey": where.storey}     # the storey whose shear residual stands out
        elif max(excess_rep.values(), default=0) > max(excess_eq.values()):
            worst = max(excess_rep, key=excess_rep.get)
            loc = {"channel": worst}
        else:
            loc = {"floor": int(worst[5:])}
        mech, params, std = "unexplained", {}, {}
    else:
        mech, loc, params, std = chosen.mechanism, chosen.location, chosen.parameters, chosen.std
    before = after = float("nan")
    curves: dict = {}
    xml = ""
    selection: dict = {}
    aug = _Augmenter(result, nominal, pattern, train_exp, band, f_top, ideal)
    if isinstance(chosen, Candidate) and chosen.domain != "sensors" and replay:
        # Screening ranks signatures on residuals; the choice among the plausible ones is made by
        # re-simulation: each augmented model replays the training runs, and the lowest NRMSE wins.
        shortlist = _shortlist(pool + ([pattern[0]] if pattern else []), chosen)
        if len(shortlist) > 1:
            base = aug.score(linear_structure, "none", {}, {}, ())
            scored = []
            for c in shortlist:
                st, p_, s_, mechs = aug(c.mechanism, c.location, c.parameters, c.std)
                scored.append((aug.score(st, c.mechanism, c.location, p_, mechs), c))
            _, best_c = min(scored, key=lambda x: x[0])
            selection = {"training_nrmse_linear": base,
                         "training_nrmse": [{"mechanism": c.mechanism, "location": c.location,
                                             "nrmse": sc_} for sc_, c in scored]}
            mech, loc, params, std = best_c.mechanism, best_c.location, best_c.parameters, best_c.std
    ident_structure, params, std, mechanisms = aug(mech, loc, params, std)
    if mech == "extra_damper" and not std:
        # From the damping pattern of the identified C: take the standard error of the same damper
        # fitted to the equation residual (noise only, given the linear model).
        same = [c for c in candidates if c.mechanism == mech and c.location == loc and c.std.get("c")]
        if same:
            std = {"c": float(max(same, key=lambda c: c.explained).std["c"])}
    if mech == "p_delta" and nominal is not None:   # in the lab's terms: 1 = the full weight above
        h = nominal.storey_heights[loc["storey"] - 1]
        params = {**params, "factor": params["weight_per_height"] * h}
        if "weight_per_height" in std:
            std = {**std, "factor": std["weight_per_height"] * h}
    if replay and mech not in ("none", "unexplained"):
        # Does the augmented model explain the mismatch?  Re-simulate the training runs: it must remove
        # at least ACCEPTED of the misfit above the noise, else the best candidate is only partial.
        lin_nrmse = aug.score(linear_structure, "none", {}, {}, ())
        aug_nrmse = aug.score(ident_structure, mech, loc, params, mechanisms)
        noise = aug.noise_nrmse()
        share = _explained_share(lin_nrmse, aug_nrmse, noise)
        selection.update({"training_nrmse_linear": lin_nrmse, "training_nrmse_augmented": aug_nrmse,
                          "training_nrmse_noise": noise, "explained": share, "accepted_above": ACCEPTED})
        if share < ACCEPTED:
            selection["partial"] = {"mechanism": mech, "location": loc, "parameters": params}
            mech, params, std, mechanisms = "unexplained", {}, {}, ()
            ident_structure = linear_structure
            if where.storeys[f"storey{where.storey}"] > EXCESS:   # where the residual says, not the guess
                loc = {"storey": where.storey}
    eval_run = hold if hold is not None else runs[-1]
    if replay:
        before, after, curves, xml = _replay_check(linear_structure, ident_structure, mech, loc, params,
                                                   mechanisms, eval_run, d, band, f_top,
                                                   static=ident_structure != nominal)
    sensor_check = {} if kin is None else {
        "relation": "a_j = zdd + q_j''", "band_hz": list(kin.band), "excess": kin.excess,
        "consistent": kin.consistent, "fits": [asdict(f) for f in kin.fits[:3]]}
    summary = _summary(mech, loc, params, std, excess_eq, excess_rep, before, after, eval_run.name, hold,
                       sensor_check, selection, where.words)
    return Diagnosis(mechanism=mech, location=loc, parameters=params, std=std, nrmse_before=before,
                     nrmse_after=after, excess_equation=excess_eq, excess_replay=excess_rep,
                     candidates=tuple(sorted(candidates, key=lambda c: -c.explained)[:8]), summary=summary,
                     holdout=eval_run.name if hold is not None else f"{eval_run.name} (no run held out)",
                     parameter_pattern=pattern_info, sensor_check=sensor_check, selection=selection,
                     localisation=where.to_dict(),
                     augmented_xml=xml, curves=curves)


def _physical(c: Candidate) -> bool:
    """A passive rig: no negative damper, friction or weight (cubic stiffness may soften)."""
    key = {"extra_damper": "c", "coulomb_friction": "force", "p_delta": "weight_per_height"}.get(c.mechanism)
    return key is None or c.parameters.get(key, 0.0) > 0


def _screen_equation(result, rows, d, noise_floor, f_top) -> list[Candidate]:
    """Candidates whose signature lives in the floor-force residual."""
    fs = rows[0][0].sample_rate
    train = np.concatenate([_blocks(r[0].n_samples if r[1]["a"].shape[0] == r[0].n_samples
                                    else r[1]["a"].shape[0], fs)[0] for r in rows])
    test = ~train
    target = np.concatenate([r[2] for r in rows])                     # (N, d)
    n_test = int(test.sum())
    noise_rss = float(np.sum(noise_floor ** 2)) * n_test
    a = np.concatenate([r[1]["a"] for r in rows])
    v = np.concatenate([r[1]["v"] for r in rows])
    q = np.concatenate([r[1]["q"] for r in rows])
    dm = np.concatenate([np.broadcast_to(r[0].added_mass, r[1]["a"].shape) for r in rows])
    drift, dvel = rig.drifts(q), rig.drifts(v)
    jerk = np.gradient(a, 1 / fs, axis=0)
    ones = np.ones(len(a))
    out = []

    def storey_cols(phi, s):
        e = np.zeros((len(phi), d))
        e[:, s] = phi
        return rig.storey_to_floor(e)

    def floor_cols(phi, j):
        e = np.zeros((len(phi), d))
        e[:, j] = phi
        return e

    def add(mech, loc, cols, conf, to_params):
        res = _fit([c.ravel() for c in cols], [c.ravel() for c in conf], target.ravel(),
                   np.repeat(train, d), np.repeat(test, d), noise_rss)
        if res is None:
            return
        coef, std, explained = res
        params, pstd = to_params(coef, std)
        out.append(Candidate(mech, loc, params, pstd, explained, "equation"))

    g = rig.GRAVITY
    for s in range(d):
        conf = [storey_cols(drift[:, s], s), storey_cols(dvel[:, s], s)]
        eps = 0.05 * float(np.sqrt(np.mean(dvel[:, s] ** 2))) or 1e-9
        add("coulomb_friction", {"storey": s + 1}, [storey_cols(np.tanh(dvel[:, s] / eps), s)], conf,
            lambda c, e: ({"force": float(c[0])}, {"force": float(e[0])}))
        add("cubic_stiffness", {"storey": s + 1}, [storey_cols(drift[:, s] ** 3, s)], conf,
            lambda c, e: ({"k3": float(c[0])}, {"k3": float(e[0])}))
        add("extra_damper", {"storey": s + 1}, [storey_cols(dvel[:, s], s)], [storey_cols(drift[:, s], s)],
            lambda c, e: ({"c": float(c[0])}, {"c": float(e[0])}))
        above = dm[:, s:].sum(axis=1)
        if np.any(above > 0):
            add("p_delta", {"storey": s + 1}, [storey_cols(-g * above * drift[:, s], s)], conf,
                lambda c, e: ({"weight_per_height": float(c[0])}, {"weight_per_height": float(e[0])}))
    Mdiag = np.diag(result.M)
    # The attachment oscillator is driven by the measured (band-limited) floor acceleration; its
    # resonance amplifies that channel's noise too, which biases the fitted amplitude low.
    a_model = a
    for j in range(d):
        tag = f"a{j + 1}"
        if np.any(dm[:, j] > 0):
            add("sensor_gain", {"channel": tag}, [floor_cols(dm[:, j] * a[:, j], j)],
                [floor_cols(a[:, j], j)],
                lambda c, e: ({"gain": float(1 / (1 - c[0]))}, {"gain": float(e[0] / (1 - c[0]) ** 2)}))
        if np.any(dm[:, j] > 0) and a_model is not None:
            best = None
            for f_a in np.geomspace(1.2 * f_top, 0.3 * fs, 24):
                w = 2 * np.pi * f_a
                osc = discretize(np.eye(1), np.eye(1) * 2 * 0.05 * w, np.eye(1) * w * w, 1 / fs)
                rel = outputs(osc, simulate_linear(osc, a_model[:, j]))["a"][:, 0] - a_model[:, j]
                phi = np.where(dm[:, j] > 0, -dm[:, j] * rel, 0.0)
                res = _fit([floor_cols(phi, j).ravel()], [floor_cols(a[:, j], j).ravel()], target.ravel(),
                           np.repeat(train, d), np.repeat(test, d), noise_rss)
                if res and (best is None or res[2] > best[2]):
                    best = (f_a, *res)
            if best:
                f_a, coef, std, explained = best
                out.append(Candidate("flexible_added_mass", {"floor": j + 1},
                                     {"frequency": float(f_a), "damping_ratio": 0.05, "amplitude": float(coef[0])},
                                     {"amplitude": float(std[0])}, explained, "equation"))
        add("sensor_delay", {"channel": tag}, [floor_cols(-(Mdiag[j] + dm[:, j]) * jerk[:, j], j)], [],
            lambda c, e: ({"delay": float(c[0])}, {"delay": float(e[0])}))
        add("sensor_bias", {"channel": tag}, [floor_cols((Mdiag[j] + dm[:, j]) * ones, j)], [],
            lambda c, e: ({"bias": float(c[0])}, {"bias": float(e[0])}))
        qtag = f"q{j + 1}"
        kcol = np.outer(q[:, j], result.K[:, j]) + np.outer(v[:, j], result.C[:, j])
        add("sensor_gain", {"channel": qtag}, [kcol], [],
            lambda c, e: ({"gain": float(1 / (1 - c[0]))}, {"gain": float(e[0] / (1 - c[0]) ** 2)}))
        add("sensor_delay", {"channel": qtag}, [-np.outer(v[:, j], result.K[:, j])], [],
            lambda c, e: ({"delay": float(c[0])}, {"delay": float(e[0])}))
        add("sensor_bias", {"channel": qtag}, [np.outer(ones, result.K[:, j])], [],
            lambda c, e: ({"bias": float(c[0])}, {"bias": float(e[0])}))
    return out


def _lowpass(x, fs, band):
    if not band.high:
        return x
    sos = scipy.signal.butter(4, band.high, fs=fs, output="sos")
    return scipy.signal.sosfiltfilt(sos, x, axis=0)


def _replay_outputs(result, run, d, zdd=None):
    dm = np.diag(run.added_mass)
    model = discretize(result.M + dm, result.C + result.mu * dm, result.K, 1 / run.sample_rate)
    y = outputs(model, simulate_linear(model, run["zdd"] if zdd is None else zdd))
    return y


def _replay_noise(result, run, d, band) -> dict[str, np.ndarray]:
    """RMS per channel group (``'a'``, ``'q'``: (d,)) that sensor noise alone leaves between a
    band-limited recording and a replay of the right model: the channel's own noise plus the
    table accelerometer's noise carried through the structure into the replay (which the
    structure's resonances amplify: with a narrow-band excitation it is the larger part)."""
    fs = run.sample_rate
    sig = noise_sigma(run)
    gain = math.sqrt(2 * band.high / fs) if band.high else 1.0
    rng = np.random.default_rng(7)
    carried = _replay_outputs(result, run, d, rng.standard_normal(run.n_samples) * sig.get("zdd", 0.0))
    out = {}
    for g in ("a", "q"):
        own = np.array([sig.get(f"{g}{j + 1}", 0.0) for j in range(d)]) * gain
        prop = np.sqrt(np.mean(_lowpass(carried[g], fs, band) ** 2, axis=0))
        out[g] = np.sqrt(own ** 2 + prop ** 2)
    return out


def _screen_replay(result, runs, d, band):
    """Table-accelerometer effects: visible only when the model is driven by the recorded base."""
    fs = runs[0].sample_rate
    target, sims, dsims, steps, noise = [], [], [], [], []
    for run in runs:
        y = _replay_outputs(result, run, d)
        meas = _lowpass(run.group("a", d), fs, band)
        sim = _lowpass(y["a"], fs, band)
        target.append(meas - sim)
        sims.append(sim)
        dsims.append(np.gradient(sim, 1 / fs, axis=0))
        steps.append(_lowpass(_replay_outputs(result, run, d, np.ones(run.n_samples))["a"], fs, band))
        noise.append(_replay_noise(result, run, d, band)["a"])
    target = np.concatenate(target)
    scale = np.sqrt(np.mean(np.concatenate(sims) ** 2, axis=0))
    noise_lvl = np.mean(noise, axis=0)
    rms = np.sqrt(np.mean(target ** 2, axis=0))
    floor = np.maximum(noise_lvl, 1e-6 * scale)
    excess = {f"a{j + 1}": float(rms[j] / floor[j]) for j in range(d)}
    train = np.concatenate([_blocks(r.n_samples, fs)[0] for r in runs])
    test = ~train
    noise_rss = float(np.sum(floor ** 2)) * int(test.sum())
    cands = []
    specs = (("sensor_delay", np.concatenate(dsims), lambda c, e: ({"delay": float(c)}, {"delay": float(e)})),
             ("sensor_gain", np.concatenate(sims),
              lambda c, e: ({"gain": float(1 / (1 + c))}, {"gain": float(e / (1 + c) ** 2)})),
             ("sensor_bias", -np.concatenate(steps), lambda c, e: ({"bias": float(c)}, {"bias": float(e)})))
    for mech, col, conv in specs:
        res = _fit([col.ravel()], [], target.ravel(), np.repeat(train, d), np.repeat(test, d), noise_rss)
        if res:
            params, std = conv(res[0][0], res[1][0])
            cands.append(Candidate(mech, {"channel": "zdd"}, params, std, res[2], "replay"))
    return excess, cands


def _flex_replay(result, run, d, j, f_a, zeta=0.05):
    """Floor accelerations of the model with run's added mass on floor j on a spring (an extra DOF)."""
    dm = np.asarray(run.added_mass, float).copy()
    m_a = dm[j]
    dm[j] = 0.0
    w = 2 * np.pi * f_a
    n = d + 1
    M = np.zeros((n, n))
    C = np.zeros((n, n))
    K = np.zeros((n, n))
    M[:d, :d] = result.M + np.diag(dm)
    C[:d, :d] = result.C + result.mu * np.diag(np.asarray(run.added_mass))   # floor damping as before
    K[:d, :d] = result.K
    M[d, d] = m_a
    k_a, c_a = m_a * w * w, 2 * zeta * m_a * w
    for X, v in ((K, k_a), (C, c_a)):
        X[j, j] += v
        X[d, d] += v
        X[j, d] -= v
        X[d, j] -= v
    model = discretize(M, C, K, 1 / run.sample_rate)
    return outputs(model, simulate_linear(model, run["zdd"]))["a"][:, :d]


def _screen_flexible(result, runs, d, band, f_top) -> list[Candidate]:
    """A flexibly attached added mass, tested by replay (sensor noise does not enter the signature)."""
    fs = runs[0].sample_rate
    out = []
    for j in range(d):
        loaded = [r for r in runs if r.added_mass[j] > 0 and r.has("a1")]
        if not loaded:
            continue
        meas = [_lowpass(r.group("a", d), fs, band) for r in loaded]
        rigid = [_lowpass(_replay_outputs(result, r, d)["a"], fs, band) for r in loaded]
        noise = sum(r.n_samples * float(np.sum(_replay_noise(result, r, d, band)["a"] ** 2)) for r in loaded)
        base = sum(float(np.sum((m - y) ** 2)) for m, y in zip(meas, rigid))
        if base <= 1.02 * noise:
            continue
        def rss(f_a, zeta, j=j, meas=meas, loaded=loaded):   # bound now: refined after the loop
            return sum(float(np.sum((m - _lowpass(_flex_replay(result, r, d, j, f_a, zeta), fs, band)) ** 2))
                       for m, r in zip(meas, loaded))

        grid = [(f_a, rss(f_a, 0.05)) for f_a in np.geomspace(1.1 * f_top, min(0.4 * fs, 20 * f_top), 28)]
        f_a, best = min(grid, key=lambda x: x[1])
        n_eff = sum(r.n_samples for r in loaded) * d * min(1.0, 2 * (band.high or fs / 2) / fs)
        out.append((best, j, f_a, base, noise, rss, n_eff))
    if not out:
        return []
    # The attachment's frequency and damping, refined where the grid fits best.
    _, j, f_a, base, noise, rss, n_eff = min(out, key=lambda x: x[0])
    params, std, best = _refine_oscillator(rss, f_a, 0.05, n_eff)
    explained = (base - best) / (base - noise)
    cands = [Candidate("flexible_added_mass", {"floor": j + 1}, params, std, float(explained), "replay")]
    for b, k, f_k, base_k, noise_k, _, _ in out:
        if k != j:
            cands.append(Candidate("flexible_added_mass", {"floor": k + 1}, {"frequency": float(f_k),
                                   "damping_ratio": 0.05}, {}, float((base_k - b) / (base_k - noise_k)), "replay"))
    return cands


def _refine_oscillator(rss, f0: float, zeta0: float, n_eff: float):
    """Least-squares (frequency, damping ratio) of an attachment from the grid's best point.

    Nelder-Mead on (log f, log zeta); standard errors from the curvature of the misfit,
    ``cov = 2 s^2 H^-1`` with ``s^2 = rss / n_eff``.  Returns (parameters, std, rss at the optimum).
    """
    import scipy.optimize

    def cost(x):
        return rss(math.exp(x[0]), min(math.exp(x[1]), 2.0))

    x0 = np.array([math.log(f0), math.log(zeta0)])
    res = scipy.optimize.minimize(cost, x0, method="Nelder-Mead",
                                  options={"xatol": 1e-3, "fatol": 1e-9 * cost(x0), "maxfev": 80})
    x = res.x if res.fun < cost(x0) else x0
    f, zeta = math.exp(x[0]), min(math.exp(x[1]), 2.0)
    q0 = cost(x)
    h = np.array([0.002, 0.02])   # steps in log f, log zeta
    H = np.zeros((2, 2))
    for a in range(2):
        for b in range(2):
            ea, eb = np.eye(2)[a] * h[a], np.eye(2)[b] * h[b]
            H[a, b] = (cost(x + ea + eb) - cost(x + ea - eb) - cost(x - ea + eb) + cost(x - ea - eb)) / (4 * h[a] * h[b])
    std = {}
    try:
        cov = 2 * (q0 / max(n_eff - 2, 1)) * np.linalg.inv(H)
        if np.all(np.diag(cov) > 0):
            std = {"frequency": float(f * math.sqrt(cov[0, 0])), "damping_ratio": float(zeta * math.sqrt(cov[1, 1]))}
    except np.linalg.LinAlgError:
        pass
    return {"frequency": float(f), "damping_ratio": float(zeta)}, std, float(q0)


def _damping_pattern(result, d):
    """A linear damper across one storey hides in the identified C: look for its pattern."""
    fits = {f.model: f for f in damping_models(result)}
    ray = fits["rayleigh"]
    if not (ray.p_value < 1e-3 and ray.misfit > 0.02):
        return None
    iu = np.triu_indices(d)
    c = result.C[iu]
    best = None
    for s in range(d):
        e = np.zeros(d)
        e[s] = 1.0
        if s > 0:
            e[s - 1] = -1.0
        P = np.outer(e, e)[iu]
        A = np.column_stack([result.M[iu], result.K[iu], P])
        coef, *_ = np.linalg.lstsq(A, c, rcond=None)
        mis = float(np.linalg.norm(c - A @ coef) / np.linalg.norm(c))
        if best is None or mis < best[1]:
            best = (s, mis, coef)
    s, mis, coef = best
    explained = 1.0 - mis / ray.misfit
    cand = Candidate("extra_damper", {"storey": s + 1}, {"c": float(coef[2])}, {}, float(explained), "parameters")
    return cand, {"rayleigh_misfit": ray.misfit, "rayleigh_p_value": ray.p_value, "with_damper_misfit": mis,
                  "coefficients": [float(x) for x in coef]}


def _signature(mech, loc, params, run, s, d):
    """Floor direction (d, 1) and signal (n, 1) of a mechanism's force on one run."""
    e = np.zeros((1, d))
    if mech in ("coulomb_friction", "cubic_stiffness", "p_delta"):
        k = loc["storey"] - 1
        e[0, k] = 1.0
        direction = rig.storey_to_floor(e).T
        if mech == "coulomb_friction":
            sig = np.tanh(rig.drifts(s["v"])[:, k] / rig.FRICTION_SMOOTHING)
        elif mech == "cubic_stiffness":
            sig = rig.drifts(s["q"])[:, k] ** 3
        else:
            sig = -rig.GRAVITY * run.added_mass[k:].sum() * rig.drifts(s["q"])[:, k]
    else:
        j = loc["floor"] - 1
        e[0, j] = 1.0
        direction = e.T
        w = 2 * np.pi * params["frequency"]
        osc = discretize(np.eye(1), np.eye(1) * 2 * params["damping_ratio"] * w, np.eye(1) * w * w,
                         1 / run.sample_rate)
        a_j = s["a"][:, j]
        sig = -run.added_mass[j] * (outputs(osc, simulate_linear(osc, a_j))["a"][:, 0] - a_j)
    return direction, sig[:, None]


#: Misfit of a trial model that goes unstable: worse than any fit, finite for the line search.
_UNSTABLE = 1e200

_PARAM = {"coulomb_friction": "force", "cubic_stiffness": "k3", "p_delta": "weight_per_height",
          "flexible_added_mass": "amplitude"}


def _refit(mech, loc, params, runs, result, band, f_top):
    """Errors-in-variables fit of the linear model together with the mechanism's force."""
    from momentid.estimation.eiv import fit_eiv
    d = result.storeys
    forces = []
    for run in runs:
        if not run.has("q1") and mech != "flexible_added_mass":
            return None
        # From measured signals: a band just above the modes keeps sensor noise from flipping
        # the sign of small drift velocities (which would shrink the fitted force).
        s = _signals(run, d, Prefilter(high=1.5 * f_top) if band.high else band)
        if s["a"].shape[0] != run.n_samples:
            return None
        forces.append(_signature(mech, loc, params, run, s, d))
    lay = result.layout
    theta0 = np.concatenate([result.theta, [params[_PARAM[mech]]]])
    fit = fit_eiv(lay, runs, theta0, f_max=2.0 * f_top, forces=forces)
    M, C, K, mu = lay.unpack(fit.theta[:lay.p])
    kappa = float(np.sum(K * (C - mu * M)) / np.sum(K * K))
    new = replace(result, M=M, C=C, K=K, mu=mu, kappa=kappa, covariance=fit.covariance[:lay.p, :lay.p])
    value = float(fit.theta[lay.p])
    err = float(np.sqrt(fit.covariance[lay.p, lay.p]))
    params = dict(params)
    params[_PARAM[mech]] = value
    return new, params, {_PARAM[mech]: err}


def _correct(run: RunData, mech: str, loc: dict, params: dict) -> RunData:
    """Undo a diagnosed sensor fault on one run's recorded channel."""
    ch = loc["channel"]
    if not run.has(ch):
        return run
    j = run.channels.index(ch)
    x = run.values[:, j]
    if mech == "sensor_delay":
        x = np.interp(run.time + params["delay"], run.time, x)
    elif mech == "sensor_gain":
        x = x / params["gain"]
    else:
        x = x - params["bias"]
    values = run.values.copy()
    values[:, j] = x
    return replace(run, values=values)


def _as_mechanisms(mech, loc, params) -> tuple[Mechanism, ...]:
    if mech == "coulomb_friction":
        return (Mechanism(mech, loc["storey"], (("force", params["force"]),)),)
    if mech == "cubic_stiffness":
        return (Mechanism(mech, loc["storey"], (("k3", params["k3"]),)),)
    if mech == "extra_damper":
        return (Mechanism(mech, loc["storey"], (("c", params["c"]),)),)
    if mech == "p_delta":
        return (Mechanism(mech, loc["storey"], (("factor", 1.0),)),)
    if mech == "flexible_added_mass":
        return (Mechanism(mech, loc["floor"], (("frequency", params["frequency"]),
                                               ("damping_ratio", params["damping_ratio"]))),)
    return ()


class _Augmenter:
    """Builds the augmented model of a candidate and scores it by re-simulating the training runs."""

    def __init__(self, result, nominal, pattern, train_exp, band, f_top, ideal):
        self.result, self.nominal, self.pattern = result, nominal, pattern
        self.train_exp, self.band, self.f_top, self.ideal = train_exp, band, f_top, ideal
        self.d = result.storeys
        self._replays: dict = {}

    def __call__(self, mech, loc, params, std):
        """(structure, parameters, std, mechanisms) of the model with ``mech`` added (memoised)."""
        key = (mech, json.dumps(loc, sort_keys=True), json.dumps(params, sort_keys=True))
        if key not in self._replays:
            self._replays[key] = self._build(mech, loc, params, std)
        return self._replays[key]

    def _build(self, mech, loc, params, std):
        result, nominal, runs = self.result, self.nominal, self.train_exp.runs
        structure = _identified_structure(result, nominal)
        if mech in ("coulomb_friction", "cubic_stiffness", "p_delta") and not self.ideal:
            refit = _refit(mech, loc, params, runs, result, self.band, self.f_top)
            if refit is not None:
                refitted, params, std = refit
                structure = _identified_structure(refitted, nominal)
        if mech in ("coulomb_friction", "cubic_stiffness", "p_delta") and not self.ideal:
            # The force's size by re-simulation, on the refitted linear model and on the nominal one
            # (a friction that sticks a storey leaves the linear fit poorly determined); the pair that
            # replays best wins.
            bases = [structure] + ([nominal] if nominal is not None else [])
            structure = min(bases, key=lambda b: self._misfit(b, mech, loc, params))
            params, sim_std = self._resimulate(structure, mech, loc, params)
            # the search's std is conditional on the linear model; the refit's marginal std carries
            # the linear model's own uncertainty: report both, in quadrature
            std = {k: float(math.hypot(v, std.get(k, 0.0))) for k, v in sim_std.items()}
        if mech == "flexible_added_mass" and nominal is not None:
            # Found by replaying the nominal model (the identified one has absorbed part of the attachment's
            # dynamics in the runs that carry it): augment the nominal model.
            structure = nominal
        if mech == "extra_damper":
            # Rayleigh part + the storey damper: from the pattern fit of the identified C when there is one,
            # else the nominal Rayleigh coefficients.
            pattern = self.pattern
            if pattern and pattern[0].location == loc:
                a_, b_, c_ = pattern[1]["coefficients"]
                params = {"c": float(c_)}
            elif nominal is not None:
                a_, b_ = nominal.rayleigh_mu, nominal.rayleigh_kappa
            else:
                a_, b_ = structure.rayleigh_mu, structure.rayleigh_kappa
            structure = replace(structure, rayleigh_mu=max(a_, 0.0), rayleigh_kappa=max(b_, 0.0))
            if nominal is not None:   # the lab's own model with the damper may replay better
                structure = min((structure, nominal), key=lambda b: self._misfit(b, mech, loc, params))
        if mech in ("sensor_delay", "sensor_gain", "sensor_bias"):
            fixed = replace(self.train_exp, runs=tuple(_correct(r, mech, loc, params) for r in runs))
            structure = _identified_structure(identify(fixed), nominal)
            if nominal is not None:   # the corrected data may fit the lab's own model better
                structure = min((structure, nominal), key=lambda b: self._misfit(b, mech, loc, params))
        return structure, params, std, _as_mechanisms(mech, loc, params)

    def _search_run(self) -> RunData:
        """The training run with the most added mass (the strongest test of a storey force)."""
        return max(self.train_exp.runs, key=lambda r: float(np.sum(r.added_mass)))

    def _misfit(self, structure, mech, loc, params) -> float:
        """Normalised sum of squares of the search run replayed through the augmented model:
        sum over channels and samples of ((measured - simulated) / RMS(measured))^2."""
        run = self._search_run()
        try:
            sim, measured = _augmented_replay(structure, mech, loc, params, _as_mechanisms(mech, loc, params),
                                              run, self.d, structure != self.nominal)
        except (SimulationError, ModelError):   # e.g. a storey made unstable: not a candidate fit
            return _UNSTABLE
        fs = run.sample_rate
        q = 0.0
        for g in measured:
            m = _lowpass(measured[g], fs, self.band)
            q += float(np.sum(((m - _lowpass(sim[g], fs, self.band)) / np.sqrt(np.mean(m ** 2, axis=0))) ** 2))
        return q

    def _resimulate(self, structure, mech, loc, params) -> tuple[dict, dict]:
        """Output-error refinement of a nonlinear storey force's size by re-simulation.

        The regression estimates it from measured drift velocities and drifts, whose noise
        pulls it towards zero (a noisy velocity flips sign around its zero crossings); a
        simulation has no such noise.  A bounded scalar search (from half to five times the
        regression's value, on a log scale) of :meth:`_misfit` on one training run.  The standard error comes from the
        misfit's curvature at the minimum, ``var = 2 s^2 / Q''`` with ``s^2`` the misfit per
        independent sample (band-limited channels), so it grows with any misfit the model leaves.

        Returns
        -------
        params, std : the refined parameters and their standard errors.
        """
        import scipy.optimize
        key = _PARAM[mech]
        p0 = float(params[key])
        if not np.isfinite(p0) or p0 == 0:
            return params, {}
        seen: dict[float, float] = {}

        def cost(x):
            x = float(x)
            if x not in seen:
                seen[x] = self._misfit(structure, mech, loc, dict(params, **{key: x}))
            return seen[x]

        # On a log scale from half to five times the regression's value: the regression is pulled
        # towards zero (by a factor of 3 and more for a storey that sticks, at 2 % noise).
        sign = math.copysign(1.0, p0)
        res = scipy.optimize.minimize_scalar(lambda u: cost(sign * math.exp(u)),
                                             bounds=(math.log(0.5 * abs(p0)), math.log(5.0 * abs(p0))),
                                             method="bounded", options={"xatol": 0.005, "maxiter": 14})
        best = sign * math.exp(float(res.x)) if res.fun < cost(p0) else p0
        step = 0.02 * abs(best)
        q0, qm, qp = cost(best), cost(best - step), cost(best + step)
        curvature = (qp - 2 * q0 + qm) / step ** 2
        if curvature > 0:   # the search stops within its tolerance: finish with the parabola's vertex
            vertex = best - step * (qp - qm) / (2 * (qp - 2 * q0 + qm))
            if abs(vertex - best) < step and cost(vertex) < q0:
                best, q0 = vertex, cost(vertex)
        run = self._search_run()
        n_channels = sum(1 for g in ("a", "q") if run.has(f"{g}1")) * self.d
        band = self.band.high or run.sample_rate / 2
        n_eff = n_channels * run.n_samples * min(1.0, 2 * band / run.sample_rate)
        std = float(np.sqrt(2 * (q0 / max(n_eff - 1, 1)) / curvature)) if curvature > 0 else float("inf")
        return dict(params, **{key: best}), {key: std}

    def score(self, structure, mech, loc, params, mechanisms) -> float:
        """Mean NRMSE of the training runs replayed through the model (band-limited channels)."""
        key = ("score", repr(structure), mech, json.dumps(loc, sort_keys=True), json.dumps(params, sort_keys=True))
        if key not in self._replays:
            out = []
            for run in self.train_exp.runs:
                try:
                    sim, measured = _augmented_replay(structure, mech, loc, params, mechanisms, run, self.d,
                                                      structure != self.nominal)
                except (SimulationError, ModelError):   # an unstable augmented model explains nothing
                    out.append(float("inf"))
                    break
                out.append(_nrmse(sim, measured, run.sample_rate, self.band))
            self._replays[key] = float(np.mean(out))
        return self._replays[key]

    def noise_nrmse(self) -> float:
        """The NRMSE sensor noise alone leaves in :meth:`score` (white levels, band-limited)."""
        out = []
        for run in self.train_exp.runs:
            fs = run.sample_rate
            noise = _replay_noise(self.result, run, self.d, self.band)
            for g in ("a", "q"):
                if not run.has(f"{g}1"):
                    continue
                m = _lowpass(run.group(g, self.d), fs, self.band)
                out += list(noise[g] / np.sqrt(np.mean(m ** 2, axis=0)))
        return float(np.mean(out))


def _explained_share(before: float, after: float, noise: float) -> float:
    """Share of the misfit power above the noise that a model removes (NRMSEs in, 1 = all)."""
    excess = before ** 2 - noise ** 2
    if excess <= 0:
        return 1.0
    return float(1.0 - max(after ** 2 - noise ** 2, 0.0) / excess)


def _shortlist(pool, chosen, *, size=4, floor=0.15) -> list[Candidate]:
    """The screened candidates worth re-simulating: the chosen one and the best candidate of each
    other kind of physics that explains at least ``floor`` of the excess (up to ``size`` in all;
    one per kind, so that a kind which screens well at several places cannot crowd the others out)."""
    out, kinds = [chosen], {chosen.mechanism}
    for c in sorted(pool, key=lambda c: -c.explained):
        if c.mechanism in kinds or c.explained < floor or c.mechanism.startswith("sensor_"):
            continue
        kinds.add(c.mechanism)
        out.append(c)
        if len(out) == size:
            break
    return out


def _nrmse(sim, meas, fs, band) -> float:
    """Mean over channels of RMS(measured - simulated) / RMS(measured), band-limited."""
    errs = []
    for g in meas:
        m = _lowpass(meas[g], fs, band)
        s = _lowpass(sim[g], fs, band)
        errs.append(np.sqrt(np.mean((m - s) ** 2, axis=0)) / np.sqrt(np.mean(m ** 2, axis=0)))
    return float(np.mean(np.concatenate(errs)))


def _augmented_replay(structure, mech, loc, params, mechanisms, run, d, static=True):
    """Replay ``run`` through the augmented model: (simulated, measured-and-corrected) channels.

    ``static``: for ``p_delta``, whether ``structure`` already holds the geometric stiffness of
    the floors' own weight (an identified model does, a nominal one does not).
    """
    from momentid.lab.simulation import replay
    measured = {g: run.group(g, d) for g in ("a", "q") if run.has(f"{g}1")}
    zdd = run["zdd"].copy()
    if mech == "p_delta":
        # The identified K already holds the reference run's geometric stiffness; the MJCF mechanism
        # subtracts g (m_above + dm_above) / h, so add the static part back: net -g dm_above / h.
        structure = _pdelta_structure(structure, loc, params, static)
    if mech in ("sensor_delay", "sensor_gain", "sensor_bias"):
        fixed = _correct(run, mech, loc, params)
        zdd = fixed["zdd"]
        measured = {g: fixed.group(g, d) for g in measured}
    return replay(structure, mechanisms, run, zdd), measured


def _pdelta_structure(structure, loc, params, static=True):
    """The structure whose MJCF ``p_delta`` (factor 1) loses ``weight_per_height x g x weight above``:
    the storey's height is set to 1 / weight_per_height; with ``static`` the loss of the floors' own
    weight, which an identified stiffness already holds, is added back."""
    s = loc["storey"] - 1
    h_eff = 1.0 / params["weight_per_height"] if params["weight_per_height"] > 0 else float("inf")
    k = list(structure.storey_stiffness)
    if static:
        k[s] += rig.GRAVITY * sum(structure.masses[s:]) / h_eff
    return replace(structure, storey_stiffness=tuple(k), storey_heights=tuple(
        h_eff if i == s else h for i, h in enumerate(structure.storey_heights)))


def _replay_check(linear_structure, structure, mech, loc, params, mechanisms, run, d, band, f_top, static=True):
    """NRMSE of the held-out run: linear model vs. augmented model, both in MuJoCo."""
    from momentid.lab.simulation import replay
    fs = run.sample_rate
    measured = {g: run.group(g, d) for g in ("a", "q") if run.has(f"{g}1")}
    lin = replay(linear_structure, (), run, run["zdd"])
    before = _nrmse(lin, measured, fs, band)
    if mechanisms or mech.startswith("sensor"):
        aug, corrected = _augmented_replay(structure, mech, loc, params, mechanisms, run, d, static)
        after = _nrmse(aug, corrected, fs, band)
    else:
        aug, after = lin, before
    if mech == "p_delta":
        structure = _pdelta_structure(structure, loc, params, static)
    spec = rig.build_spec(structure, run.added_mass, timestep=1 / fs, name="augmented",
                          mechanisms=mechanisms)
    spec.compiler.saveinertial = True
    curves = {"time": run.time, "measured": measured, "linear": lin, "augmented": aug}
    return before, after, curves, spec.to_xml()


def _summary(mech, loc, params, std, excess_eq, excess_rep, before, after, run_name, hold, sensor_check,
             selection, where) -> str:
    worst = max(excess_eq, key=excess_eq.get)
    lines = ["Equation residual vs. noise: " + ", ".join(f"{k} {v:.2f}x" for k, v in excess_eq.items()) + ".",
             "Replay residual vs. noise: " + ", ".join(f"{k} {v:.2f}x" for k, v in excess_rep.items()) + "."]
    if max(excess_eq.values()) > EXCESS:
        lines.append(where)
    if sensor_check:
        verdict = "consistent" if sensor_check["consistent"] else "INCONSISTENT"
        lines.append("Sensors against each other (a = zdd + q''): " + ", ".join(
            f"{k} {v:.2f}x" for k, v in sensor_check["excess"].items()) + f" of noise ({verdict}).")
    if mech == "none":
        lines.append("No missing physics: the linear model explains the recordings to the noise level.")
    elif mech == "unexplained" and "partial" in selection:
        part = selection["partial"]
        lines.append(f"Unexplained mismatch at {json.dumps(loc)}: the best candidate, "
                     f"{part['mechanism'].replace('_', ' ')} at {json.dumps(part['location'])}, removes only "
                     f"{100 * max(selection['explained'], 0):.0f} % of the training runs' misfit above noise "
                     f"(NRMSE {100 * selection['training_nrmse_linear']:.2f} % -> "
                     f"{100 * selection['training_nrmse_augmented']:.2f} %, noise alone "
                     f"{100 * selection['training_nrmse_noise']:.2f} %); the model is left linear.")
    elif mech == "unexplained":
        lines.append(f"Unexplained mismatch at {json.dumps(loc)} (largest at {worst}); no candidate mechanism "
                     f"explains at least {int(EXPLAINED * 100)} % of it.")
    else:
        where = ", ".join(f"{k} {v}" for k, v in loc.items())
        p = ", ".join(f"{k} = {v:.4g}" + (f" +/- {std[k]:.2g}" if k in std else "") for k, v in params.items())
        lines.append(f"Best explanation: {mech.replace('_', ' ')} at {where}: {p}.")
    if math.isfinite(before):
        which = f"held-out run {run_name}" if hold is not None else f"run {run_name}"
        lines.append(f"{which} NRMSE {100 * before:.2f} % -> {100 * after:.2f} %.")
    return "\n".join(lines)


def write_report(diag: Diagnosis, folder) -> Path:
    """``report.json``, ``summary.txt``, ``model_augmented.xml``, ``diagnosis.rrd`` and the PNG plots
    ``replay.png`` (recorded vs. linear vs. augmented) and ``locate.png`` (where the mismatch is)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "report.json").write_text(json.dumps(json_safe(diag.to_dict()), indent=2))
    (folder / "summary.txt").write_text(diag.summary + "\n")
    if diag.augmented_xml:
        (folder / "model_augmented.xml").write_text(diag.augmented_xml)
    if diag.curves:
        _plots(diag, folder)
        _rerun(diag, folder / "diagnosis.rrd")
    if diag.localisation:
        from momentid.diagnosis.locate import plot_localisation
        plot_localisation(diag.localisation, folder / "locate.png")
    return folder


def _rerun(diag: Diagnosis, path: Path) -> None:
    """Recorded, linear-model and augmented-model responses overlaid, for ``rerun diagnosis.rrd``."""
    import rerun as rr
    import rerun.blueprint as rrb

    c = diag.curves
    rec = rr.RecordingStream("momentid_diagnosis")
    views = []
    time = rr.TimeColumn("time", duration=np.asarray(c["time"], float))
    styles = {"recorded": [20, 20, 20], "linear": [31, 119, 180], "augmented": [214, 39, 40]}
    for g, unit in (("a", "m/s^2"), ("q", "m")):
        if g not in c["measured"]:
            continue
        for j in range(c["measured"][g].shape[1]):
            base = f"/{g}{j + 1}"
            for label, data in (("recorded", c["measured"]), ("linear", c["linear"]), ("augmented", c["augmented"])):
                entity = f"{base}/{label}"
                rec.log(entity, rr.SeriesLines(colors=[styles[label]], names=[f"{g}{j + 1} {label} ({unit})"]),
                        static=True)
                rec.send_columns(entity, indexes=[time], columns=rr.Scalars.columns(scalars=data[g][:, j]))
            views.append(rrb.TimeSeriesView(origin=base, name=f"{g}{j + 1} ({unit})"))
    rec.log("/report", rr.TextDocument(diag.summary.replace("\n", "\n\n"), media_type=rr.MediaType.MARKDOWN), static=True)
    layout = rrb.Horizontal(rrb.Grid(*views), rrb.TextDocumentView(origin="/report", name="diagnosis"),
                            column_shares=[3, 1])
    rec.save(str(path), default_blueprint=rrb.Blueprint(layout))
    rec.flush()


def _plots(diag: Diagnosis, folder: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = diag.curves
    t = c["time"]
    g = "q" if "q" in c["measured"] else "a"
    d = c["measured"][g].shape[1]
    fig, axes = plt.subplots(d, 2, figsize=(12, 2.4 * d), squeeze=False, sharex=True)
    unit = "m" if g == "q" else "m/s^2"
    for j in range(d):
        m, lin, aug = c["measured"][g][:, j], c["linear"][g][:, j], c["augmented"][g][:, j]
        ax = axes[j, 0]
        ax.plot(t, m, "k", lw=0.8, label="recorded")
        ax.plot(t, lin, "C0", lw=0.8, label="linear model")
        ax.plot(t, aug, "C3--", lw=0.8, label="augmented model")
        ax.set_ylabel(f"{g}{j + 1} ({unit})")
        ax = axes[j, 1]
        ax.plot(t, m - lin, "C0", lw=0.6, label="residual, linear")
        ax.plot(t, m - aug, "C3", lw=0.6, label="residual, augmented")
        ax.set_ylabel(f"{g}{j + 1} residual ({unit})")
    axes[0, 0].legend(fontsize=7)
    axes[0, 1].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    fig.suptitle(f"{diag.mechanism} {json.dumps(diag.location)}: held-out NRMSE "
                 f"{100 * diag.nrmse_before:.2f} % -> {100 * diag.nrmse_after:.2f} %")
    fig.tight_layout()
    fig.savefig(folder / "replay.png", dpi=90)
    plt.close(fig)
