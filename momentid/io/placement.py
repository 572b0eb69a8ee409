"""Which sensor is on which floor: a check of every run's labels against physics, and across runs.

Labs swap sensor files, list the floors top first, mount a sensor on the wrong floor or turned off
the shaking axis.  Nothing in the numbers of one channel shows it; the physics of a building on a
shake table does, cheaply, from spectra (:mod:`momentid.io.operating_shapes`, no model fit):

1. **Low-frequency gains.**  Below its first mode a building moves with the table: every floor
   sensor reads the table's motion (gain ~1, a little more up the building).  A gain of -1 is a
   sensor mounted reversed (flipped, noted); a gain outside :data:`GAIN_RANGE` is a sensor turned
   off the shaking axis, loose, or in other units (named; left out of the order checks).
2. **The first mode grows with height.**  At the first resonance the table barely moves and each
   floor moves more than the one below (a shear building: strictly; a frame: as well).  The
   operating shape, read label-free, gives the order of the channels; an inversion larger than
   :data:`ORDER_MARGIN` (plus three times the shape's scatter between the record's halves) means
   mislabelled sensors, and the relabelling that moves the fewest sensors while making the shape
   grow gives the labels back (floors within the margin of each other keep their labels).
3. **The rest of the evidence must not contradict the fix**: one mode must hold the first peak (a
   torsional mode beside it can move the sensors in another order: then nothing is said), the
   higher modes must not fit a shear building worse (mode k changes sign k - 1 times up the
   building: Sturm's oscillation theorem for the tridiagonal stiffness), and with stated masses
   the modes must not become clearly less orthogonal.  Otherwise a large inversion is named as a
   suspicion and the run left as it is.
4. **Across runs.**  The runs of one rig share their mode shapes (MAC ~1).  A run whose shapes
   match the others' only under another labelling, while the others agree among themselves, is
   mislabelled; with two runs only, the data cannot say which one, and both are named.

:func:`check_placement` returns the findings (one line of evidence each); :func:`corrected` applies
one to a run; :func:`placement_warnings` is the check identification runs on any recording.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import enum
import itertools
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from momentid.core.series import TABLE_MOTION, Experiment, RunData
from momentid.io.operating_shapes import Resonance, RunSpectra, mac, run_spectra

__all__ = ["Fault", "Finding", "check_placement", "corrected", "placement_warnings", "GAIN_RANGE",
           "ORDER_MARGIN", "MATCH_MAC"]

#: Plausible low-frequency gain of a floor sensor against the table.  Real gains are 1.0-1.3 (a few
#: percent of calibration plus the floors' quasi-static amplification below the first mode, 1.05-1.3
#: on the shipped trials); a sensor turned 60 degrees off the shaking axis reads 0.5, one in g 0.1.
GAIN_RANGE = (0.5, 2.0)
#: Smallest inversion of the first mode's shape (as a fraction of its largest entry) that names
#: mislabelled sensors: adjacent floors of a 5-storey uniform shear building differ by 0.08-0.28,
#: sensor gains by a few percent; a stiff top storey leaves the two top floors within 0.05 of each
#: other.  Swapped floors of the shipped rig invert by 0.38-0.57.
ORDER_MARGIN = 0.1
#: How many times its scatter (between the record's halves) an inversion must exceed on top of the margin.
SCATTER_FACTOR = 3.0
#: How many times the margin an inversion that the rest of the evidence contradicts must reach to be
#: named at all (as a suspicion): a strong mode beyond the storeys beside the first one can invert
#: its shape by up to ~2.5 margins in the validation rigs (0.37 against 0.15), a swap by 0.3-1.
SUSPECT_FACTOR = 3.0
#: A floor entry of the first mode more negative than this (fraction of the largest) is no first mode.
NEGATIVE = 0.1
#: Least MAC between the shapes one bin either side of the first peak for one mode to hold it.
SINGLE_MODE = 0.9
#: A resonance of the building leaves the table this still (fraction of the largest entry).
TABLE_STILL = 0.3
#: An entry smaller than this fraction of a shape's largest is not counted in its sign changes.
NODE_FLOOR = 0.15
#: Two runs' resonances within this relative frequency difference are the same mode.
FREQUENCY_MATCH = 0.1
#: Mean MAC above which two runs share their mode shapes: 0.97-1.00 between the shipped synchronised
#: trials; their swapped trial reaches 0.95+ only with its floors swapped back.
MATCH_MAC = 0.9
#: Smallest rise of the mean MAC (against the other runs) that another labelling must bring.
MAC_MARGIN = 0.1
#: Largest relaxation of the orthogonality (largest normalised cross term) a fix may bring: operating
#: shapes are not mode shapes (the neighbouring modes add 0.05-0.2 to the cross terms, more at 3 %
#: damping), so only a clear loss of orthogonality contradicts a fix.
ORTHOGONALITY_SLACK = 0.2
#: Floors up to which every permutation is tried across runs (6! = 720); beyond, pair swaps only.
MAX_PERMUTED_FLOORS = 6


class Fault(enum.Enum):
    """What a finding is about."""

    ORDER = "sensors on other floors than listed"
    REVERSED = "a floor sensor mounted reversed"
    GAIN = "a floor sensor reading too little or too much of the table's motion"
    SUSPECT = "a first mode that does not grow with height, unconfirmed"
    DISAGREE = "runs that disagree on the sensors' floors"


@dataclass(frozen=True)
class Finding:
    """One fault of one run.

    Attributes
    ----------
    run : str
    fault : Fault
    message : str
        One line: the fault and the evidence the code computed.
    permutation : tuple of int or None
        The fix for :attr:`Fault.ORDER`: column k of ``(zdd, a1..ad)`` is the listed column
        ``permutation[k]``.
    flips : tuple of int
        Columns to negate (:attr:`Fault.REVERSED`).
    """

    run: str
    fault: Fault
    message: str
    permutation: tuple[int, ...] | None = None
    flips: tuple[int, ...] = ()

    @property
    def fixable(self) -> bool:
        """Whether the finding carries its fix: a floor order (``permutation``) or sensors to negate."""
        return self.permutation is not None or bool(self.flips)


@dataclass(frozen=True)
class _Run:
    """A run's spectra, its files (for messages) and the sign of each channel (-1: mounted reversed)."""

    name: str
    spectra: RunSpectra
    files: tuple[str, ...]
    signs: np.ndarray

    def shape(self, res: Resonance, perm) -> np.ndarray:
        return (res.shape * self.signs)[list(perm)]


