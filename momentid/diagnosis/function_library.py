"""The open search's function library: candidate force terms at one place, and their sparse selection.

A place is a link of the rig (:class:`~momentid.mechanisms.place.Place`): a storey (the force acts
against its drift ``x`` and drift velocity ``v``) or a floor against the table (against its
displacement and velocity relative to the table).  A force ``f`` (n,) there puts the floor forces
``f w`` into the equation residual, with ``w`` (d,) the place's direction (a storey: ``-1`` on its
floor, ``+1`` on the floor below; a floor: ``-1`` on it), so the residual's least-squares force at
the place is ``y = R w / |w|^2`` (:meth:`~momentid.mechanisms.place.Place.force`) and every fit is a
scalar regression of ``y``.

The library (:func:`columns`) holds the terms of :data:`momentid.mechanisms.data_driven.TERMS` on
grids of their shape parameters: polynomial and velocity terms, gaps (two-sided dead zone, one-sided
stops) at fractions of the peak ``|x|``, a Bouc-Wen hysteretic state integrated from the measured
``v`` over a grid of yield drifts and exponents, and a stiffness switch ``x H(t - t0)`` over a grid
of times.  :func:`select` adds terms forward, one at a time, scored on held-out time blocks, while
each lowers the held-out residual by a clear share of the excess over the noise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from momentid.mechanisms.bouc_wen import bouc_wen_state
from momentid.mechanisms.data_driven import HYSTERETIC_BETA, term_signal

__all__ = ["Column", "Selected", "columns", "hysteretic_columns", "select", "refine",
           "ALWAYS", "GAP_TERMS", "GAP_TOLERANCE", "DELTA_FRACTIONS", "YIELD_FRACTIONS", "EXPONENTS", "SWITCH_STEP",
           "MIN_GAIN", "MAX_TERMS"]

#: Terms every discovered force carries: the linear spring and dashpot at its place, which the
#: identified model may have absorbed (or missed) there, as the screening's confounds.
ALWAYS = ("x", "v")
#: Gaps and stops tried at these fractions of the peak ``|x|`` at the place (a stop that is never
#: reached leaves no trace; one reached by most of the motion is a stiffness) ...
DELTA_FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)
#: ... hysteretic yield drifts at these fractions of it, each with these Bouc-Wen exponents ...
YIELD_FRACTIONS = (0.1, 0.2, 0.35, 0.5)
EXPONENTS = (1.0, 2.0)
#: ... and stiffness switches every this many seconds, at least one step from either end of a run.
SWITCH_STEP = 0.5
#: Smoothed sign of the velocity: scale as a fraction of RMS(v) (the screening's friction signature).
SIGN_SCALE = 0.05
#: A term joins the force when it lowers the held-out residual by this share of what the linear terms
#: (:data:`ALWAYS`) leave above the noise (a term that removes less is fitting noise, or a detail of a
#: shape the library does not hold) ...
MIN_GAIN = 0.05
#: ... and at most this many terms beyond :data:`ALWAYS` (one per term kind).
MAX_TERMS = 3


@dataclass(frozen=True)
class Column:
    """One candidate term on the training data: its term name, shape parameters and signal (n,)."""

    term: str
    shape: dict
    signal: np.ndarray


def hysteretic_columns(velocities: list[np.ndarray], peaks: list[float], segments: Sequence[tuple[int, int]],
                       dt: float) -> list[list[Column]]:
    """Bouc-Wen states over the grid (:data:`YIELD_FRACTIONS` x :data:`EXPONENTS`) at several places at
    once, integrated run by run from each place's measured velocity (n,) (m/s); ``peaks``: each
    place's peak ``|x|`` (m).  Returns each place's columns."""
    grid = [(f, n) for f in YIELD_FRACTIONS for n in EXPONENTS]
    yields = np.array([f * peak for peak in peaks for f, _ in grid])
    exps = np.array([n for _ in peaks for _, n in grid])
    v = np.repeat(np.column_stack(velocities), len(grid), axis=1)
    z = np.concatenate([bouc_wen_state(v[a:b], dt, yields, exps, HYSTERETIC_BETA) for a, b in segments])
    k = len(grid)
    return [[Column("hysteretic", {"hysteretic_yield": float(yields[p * k + i]), "hysteretic_exponent": float(n)},
                    z[:, p * k + i]) for i, (_, n) in enumerate(grid)] for p in range(len(peaks))]


def columns(x: np.ndarray, v: np.ndarray, time: np.ndarray, segments: Sequence[tuple[int, int]],
            hysteretic: list[Column]) -> list[Column]:
    """Every candidate term at one place: :data:`ALWAYS` first, then the library on its grids.

    Parameters
    ----------
    x, v : ndarray, shape (n,)
        Drift or displacement (m) and its rate (m/s) at the place, the training runs stacked.
    time : ndarray, shape (n,)
        Time since each run started (s).
    segments : sequence of (start, stop)
        Each run's rows (the hysteretic state restarts from zero at each run's start).
    hysteretic : list of Column
        The place's hysteretic states (:func:`hysteretic_columns`, computed for every place at once).
    """
    peak = float(np.max(np.abs(x))) or 1.0
    scale = SIGN_SCALE * float(np.sqrt(np.mean(v ** 2))) or 1.0
    out = [Column(name, {}, term_signal(name, {}, x, v, time)) for name in ALWAYS + ("x_abs_x", "x3", "v_abs_v")]
    out.append(Column("sign_v", {"sign_v_scale": scale}, term_signal("sign_v", {"sign_v_scale": scale}, x, v, time)))
    for name in ("dead_zone", "gap_pos", "gap_neg"):
        key = f"{name}_delta"
        out += [Column(name, {key: f * peak}, term_signal(name, {key: f * peak}, x, v, time)) for f in DELTA_FRACTIONS]
    out += hysteretic
    t_end = float(min(time[b - 1] for a, b in segments))
    for t0 in np.arange(SWITCH_STEP, t_end - SWITCH_STEP / 2, SWITCH_STEP):
        out.append(Column("switch", {"switch_time": float(t0)}, term_signal("switch", {"switch_time": t0}, x, v, time)))
    return out


@dataclass(frozen=True)
class Selected:
    """The terms chosen at one place: their columns, coefficients (N per unit signal, fitted on every
    sample), and the held-out residual (floor forces, N^2 summed) with :data:`ALWAYS` alone and with all."""

    columns: tuple[Column, ...]
    coefficients: np.ndarray
    test_rss_linear: float
    test_rss: float


class _Gram:
    """Scaled normal equations of a scalar regression of ``y`` on ``X`` on train and test rows; columns
    can be added (:meth:`add`) or tried without adding (:meth:`test_rss_with`)."""

    def __init__(self, X: np.ndarray, y: np.ndarray, train: np.ndarray, test: np.ndarray):
        self.scale = np.linalg.norm(X[train], axis=0)
        self.scale[self.scale == 0] = 1.0
        Xs = X / self.scale
        self.train, self.test, self.y = train, test, y
        self.Xtr, self.Xte = Xs[train], Xs[test]
        self.G, self.g = self.Xtr.T @ self.Xtr, self.Xtr.T @ y[train]
        self.H, self.h, self.zz = self.Xte.T @ self.Xte, self.Xte.T @ y[test], float(y[test] @ y[test])

    def test_rss(self, idx: list[int]) -> float:
        return self._rss(self.G[np.ix_(idx, idx)], self.g[idx], self.H[np.ix_(idx, idx)], self.h[idx])

    def _rss(self, G, g, H, h) -> float:
        c = np.linalg.lstsq(G, g, rcond=1e-12)[0]
        return max(self.zz - 2 * float(c @ h) + float(c @ H @ c), 0.0)

    def _blocks(self, idx: list[int], signal: np.ndarray):
        """The Gram blocks of the columns ``idx`` and one more column ``signal`` (n,)."""
        s = signal / (np.linalg.norm(signal[self.train]) or 1.0)
        st, se = s[self.train], s[self.test]
        gx, hx = self.Xtr[:, idx].T @ st, self.Xte[:, idx].T @ se
        G = np.block([[self.G[np.ix_(idx, idx)], gx[:, None]], [gx[None, :], np.array([[st @ st]])]])
        H = np.block([[self.H[np.ix_(idx, idx)], hx[:, None]], [hx[None, :], np.array([[se @ se]])]])
        return G, np.append(self.g[idx], st @ self.y[self.train]), H, np.append(self.h[idx], se @ self.y[self.test])

    def test_rss_with(self, idx: list[int], signal: np.ndarray) -> float:
        """:meth:`test_rss` of the columns ``idx`` and the column ``signal`` (n,)."""
        return self._rss(*self._blocks(idx, signal))

    def add(self, signal: np.ndarray) -> int:
        """Add the column ``signal`` (n,); returns its index."""
        k = self.G.shape[0]
        G, g, H, h = self._blocks(list(range(k)), signal)
        norm = np.linalg.norm(signal[self.train]) or 1.0
        self.G, self.g, self.H, self.h = G, g, H, h
        self.scale = np.append(self.scale, norm)
        self.Xtr = np.column_stack([self.Xtr, signal[self.train] / norm])
        self.Xte = np.column_stack([self.Xte, signal[self.test] / norm])
        return k


#: Gap and stop terms: their distance ``delta`` is refined between grid points before they compete
#: (a stiff stop's force starts sharply at its gap: a grid point 2 % of the peak off fits it 5x worse).
GAP_TERMS = ("dead_zone", "gap_pos", "gap_neg")
#: ... to this fraction of the peak ``|x|``.
GAP_TOLERANCE = 1e-3


def _sharpened(trials, cols: list[Column], chosen: list[int], gram: _Gram, signals) -> list:
    """``trials`` ((held-out RSS, column index) each) with the best grid point of each gap term
    replaced by its refined delta (bounded search between its grid neighbours on the held-out RSS),
    the refined column appended to ``cols`` and ``gram``."""
    x, v, time = signals
    peak = float(np.max(np.abs(x))) or 1.0
    step = (DELTA_FRACTIONS[1] - DELTA_FRACTIONS[0]) * peak
    out = list(trials)
    for term in GAP_TERMS:
        mine = [(rss, i) for rss, i in trials if cols[i].term == term]
        if not mine:
            continue
        rss0, i = min(mine)
        key = f"{term}_delta"
        value = cols[i].shape[key]

        def cost(p, term=term, key=key):
            return gram.test_rss_with(chosen, term_signal(term, {key: p}, x, v, time))

        res = scipy.optimize.minimize_scalar(cost, bounds=(max(value - step, 0.0), value + step), method="bounded",
                                             options={"xatol": GAP_TOLERANCE * peak})
        if res.fun < rss0:
            signal = term_signal(term, {key: float(res.x)}, x, v, time)
            cols.append(Column(term, {key: float(res.x)}, signal))
            out.append((float(res.fun), gram.add(signal)))
    return out


def select(cols: list[Column], y: np.ndarray, weight: float, other_test: float, noise_test: float,
           train: np.ndarray, test: np.ndarray, signals: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
           ) -> Selected:
    """Forward selection of terms for the force ``y`` (n,) at one place.

    Parameters
    ----------
    cols : list of Column
        :func:`columns` (:data:`ALWAYS` first: always in).
    y : ndarray, shape (n,)
        The residual's force at the place (N).
    weight : float
        ``|w|^2`` of the place: the floor-force residual's sum of squares is ``other + weight x`` that of ``y``.
    other_test : float
        The held-out floor-force residual's sum of squares the place cannot touch (N^2).
    noise_test : float
        What sensor noise alone leaves in the held-out floor-force residual (N^2).
    train, test : ndarray of bool, shape (n,)
        Alternate time blocks.
    signals : (x, v, time), optional
        The place's displacement, velocity and time (n,) each: with them, a gap term's distance is
        refined between grid points before the terms compete (:data:`GAP_TERMS`).
    """
    cols = list(cols)
    X = np.column_stack([c.signal for c in cols])
    gram = _Gram(X, y, train, test)
    chosen = list(range(len(ALWAYS)))
    total = other_test + weight * gram.test_rss(chosen)
    linear = total
    for _ in range(MAX_TERMS):
        used = {cols[i].term for i in chosen}
        trials = [(gram.test_rss(chosen + [i]), i) for i in range(len(cols)) if cols[i].term not in used]
        if not trials:
            break
        if signals is not None:
            trials = _sharpened(trials, cols, chosen, gram, signals)
        best, i = min(trials)
        best = other_test + weight * best
        if total - best < MIN_GAIN * max(linear - noise_test, 0.0):
            break
        chosen.append(i)
        total = best
    picked = tuple(cols[i] for i in chosen)
    coef = np.linalg.lstsq(np.column_stack([c.signal for c in picked]), y, rcond=None)[0]
    return Selected(picked, coef, float(linear), float(total))


def refine(selected: Selected, y: np.ndarray, x: np.ndarray, v: np.ndarray, time: np.ndarray) -> Selected:
    """The chosen gaps and switch times refined between their grid neighbours (least squares on every
    sample, each shape parameter in turn, the others held); the hysteretic state stays on its grid."""
    cols = list(selected.columns)
    peak = float(np.max(np.abs(x)))
    step = {"switch_time": SWITCH_STEP, **{f"{n}_delta": (DELTA_FRACTIONS[1] - DELTA_FRACTIONS[0]) * peak
                                          for n in ("dead_zone", "gap_pos", "gap_neg")}}
    for k, col in enumerate(cols):
        if col.term not in ("dead_zone", "gap_pos", "gap_neg", "switch"):
            continue
        (key, value), = col.shape.items()

        def fit(p, k=k, key=key, col=col):
            trial = cols[:k] + [Column(col.term, {key: p}, term_signal(col.term, {key: p}, x, v, time))] + cols[k + 1:]
            X = np.column_stack([c.signal for c in trial])
            c, *_ = np.linalg.lstsq(X, y, rcond=None)
            return float(np.sum((y - X @ c) ** 2)), trial, c

        lo, hi = max(value - step[key], 0.0), value + step[key]
        res = scipy.optimize.minimize_scalar(lambda p: fit(p)[0], bounds=(lo, hi), method="bounded")
        if res.fun < fit(value)[0]:
            cols = fit(float(res.x))[1]
    X = np.column_stack([c.signal for c in cols])
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    return Selected(tuple(cols), coef, selected.test_rss_linear, selected.test_rss)
