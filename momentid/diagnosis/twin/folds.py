"""Held-out proof of the augmented twin on a real rig's trials: one fold per held-out trial, its physics
chosen by evidence from the training trials alone.

For a held-out trial, with the other trials of the same rig state for training:

* the choice (:func:`select`): every :func:`candidates` (the linear twin; each real-rig kind of the
  registry, :func:`~momentid.mechanisms.registry.real_rig_kinds`: joint friction, cubic spring,
  quadratic damping, in every storey, each storey its own law or one law shared) is fitted on the
  training trials but one (:func:`inner_hold_out`) and replayed on that one; the lowest NRMSE wins;
* ``nrmse_linear_refit``: the linear twin (:class:`~momentid.twin.fit.FittedRig` without mechanisms)
  fitted to the training trials by re-simulation (:func:`~momentid.twin.fit.fit_twin`),
  replayed on the held-out trial;
* ``nrmse_after``: the augmented twin (the same plus the chosen physics) fitted the same way on all the
  training trials, from the linear twin, replayed on the held-out trial (the linear refit's own when
  the choice is the linear twin);
* ``nrmse_linear_own``: a linear twin fitted to the held-out trial itself (the best any model without
  amplitude dependence does on it);
* ``noise_nrmse``: what the held-out trial's sensor noise alone leaves
  (:func:`~momentid.diagnosis.modal.check.noise_nrmse`, on the own twin's modes).

The held-out trial's outputs enter none of the first two.  :func:`amplitude_trend` identifies the
augmented twin's own simulated trials exactly as the recordings are identified
(:func:`~momentid.estimation.scaled.identify_modal`, per trial), so that its predicted change of mode
1 with the response amplitude can be held to the recordings' (the identification's smearing of a
drifting frequency into damping is then the same on both sides).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from momentid.core.series import Experiment
from momentid.diagnosis.modal import check as mc
from momentid.twin import fit as twin_fit
from momentid.errors import IdentificationError
from momentid.estimation.noise import estimate_noise
from momentid.estimation.scaled import AmplitudeTrend, amplitude_trend as trend_of, identify_modal
from momentid.mechanisms import registry

__all__ = ["Fold", "Candidate", "candidates", "table_motion", "select", "inner_hold_out", "hold_out", "linear_start",
           "amplitude_trend", "FRICTION_STARTS"]

#: Starts of the augmented fit (stiffness lost at the reference drift as a share of the storey's,
#: slip drift in m, exponent); the fit keeps the one that explains the training trials best.
FRICTION_STARTS = ((0.02, 0.03, -0.5),)
#: Optimiser evaluations of the augmented fit (each costs a Jacobian of all its physical parameters: the
#: augmented fit is ~80 % of `diagnose`'s CPU).  On the shipped rig's four folds (benchmarks/real_folds.py)
#: 10 hold every criterion (after/refit 0.24-0.61); 12 cost ~20 % more CPU (on the sine_2p0 fold they
#: reached 18.6 % against 20.4 % held-out NRMSE, in a probe without the command's one-thread BLAS).
AUGMENTED_NFEV = 10
#: The kind fitted when the training trials are too few to choose (two: an inner fit needs two of its
#: own): joint friction, whose softening and damping both grow with the drift.
UNCHOSEN = "joint_friction"
#: The candidate name of the table's other motions as the twin's inputs, and its words.
TABLE_MOTION = "table_motion"
MOTION_WORDS = "the table's other motions as inputs"
#: Largest ratio of the inner held-out NRMSE of the linear twin driven by the table's other motions to the
#: linear twin's for the motions to drive the twin: five gains fitted to the training trials buy a percent
#: or two on a trial they do not drive (the shipped flexible rig: 1.00-1.01 x), a table that rocks under
#: the structure far more (the shipped stiff rig: 0.47-0.87 x).
MOTION_RATIO = 0.95
#: Seed of the sensor noise added to a simulated trial before it is identified.
NOISE_SEED = 7


@dataclass(frozen=True)
class Fold:
    """One held-out trial's result (see the module docstring)."""

    held_out: str
    training: tuple
    nrmse_linear_refit: float
    nrmse_after: float
    nrmse_linear_own: float
    noise_nrmse: float
    linear: twin_fit.FitResult
    augmented: twin_fit.FitResult
    own: twin_fit.FitResult
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    chosen: object = None
    inner_held_out: str = ""
    selection: dict = None

    def to_dict(self) -> dict:
        """The fold as ``report.json`` states it: held-out and training trials, the NRMSE of each twin and their
        ratios, the fits.
        """
        return {"held_out": self.held_out, "training": list(self.training),
                "nrmse_linear_refit": self.nrmse_linear_refit, "nrmse_after": self.nrmse_after,
                "nrmse_linear_own": self.nrmse_linear_own, "noise_nrmse": self.noise_nrmse,
                "ratio_to_linear_refit": self.nrmse_after / self.nrmse_linear_refit,
                "ratio_to_linear_own": self.nrmse_after / self.nrmse_linear_own,
                "training_nrmse": {"linear": self.linear.nrmse, "augmented": self.augmented.nrmse},
                "linear": self.linear.model.to_dict(), "augmented": self.augmented.model.to_dict(),
                "own": self.own.model.to_dict(), "seconds": self.seconds,
                "cpu_seconds": self.cpu_seconds, "chosen": self.chosen.name if self.chosen else None,
                "inner_held_out": self.inner_held_out, "selection": self.selection or {}}


