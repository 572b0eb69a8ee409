"""Stage 8 of the added-mass diagnosis, the open search: when no mechanism of the library explains the misfit,
model it from the data.

:func:`discover` runs after selection when the verdict is ``unexplained``.  At every storey (a force
against its drift) and every floor above the first against the table (floor 1 against the table
*is* storey 1), it selects a sparse force from the function library
(:mod:`momentid.diagnosis.function_library`) on the training runs' equation residual, scored on
held-out time blocks; the place whose force leaves the smallest held-out residual wins.  This is
done on the identified model's residual and, when the lab states one, on the nominal model's (the
identified model may have absorbed part of the force); the force whose MuJoCo model (a
``data_driven_storey`` / ``data_driven_floor`` record, :mod:`momentid.mechanisms.data_driven`)
replays a training run best is kept.  Its nonlinear terms are then sized by re-simulation (the
regression on noisy signals is pulled towards zero), and the held-out run is replayed: the
discovery is reported only when it removes at least :data:`ACCEPTED_SHARE` of the held-out misfit
above the noise.
"""

from __future__ import annotations

from collections.abc import Sequence
import math
from dataclasses import dataclass, field, replace
import os
from typing import TYPE_CHECKING

import numpy as np
import scipy.optimize
from threadpoolctl import threadpool_limits

from momentid import mechanisms
from momentid.core.structure import Mechanism, Structure
from momentid.diagnosis.function_library import ALWAYS, Selected, columns, hysteretic_columns, refine, select
from momentid.diagnosis.discovered_physics import describe, physics
from momentid.diagnosis.added_mass.resimulation import Refitter, Resimulator, brent_opening, side_by_side
from momentid.diagnosis.added_mass.augmented import Entry, measured_groups
from momentid.diagnosis.added_mass.residuals import EquationResiduals, LinearModel, ResidualRow, blocks, nrmse
from momentid.diagnosis.added_mass.selection import Finding, OutsideLibrary, explained_share
from momentid.diagnosis.thresholds import EXCESS
from momentid.diagnosis.verdict import Verdict
from momentid.core.processes import run_forked
from momentid.diagnosis.added_mass.screening import Candidate
from momentid.errors import ModelError, SimulationError
from momentid.mechanisms.data_driven import TERMS
from momentid.mechanisms.place import Place, Target

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["Discovery", "Found", "discover", "search", "found_terms", "challenge", "as_unexplained", "plot_discovered",
           "discovered_figure", "ACCEPTED_SHARE", "BEATS_LIBRARY", "TERM_EARNS", "SCALE_RANGE", "SCALE_REPLAYS",
           "SCALE_TOLERANCE", "PLOT_POINTS"]

#: A discovered force is reported when its model removes this share of the held-out run's replay
#: misfit above the noise (0.5: the misfit's excess power at least halves).
ACCEPTED_SHARE = 0.5
#: A discovered force replaces the physics the library named when its training replays remove at
#: least this share of the misfit above noise that the named model leaves (as a further mechanism
#: earns its place in a compound diagnosis: a data-driven force's extra freedom gains a little on
#: any fit; half is physics the library lacks).
BEATS_LIBRARY = 0.5
#: A nonlinear term after the first stays in the discovered force when the force with it removes this
#: share of the training replays' misfit above noise that the force without it leaves (the rule a
#: further mechanism of a compound diagnosis meets).
TERM_EARNS = 0.5
#: Re-simulation search of the nonlinear terms' common scale, from half to twice the regression's
#: (noisy signals pull the regression towards zero), in at most this many replays.
SCALE_RANGE = (0.5, 2.0)
SCALE_REPLAYS = 8
#: ... to this tolerance of its logarithm.
SCALE_TOLERANCE = 0.02
#: Samples drawn in ``discovered.png``.
PLOT_POINTS = 4000


