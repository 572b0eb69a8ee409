"""Stage 5 of the diagnosis: refit a candidate and re-simulate its augmented MuJoCo model.

A candidate's kind says how it is sized (:class:`~momentid.mechanisms.base.Refit`): a nonlinear
storey force is refitted with the linear model by errors-in-variables, then its size searched by
re-simulation; a flexible attachment is put on the lab's nominal model; a storey damper takes the
damping pattern of the identified C; a sensor fault is undone on the recordings, which are then
re-identified.  :class:`Refitter` builds each augmented model once and scores it by replaying the
training runs in MuJoCo.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.optimize

from momentid import mechanisms
from momentid.core.analytic import shear_stiffness
from momentid.core.series import RunData
from momentid.core.structure import Mechanism, Structure
from momentid.diagnosis.residuals import LinearModel, band_signals, nrmse, replay_noise
from momentid.estimation.reconstruct import band_filter
from momentid.errors import ModelError, SimulationError
from momentid.estimation.identification import identify
from momentid.estimation.reconstruct import Prefilter
from momentid.lab import rig
from momentid.mechanisms.base import MechanismKind, Refit, Target, drifts, storey_to_floor

__all__ = ["Augmented", "Refitter", "identified_structure", "joint_replay", "kind_of", "measured_groups", "refit_eiv",
           "replay_check"]

#: Misfit of a trial model that goes unstable: worse than any fit, finite for the line search.
_UNSTABLE = 1e200
#: The errors-in-variables refit reads its storey force from signals low-passed at this multiple of
#: the top mode (noise would flip the sign of small drift velocities and shrink a friction force) ...
REFIT_BAND_OVER_TOP_MODE = 1.5
#: ... and fits the equations up to this multiple of the top mode.
REFIT_F_MAX_OVER_TOP_MODE = 2.0
#: The re-simulation search of a storey force's size: from half to five times the regression's value
#: (on a log scale; the regression is pulled towards zero, by a factor of 3 and more for a storey
#: that sticks, at 2 % noise), to this relative tolerance, in at most this many replays ...
SEARCH_RANGE = (0.5, 5.0)
SEARCH_TOLERANCE = 0.005
SEARCH_REPLAYS = 14
#: ... and the relative step of the misfit's curvature at the optimum (the standard error).
CURVATURE_STEP = 0.02
#: A storey stiffness a linear fit left at or below zero becomes this (N/m): a valid MJCF.
MIN_STIFFNESS = 1e-9
#: Without a nominal model: storey height (m, drawing only) and platen mass (kg) of the replay model.
DEFAULT_STOREY_HEIGHT = 0.3
DEFAULT_BASE_MASS = 100.0


def kind_of(mechanism: str) -> MechanismKind | None:
    """The registered kind of a verdict's mechanism; None for ``"none"`` and ``"unexplained"``."""
    return mechanisms.REGISTRY.get(mechanism)


@dataclass(frozen=True)
class Augmented:
    """A candidate's augmented model: the linear structure it sits on, its refitted parameters and
    standard errors, and its mechanism records (for :func:`momentid.lab.rig.build_spec`)."""

    structure: Structure
    parameters: dict
    std: dict
    records: tuple[Mechanism, ...]


def identified_structure(result, nominal: Structure | None) -> Structure:
    """An identification result as a :class:`Structure` (least-squares storey stiffnesses)."""
    d = result.storeys
    A = np.stack([shear_stiffness(np.eye(d)[s]) for s in range(d)], axis=-1).reshape(d * d, d)
    k, *_ = np.linalg.lstsq(A, result.K.ravel(), rcond=None)
    heights = nominal.storey_heights if nominal else (DEFAULT_STOREY_HEIGHT,) * d
    base = nominal.base_mass if nominal else DEFAULT_BASE_MASS
    return Structure(masses=tuple(np.diag(result.M)), storey_stiffness=tuple(np.maximum(k, MIN_STIFFNESS)),
                     storey_heights=tuple(heights), rayleigh_mu=max(result.mu, 0.0),
                     rayleigh_kappa=max(result.kappa, 0.0), base_mass=base)


def measured_groups(run: RunData, d: int) -> dict[str, np.ndarray]:
    """The floor channels a replay is compared with: ``{"a": (n, d), "q": (n, d)}``, those measured."""
    return {g: run.group(g, d) for g in ("a", "q") if run.has(f"{g}1")}