def _channels(run: RunData, d: int) -> tuple[str, ...]:
    return ("zdd", *(f"a{j + 1}" for j in range(d)))


def _label(k: int) -> str:
    return "the table" if k == 0 else f"floor {k}"


def _fmt(values) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def _inversion(v: np.ndarray, keep: list[int]) -> float:
    """Largest amount by which a channel of ``keep`` exceeds one listed after it (0: growing)."""
    return max([v[i] - v[j] for a, i in enumerate(keep) for j in keep[a + 1:]] + [0.0])


def _untangle(shape: np.ndarray, margin: float, keep: list[int]) -> tuple[list[int], float]:
    """The relabelling of ``keep`` channels under which the first mode grows (no inversion beyond
    ``margin``) that moves the fewest channels (then: the smallest remaining inversion), and the
    largest inversion as listed.  Channels within the margin of each other keep their labels."""
    worst = _inversion(shape, keep)
    if worst <= margin:
        return list(range(shape.size)), float(worst)
    if len(keep) > MAX_PERMUTED_FLOORS + 1:
        return _untangle_greedily(shape, margin, keep), float(worst)
    best = None
    for order in itertools.permutations(keep):
        perm = list(range(shape.size))
        for slot, channel in zip(keep, order):
            perm[slot] = channel
        left = _inversion(shape[perm], keep)
        if left <= margin:
            key = (sum(p != k for k, p in enumerate(perm)), left)
            if best is None or key < best[0]:
                best = (key, perm)
    return (best[1] if best else _untangle_greedily(shape, margin, keep)), float(worst)