def linear_start(experiment: Experiment, names: str | Sequence[str]) -> twin_fit.FittedRig:
    """The linear twin of the modal identification of run(s) ``names`` (a name or a list) with the lab's
    stated masses.

    Raises
    ------
    IdentificationError
        No stated masses (the twin's forces need them).
    """
    ident = identify_modal(experiment, [names] if isinstance(names, str) else list(names))
    if ident.K is None:
        raise IdentificationError(f"{experiment.source}: no floor masses stated: the twin needs them "
                                  f"(experiment.toml [structure] masses)")
    return twin_fit.FittedRig(np.asarray(ident.masses, float), ident.K, np.clip(ident.linear_damping_ratio, 1e-4, None))


@dataclass(frozen=True)
class Candidate:
    """One physics the augmented twin may carry: a real-rig kind (:func:`~momentid.mechanisms.registry.real_rig_kinds`)
    in every storey, each storey with its own parameters or one law ``shared`` by all; ``kind`` None: the
    linear twin (no physics).  ``motion``: the twin is also driven by the table sensor's other motions
    (:attr:`~momentid.twin.fitted_rig.FittedRig.table_motion`, a gain each): a table that rocks or sways
    under the structure."""

    kind: str | None
    shared: bool = False
    motion: bool = False

    @property
    def linear(self) -> bool:
        """The linear twin as it is: no physics and the table's shaking axis alone."""
        return self.kind is None and not self.motion

    @property
    def name(self) -> str:
        """The candidate's name in reports (``"linear"``, ``"joint_friction_shared"``, ``"table_motion"``,
        ``"bouc_wen+table_motion"``, ...)."""
        if self.kind is None:
            return TABLE_MOTION if self.motion else "linear"
        return self.kind + ("_shared" if self.shared else "") + (f"+{TABLE_MOTION}" if self.motion else "")

    def words(self, storeys: int) -> str:
        """The candidate in words for a rig of ``storeys`` storeys."""
        if self.kind is None:
            return MOTION_WORDS if self.motion else "no physics (the linear twin)"
        where = "storey 1" if storeys == 1 else ("every storey, one law shared" if self.shared
                                                  else "every storey, each its own")
        return f"{self.kind.replace('_', ' ')} at {where}" + (f", with {MOTION_WORDS}" if self.motion else "")


def candidates(storeys: int, motion: bool = False) -> tuple:
    """The linear twin; with ``motion`` the twin driven by the table's other motions too; then every real-rig
    kind per storey and (more than one storey) shared, each driven by them when ``motion``."""
    out = [Candidate(None)] + ([Candidate(None, motion=True)] if motion else [])
    for kind in registry.real_rig_kinds():
        out.append(Candidate(kind.name, motion=motion))
        if storeys > 1:
            out.append(Candidate(kind.name, shared=True, motion=motion))
    return tuple(out)


def table_motion(trials: Sequence[twin_fit.Trial]) -> tuple:
    """The table sensor's other motions every one of ``trials`` records, and records moving (a column an
    export fills with zeros is no motion), channel names in order."""
    trials = list(trials)

    def moves(t: twin_fit.Trial, c: str) -> bool:
        return c in t.motion_channels and bool(np.any(t.motion[t.start:, t.motion_channels.index(c)] != 0))

    return tuple(c for c in (trials[0].motion_channels if trials else ()) if all(moves(t, c) for t in trials))


