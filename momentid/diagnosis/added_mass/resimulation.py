"""Stage 6 of the added-mass diagnosis: size a candidate and re-simulate its augmented MuJoCo model.

A candidate's kind sizes itself (:meth:`~momentid.mechanisms.base.MechanismKind.size`,
:mod:`momentid.mechanisms.sizing`): a nonlinear force at a link is refitted with the linear model by
errors-in-variables, then its size searched by re-simulation; a flexible attachment is put on the lab's
nominal model; a dashpot takes the damping pattern of the identified C; a sensor fault is undone on the
recordings, which are then re-identified; a tuned-mass damper searches its mass, frequency and damping
by re-simulation.  :class:`Refitter` is what they ask (a :class:`~momentid.mechanisms.sizing.Sizer`):
it builds a candidate's augmented model and scores it by replaying the training runs in MuJoCo.

:class:`Resimulator` is what the later stages (selection, compound, open search) ask of it: another
rig model (a calibrated twin of a real rig, replayed with its sensor models) plugs into the same
stages by providing the same.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
import json
import math
from dataclasses import dataclass, replace
from typing import Any, Protocol, TYPE_CHECKING, runtime_checkable

import numpy as np
import scipy.optimize

from momentid.core.series import RunData
from momentid.core.structure import Mechanism, Structure
from momentid.diagnosis.added_mass.augmented import Entry, identified_structure, joint_replay, records
from momentid.diagnosis.added_mass.joint_search import search_logs
from momentid.diagnosis.added_mass.residuals import LinearModel, band_signals, nrmse, replay_noise
from momentid.diagnosis.thresholds import UNSTABLE_MISFIT
from momentid.core.processes import run_forked, run_threaded
from momentid.errors import ModelError, SimulationError
from momentid.estimation.identification import identify
from momentid.estimation.identified import Identification
from momentid.estimation.reconstruct import Prefilter, band_filter
from momentid.mechanisms.base import MechanismKind, Refit
from momentid.mechanisms.place import Place

if TYPE_CHECKING:
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["Augmented", "ForceRefit", "Refitter", "Resimulator", "refit_eiv", "noise_ratios", "noise_carrier",
           "brent_opening", "side_by_side", "SEARCH_RANGE"]

#: The errors-in-variables refit reads its forces from signals low-passed at this multiple of the top
#: mode (noise would flip the sign of small drift velocities and shrink a friction force) ...
REFIT_BAND_OVER_TOP_MODE = 1.5
#: ... and fits the equations up to this multiple of the top mode.
REFIT_F_MAX_OVER_TOP_MODE = 2.0
#: The re-simulation search of a force's size: from half to five times the regression's value (on a
#: log scale; the regression is pulled towards zero, by a factor of 3 and more for a storey that
#: sticks, at 2 % noise), to this relative tolerance, in at most this many replays ...
SEARCH_RANGE = (0.5, 5.0)
SEARCH_TOLERANCE = 0.005
SEARCH_REPLAYS = 14
#: ... and the relative step of the misfit's curvature at the optimum (the standard error).
CURVATURE_STEP = 0.02


#: scipy's bounded search: its golden section and its floor on the square root of the machine epsilon.
_GOLDEN = 0.5 * (3.0 - np.sqrt(5.0))
_SQRT_EPS = np.sqrt(2.2e-16)


def _golden_step(a: float, b: float, xf: float, xatol: float) -> float:
    """The golden-section step of scipy's bounded search from its best point ``xf`` in ``[a, b]``."""
    tol1 = _SQRT_EPS * np.abs(xf) + xatol / 3.0
    rat = _GOLDEN * ((a - xf) if xf >= 0.5 * (a + b) else (b - xf))
    return float(xf + (np.sign(rat) + (rat == 0)) * np.maximum(np.abs(rat), tol1))