def _untangle_greedily(shape: np.ndarray, margin: float, keep: list[int]) -> list[int]:
    """Swap the most inverted pair of ``keep`` channels until no inversion exceeds ``margin``."""
    order = list(range(shape.size))
    v = shape.copy()
    while True:
        pairs = [(v[i] - v[j], i, j) for a, i in enumerate(keep) for j in keep[a + 1:] if v[i] - v[j] > margin]
        if not pairs:
            return order
        _, i, j = max(pairs)
        v[[i, j]] = v[[j, i]]
        order[i], order[j] = order[j], order[i]


def _structural(run: _Run, perm, clean: bool = False) -> list[tuple[float, np.ndarray]]:
    """(frequency, relative shape) of the resonances of the building under the labelling ``perm``:
    the table still, two or more channels moving (floors minus table, largest entry +-1); of peaks
    within :data:`FREQUENCY_MATCH` of each other (a mode and a harmonic of the drive beside it, or a
    mode split by the estimate) the strongest.  ``clean``: only peaks one mode holds
    (:data:`SINGLE_MODE`), for comparing runs: two modes sharing a peak mix in proportions that
    change with each run's excitation and resolution."""
    kept: list[Resonance] = []
    for res in run.spectra.resonances:
        s = run.shape(res, perm)
        if abs(s[0]) > TABLE_STILL or (res.moving() < 2 and s.size > 2) or (clean and res.single < SINGLE_MODE):
            continue
        if kept and res.frequency - kept[-1].frequency <= FREQUENCY_MATCH * kept[-1].frequency:
            if res.power > kept[-1].power:
                kept[-1] = res
            continue
        kept.append(res)
    out = []
    for res in kept:
        s = run.shape(res, perm)
        rel = s[1:] - s[0]
        out.append((res.frequency, rel / rel[np.argmax(np.abs(rel))]))
    return out


def _sign_changes(shape: np.ndarray) -> int:
    big = shape[np.abs(shape) >= NODE_FLOOR * np.max(np.abs(shape))]
    return int(np.sum(np.diff(np.sign(big)) != 0))


def _nodal_misfit(shapes: list[np.ndarray], d: int) -> int:
    """How far the resonances, by frequency, are from k - 1 sign changes for mode k."""
    return sum(abs(_sign_changes(s) - k) for k, (_, s) in enumerate(shapes[:d]))


def _cross_term(shapes: list[np.ndarray], masses) -> float:
    """Largest normalised cross term of the first d resonances' shapes with the stated masses."""
    if masses is None or len(shapes) < 2:   # masses are optional: no orthogonality evidence without them
        return float("nan")
    d = len(masses)
    P = np.column_stack([s for _, s in shapes[:d]])
    gram = P.T @ np.diag(masses) @ P
    norm = np.sqrt(np.outer(np.diag(gram), np.diag(gram)))
    off = np.abs(gram) / norm
    np.fill_diagonal(off, 0.0)
    return float(off.max())


def _describe(perm: tuple[int, ...]) -> str:
    """The labelling fault that ``perm`` undoes, in words."""
    moved = [k for k, p in enumerate(perm) if p != k]
    d = len(perm) - 1
    if d >= 3 and perm[0] == 0 and perm[1:] == tuple(range(d, 0, -1)):
        return "the floor order appears reversed (the top floor listed first)"
    if len(moved) == 2:
        a, b = moved
        who = f"the sensors of {_label(a)} and {_label(b)}" if a else f"the table's sensor and floor {b}'s"
        return f"{who} appear swapped"
    return (f"the sensors listed for {', '.join(_label(perm[k]) for k in moved)} appear to sit on "
            f"{', '.join(_label(k) for k in moved)}")