def joint_replay(structure, entries, records, run, d, static=True):
    """Replay ``run`` through an augmented model: (simulated, measured-and-corrected) channels.

    ``entries``: (kind, location, parameters) of each mechanism, applied in turn: its structure
    change (:meth:`~momentid.mechanisms.base.MechanismKind.replay_structure`), and for a sensor
    fault the correction of the run.  ``records``: every mechanism's model records.  ``static``:
    whether ``structure`` already holds what the floors' own weight does to it (an identified model
    does, a nominal one does not; see ``p_delta``).
    """
    from momentid.lab.simulation import replay
    measured = measured_groups(run, d)
    for kind, loc, params in entries:
        structure = kind.replay_structure(structure, loc, params, static)
        if kind.target is Target.CHANNEL:
            run = kind.correct_run(run, loc, params)
            measured = {g: run.group(g, d) for g in measured}
    return replay(structure, records, run, run["zdd"]), measured


def replay_check(model: LinearModel, linear_structure, structure, entries, records):
    """NRMSE of the evaluation run: linear model vs. augmented model, both in MuJoCo.

    ``entries``: (kind, location, parameters) of every mechanism of the augmented model (sensor
    faults are undone on the run), as :func:`joint_replay` takes them; ``records`` their model records.
    Returns (before, after, curves, augmented MJCF text).
    """
    from momentid.lab.simulation import replay
    run, d, band = model.evaluation_run, model.storeys, model.band
    static = structure != model.nominal
    fs = run.sample_rate
    measured = measured_groups(run, d)
    lin = replay(linear_structure, (), run, run["zdd"])
    before = nrmse(lin, measured, fs, band)
    if records or any(kind.target is Target.CHANNEL for kind, _, _ in entries):
        aug, corrected = joint_replay(structure, entries, records, run, d, static)
        after = nrmse(aug, corrected, fs, band)
    else:
        aug, after = lin, before
    for kind, loc, params in entries:
        structure = kind.replay_structure(structure, loc, params, static)
    spec = rig.build_spec(structure, run.added_mass, timestep=1 / fs, name="augmented", mechanisms=records)
    spec.compiler.saveinertial = True
    curves = {"time": run.time, "measured": measured, "linear": lin, "augmented": aug}
    return before, after, curves, spec.to_xml()


def _force_signature(kind, loc, params, run, signals, d):
    """Floor direction (d, 1) and signal (n, 1) of a storey force on one run."""
    k = loc["storey"] - 1
    e = np.zeros((1, d))
    e[0, k] = 1.0
    signal = kind.force_signal(params, drifts(signals["q"])[:, k], drifts(signals["v"])[:, k],
                               run.added_mass[k:].sum())
    return storey_to_floor(e).T, signal[:, None]


def refit_eiv(entries, runs, result, band, f_top):
    """Errors-in-variables fit of the linear model together with the mechanisms' forces.

    ``entries``: (kind, location, parameters) of each storey force (``RESIMULATE`` kinds), fitted
    jointly.  Returns (refitted result, [parameters], [std]) in the order of ``entries``, or None
    when the runs do not allow it.
    """
    from momentid.estimation.eiv import fit_eiv
    d = result.storeys
    forces = []
    for run in runs:
        if not run.has("q1"):
            return None
        s = band_signals(run, d, Prefilter(high=REFIT_BAND_OVER_TOP_MODE * f_top) if band.high else band)
        if s["a"].shape[0] != run.n_samples:
            return None
        parts = [_force_signature(kind, loc, params, run, s, d) for kind, loc, params in entries]
        forces.append((np.hstack([p[0] for p in parts]), np.hstack([p[1] for p in parts])))
    lay = result.layout
    keys = [kind.fitted.name for kind, _, _ in entries]
    theta0 = np.concatenate([result.theta, [params[key] for key, (_, _, params) in zip(keys, entries)]])
    fit = fit_eiv(lay, runs, theta0, f_max=REFIT_F_MAX_OVER_TOP_MODE * f_top, forces=forces)
    M, C, K, mu = lay.unpack(fit.theta[:lay.p])
    kappa = float(np.sum(K * (C - mu * M)) / np.sum(K * K))
    new = replace(result, M=M, C=C, K=K, mu=mu, kappa=kappa, covariance=fit.covariance[:lay.p, :lay.p])
    i = lay.p + np.arange(len(entries))
    return (new, [dict(params, **{key: float(fit.theta[k])}) for key, (_, _, params), k in zip(keys, entries, i)],
            [{key: float(np.sqrt(fit.covariance[k, k]))} for key, k in zip(keys, i)])