def inner_hold_out(trials: dict[str, twin_fit.Trial], training: Sequence[str]) -> str:
    """The training trial the selection holds out: the last whose RMS floor response lies inside the other
    training trials' (an interpolation, as the outer hold-out's default), else the last."""
    level = {n: float(np.sqrt(np.mean(trials[n].a[trials[n].start:] ** 2))) for n in training}
    for name in reversed(list(training)):
        others = [v for n, v in level.items() if n != name]
        if others and min(others) <= level[name] <= max(others):
            return name
    return list(training)[-1]


def _augmented_start(linear: twin_fit.FittedRig, candidate: Candidate, starts, train) -> list:
    storeys = tuple(range(1, linear.storeys + 1))
    if candidate.kind != "joint_friction":
        return [twin_fit.mechanism_start(linear, candidate.kind, storeys, train)]
    return [twin_fit.friction_start(linear, storeys, loss, slip, chi) for loss, slip, chi in starts]


def select(trials: dict[str, twin_fit.Trial], training: Sequence[str], *, substeps: int | None = None,
           max_nfev: int = twin_fit.MAX_NFEV, augmented_nfev: int = AUGMENTED_NFEV,
           starts: Sequence[tuple[float, float, float]] = FRICTION_STARTS, start: twin_fit.FittedRig,
           pool: Callable[[Callable[[Any], Any], list], list] | None = None) -> tuple:
    """The physics the training trials alone choose: every :func:`candidates` fitted on the training trials
    but :func:`inner_hold_out`, replayed on that one; the lowest NRMSE wins (the linear twin when no
    physics predicts it better).  When ``trials`` record the table's other motions (:func:`table_motion`),
    the linear twin driven by them is fitted too; when it predicts the inner held-out trial within
    :data:`MOTION_RATIO` of the linear twin's NRMSE it is a candidate and every physics candidate is driven
    by them as well (its score is reported either way).

    Returns
    -------
    (Candidate, str, dict)
        The winner, the inner held-out trial, and per candidate name its inner held-out NRMSE and ratio to
        the inner linear refit's.
    """
    training = list(training)
    d = trials[training[0]].a.shape[1]
    if len(training) < 3:            # an inner fit needs two trials: no evidence to choose by
        return Candidate(UNCHOSEN), "", {}
    inner = inner_hold_out(trials, training)
    train = [trials[n] for n in training if n != inner]
    linear = twin_fit.fit_twin(train, start, substeps=substeps, max_nfev=max_nfev)
    score = {"linear": twin_fit.nrmse(linear.model, trials[inner], substeps)}
    # the twin's inputs first: the table's other motions drive every physics candidate when they alone
    # predict the inner held-out trial clearly better than the shaking axis alone (MOTION_RATIO)
    base, motion = linear, table_motion(trials.values())
    if motion:
        moved = twin_fit.fit_twin(train, linear.model.driven_by(motion), substeps=substeps, max_nfev=max_nfev)
        score[TABLE_MOTION] = twin_fit.nrmse(moved.model, trials[inner], substeps)
        base = moved if score[TABLE_MOTION] <= MOTION_RATIO * score["linear"] else linear
    cands = candidates(d, base is not linear)
    physics = [c for c in cands if c.kind is not None]

    def fit(candidate):
        fits = [twin_fit.fit_twin(train, guess, substeps=substeps, max_nfev=augmented_nfev, shared=candidate.shared,
                                     fit_motion=False)
                for guess in _augmented_start(base.model, candidate, starts, train)]
        return min(fits, key=lambda f: f.cost)

    fits = (pool or twin_fit.each)(fit, physics)
    score.update({c.name: twin_fit.nrmse(f.model, trials[inner], substeps) for c, f in zip(physics, fits)})
    table = {n: {"inner_nrmse": v, "ratio_to_linear": v / score["linear"]} for n, v in score.items()}
    best = min(cands, key=lambda c: score[c.name])
    return best, inner, table