def _gain_findings(run: _Run, d: int) -> tuple[list[Finding], list[int]]:
    """Reversed sensors (fixable) and implausible gains (named); the channels fit for the order check."""
    gains = run.spectra.gains[0]
    findings, keep, flips = [], [0], []
    for j in range(1, d + 1):
        g = gains[j]
        if not np.isfinite(g):
            keep.append(j)
        elif GAIN_RANGE[0] <= -g <= GAIN_RANGE[1]:
            flips.append(j)
            keep.append(j)
        elif not GAIN_RANGE[0] <= g <= GAIN_RANGE[1]:
            findings.append(Finding(run.name, Fault.GAIN, (
                f"run {run.name!r}: floor {j}'s sensor reads {g:.2f} of the table's motion below the first mode "
                f"(expected {GAIN_RANGE[0]:g}-{GAIN_RANGE[1]:g}: a floor moves with the table there): turned off "
                f"the shaking axis, loose, or in other units; left out of the floor-order check")))
        else:
            keep.append(j)
    if flips:
        findings.append(Finding(run.name, Fault.REVERSED, (
            f"run {run.name!r}: the sensor{'s' if len(flips) > 1 else ''} of "
            f"{', '.join(_label(j) for j in flips)} read{'' if len(flips) > 1 else 's'} "
            f"{_fmt(gains[flips])} of the table's motion below the first mode: mounted reversed"), flips=tuple(flips)))
    return findings, keep


def _table_fix(shape: np.ndarray, margin: float, keep: list[int]) -> tuple[int, ...]:
    """The labelling with the table where the first mode is stillest: the listed table swapped with
    that channel when it moves more than it by the margin (at the building's resonance the table
    that drives it barely moves, whatever the floors do: this alone decides)."""
    perm = list(range(shape.size))
    still = min(keep, key=lambda k: shape[k])
    if still != 0 and shape[0] - shape[still] > margin:
        perm[0], perm[still] = still, 0
    return tuple(perm)


def _floor_doubts(run: _Run, d: int, before, after, masses) -> tuple[list[str], list[str]]:
    """What speaks against and for relabelling the floors from ``before`` to ``after`` (labellings)."""
    first = run.spectra.first
    shapes = (_structural(run, before), _structural(run, after))
    nodes = (_nodal_misfit(shapes[0], d), _nodal_misfit(shapes[1], d))
    cross = (_cross_term(shapes[0], masses), _cross_term(shapes[1], masses))
    against = []
    if first.single < SINGLE_MODE:
        against.append(f"two modes share the first peak (MAC {first.single:.2f} across it)")
    if nodes[1] > nodes[0]:
        against.append(f"the higher modes would fit a shear building worse ({nodes[0]} -> {nodes[1]} sign changes off)")
    if np.isfinite(cross[0]) and cross[1] > cross[0] + ORTHOGONALITY_SLACK:
        against.append(f"the modes would be less orthogonal with the stated masses (cross term {cross[0]:.2f} -> "
                       f"{cross[1]:.2f})")
    support = [f"the higher modes' sign changes fit a shear building ({nodes[0]} -> {nodes[1]} off)"]
    if np.isfinite(cross[0]) and abs(cross[1] - cross[0]) >= 0.02:  # with equal masses a relabelling barely moves it
        support.append(f"largest cross term of the modes with the stated masses {cross[1]:.2f} (was {cross[0]:.2f})")
    return against, support