def brent_opening(bounds: tuple[float, float], xatol: float, values: tuple[float, float] | None = None
                  ) -> list[float]:
    """The points scipy's bounded scalar search (``minimize_scalar(method="bounded")``) evaluates
    first within ``bounds``: the golden-section point and a golden step beyond it (they depend on the
    bounds alone); given their ``values``, the third (a golden step again: two points fit no
    parabola).  Replayed side by side before the search asks for them, they are there when it does (a
    prediction that missed would cost a replay, never change a result: the search reads values only
    of the points it asks for; ``tests/test_parallel_stages.py`` checks the prediction)."""
    a, b = bounds
    x1 = float(a + _GOLDEN * (b - a))
    x2 = _golden_step(a, b, x1, xatol)
    if values is None:
        return [x1, x2]
    if values[1] <= values[0]:   # the step found a better point: the bracket closes from below
        return [_golden_step(x1, b, x2, xatol)]
    return [_golden_step(a, x2, x1, xatol)]


def side_by_side(job: Callable[[Any], Any], tasks: Iterable[Any], mechanisms: Iterable[Mechanism] = ()) -> list:
    """``[job(task) for task in tasks]`` for jobs that replay models with ``mechanisms`` (the records of
    every task's model together), side by side on the machine's cores: on threads when those replays run
    no Python in MuJoCo's step (:func:`momentid.lab.native_forces.threadable`: ``mujoco.rollout``
    releases the GIL, and a thread starts no process), else on forked workers
    (:func:`~momentid.core.processes.run_forked`).  The same values either way, and as one after the
    other (``tests/test_parallel_stages.py``)."""
    from momentid.lab.native_forces import threadable

    tasks = list(tasks)
    if len(tasks) < 2:
        return [job(task) for task in tasks]
    return (run_threaded if threadable(list(mechanisms)) else run_forked)(job, tasks)


@dataclass(frozen=True)
class ForceRefit:
    """The linear model refitted by errors-in-variables with forces at links as inputs
    (:func:`refit_eiv`): the refitted identification and each force's parameters and standard
    errors, in the order of the entries."""

    result: object
    parameters: tuple[dict, ...]
    std: tuple[dict, ...]


@dataclass(frozen=True)
class Augmented:
    """A candidate's augmented model: its kind and place (None for the linear model), the linear
    structure it sits on, its refitted parameters and standard errors, and its mechanism records (for
    :func:`momentid.lab.rig.build_spec`).

    ``refit``: the errors-in-variables refit behind it (a ``RESIMULATE`` kind's; None otherwise or
    when the runs do not allow one); ``corrected``: the linear model identified from the training
    runs with the sensor fault undone (a ``CORRECT_DATA`` kind's).
    """

    kind: MechanismKind | None
    place: Place | None
    structure: Structure
    parameters: dict
    std: dict
    records: tuple[Mechanism, ...]
    refit: ForceRefit | None = None
    corrected: object | None = None

    @property
    def entries(self) -> tuple[Entry, ...]:
        """The model's mechanisms as :func:`~momentid.diagnosis.added_mass.augmented.joint_replay` replays them."""
        return () if self.kind is None else (Entry(self.kind, self.place, self.parameters),)


def _force_signature(entry: Entry, run: RunData, signals: dict, d: int):
    """Floor direction (d, 1) and signal (n, 1) of a force at a link on one run."""
    kind, place, params = entry
    signal = kind.force_signal(params, place.stretch(signals["q"]), place.stretch(signals["v"]),
                               place.above(run.added_mass))
    return place.direction(d)[:, None], signal[:, None]