@dataclass(frozen=True)
class Discovery:
    """A force found by the open search (``report.json``'s ``discovered``).

    Attributes
    ----------
    place : Place
        A storey (against its drift) or a floor against the table; its ``location`` is
        ``{"storey": i}`` or ``{"floor": j}``, 1-based.
    description : str
        The force in words.
    terms : tuple of dict
        Each term: ``term``, ``meaning``, ``coefficient`` with its ``unit``, and its shape parameters.
    nrmse_before, nrmse_after : float
        Held-out run's replay NRMSE, linear model and with the force.
    record : Mechanism
        The force's model record (for :func:`momentid.lab.rig.build_spec`).
    structure : Structure
        The linear model it is added to.
    plot : dict
        ``x`` (m), ``measured`` and ``law`` (N): the residual's force at the place and the discovered law.
    physics : dict
        Its class of physics and that class's numbers (:func:`~momentid.diagnosis.discovered_physics.physics`).
    replaces : OutsideLibrary or None
        When it beat the physics the library named (:func:`challenge`): what, and the training NRMSEs.
    """

    place: Place
    description: str
    terms: tuple[dict, ...]
    nrmse_before: float
    nrmse_after: float
    record: Mechanism = field(repr=False)
    structure: Structure = field(repr=False)
    plot: dict = field(default_factory=dict, repr=False)
    physics: dict = field(default_factory=dict)
    replaces: OutsideLibrary | None = None

    @property
    def location(self) -> dict:
        """The place as a record's location (``{"storey": 2}``, ...)."""
        return self.place.location

    def draw(self, path: str | os.PathLike) -> None:
        """``discovered.png`` at ``path``: :func:`plot_discovered`."""
        plot_discovered(self, path)

    def to_dict(self) -> dict:
        """The discovery as ``report.json`` states it: place, force in words and terms, the replays' NRMSE."""
        return {"location": self.location, "description": self.description, "terms": list(self.terms),
                "physics": self.physics, "nrmse_before": self.nrmse_before, "nrmse_after": self.nrmse_after,
                "replaces": self.replaces.to_dict() if self.replaces is not None else None}


@dataclass(frozen=True)
class Found:
    """The best force on one residual (:func:`search`): its place, the selected terms, the place's
    stretch ``x`` (n,) (m) and its rate ``v`` (n,) (m/s), and the residual's force there ``y`` (n,) (N)
    behind the plot."""

    place: Place
    selected: Selected
    x: np.ndarray
    v: np.ndarray
    y: np.ndarray


def _places(d: int) -> list[Place]:
    """Every storey, and every floor above the first against the table (floor 1 against the table is
    storey 1)."""
    return [Place(Target.STOREY, i) for i in range(1, d + 1)] + [Place(Target.FLOOR_TABLE, j) for j in range(2, d + 1)]


def search(rows: Sequence[ResidualRow], noise_floor: np.ndarray, d: int) -> Found | None:
    """The force at the place where the library explains the held-out residual best.

    Parameters
    ----------
    rows : sequence of ResidualRow
        The training runs' equation residual (:class:`~momentid.diagnosis.added_mass.residuals.ResidualRow`).
    noise_floor : ndarray, shape (d,)
        Per floor, the residual RMS sensor noise alone leaves (N).
    d : int
        Storeys.

    Returns
    -------
    Found or None
        None for reconstructed signals (no sample clock to integrate a hysteretic state on).
    """
    if any(r.signals["q"].shape[0] != r.run.n_samples for r in rows):
        return None   # reconstructed (weak-form) signals have no sample clock to integrate a state on
    fs = rows[0].run.sample_rate
    q, v, R = (np.concatenate(x) for x in zip(*[(r.signals["q"], r.signals["v"], r.residual) for r in rows]))
    time = np.concatenate([r.run.time - r.run.time[0] for r in rows])
    ends = np.cumsum([len(r.residual) for r in rows])
    segments = list(zip(np.r_[0, ends[:-1]], ends))
    train = np.concatenate([blocks(len(r.residual), fs)[0] for r in rows])
    test = ~train
    noise_test = float(np.sum(noise_floor ** 2)) * int(test.sum())
    total_test = float(np.sum(R[test] ** 2))
    places = _places(d)
    xv = [(p.stretch(q), p.stretch(v)) for p in places]
    hyst = hysteretic_columns([s[1] for s in xv], [float(np.max(np.abs(s[0]))) for s in xv], segments, 1 / fs)
    best = None
    for place, (x, vel), h in zip(places, xv, hyst):
        w = place.direction(d)
        y, w2 = place.force(R), float(w @ w)
        sel = select(columns(x, vel, time, segments, h), y, w2, total_test - w2 * float(np.sum(y[test] ** 2)),
                     noise_test, train, test, (x, vel, time))
        if best is None or sel.test_rss < best[0].test_rss:
            best = (sel, place, x, vel, y)
    sel, place, x, vel, y = best
    return Found(place, refine(sel, y, x, vel, time), x, vel, y)