def _order_finding(run: _Run, d: int, keep: list[int], masses) -> Finding | None:
    """The first mode's order of the channels: the table where it is stillest, then the floors where
    the rest of the evidence does not contradict them (module docstring)."""
    first = run.spectra.first
    if first is None or len(keep) < 2:
        return None
    shape = run.shape(first, range(d + 1))
    if np.min(shape[keep]) < -NEGATIVE:
        return None  # no clean first mode: a sensor reads another motion; the gains said so, if so
    margin = ORDER_MARGIN + SCATTER_FACTOR * float(np.max(first.scatter[keep]))
    worst = _inversion(shape, keep)
    table = _table_fix(shape, margin, keep)
    order, _ = _untangle(shape[list(table)], margin, [k for k in keep if k != 0])
    floors = tuple(table[i] for i in order)
    against, support = _floor_doubts(run, d, table, floors, masses) if floors != table else ([], [])
    perm = table if against else floors
    evidence = (f"the first mode ({first.frequency:.2f} Hz) moves the channels {_fmt(shape)} (table first), not "
                f"growing with height (inversion {worst:.2f}, margin {margin:.2f})")
    if perm == tuple(range(d + 1)):
        if not against or worst < SUSPECT_FACTOR * margin or first.single < SINGLE_MODE:
            return None  # a small inversion the evidence contradicts, or two modes under one peak: no word
        return Finding(run.name, Fault.SUSPECT, f"run {run.name!r}: {evidence}; but {'; '.join(against)}: "
                                                f"mislabelled sensors or a mode beyond the storeys; left as listed")
    evidence += f"; relabelled: {_fmt(shape[list(perm)])}"
    if against:
        support = [f"the floors' order left as listed ({'; '.join(against)})"]
    return Finding(run.name, Fault.ORDER, f"run {run.name!r}: {_describe(perm)}{_files(run, perm)}: {evidence}"
                                          + "".join(f", {s}" for s in support), permutation=perm)


def _files(run: _Run, perm) -> str:
    if not run.files:
        return ""
    moved = [k for k, p in enumerate(perm) if p != k]
    short = ["/".join(Path(f).parts[-2:]) for f in run.files]
    return " (" + "; ".join(f"{short[perm[k]]} is {_label(k)}'s" for k in moved) + ")"


def _matched(a: list[tuple[float, np.ndarray]], b: list[tuple[float, np.ndarray]]) -> list[tuple[int, int]]:
    """Pairs (i, j) of resonances of two runs within :data:`FREQUENCY_MATCH`, nearest first, one to one."""
    pairs = sorted((abs(fa - fb) / fb, i, j) for i, (fa, _) in enumerate(a) for j, (fb, _) in enumerate(b)
                   if abs(fa - fb) <= FREQUENCY_MATCH * fb)
    used_a, used_b, out = set(), set(), []
    for _, i, j in pairs:
        if i not in used_a and j not in used_b:
            used_a.add(i), used_b.add(j), out.append((i, j))
    return out


def _agreement(mine, others, floors_perm) -> float:
    """Mean MAC of ``mine`` (relabelled by ``floors_perm``) with each other run's matched shapes."""
    values = []
    for other in others:
        pairs = _matched(mine, other)
        if len(pairs) >= 2:  # one shared mode (the first, growing with height in any order) cannot tell
            values.append(np.mean([mac(mine[i][1][list(floors_perm)], other[j][1]) for i, j in pairs]))
    return float(np.mean(values)) if values else float("nan")


def _floor_permutations(d: int) -> list[tuple[int, ...]]:
    """Every order of d floors (up to :data:`MAX_PERMUTED_FLOORS`), else every pair swapped and the reversal."""
    if d <= MAX_PERMUTED_FLOORS:
        return list(itertools.permutations(range(d)))
    out = [tuple(range(d)), tuple(range(d - 1, -1, -1))]
    for i, j in itertools.combinations(range(d), 2):
        p = list(range(d))
        p[i], p[j] = j, i
        out.append(tuple(p))
    return out


def _grows(run: _Run, perm: tuple[int, ...], d: int) -> bool:
    """Whether the first mode, relabelled by ``perm``, grows with height (within the margin); True
    without a first mode."""
    first = run.spectra.first
    if first is None:
        return True
    margin = ORDER_MARGIN + SCATTER_FACTOR * float(np.max(first.scatter))
    _, worst = _untangle(run.shape(first, perm), margin, list(range(d + 1)))
    return worst <= margin


