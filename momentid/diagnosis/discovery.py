"""The open search: when no mechanism of the library explains the misfit, model it from the data.

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

import json
import math
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize
from threadpoolctl import threadpool_limits

from momentid import mechanisms
from momentid.core.structure import Mechanism, Structure
from momentid.diagnosis.interpret import physics
from momentid.diagnosis.function_library import (ALWAYS, Place, Selected, columns, hysteretic_columns,
                                                 place_direction, refine, select)
from momentid.diagnosis.refit import Refitter, measured_groups
from momentid.diagnosis.residuals import EquationResiduals, LinearModel, blocks, nrmse
from momentid.diagnosis.selection import Finding, Verdict, explained_share
from momentid.errors import ModelError, SimulationError
from momentid.mechanisms.bouc_wen import bouc_wen_state
from momentid.mechanisms.data_driven import HYSTERETIC_BETA, TERMS

__all__ = ["Discovery", "discover", "describe", "plot_discovered", "ACCEPTED_SHARE", "SCALE_RANGE",
           "SCALE_REPLAYS", "PLOT_POINTS"]

#: A discovered force is reported when its model removes this share of the held-out run's replay
#: misfit above the noise (0.5: the misfit's excess power at least halves).
ACCEPTED_SHARE = 0.5
#: Re-simulation search of the nonlinear terms' common scale, from half to twice the regression's
#: (noisy signals pull the regression towards zero), in at most this many replays.
SCALE_RANGE = (0.5, 2.0)
SCALE_REPLAYS = 8
#: Samples drawn in ``discovered.png``.
PLOT_POINTS = 4000
#: Cycles of the hysteretic law's loop computed for its area (the first ones settle from z = 0),
#: and samples per cycle.
_LOOP_CYCLES, _LOOP_SAMPLES = 3, 2000


@dataclass(frozen=True)
class Discovery:
    """A force found by the open search (``report.json``'s ``discovered``).

    Attributes
    ----------
    location : dict
        ``{"storey": i}`` (against its drift) or ``{"floor": j}`` (against the table), 1-based.
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
        Its class of physics and that class's numbers (:func:`~momentid.diagnosis.interpret.physics`).
    """

    location: dict
    description: str
    terms: tuple[dict, ...]
    nrmse_before: float
    nrmse_after: float
    record: Mechanism = field(repr=False)
    structure: Structure = field(repr=False)
    plot: dict = field(default_factory=dict, repr=False)
    physics: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"location": self.location, "description": self.description, "terms": list(self.terms),
                "physics": self.physics, "nrmse_before": self.nrmse_before, "nrmse_after": self.nrmse_after}


@dataclass(frozen=True)
class _Found:
    """The best force on one residual: place, selected terms, the signals behind the plot."""

    place: Place
    selected: Selected
    x: np.ndarray
    y: np.ndarray


def _places(d: int) -> list[Place]:
    locations = [{"storey": i + 1} for i in range(d)] + [{"floor": j + 1} for j in range(1, d)]
    return [Place(loc, place_direction(loc, d)) for loc in locations]


def _search(rows, noise_floor: np.ndarray, d: int) -> _Found | None:
    """The force at the place where the library explains the held-out residual best."""
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
    xv = [p.signals(q, v) for p in places]
    hyst = hysteretic_columns([s[1] for s in xv], [float(np.max(np.abs(s[0]))) for s in xv], segments, 1 / fs)
    best = None
    for place, (x, vel), h in zip(places, xv, hyst):
        y, w2 = place.force(R), float(place.w @ place.w)
        sel = select(columns(x, vel, time, segments, h), y, w2, total_test - w2 * float(np.sum(y[test] ** 2)),
                     noise_test, train, test)
        if best is None or sel.test_rss < best[0].test_rss:
            best = (sel, place, x, vel, y)
    sel, place, x, vel, y = best
    return _Found(place, refine(sel, y, x, vel, time), x, y)


def _record(found: _Found, scale: float = 1.0) -> Mechanism:
    """The force as a ``data_driven_*`` record; ``scale`` multiplies the nonlinear terms' coefficients."""
    (kind_name, index), = found.place.location.items()
    kind = mechanisms.get(f"data_driven_{kind_name}")
    params = {p.name: (0.0 if p.name.startswith("c_") else p.example) for p in kind.params}
    for col, c in zip(found.selected.columns, found.selected.coefficients):
        params[f"c_{col.term}"] = float(c) * (1.0 if col.term in ALWAYS else scale)
        params.update(col.shape)
    return Mechanism(kind.name, index, tuple(params.items()))


def _misfit(refitter: Refitter, structure: Structure, record: Mechanism) -> float:
    """The refitter's replay misfit of its search run through ``structure`` with the force ``record``."""
    kind = mechanisms.get(record.type)
    return refitter.misfit(structure, [(kind, {kind.target.value: record.location}, dict(record.parameters))])


def _sized(refitter: Refitter, structure: Structure, found: _Found) -> tuple[float, float]:
    """Common scale of the nonlinear terms by re-simulation of the search run, and its misfit."""
    if all(c.term in ALWAYS for c in found.selected.columns):
        return 1.0, _misfit(refitter, structure, _record(found))
    seen: dict[float, float] = {}

    def cost(u: float) -> float:
        if u not in seen:
            seen[u] = _misfit(refitter, structure, _record(found, math.exp(u)))
        return seen[u]

    low, high = SCALE_RANGE
    res = scipy.optimize.minimize_scalar(cost, bounds=(math.log(low), math.log(high)), method="bounded",
                                         options={"maxiter": SCALE_REPLAYS, "xatol": 0.02})
    u = float(res.x) if res.fun < cost(0.0) else 0.0
    return math.exp(u), cost(u)


def discover(model: LinearModel, residuals: EquationResiduals, refitter: Refitter, found: Finding,
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
    if found.mechanism != Verdict.UNEXPLAINED.value or not math.isfinite(before):
        return None
    bases = [(residuals.rows, refitter.linear_structure)]
    if residuals.nominal_rows is not None and model.nominal is not None:
        bases.append((residuals.nominal_rows, model.nominal))
    trials = []
    for rows, structure in bases:
        with threadpool_limits(limits=1, user_api="blas"):   # tall, thin products: threads only add waiting
            got = _search(rows, residuals.noise_floor, model.storeys)
        if got is not None:
            trials.append((_misfit(refitter, structure, _record(got)), structure, got))
    if not trials:
        return None
    _, structure, got = min(trials, key=lambda t: t[0])
    scale, _ = _sized(refitter, structure, got)
    record = _record(got, scale)
    after = _held_out(model, structure, record)
    if explained_share(before, after, refitter.noise_nrmse()) < ACCEPTED_SHARE:
        return None
    terms = _terms(got, scale)
    fitted = np.column_stack([c.signal for c in got.selected.columns]) @ np.array(
        [t["coefficient"] for t in terms])
    pick = np.linspace(0, len(got.x) - 1, min(PLOT_POINTS, len(got.x))).astype(int)
    return Discovery(location=got.place.location, description=describe(got.place.location, terms, structure,
                                                                       float(np.max(np.abs(got.x)))),
                     terms=tuple(terms), nrmse_before=float(before), nrmse_after=float(after), record=record,
                     structure=structure, plot={"x": got.x[pick], "measured": got.y[pick], "law": fitted[pick]},
                     physics=physics(got.place.location, terms))


def _held_out(model: LinearModel, structure: Structure, record: Mechanism) -> float:
    """NRMSE of the evaluation run replayed through ``structure`` with the discovered force."""
    from momentid.lab.simulation import replay
    run = model.evaluation_run
    try:
        sim = replay(structure, (record,), run, run["zdd"])
    except (SimulationError, ModelError):   # an unstable model explains nothing
        return float("inf")
    return nrmse(sim, measured_groups(run, model.storeys), run.sample_rate, model.band)


def _terms(found: _Found, scale: float) -> list[dict]:
    by_name = {t.name: t for t in TERMS}
    out = []
    for col, c in zip(found.selected.columns, found.selected.coefficients):
        term = by_name[col.term]
        out.append({"term": term.name, "meaning": term.meaning,
                    "coefficient": float(c) * (1.0 if term.name in ALWAYS else scale), "unit": term.unit,
                    **col.shape})
    return out


def _loop_area(coefficient: float, yield_drift: float, exponent: float, amplitude: float) -> float:
    """Energy (J) one cycle of amplitude ``amplitude`` (m) dissipates in the hysteretic term."""
    theta = np.linspace(0, 2 * np.pi * _LOOP_CYCLES, _LOOP_CYCLES * _LOOP_SAMPLES + 1)
    x = amplitude * np.sin(theta)
    rate = amplitude * np.cos(theta)
    z = bouc_wen_state(rate, float(theta[1] - theta[0]), yield_drift, exponent, HYSTERETIC_BETA)[:, 0]
    last = slice((_LOOP_CYCLES - 1) * _LOOP_SAMPLES, None)
    return float(coefficient * np.sum(0.5 * (z[last][1:] + z[last][:-1]) * np.diff(x[last])))


def describe(location: dict, terms: list[dict], structure: Structure, peak: float) -> str:
    """The discovered force in words (gaps in mm, stiffness changes in % of the place's stiffness)."""
    (kind, index), = location.items()
    name = f"the drift of storey {index}" if kind == "storey" else f"q{index} (floor {index} against the table)"
    short = "|x|" if kind == "storey" else f"|q{index}|"
    coef = {t["term"]: t for t in terms}
    k_lin = (structure.storey_stiffness[index - 1] if kind == "storey" else 0.0) + coef["x"]["coefficient"]
    words = []
    for t in terms:
        c, term = t["coefficient"], t["term"]
        trend = "stiffening" if c > 0 else "softening"
        if term == "gap_pos":
            words.append(f"{trend} beyond {short[1:-1]} = +{1e3 * t['gap_pos_delta']:.1f} mm (a stop on the + side, "
                         f"{abs(c):.3g} N/m)")
        elif term == "gap_neg":
            words.append(f"{trend} beyond {short[1:-1]} = -{1e3 * t['gap_neg_delta']:.1f} mm (a stop on the - side, "
                         f"{abs(c):.3g} N/m)")
        elif term == "dead_zone":
            words.append(f"{trend} beyond {short} = {1e3 * t['dead_zone_delta']:.1f} mm (a two-sided gap, "
                         f"{abs(c):.3g} N/m)")
        elif term in ("x3", "x_abs_x"):
            extra = c * peak ** (2 if term == "x3" else 1)
            share = f" ({100 * extra / k_lin:+.0f} % of its stiffness at the peak {1e3 * peak:.1f} mm)" if k_lin > 0 else ""
            words.append(f"{trend} with amplitude, {t['meaning'].split(' (')[0]} x {c:.3g} {t['unit']}{share}")
        elif term == "v_abs_v":
            words.append(f"quadratic damping {c:.3g} {t['unit']}")
        elif term == "sign_v":
            words.append(f"a friction-like force of {c:.3g} N")
        elif term == "hysteretic":
            area = _loop_area(c, t["hysteretic_yield"], t["hysteretic_exponent"], peak)
            words.append(f"hysteretic: softening with amplitude (yield near {short} = "
                         f"{1e3 * t['hysteretic_yield']:.2f} mm), loops of area {1e3 * area:.3g} mJ at the peak "
                         f"{1e3 * peak:.1f} mm")
        elif term == "switch":
            change = -c / k_lin if k_lin > 0 else float("nan")
            verb = "loses" if change > 0 else "gains"
            words.append(f"{verb} {100 * abs(change):.0f} % of its stiffness from t = {t['switch_time']:.1f} s")
    if not words:
        words.append(f"a linear spring {coef['x']['coefficient']:.3g} N/m and dashpot {coef['v']['coefficient']:.3g} "
                     f"N s/m missing from the model")
    return f"Discovered at {json.dumps(location)}, against {name}: " + "; ".join(words) + "."


def plot_discovered(discovery: Discovery, path) -> None:
    """``discovered.png``: the residual's force at the place against ``x``, measured and discovered."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    p = discovery.plot
    (kind, index), = discovery.location.items()
    fig, ax = plt.subplots(figsize=(7, 5))
    ax.plot(1e3 * p["x"], p["measured"], ".", color="0.5", ms=3, label="residual force of the linear model "
            "(training runs)")
    ax.plot(1e3 * p["x"], p["law"], ".", color="C3", ms=1, label="discovered force")
    ax.set_xlabel(f"{'drift of storey' if kind == 'storey' else 'displacement vs. table of floor'} {index} (mm)")
    ax.set_ylabel("force resisting it (N)")
    ax.set_title(f"{kind} {index}: held-out NRMSE {100 * discovery.nrmse_before:.2f} % -> "
                 f"{100 * discovery.nrmse_after:.2f} %", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