def _record(found: Found, scale: float = 1.0) -> Mechanism:
    """The force as a record of the open search's kind at its place; ``scale`` multiplies the nonlinear
    terms' coefficients."""
    kind = mechanisms.open_search_kind(found.place.target)
    params = {p.name: (0.0 if p.name.startswith("c_") else p.example) for p in kind.params}
    for col, c in zip(found.selected.columns, found.selected.coefficients):
        params[f"c_{col.term}"] = float(c) * (1.0 if col.term in ALWAYS else scale)
        params.update(col.shape)
    return Mechanism(kind.name, found.place.index, tuple(params.items()))


def _side_by_side(refitter: Resimulator, misfit, scales: list, record: Mechanism) -> list:
    """``misfit`` at each of ``scales`` side by side: a :class:`Refitter`'s replays with ``record``'s kind
    on threads when they run natively (:func:`side_by_side`), another rig model's on forked workers."""
    if isinstance(refitter, Refitter):
        return side_by_side(misfit, scales, [record])
    return run_forked(misfit, scales)


def _misfit(refitter: Resimulator, structure: Structure, record: Mechanism) -> float:
    """The refitter's replay misfit of its search run through ``structure`` with the force ``record``."""
    kind = mechanisms.get(record.type)
    return refitter.misfit(structure, [Entry(kind, kind.place(record.location), dict(record.parameters))])


def _pruned(refitter: Resimulator, structure: Structure, found: Found) -> Found:
    """The fewest of the selected terms that earn their place in the training replays.

    Selection scores terms on the equation residual's held-out blocks, where a term that mimics a
    detail the library lacks (a hysteretic state or a stiffness switch for a stop's contact dashpot)
    lowers the residual a little and joins.  Here each nonlinear term after the first, in the order
    selection took them, stays only when the force with it removes ``TERM_EARNS`` of the training
    replays' misfit above noise that the force without it leaves (coefficients refitted by least
    squares on every sample for each set of terms).
    """
    always = [c for c in found.selected.columns if c.term in ALWAYS]
    nonlinear = [c for c in found.selected.columns if c.term not in ALWAYS]
    if len(nonlinear) < 2:
        return found

    def with_terms(k: int) -> Found:
        cols = tuple(always + nonlinear[:k])
        coef = np.linalg.lstsq(np.column_stack([c.signal for c in cols]), found.y, rcond=None)[0]
        return replace(found, selected=replace(found.selected, columns=cols, coefficients=coef))

    noise = refitter.noise_nrmse()
    kept = with_terms(1)
    score = refitter.score_joint(structure, [], (_record(kept),))
    for k in range(2, len(nonlinear) + 1):
        trial = with_terms(k)
        after = refitter.score_joint(structure, [], (_record(trial),))
        if explained_share(score, after, noise) < TERM_EARNS:
            break
        kept, score = trial, after
    return kept


def _sized(refitter: Resimulator, structure: Structure, found: Found) -> tuple[float, float]:
    """Common scale of the nonlinear terms by re-simulation of the search run, and its misfit."""
    if all(c.term in ALWAYS for c in found.selected.columns):
        return 1.0, _misfit(refitter, structure, _record(found))

    def misfit(u: float) -> float:
        return _misfit(refitter, structure, _record(found, math.exp(u)))

    low, high = SCALE_RANGE
    bounds = (math.log(low), math.log(high))
    first = brent_opening(bounds, SCALE_TOLERANCE)   # the search's first points and 0: side by side
    seen: dict[float, float] = dict(zip(first, _side_by_side(refitter, misfit, first, _record(found))))
    known = brent_opening(bounds, SCALE_TOLERANCE, (seen[first[0]], seen[first[1]])) + [0.0]
    seen.update(zip(known, _side_by_side(refitter, misfit, known, _record(found))))

    def cost(u: float) -> float:
        if u not in seen:
            seen[u] = misfit(u)
        return seen[u]

    res = scipy.optimize.minimize_scalar(cost, bounds=bounds, method="bounded",
                                         options={"maxiter": SCALE_REPLAYS, "xatol": SCALE_TOLERANCE})
    u = float(res.x) if res.fun < cost(0.0) else 0.0
    return math.exp(u), cost(u)