def _cross_run(runs: list[_Run], perms: dict[str, tuple[int, ...]], d: int) -> list[Finding]:
    """Runs whose shapes match the others' only under another labelling of the floors."""
    if len(runs) < 2 or d < 2:
        return []
    shapes = {r.name: _structural(r, perms.get(r.name, tuple(range(d + 1))), clean=True) for r in runs}
    candidates = _floor_permutations(d)
    findings, doubts = [], []
    for run in runs:
        others = [shapes[o.name] for o in runs if o is not run and len(shapes[o.name]) >= 2]
        if len(shapes[run.name]) < 2 or not others:
            continue
        base = _agreement(shapes[run.name], others, tuple(range(d)))
        best, perm = max((_agreement(shapes[run.name], others, p), p) for p in candidates)
        if not (np.isfinite(base) and best >= MATCH_MAC and best - base >= MAC_MARGIN and perm != tuple(range(d))):
            continue
        full = (0, *(p + 1 for p in perm))
        evidence = (f"its mode shapes match the other runs' with MAC {base:.2f}; relabelled, {best:.2f}")
        peers = [o for o in runs if o is not run]
        consensus = len(peers) >= 2 and all(
            _agreement(shapes[a.name], [shapes[b.name]], tuple(range(d))) >= MATCH_MAC
            for a, b in itertools.combinations(peers, 2))
        if consensus and _grows(run, full, d):
            findings.append(Finding(run.name, Fault.ORDER, f"run {run.name!r}: {_describe(full)}{_files(run, full)}: "
                                                           f"{evidence}", permutation=full))
        else:
            doubts.append((best - base, run, full, evidence))
    if doubts and not findings:  # one warning: which run the others' shapes accuse most
        _, run, full, evidence = max(doubts, key=lambda x: x[0])
        findings.append(Finding(run.name, Fault.DISAGREE, (
            f"runs {', '.join(repr(r.name) for r in runs)} disagree on which sensor is on which floor: run "
            f"{run.name!r} {evidence.replace('its mode shapes match', 'matches')} ({_describe(full)} in it), and "
            f"neither its first mode nor a consensus of the others settles it: check the labels")))
    return findings


def check_placement(runs: Sequence[RunData], masses: Sequence[float] | None = None,
                    files: Mapping[str, Sequence[str]] | None = None) -> tuple[Finding, ...]:
    """Check every run's sensor labels against physics and against the other runs.

    Parameters
    ----------
    runs : sequence of RunData
        Runs with ``zdd`` and ``a1..ad`` (m/s^2); others are skipped, as are runs too short for
        spectra (:data:`~momentid.io.operating_shapes.MIN_SECONDS`).
    masses : sequence of float, optional
        Stated floor masses (kg), for the orthogonality of the modes.
    files : dict, optional
        Run name -> the files of ``(zdd, a1..ad)``, to name them in the messages.

    Returns
    -------
    tuple of Finding
        Per run: reversed sensors and implausible gains, then a floor order that the first mode
        contradicts (fixable when the rest of the evidence agrees), then disagreements across runs.
    """
    usable = []
    for run in runs:
        d = run.added_mass.shape[0]
        channels = _channels(run, d)
        if not all(run.has(c) for c in channels):
            continue
        spectra = run_spectra(np.column_stack([run[c] for c in channels]), run.sample_rate)
        if spectra is not None:
            reversed_ = (spectra.gains[0] <= -GAIN_RANGE[0]) & (spectra.gains[0] >= -GAIN_RANGE[1])
            usable.append(_Run(run.name, spectra, tuple((files or {}).get(run.name, ())),
                               np.where(reversed_, -1.0, 1.0)))
    if not usable:
        return ()
    d = runs[0].added_mass.shape[0]
    findings, perms = [], {}
    for run in usable:
        named, keep = _gain_findings(run, d)
        findings += named
        order = _order_finding(run, d, keep, masses)
        if order is not None:
            findings.append(order)
            if order.fault is Fault.ORDER:
                perms[run.name] = order.permutation
    findings = [_with_peers(f, usable, perms, d) for f in findings]
    perms = {f.run: f.permutation for f in findings if f.fault is Fault.ORDER}
    across = _cross_run(usable, perms, d)
    relabelled = {f.run for f in across if f.fault is Fault.ORDER}  # the other runs settle a suspicion
    return tuple([f for f in findings if not (f.fault is Fault.SUSPECT and f.run in relabelled)] + across)