def refit_eiv(entries: Sequence[Entry], runs: Sequence[RunData], result: Identification, band: Prefilter,
              f_top: float) -> ForceRefit | None:
    """Errors-in-variables fit of the linear model together with the mechanisms' forces.

    ``entries``: the :class:`~momentid.diagnosis.added_mass.augmented.Entry` of each force at a link
    (``RESIMULATE`` kinds), fitted jointly, each from its parameters' values.  None when the runs do
    not allow it.
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
        parts = [_force_signature(entry, run, s, d) for entry in entries]
        forces.append((np.hstack([p[0] for p in parts]), np.hstack([p[1] for p in parts])))
    lay = result.layout
    keys = [entry.kind.fitted.name for entry in entries]
    theta0 = np.concatenate([result.theta, [entry.parameters[key] for key, entry in zip(keys, entries)]])
    fit = fit_eiv(lay, runs, theta0, f_max=REFIT_F_MAX_OVER_TOP_MODE * f_top, forces=forces)
    M, C, K, mu = lay.unpack(fit.theta[:lay.p])
    kappa = float(np.sum(K * (C - mu * M)) / np.sum(K * K))
    new = replace(result, M=M, C=C, K=K, mu=mu, kappa=kappa, covariance=fit.covariance[:lay.p, :lay.p])
    i = lay.p + np.arange(len(entries))
    return ForceRefit(new, tuple(dict(entry.parameters, **{key: float(fit.theta[k])})
                                 for key, entry, k in zip(keys, entries, i)),
                      tuple({key: float(np.sqrt(fit.covariance[k, k]))} for key, k in zip(keys, i)))


def noise_ratios(result: Identification, run: RunData, d: int, band: Prefilter) -> list[float]:
    """Per recorded floor channel of ``run``: the RMS sensor noise alone leaves between it and a replay
    of the right model, over its own RMS (band-limited)."""
    out = []
    fs = run.sample_rate
    noise = replay_noise(result, run, d, band)
    for g in ("a", "q"):
        if not run.has(f"{g}1"):
            continue
        m = band_filter(run.group(g, d), fs, band)
        out += list(noise[g] / np.sqrt(np.mean(m ** 2, axis=0)))
    return out


@runtime_checkable
class Resimulator(Protocol):
    """What selection, compound diagnoses and the open search ask of a rig model they re-simulate:
    :class:`Refitter` for a rig identified with added masses; a calibrated twin provides the same."""

    linear_structure: Structure

    def augment(self, kind: MechanismKind, place: Place, params: dict, std: dict) -> Augmented:
        """The model with ``kind`` added at ``place``, sized (:meth:`~momentid.mechanisms.base.MechanismKind.size`)."""

    def score(self, augmented: Augmented) -> float:
        """Mean NRMSE of the training runs replayed through ``augmented``'s model."""

    def score_joint(self, structure: Structure, entries: Sequence[Entry],
                    mechanism_records: Sequence[Mechanism]) -> float:
        """:meth:`score` of a model with several mechanisms."""

    def linear_score(self) -> float:
        """:meth:`score` of the linear model alone."""

    def noise_nrmse(self) -> float:
        """The NRMSE the sensor noise alone leaves in :meth:`score`."""

    def misfit(self, structure: Structure, entries: Sequence[Entry]) -> float:
        """Normalised sum of squares of a training replay through the model with ``entries``."""

    def better_of(self, structures: Sequence[Structure], entries: Sequence[Entry]) -> Structure:
        """Of ``structures``, the one whose model with ``entries`` has the least :meth:`misfit`."""

    def resimulate(self, structure: Structure, entry: Entry, others: Sequence[Entry] = (),
                   span: tuple[float, float] = SEARCH_RANGE, grid: int = 0) -> tuple[dict, dict]:
        """``entry``'s fitted coefficient searched by re-simulation: (parameters, standard errors)."""

    def search(self, structure: Structure, entry: Entry, names: tuple[str, ...]) -> tuple[dict, dict]:
        """``entry``'s parameters ``names`` searched together by re-simulation: (parameters, standard errors)."""

    def refit_forces(self, entries: Sequence[Entry]) -> ForceRefit | None:
        """The errors-in-variables refit of the linear model with these forces (None: the runs allow none)."""

    def identify_corrected(self, kind: MechanismKind, place: Place, params: dict) -> Any:
        """The linear identification of the training runs with the sensor fault undone."""

    def remember(self, augmented: Augmented, score: float) -> None:
        """Record an augmented model built elsewhere and its :meth:`score`."""

    def remember_refit(self, entries: Sequence[Entry], refit: ForceRefit | None) -> None:
        """Record a refit of the forces ``entries`` computed elsewhere."""