def hold_out(experiment: Experiment, held: str, training: Sequence[str], *, substeps: int | None = None,
             max_nfev: int = twin_fit.MAX_NFEV, augmented_nfev: int = AUGMENTED_NFEV,
             starts: Sequence[tuple[float, float, float]] = FRICTION_STARTS, start: twin_fit.FittedRig | None = None,
             candidate: Candidate | None = None) -> Fold:
    """Choose the physics on ``training`` (:func:`select`), fit the linear and the chosen twin on all of
    ``training`` and check them on ``held`` (module docstring).

    Parameters
    ----------
    experiment : Experiment
        Runs without added mass, ``zdd`` and ``a1..ad`` (m/s^2), stated floor masses.
    held : str
        The held-out run.
    training : sequence of str
        The training runs (``held`` not among them).
    start : RigModel, optional
        The linear fit's start (default: the modal identification of the quietest training run).
    candidate : Candidate, optional
        The physics to fit without choosing (default: :func:`select`'s).
    """
    import time

    began, cpu = time.perf_counter(), time.process_time()
    d = experiment.storeys
    trials = {n: twin_fit.trial(experiment.run(n), d) for n in list(training) + [held]}
    train = [trials[n] for n in training]
    quietest = min(training, key=lambda n: float(np.sqrt(np.mean(trials[n].a[trials[n].start:] ** 2))))
    start = linear_start(experiment, quietest) if start is None else start

    def linear_fit():
        return twin_fit.fit_twin(train, start, substeps=substeps, max_nfev=max_nfev)

    def own_fit(model):
        return twin_fit.fit_twin([trials[held]], model, substeps=substeps, max_nfev=max_nfev)

    def choose():
        if candidate is not None:
            return candidate, "", {}
        return select(trials, training, substeps=substeps, max_nfev=max_nfev, augmented_nfev=augmented_nfev,
                      starts=starts, start=start)

    # the selection runs beside the linear refit (threads: MuJoCo releases the GIL), its candidates side by
    # side once that is done; then the held-out trial's own fit beside the chosen physics' fits
    linear, (chosen, inner, table) = twin_fit.each(lambda job: job(), [linear_fit, choose])
    base = linear
    if chosen.motion:              # the linear twin driven by the table's other motions, then its physics
        base = twin_fit.fit_twin(train, linear.model.driven_by(table_motion(trials.values())), substeps=substeps,
                                 max_nfev=max_nfev)
    if chosen.kind is None:
        fits = [own_fit(linear.model), base]
    else:
        guesses = _augmented_start(base.model, chosen, starts, train)
        jobs = [lambda: own_fit(linear.model)] + [
            lambda guess=guess: twin_fit.fit_twin(train, guess, substeps=substeps, max_nfev=augmented_nfev,
                                                  shared=chosen.shared, fit_motion=False) for guess in guesses]
        fits = twin_fit.each(lambda job: job(), jobs)
    own, augmented = fits[0], min(fits[1:], key=lambda fit: fit.cost)
    tr = trials[held]
    omega, zeta, residues = twin_fit.twin_modes(own.model)
    noise = mc.noise_nrmse(omega, zeta, residues, own.model.gain, experiment.run(held), experiment)
    refit = twin_fit.nrmse(linear.model, tr, substeps)
    return Fold(held_out=held, training=tuple(training),
                nrmse_linear_refit=refit,
                nrmse_after=refit if chosen.linear else twin_fit.nrmse(augmented.model, tr, substeps),
                nrmse_linear_own=own.nrmse[held], noise_nrmse=noise, linear=linear, augmented=augmented, own=own,
                seconds=time.perf_counter() - began, cpu_seconds=time.process_time() - cpu,
                chosen=chosen, inner_held_out=inner, selection=table)


def _simulated_experiment(experiment: Experiment, model: twin_fit.FittedRig, names, substeps: int | None) -> Experiment:
    """``experiment``'s runs ``names`` with their floor channels replaced by ``model``'s simulation, read by its
    sensors, plus white noise at each channel's measured level (the identification needs a noise floor)."""
    rng = np.random.default_rng(NOISE_SEED)
    d = experiment.storeys
    runs = []
    for n in names:
        run = experiment.run(n)
        tr = twin_fit.trial(run, d)
        a = twin_fit.predict(model, tr, substeps)
        sigma = estimate_noise(run).sigma
        values = run.values.copy()
        for j in range(d):
            values[:, run.channels.index(f"a{j + 1}")] = a[:, j] + rng.normal(0.0, sigma[f"a{j + 1}"], a.shape[0])
        runs.append(replace(run, values=values))
    return replace(experiment, runs=tuple(runs))


def amplitude_trend(experiment: Experiment, model: twin_fit.FittedRig, names: Sequence[str],
                    substeps: int | None = None) -> AmplitudeTrend:
    """Mode 1 against the response amplitude, as the twin ``model`` predicts it on the runs ``names``.

    Returns
    -------
    AmplitudeTrend
        :func:`~momentid.estimation.scaled.amplitude_trend` of the per-run identification of the twin's
        simulated runs.
    """
    simulated = _simulated_experiment(experiment, model, names, substeps)
    return trend_of([identify_modal(simulated, [n]) for n in names])