def _with_peers(finding: Finding, runs: list[_Run], perms: dict, d: int) -> Finding:
    """A within-run relabelling with the other runs' word on it: their MAC is added to the evidence,
    and a relabelling that matches them worse (by :data:`MAC_MARGIN`) is only a suspicion."""
    if finding.fault is not Fault.ORDER:
        return finding
    run = next(r for r in runs if r.name == finding.run)
    ident = tuple(range(d + 1))
    others = [_structural(r, perms.get(r.name, ident), clean=True) for r in runs if r is not run]
    others = [o for o in others if len(o) >= 2]
    if not others:
        return finding
    before = _agreement(_structural(run, ident, clean=True), others, tuple(range(d)))
    after = _agreement(_structural(run, finding.permutation, clean=True), others, tuple(range(d)))
    if not (np.isfinite(before) and np.isfinite(after)):
        return finding
    peers = f"the mode shapes match the other runs' with MAC {after:.2f} (was {before:.2f})"
    if after < before - MAC_MARGIN:
        return Finding(finding.run, Fault.SUSPECT, f"{finding.message}; but {peers}: left as listed")
    return replace(finding, message=f"{finding.message}, {peers}")


def corrected(run: RunData, finding: Finding) -> RunData:
    """``run`` with ``finding``'s fix applied to ``zdd, a1..ad`` (and to its per-sensor reports and
    source files), the finding's message added to ``meta["notes"]``; the table's other motions
    (:data:`~momentid.core.series.TABLE_MOTION`) dropped when another sensor becomes the table's."""
    d = run.added_mass.shape[0]
    channels = _channels(run, d)
    index = [run.channels.index(c) for c in channels]
    values = run.values.copy()
    meta = dict(run.meta)
    if finding.permutation is not None:
        values[:, index] = run.values[:, [index[p] for p in finding.permutation]]
        if "sensors" in meta:
            meta["sensors"] = [dict(meta["sensors"][p], channel=channels[k]) for k, p in enumerate(finding.permutation)]
        if "source_files" in meta:
            meta["source_files"] = [meta["source_files"][p] for p in finding.permutation]
    for j in finding.flips:
        values[:, index[j]] = -values[:, index[j]]
    fix = "relabelled" if finding.permutation is not None else "sign flipped"
    meta["notes"] = [*meta.get("notes", ()), f"{finding.message}: {fix}"]
    keep = list(range(len(run.channels)))
    if finding.permutation is not None and finding.permutation[0] != 0:   # another sensor is the table's
        keep = [j for j, c in enumerate(run.channels) if c not in TABLE_MOTION]
        if len(keep) < len(run.channels):
            meta["notes"].append("the listed table sensor's other motions dropped: it is not the table's")
    return replace(run, channels=tuple(run.channels[j] for j in keep), values=values[:, keep], meta=meta)


def placement_warnings(experiment: Experiment) -> tuple[str, ...]:
    """What :func:`check_placement` finds in a recording (from any source), one warning per finding.

    Identification calls this and prints each line as a WARNING: it does not change the data (an
    import fixes what it can and notes it in the recording, so a fixed recording passes).
    """
    masses = None
    if experiment.structure is not None:
        masses = experiment.structure.masses
    elif experiment.statement is not None:
        masses = experiment.statement.masses
    files = {r.name: tuple(r.meta["source_files"]) for r in experiment.runs if "source_files" in r.meta}
    return tuple(f"{f.message} (sensor placement check; not changed)"
                 for f in check_placement(experiment.runs, masses, files))