def _stable(result) -> bool:
    """Whether a linear model's free motion decays (every eigenvalue of its state matrix in the left
    half-plane)."""
    d = result.M.shape[0]
    Minv = np.linalg.inv(result.M)
    A = np.block([[np.zeros((d, d)), np.eye(d)], [-Minv @ result.K, -Minv @ result.C]])
    return bool(np.all(np.linalg.eigvals(A).real < 0))


def noise_carrier(model: LinearModel) -> Identification:
    """The linear model that carries sensor noise into a replay (:func:`noise_ratios`): the identified
    one, or the lab's nominal one when a strong nonlinearity left the identified one unstable (it would
    carry the noise without bound; the nominal model carries it as the rig does)."""
    if model.nominal_result is not None and not _stable(model.result):
        return model.nominal_result
    return model.result


class Refitter:
    """Builds the augmented model of a candidate and scores it by re-simulating the training runs
    (a :class:`Resimulator`).

    It keeps what it computed for reuse within its process: the training runs' scores and the
    corrected identifications (each a function of its inputs), and the errors-in-variables refit of
    each set of forces, by kind and place (a force's signal per unit of its coefficient does not
    depend on its size: the first refit of a set of forces is the one every later step uses).  Work
    done in another process comes back as values (:mod:`~momentid.core.processes`) and is
    recorded with :meth:`remember` / :meth:`remember_refit`.
    """

    def __init__(self, model: LinearModel, pattern):
        self.model, self.pattern = model, pattern
        self.result, self.nominal, self.d = model.result, model.nominal, model.storeys
        self.linear_structure = identified_structure(model.result, model.nominal)
        self._refits: dict = {}
        self._scores: dict = {}
        self._corrected: dict = {}

    # ---------------------------------------------------------------- what was computed

    @staticmethod
    def _refit_key(entries) -> str:
        return json.dumps([(e.kind.name, e.place.location) for e in entries], sort_keys=True)

    @staticmethod
    def _score_key(structure, entries, mechanism_records) -> tuple:
        return repr(structure), json.dumps([e.key() for e in entries], sort_keys=True), repr(mechanism_records)

    @staticmethod
    def _corrected_key(kind, place, params) -> tuple:
        return kind.name, json.dumps(place.location, sort_keys=True), json.dumps(params, sort_keys=True)

    def remember(self, augmented: Augmented, score: float) -> None:
        """Record an augmented model built elsewhere (another process) and its :meth:`score`: its
        errors-in-variables refit and its corrected identification, where it has them."""
        kind, place = augmented.kind, augmented.place
        self._scores.setdefault(self._score_key(augmented.structure, augmented.entries, augmented.records), score)
        if kind is not None and kind.refit is Refit.RESIMULATE and not self.model.ideal:
            self.remember_refit([Entry(kind, place, augmented.parameters)], augmented.refit)
        if kind is not None and augmented.corrected is not None:
            key = self._corrected_key(kind, place, augmented.parameters)
            self._corrected.setdefault(key, augmented.corrected)

    def remember_refit(self, entries: Sequence[Entry], refit: ForceRefit | None) -> None:
        """Record the errors-in-variables refit of the forces ``entries`` computed elsewhere (the first
        one recorded for a set of kinds and places stays)."""
        self._refits.setdefault(self._refit_key(entries), refit)

    # ---------------------------------------------------------------- models

    def augment(self, kind: MechanismKind | None, place: Place | None, params: dict, std: dict) -> Augmented:
        """The model with ``kind`` added at ``place``; the linear one for a verdict with none."""
        if kind is None:
            return Augmented(None, None, self.linear_structure, params, std, ())
        return self._build(kind, place, params, std)

    def refit_forces(self, entries: Sequence[Entry]) -> ForceRefit | None:
        """:func:`refit_eiv` of the training runs with the forces of ``entries`` (:class:`Entry` each),
        once per set of kinds and places (see the class docstring); each entry's fitted coefficient in
        the returned parameters, the entries' other parameters kept.  None when the runs do not allow it."""
        model = self.model
        key = self._refit_key(entries)
        if key not in self._refits:
            self._refits[key] = refit_eiv(entries, model.train.runs, self.result, model.band, model.f_top)
        out = self._refits[key]
        if out is None:
            return None
        return replace(out, parameters=tuple(dict(e.parameters, **{e.kind.fitted.name: p[e.kind.fitted.name]})
                                             for e, p in zip(entries, out.parameters)))

    def identify_corrected(self, kind: MechanismKind, place: Place, params: dict
                           ) -> Identification | ModalIdentification:
        """The linear model identified from the training runs with the sensor fault ``kind`` at ``place``
        undone."""
        key = self._corrected_key(kind, place, params)
        if key not in self._corrected:
            train = self.model.train
            fixed = replace(train, runs=tuple(kind.correct_run(r, place, params) for r in train.runs))
            self._corrected[key] = identify(fixed)
        return self._corrected[key]

    def _build(self, kind: MechanismKind, place: Place, params: dict, std: dict) -> Augmented:
        sized = kind.size(self, place, params, std)
        return Augmented(kind, place, sized.structure, sized.parameters, sized.std,
                         kind.as_records(place, sized.parameters), sized.refit, sized.corrected)

    # ---------------------------------------------------------------- what a kind's sizing asks (Sizer)

    @property
    def ideal(self) -> bool:
        """Noise-free recordings: a force needs no errors-in-variables refit."""
        return self.model.ideal

    @staticmethod
    def entry(kind: MechanismKind, place: Place, params: dict) -> Entry:
        """One mechanism of an augmented model (:class:`~momentid.diagnosis.added_mass.augmented.Entry`)."""
        return Entry(kind, place, params)

    def structure_of(self, result: Identification) -> Structure:
        """An identification as the structure a replay is built on (the nominal one's heights and base)."""
        return identified_structure(result, self.nominal)

    # ---------------------------------------------------------------- replays of the training runs

    def _search_run(self) -> RunData:
        """The training run with the most added mass (the strongest test of a force)."""
        return max(self.model.train.runs, key=lambda r: float(np.sum(r.added_mass)))

    def misfit(self, structure: Structure, entries: Sequence[Entry]) -> float:
        """Normalised sum of squares of the search run replayed through the model with ``entries``
        (:class:`Entry` each): sum over channels and samples of ((measured - simulated) / RMS(measured))^2."""
        parts = self.residual(structure, entries)
        return UNSTABLE_MISFIT if parts is None else sum(float(np.sum(r ** 2)) for r in parts)

    def residual(self, structure: Structure, entries: Sequence[Entry]) -> list[np.ndarray] | None:
        """The terms of :meth:`misfit`: per measured group, ((measured - simulated) / RMS(measured)) of the
        band-limited search run, shape (n_samples, d) each; None when the model goes unstable."""
        run = self._search_run()
        try:
            sim, measured = joint_replay(structure, entries, records(entries), run, self.d, structure != self.nominal)
        except (SimulationError, ModelError):   # e.g. a storey made unstable: not a candidate fit
            return None
        fs, band = run.sample_rate, self.model.band
        out = []
        for g in measured:
            m = band_filter(measured[g], fs, band)
            out.append((m - band_filter(sim[g], fs, band)) / np.sqrt(np.mean(m ** 2, axis=0)))
        return out

    def misfits(self, trials: Iterable[tuple[Structure, Sequence[Entry]]]) -> list[float]:
        """:meth:`misfit` of each ``(structure, entries)`` of ``trials``, side by side when there are several
        (:func:`side_by_side`; independent replays: the same values as one after the other)."""
        trials = list(trials)
        return side_by_side(lambda trial: self.misfit(*trial), trials,
                            [m for _, entries in trials for m in records(entries)])

    def better_of(self, structures: Sequence[Structure], entries: Sequence[Entry]) -> Structure:
        """The one of ``structures`` whose model with ``entries`` has the least :meth:`misfit` (the
        first of equals)."""
        q = self.misfits([(b, entries) for b in structures])
        return structures[min(range(len(q)), key=q.__getitem__)]

    def resimulate(self, structure: Structure, entry: Entry, others: Sequence[Entry] = (),
                   span: tuple[float, float] = SEARCH_RANGE, grid: int = 0) -> tuple[dict, dict]:
        """Output-error refinement of a nonlinear force's size by re-simulation.

        The regression estimates it from measured drift velocities and drifts, whose noise
        pulls it towards zero (a noisy velocity flips sign around its zero crossings); a
        simulation has no such noise.  A bounded scalar search (over :data:`SEARCH_RANGE` times
        the regression's value, on a log scale) of :meth:`misfit` on one training run.  The
        standard error comes from the misfit's curvature at the minimum, ``var = 2 s^2 / Q''`` with
        ``s^2`` the misfit per independent sample (band-limited channels), so it grows with any
        misfit the model leaves.  ``others``: mechanisms (:class:`Entry` each) held fixed in the
        model meanwhile; ``span``: the search range relative to the starting value;
        ``grid``: first replay this many sizes spread evenly (log scale) over the span and search
        between the best one's neighbours (for a starting value far off, on a misfit that is sharp
        near its minimum and flat, unstable, elsewhere: a storey weakened to collapse by P-Delta).

        Returns
        -------
        params, std : the refined parameters and their standard errors.
        """
        kind, place, params = entry
        key = kind.fitted.name
        p0 = float(params[key])
        if not np.isfinite(p0) or p0 == 0:
            return params, {}
        seen: dict[float, float] = {}

        def costs(xs) -> list[float]:   # sizes known in advance: replayed side by side
            xs = [float(x) for x in xs]
            new = list(dict.fromkeys(x for x in xs if x not in seen))
            trials = [(structure, [*others, Entry(kind, place, dict(params, **{key: x}))]) for x in new]
            seen.update(zip(new, self.misfits(trials)))
            return [seen[x] for x in xs]

        def cost(x):
            return costs([x])[0]

        sign = math.copysign(1.0, p0)
        bounds = (math.log(span[0] * abs(p0)), math.log(span[1] * abs(p0)))
        if grid > 1:
            u = np.linspace(*bounds, grid)
            k = int(np.argmin(costs([sign * math.exp(x) for x in u])))
            bounds = (u[max(k - 1, 0)], u[min(k + 1, grid - 1)])
            p0 = sign * math.exp(u[k])
        # the search's first three points and its start, known before it asks: side by side
        first = [sign * math.exp(u) for u in brent_opening(bounds, SEARCH_TOLERANCE)]
        third = brent_opening(bounds, SEARCH_TOLERANCE, tuple(costs(first)))
        costs([sign * math.exp(third[0]), p0])
        res = scipy.optimize.minimize_scalar(lambda u: cost(sign * math.exp(u)), bounds=bounds,
                                             method="bounded",
                                             options={"xatol": SEARCH_TOLERANCE, "maxiter": SEARCH_REPLAYS})
        best = sign * math.exp(float(res.x)) if res.fun < cost(p0) else p0
        step = CURVATURE_STEP * abs(best)
        q0, qm, qp = costs([best, best - step, best + step])
        curvature = (qp - 2 * q0 + qm) / step ** 2
        if curvature > 0:   # the search stops within its tolerance: finish with the parabola's vertex
            vertex = best - step * (qp - qm) / (2 * (qp - 2 * q0 + qm))
            if abs(vertex - best) < step and cost(vertex) < q0:
                best, q0 = vertex, cost(vertex)
        n_eff = self._independent_samples()
        std = float(np.sqrt(2 * (q0 / max(n_eff - 1, 1)) / curvature)) if curvature > 0 else float("inf")
        return dict(params, **{key: best}), {key: std}

    def _independent_samples(self) -> float:
        """Independent samples of the search run's misfit: its channels' samples within the band."""
        run = self._search_run()
        n_channels = sum(1 for g in ("a", "q") if run.has(f"{g}1")) * self.d
        band = self.model.band.high or run.sample_rate / 2
        return n_channels * run.n_samples * min(1.0, 2 * band / run.sample_rate)

    def search(self, structure: Structure, entry: Entry, names: tuple[str, ...]) -> tuple[dict, dict]:
        """Output-error search of several positive parameters ``names`` of ``entry`` together, by
        re-simulation of :meth:`residual` (:func:`~momentid.diagnosis.added_mass.joint_search.search_logs`:
        Gauss-Newton on their logarithms, each point replayed side by side with its Jacobian's columns);
        standard errors from that Jacobian at the optimum, ``cov = s^2 (J^T J)^-1`` with ``s^2`` the misfit
        per independent sample, as :meth:`resimulate`'s curvature rule.

        Returns
        -------
        params, std : dict
            The entry's parameters with ``names`` refined, and the standard errors of ``names``.
        """
        kind, place, params = entry

        def trial(x) -> list:
            return [Entry(kind, place, dict(params, **{n: float(np.exp(v)) for n, v in zip(names, x)}))]

        def residuals(xs) -> list:     # a point and its columns, known together: replayed side by side
            trials = [(structure, trial(x)) for x in xs]
            parts = side_by_side(lambda t: self.residual(*t), trials, [m for _, e in trials for m in records(e)])
            return [None if p is None else np.concatenate([r.ravel() for r in p]) for p in parts]

        x0 = np.log([float(params[n]) for n in names])
        best, std_logs = search_logs(residuals, x0, self._independent_samples())
        values = np.exp(best)
        std = {name: float(v * s) for name, v, s in zip(names, values, std_logs)}
        return dict(params, **{name: float(v) for name, v in zip(names, values)}), std

    def score(self, augmented: Augmented) -> float:
        """Mean NRMSE of the training runs replayed through an augmented model (band-limited)."""
        return self.score_joint(augmented.structure, augmented.entries, augmented.records)

    def score_joint(self, structure: Structure, entries: Sequence[Entry], mechanism_records: Sequence[Mechanism]
                    ) -> float:
        """:meth:`score` of a model with several mechanisms (:class:`Entry` each, applied as
        :func:`~momentid.diagnosis.added_mass.augmented.joint_replay` does) and their ``mechanism_records``."""
        key = self._score_key(structure, entries, mechanism_records)
        if key not in self._scores:
            def replayed(run: RunData) -> float:
                try:
                    sim, measured = joint_replay(structure, entries, mechanism_records, run, self.d,
                                                 structure != self.nominal)
                except (SimulationError, ModelError):   # an unstable augmented model explains nothing
                    return float("inf")
                return nrmse(sim, measured, run.sample_rate, self.model.band)
            out = side_by_side(replayed, self.model.train.runs, mechanism_records)   # independent runs
            self._scores[key] = float("inf") if math.inf in out else float(np.mean(out))
        return self._scores[key]

    def linear_score(self) -> float:
        """:meth:`score` of the linear model."""
        return self.score(self.augment(None, None, {}, {}))

    def noise_nrmse(self) -> float:
        """The NRMSE sensor noise alone leaves in :meth:`score` (white levels, band-limited)."""
        carrier = noise_carrier(self.model)
        return float(np.mean([r for run in self.model.train.runs
                              for r in noise_ratios(carrier, run, self.d, self.model.band)]))