def discover(model: LinearModel, residuals: EquationResiduals, refitter: Resimulator, found: Finding,
             before: float) -> Discovery | None:
    """The open search (see the module docstring); None when the verdict is not ``unexplained``, the
    held-out replay was skipped (``before`` not finite), or no force removes enough of the misfit.

    Parameters
    ----------
    model, residuals, refitter : the diagnosis's stages 1, 2 and 6.
    found : Finding
        The verdict of selection.
    before : float
        The held-out run's replay NRMSE through the linear model.
    """
    if found.verdict is not Verdict.UNEXPLAINED or not math.isfinite(before):
        return None
    return _open_search(model, residuals, refitter, before)


def challenge(model: LinearModel, residuals: EquationResiduals, refitter: Resimulator, named: Finding,
              entries: Sequence[Entry], before: float, confirmed: Candidate | None = None) -> Discovery | None:
    """The open search against the physics the library named: the discovered force when it beats it.

    A library mechanism can take in part of a force outside the library (a cubic stiffness the
    ramp of a brace engaging beyond a gap, a storey damper a stop's losses) and be accepted.  When
    the named model's training replays stay above ``EXCESS`` x their noise level, the open search
    runs on the whole mismatch; its force wins when its training replays leave at most
    ``1 - BEATS_LIBRARY`` of the named model's misfit above noise.  ``replaces`` then says what it
    beat (:class:`~momentid.diagnosis.added_mass.selection.OutsideLibrary`).  None when the named physics
    includes a sensor fault the channels show, replays at the noise level, or the search finds
    nothing better.

    A sensor fault the channels show against each other (``confirmed``, the kinematic check's) is a
    fault whatever the models say: it is not challenged.  Any other named fault is (a contact against
    a stop can replay like a bias of the table accelerometer): it stands only when no physical force
    replays as well.

    Parameters
    ----------
    model, residuals, refitter : the diagnosis's stages 1, 2 and 6.
    named : Finding
        The named mechanisms' joint model (its ``structure`` and ``records``).
    entries : sequence of Entry
        Each named mechanism (:class:`~momentid.diagnosis.added_mass.augmented.Entry`).
    before : float
        The held-out run's replay NRMSE through the linear model.
    confirmed : Candidate, optional
        The sensor fault the channels show (:attr:`~momentid.diagnosis.added_mass.sensor_faults.SensorCheck.fault`).
    """
    shown = confirmed is not None and any(e.kind.target is Target.CHANNEL and e.kind is confirmed.kind
                                          and e.place == confirmed.place for e in entries)
    if not entries or not math.isfinite(before) or shown:
        return None
    noise = refitter.noise_nrmse()
    score = refitter.score_joint(named.structure, entries, named.records)
    if score <= EXCESS * noise:
        return None
    found = _open_search(model, residuals, refitter, before)
    if found is None:
        return None
    own = refitter.score_joint(found.structure, [], (found.record,))
    share = explained_share(score, own, noise)
    if share < BEATS_LIBRARY:
        return None
    return replace(found, replaces=OutsideLibrary(named.mechanism, named.location, score, own, noise, share))


def as_unexplained(named: Finding, discovered: Discovery, refitter: Resimulator) -> Finding:
    """The verdict when a discovered force beats the named physics (:func:`challenge`): ``unexplained``
    at the force's place, on the linear model; its selection's ``outside_library`` says what it replaced."""
    selection = replace(named.selection, outside_library=discovered.replaces)
    return Finding(Verdict.UNEXPLAINED, None, None, discovered.location, {}, {}, refitter.linear_structure, (),
                   selection)