def _stable(result) -> bool:
    """Whether a linear model's free motion decays (every eigenvalue of its state matrix in the left
    half-plane)."""
    d = result.M.shape[0]
    Minv = np.linalg.inv(result.M)
    A = np.block([[np.zeros((d, d)), np.eye(d)], [-Minv @ result.K, -Minv @ result.C]])
    return bool(np.all(np.linalg.eigvals(A).real < 0))


class Refitter:
    """Builds the augmented model of a candidate and scores it by re-simulating the training runs."""

    def __init__(self, model: LinearModel, pattern):
        self.model, self.pattern = model, pattern
        self.result, self.nominal, self.d = model.result, model.nominal, model.storeys
        self.linear_structure = identified_structure(model.result, model.nominal)
        self._cache: dict = {}

    def augment(self, mech: str, loc: dict, params: dict, std: dict) -> Augmented:
        """The model with ``mech`` added at ``loc`` (memoised); the linear one for a verdict with none."""
        key = (mech, json.dumps(loc, sort_keys=True), json.dumps(params, sort_keys=True))
        if key not in self._cache:
            self._cache[key] = self._build(kind_of(mech), loc, params, std)
        return self._cache[key]

    def memo(self, key, compute):
        """``compute()``, once per ``key`` (a hashable; shared with the refitter's own memos)."""
        if key not in self._cache:
            self._cache[key] = compute()
        return self._cache[key]

    def memo_keys(self) -> set:
        """The keys memoised so far (:meth:`new_memos` hands a worker's later ones back)."""
        return set(self._cache)

    def new_memos(self, known: set) -> dict:
        """The memos added since :meth:`memo_keys` returned ``known`` (a worker process's results)."""
        return {k: v for k, v in self._cache.items() if k not in known}

    def absorb(self, memos: dict) -> None:
        """Take a worker process's memos (:meth:`new_memos`), so that nothing is computed twice."""
        self._cache.update(memos)

    def refit_forces(self, entries):
        """:func:`refit_eiv` of the training runs with the storey forces of ``entries`` ((kind,
        location, parameters) each), memoised by kind and place (a force's signal per unit of its
        coefficient does not depend on its size).  Returns (result, [parameters], [std]) or None."""
        model = self.model
        out = self.memo(("eiv", json.dumps([(k.name, loc) for k, loc, _ in entries], sort_keys=True)),
                        lambda: refit_eiv(entries, model.train.runs, self.result, model.band, model.f_top))
        if out is None:
            return None
        result, params, std = out
        return result, [dict(p0, **{k.fitted.name: p[k.fitted.name]}) for (k, _, p0), p in zip(entries, params)], std

    def identify_corrected(self, kind, loc: dict, params: dict):
        """The linear model identified from the training runs with the sensor fault ``kind`` at ``loc``
        undone (memoised)."""
        train = self.model.train
        fixed = replace(train, runs=tuple(kind.correct_run(r, loc, params) for r in train.runs))
        return self.memo(("identify", kind.name, json.dumps(loc, sort_keys=True), json.dumps(params, sort_keys=True)),
                         lambda: identify(fixed))

    def _build(self, kind, loc, params, std) -> Augmented:
        model, nominal, runs = self.model, self.nominal, self.model.train.runs
        structure = self.linear_structure
        if kind is None:
            return Augmented(structure, params, std, ())
        if kind.refit is Refit.RESIMULATE and not model.ideal:
            refit = self.refit_forces([(kind, loc, params)])
            if refit is not None:
                refitted, (params,), (std,) = refit
                structure = identified_structure(refitted, nominal)
            # The force's size by re-simulation, on the refitted linear model and on the nominal one
            # (a friction that sticks a storey leaves the linear fit poorly determined); the pair that
            # replays best wins.
            bases = [structure] + ([nominal] if nominal is not None else [])
            structure = min(bases, key=lambda b: self._misfit(b, kind, loc, params))
            params, sim_std = self.resimulate(structure, kind, loc, params)
            # the search's std is conditional on the linear model; the refit's marginal std carries
            # the linear model's own uncertainty: report both, in quadrature
            std = {k: float(math.hypot(v, std.get(k, 0.0))) for k, v in sim_std.items()}
        elif kind.refit is Refit.ATTACHMENT and nominal is not None:
            # Found by replaying the nominal model (the identified one has absorbed part of the attachment's
            # dynamics in the runs that carry it): augment the nominal model.
            structure = nominal
        elif kind.refit is Refit.DAMPING_PATTERN:
            # Rayleigh part + the storey damper: from the pattern fit of the identified C when there is one,
            # else the nominal Rayleigh coefficients.
            pattern = self.pattern
            if pattern and pattern.candidate.location == loc:
                a_, b_, c_ = pattern.info["coefficients"]
                params = {kind.fitted.name: float(c_)}
            elif nominal is not None:
                a_, b_ = nominal.rayleigh_mu, nominal.rayleigh_kappa
            else:
                a_, b_ = structure.rayleigh_mu, structure.rayleigh_kappa
            structure = replace(structure, rayleigh_mu=max(a_, 0.0), rayleigh_kappa=max(b_, 0.0))
            if nominal is not None:   # the lab's own model with the damper may replay better
                structure = min((structure, nominal), key=lambda b: self._misfit(b, kind, loc, params))
        elif kind.refit is Refit.CORRECT_DATA:
            structure = identified_structure(self.identify_corrected(kind, loc, params), nominal)
            if nominal is not None:   # the corrected data may fit the lab's own model better
                structure = min((structure, nominal), key=lambda b: self._misfit(b, kind, loc, params))
        return Augmented(structure, params, std, kind.as_records(loc, params))

    def _search_run(self) -> RunData:
        """The training run with the most added mass (the strongest test of a storey force)."""
        return max(self.model.train.runs, key=lambda r: float(np.sum(r.added_mass)))

    def _misfit(self, structure, kind, loc, params) -> float:
        """:meth:`misfit` of one mechanism."""
        return self.misfit(structure, [(kind, loc, params)])

    def misfit(self, structure, entries) -> float:
        """Normalised sum of squares of the search run replayed through the model with ``entries``
        ((kind, location, parameters) each): sum over channels and samples of
        ((measured - simulated) / RMS(measured))^2."""
        run = self._search_run()
        records = tuple(r for kind, loc, params in entries for r in kind.as_records(loc, params))
        try:
            sim, measured = joint_replay(structure, entries, records, run, self.d, structure != self.nominal)
        except (SimulationError, ModelError):   # e.g. a storey made unstable: not a candidate fit
            return _UNSTABLE
        fs, band = run.sample_rate, self.model.band
        q = 0.0
        for g in measured:
            m = band_filter(measured[g], fs, band)
            q += float(np.sum(((m - band_filter(sim[g], fs, band)) / np.sqrt(np.mean(m ** 2, axis=0))) ** 2))
        return q

    def resimulate(self, structure, kind, loc, params, others=(), span=SEARCH_RANGE,
                   grid: int = 0) -> tuple[dict, dict]:
        """Output-error refinement of a nonlinear storey force's size by re-simulation.

        The regression estimates it from measured drift velocities and drifts, whose noise
        pulls it towards zero (a noisy velocity flips sign around its zero crossings); a
        simulation has no such noise.  A bounded scalar search (over :data:`SEARCH_RANGE` times
        the regression's value, on a log scale) of :meth:`_misfit` on one training run.  The
        standard error comes from the misfit's curvature at the minimum, ``var = 2 s^2 / Q''`` with
        ``s^2`` the misfit per independent sample (band-limited channels), so it grows with any
        misfit the model leaves.  ``others``: mechanisms ((kind, location, parameters) each) held
        fixed in the model meanwhile; ``span``: the search range relative to the starting value;
        ``grid``: first replay this many sizes spread evenly (log scale) over the span and search
        between the best one's neighbours (for a starting value far off, on a misfit that is sharp
        near its minimum and flat, unstable, elsewhere: a storey weakened to collapse by P-Delta).

        Returns
        -------
        params, std : the refined parameters and their standard errors.
        """
        key = kind.fitted.name
        p0 = float(params[key])
        if not np.isfinite(p0) or p0 == 0:
            return params, {}
        seen: dict[float, float] = {}

        def cost(x):
            x = float(x)
            if x not in seen:
                seen[x] = self.misfit(structure, [*others, (kind, loc, dict(params, **{key: x}))])
            return seen[x]

        sign = math.copysign(1.0, p0)
        bounds = (math.log(span[0] * abs(p0)), math.log(span[1] * abs(p0)))
        if grid > 1:
            u = np.linspace(*bounds, grid)
            k = int(np.argmin([cost(sign * math.exp(x)) for x in u]))
            bounds = (u[max(k - 1, 0)], u[min(k + 1, grid - 1)])
            p0 = sign * math.exp(u[k])
        res = scipy.optimize.minimize_scalar(lambda u: cost(sign * math.exp(u)), bounds=bounds,
                                             method="bounded",
                                             options={"xatol": SEARCH_TOLERANCE, "maxiter": SEARCH_REPLAYS})
        best = sign * math.exp(float(res.x)) if res.fun < cost(p0) else p0
        step = CURVATURE_STEP * abs(best)
        q0, qm, qp = cost(best), cost(best - step), cost(best + step)
        curvature = (qp - 2 * q0 + qm) / step ** 2
        if curvature > 0:   # the search stops within its tolerance: finish with the parabola's vertex
            vertex = best - step * (qp - qm) / (2 * (qp - 2 * q0 + qm))
            if abs(vertex - best) < step and cost(vertex) < q0:
                best, q0 = vertex, cost(vertex)
        run = self._search_run()
        n_channels = sum(1 for g in ("a", "q") if run.has(f"{g}1")) * self.d
        band = self.model.band.high or run.sample_rate / 2
        n_eff = n_channels * run.n_samples * min(1.0, 2 * band / run.sample_rate)
        std = float(np.sqrt(2 * (q0 / max(n_eff - 1, 1)) / curvature)) if curvature > 0 else float("inf")
        return dict(params, **{key: best}), {key: std}

    def score(self, augmented: Augmented, mech: str, loc: dict) -> float:
        """Mean NRMSE of the training runs replayed through an augmented model (band-limited)."""
        kind = kind_of(mech)
        return self.score_joint(augmented.structure, [] if kind is None else [(kind, loc, augmented.parameters)],
                                augmented.records)

    def score_joint(self, structure, entries, records) -> float:
        """:meth:`score` of a model with several mechanisms ((kind, location, parameters) each,
        applied as :func:`joint_replay` does) and their ``records`` (memoised)."""
        key = ("score", repr(structure), json.dumps([(k.name, loc, p) for k, loc, p in entries], sort_keys=True),
               repr(records))
        if key not in self._cache:
            out = []
            for run in self.model.train.runs:
                try:
                    sim, measured = joint_replay(structure, entries, records, run, self.d, structure != self.nominal)
                except (SimulationError, ModelError):   # an unstable augmented model explains nothing
                    out.append(float("inf"))
                    break
                out.append(nrmse(sim, measured, run.sample_rate, self.model.band))
            self._cache[key] = float(np.mean(out))
        return self._cache[key]

    def linear_score(self) -> float:
        """:meth:`score` of the linear model."""
        return self.score(Augmented(self.linear_structure, {}, {}, ()), "none", {})

    def noise_nrmse(self) -> float:
        """The NRMSE sensor noise alone leaves in :meth:`score` (white levels, band-limited)."""
        out = []
        band = self.model.band
        for run in self.model.train.runs:
            fs = run.sample_rate
            # an identified model that a strong nonlinearity left unstable carries noise without bound:
            # the lab's nominal model carries it as the rig does
            carrier = self.model.nominal_result if not _stable(self.result) and self.model.nominal_result else self.result
            noise = replay_noise(carrier, run, self.d, band)
            for g in ("a", "q"):
                if not run.has(f"{g}1"):
                    continue
                m = band_filter(run.group(g, self.d), fs, band)
                out += list(noise[g] / np.sqrt(np.mean(m ** 2, axis=0)))
        return float(np.mean(out))