def _open_search(model: LinearModel, residuals: EquationResiduals, refitter: Resimulator,
                 before: float) -> Discovery | None:
    """The search itself: the best force on the identified (and nominal) model's residual, sized by
    re-simulation, kept when it removes ``ACCEPTED_SHARE`` of the held-out misfit above noise."""
    bases = [(residuals.rows, refitter.linear_structure)]
    if residuals.nominal_rows is not None and model.nominal is not None:
        bases.append((residuals.nominal_rows, model.nominal))

    def tried(base):   # the search on one base and its replay (the bases side by side, on the workers)
        rows, structure = base
        with threadpool_limits(limits=1, user_api="blas"):   # tall, thin products: threads only add waiting
            got = search(rows, residuals.noise_floor, model.storeys)
        return None if got is None else (_misfit(refitter, structure, _record(got)), got)
    trials = [(t[0], structure, t[1]) for (_, structure), t in zip(bases, run_forked(tried, bases)) if t is not None]
    if not trials:
        return None
    _, structure, got = min(trials, key=lambda t: t[0])
    got = _pruned(refitter, structure, got)
    scale, _ = _sized(refitter, structure, got)
    record = _record(got, scale)
    after = _held_out(model, structure, record)
    if explained_share(before, after, refitter.noise_nrmse()) < ACCEPTED_SHARE:
        return None
    terms = found_terms(got, scale)
    fitted = np.column_stack([c.signal for c in got.selected.columns]) @ np.array(
        [t["coefficient"] for t in terms])
    pick = np.linspace(0, len(got.x) - 1, min(PLOT_POINTS, len(got.x))).astype(int)
    peaks = (float(np.max(np.abs(got.x))), float(np.max(np.abs(got.v))))
    return Discovery(place=got.place, description=describe(got.place, terms, structure, *peaks),
                     terms=tuple(terms), nrmse_before=float(before), nrmse_after=float(after), record=record,
                     structure=structure, plot={"x": got.x[pick], "measured": got.y[pick], "law": fitted[pick]},
                     physics=physics(got.place, terms))


def _held_out(model: LinearModel, structure: Structure, record: Mechanism) -> float:
    """NRMSE of the evaluation run replayed through ``structure`` with the discovered force."""
    from momentid.lab.simulation import replay
    run = model.evaluation_run
    try:
        sim = replay(structure, (record,), run, run["zdd"])
    except (SimulationError, ModelError):   # an unstable model explains nothing
        return float("inf")
    return nrmse(sim, measured_groups(run, model.storeys), run.sample_rate, model.band)


def found_terms(found: Found, scale: float) -> list[dict]:
    """The selected terms of ``found`` as the report lists them (``term``, ``meaning``, ``coefficient``
    with its ``unit``, shape parameters), the nonlinear terms' coefficients multiplied by ``scale``."""
    by_name = {t.name: t for t in TERMS}
    out = []
    for col, c in zip(found.selected.columns, found.selected.coefficients):
        term = by_name[col.term]
        out.append({"term": term.name, "meaning": term.meaning,
                    "coefficient": float(c) * (1.0 if term.name in ALWAYS else scale), "unit": term.unit,
                    **col.shape})
    return out


def discovered_figure(discovery: Discovery) -> Figure:
    """The residual's force at the place against ``x``, measured and discovered (a matplotlib figure)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    p, place = discovery.plot, discovery.place
    fig, ax = plt.subplots(figsize=(7, 5))
    ax.plot(1e3 * p["x"], p["measured"], ".", color="0.5", ms=3, label="residual force of the linear model "
            "(training runs)")
    ax.plot(1e3 * p["x"], p["law"], ".", color="C3", ms=1, label="discovered force")
    what = "drift of storey" if place.target is Target.STOREY else "displacement vs. table of floor"
    ax.set_xlabel(f"{what} {place.index} (mm)")
    ax.set_ylabel("force resisting it (N)")
    ax.set_title(f"{place.words}: held-out NRMSE {100 * discovery.nrmse_before:.2f} % -> "
                 f"{100 * discovery.nrmse_after:.2f} %", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_discovered(discovery: Discovery, path: str | os.PathLike) -> None:
    """``discovered.png``: :func:`discovered_figure` as a PNG."""
    import matplotlib.pyplot as plt

    fig = discovered_figure(discovery)
    fig.savefig(path, dpi=90)
    plt.close(fig)
