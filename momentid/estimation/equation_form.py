"""The equation forms of the added-mass estimators: eq. (3), every run on its own, and the paper's
difference form, each run minus the reference run (see :mod:`momentid.estimation.identification`).

The samples stream in blocks through a QR update per floor equation (:class:`Accumulator`: each
floor's equation touches only its own row of unknowns), so memory stays flat for long records;
:func:`identify_stream` folds a recording's blocks in as they are read.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
import json
import os

import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.series import Experiment, RunData
from momentid.core.structure import Structure
from momentid.errors import IdentificationError, SensorDataError
from momentid.estimation.identified import Identification, identification_result
from momentid.estimation.layout import Layout, require_equation_memory
from momentid.estimation.reconstruct import Prefilter, prepare_run

__all__ = ["Accumulator", "solve_equations", "equation_form", "equation_residual", "check_times",
           "exact_fit", "identify_stream", "MAX_CONDITION", "ROUNDOFF"]

#: Column-scaled condition numbers above this are refused: the data cannot
#: separate the unknowns (too little excitation, too few runs).
MAX_CONDITION = 1e10
_BLOCK = 4096


def _signals(run: RunData, d: int) -> dict[str, np.ndarray]:
    out = {}
    for g in ("a", "v", "q"):
        try:
            out[g] = run.group(g, d)
        except SensorDataError as exc:
            raise SensorDataError(f"{exc}: identification needs a1..a{d}, v1..v{d}, q1..q{d}") from None
    for g, x in out.items():
        if not np.all(np.isfinite(x)):
            row, col = np.argwhere(~np.isfinite(x))[0]
            raise SensorDataError(
                f"run {run.name!r}: channel {g}{col + 1} is {x[row, col]} at t = {run.time[row]:.6g} s: "
                f"expected finite samples"
            )
    if run.has("zdd"):
        out["zdd"] = run["zdd"]
    return out


def check_times(selected: Sequence[RunData], times: Sequence[float] | None) -> None:
    """Refuse chosen instants ``times`` (s) that are not finite or lie outside a run of ``selected``.

    Raises
    ------
    IdentificationError
        Naming the instants, the run and its recorded span.
    """
    if times is None:
        return
    values = np.asarray(times, float)
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise IdentificationError(f"times = {list(times)}: expected finite instants in seconds")
    for run in selected:
        lo, hi = float(run.time[0]), float(run.time[-1])
        outside = values[(values < lo) | (values > hi)]
        if outside.size:
            raise IdentificationError(f"times = {list(times)}: {outside.tolist()} s lies outside run "
                                      f"{run.name!r}, recorded from {lo:g} to {hi:g} s")
        picked = _nearest(run, values)
        _, first, count = np.unique(picked, return_index=True, return_counts=True)
        if np.any(count > 1):
            k = int(first[np.argmax(count > 1)])
            same = values[picked == picked[k]]
            raise IdentificationError(
                f"times = {list(times)}: {', '.join(f'{x:g}' for x in same)} s pick the same sample of run "
                f"{run.name!r} (t = {run.time[picked[k]]:g} s); expected distinct instants (one instant "
                f"counted twice would shrink every standard error)")


def _rows(run: RunData, signals: dict, times) -> np.ndarray:
    """Sample indices of ``run``'s equations in its prepared ``signals``: the chosen instants of a
    measured run, or every bump position of a weak form (accelerometer-only data)."""
    if signals["a"].shape[0] == run.n_samples:
        return _sample_index(run, times)
    if times is None:
        return np.arange(signals["a"].shape[0])
    raise IdentificationError(f"times = {list(times)}: chosen instants need measured displacements "
                              f"(run {run.name!r} has accelerations only)")


def _nearest(run: RunData, times: np.ndarray) -> np.ndarray:
    """The index of the sample nearest each of ``times`` (s), in their order."""
    idx = np.clip(np.searchsorted(run.time, times), 1, run.n_samples - 1)
    left = run.time[idx - 1]
    return np.where(np.abs(times - left) <= np.abs(run.time[idx] - times), idx - 1, idx)


def _sample_index(run: RunData, times) -> np.ndarray:
    if times is None:
        return np.arange(run.n_samples)
    return np.unique(_nearest(run, np.asarray(times, float)))


class Accumulator:
    """Streaming QR of ``[A | b]``, one small triangular factor per floor."""

    def __init__(self, layout: Layout):
        self.layout = layout
        self.cols = [layout.floor_columns(j) for j in range(layout.d)]
        self.R = [np.zeros((0, len(c) + 1)) for c in self.cols]
        self.rows = 0

    def add(self, acc: np.ndarray, vel: np.ndarray, disp: np.ndarray, vel_mu: np.ndarray, rhs: np.ndarray) -> None:
        """Fold ``n`` samples into the factors: the regressors (n, d) of M (``acc``, m/s^2), C (``vel``, m/s) and
        K (``disp``, m), the added-mass term of mu (``vel_mu``, (n, d), kg m/s) and the right-hand side
        (``rhs``, (n, d), N)."""
        full = self.layout.mass == "full"
        for start in range(0, acc.shape[0], _BLOCK):
            sl = slice(start, start + _BLOCK)
            for j in range(self.layout.d):
                m = acc[sl] if full else acc[sl, j:j + 1]
                block = np.column_stack([m, vel[sl], disp[sl], vel_mu[sl, j], rhs[sl, j]])
                self.R[j] = np.linalg.qr(np.vstack([self.R[j], block]), mode="r")
            self.rows += acc[sl].shape[0] * self.layout.d

    def solve(self) -> tuple[np.ndarray, np.ndarray, float]:
        """The stacked triangular system ``A theta = b`` (``A`` (p, p), ``b`` (p,)) and its residual sum of
        squares (N^2)."""
        p = self.layout.p
        stacked = []
        rss = 0.0
        for j, cols in enumerate(self.cols):
            R = self.R[j]
            s = len(cols)
            full = np.zeros((R.shape[0], p + 1))
            np.add.at(full, (slice(None), cols), R[:, :s])  # a column may repeat (M[j,j] in full M)
            full[:, p] = R[:, s]
            if R.shape[0] > s:
                rss += float(R[s, s] ** 2)
                full = full[:s]
            stacked.append(full)
        R = np.linalg.qr(np.vstack(stacked), mode="r")
        A, b = R[:p, :p], R[:p, p]
        rss += float(R[p, p] ** 2) if R.shape[0] > p else 0.0
        return A, b, rss


def solve_equations(acc: Accumulator, estimator: str, runs: Sequence[str]
                    ) -> tuple[np.ndarray, int, float, float, np.ndarray | None]:
    """Least-squares solution of the equations folded into ``acc``, refused when ill-posed.

    Returns
    -------
    theta : ndarray, shape (p,)
    rank : int
    condition : float
        Of the column-scaled triangular factor.
    rss : float
        Residual sum of squares (N^2).
    covariance : ndarray, shape (p, p), or None
        None when there are no more equations than unknowns.

    Raises
    ------
    IdentificationError
        An unknown that no equation involves, too few equations, rank deficiency or a condition number
        above :data:`MAX_CONDITION`; ``estimator`` and ``runs`` name the problem in the message.
    """
    A, b, rss = acc.solve()
    p = acc.layout.p
    norms = np.linalg.norm(A, axis=0)
    zero = np.flatnonzero(norms == 0)
    if zero.size:
        raise IdentificationError(
            f"estimator {estimator!r} on runs {list(runs)}: {zero.size} unknowns never appear in the "
            f"equations (a floor never moves?): expected every floor to respond"
        )
    As = A / norms
    sv = np.linalg.svd(As, compute_uv=False)
    tol = sv[0] * max(acc.rows, p) * np.finfo(float).eps
    rank = int(np.sum(sv > tol))
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    if acc.rows < p:
        raise IdentificationError(
            f"estimator {estimator!r} on runs {list(runs)}: {acc.rows} equations for {p} unknowns: "
            f"expected more equations than unknowns (a longer record, more chosen instants or more runs)"
        )
    if rank < p or condition > MAX_CONDITION:
        what = (f"determine only {rank} of {p} unknowns" if rank < p else
                f"determine the {p} unknowns only with condition number {condition:.3g} "
                f"(refusing above {MAX_CONDITION:.0e})")
        raise IdentificationError(
            f"estimator {estimator!r} on runs {list(runs)}: the equations {what}: expected a richer "
            f"excitation (more frequencies than storeys), a longer record or more added-mass runs"
        )
    theta_s, *_ = np.linalg.lstsq(As, b, rcond=None)
    theta = theta_s / norms
    dof = acc.rows - p
    cov = None
    if dof > 0:
        Rinv = np.linalg.inv(As)
        cov = (Rinv @ Rinv.T) * (rss / dof) / np.outer(norms, norms)
    return theta, rank, condition, rss, cov


#: Relative equation residual below which data count as noise-free.
ROUNDOFF = 1e-8


def _force_scale(result: Identification, runs) -> float:
    """RMS inertia force M a of the runs (N): the scale equation residuals are judged on."""
    total, count = 0.0, 0
    for run in runs:
        f = run.group("a", result.storeys) @ result.M.T
        total += float(np.sum(f ** 2))
        count += f.size
    return float(np.sqrt(total / max(count, 1)))


def exact_fit(result: Identification, runs: Iterable[RunData]) -> bool:
    """Whether ``result`` (an equation form) satisfies its equations on ``runs`` to round-off: an
    RMS residual at most :data:`ROUNDOFF` times the runs' RMS inertia force (noise-free data)."""
    return result.residual_rms <= ROUNDOFF * _force_scale(result, runs)


def equation_form(experiment: Experiment, selected: Sequence[RunData], layout: Layout, eq_name: str,
                  times: Sequence[float] | None, band: Prefilter, names: tuple[str, ...], notes: list[str]
                  ) -> Identification:
    """Solve one equation form over the checked runs ``selected``.

    Parameters
    ----------
    experiment : Experiment
        For its source (messages) and the memory check.
    selected : sequence of RunData
        The runs, already checked (:func:`momentid.io.run_checks.check_run`).
    layout : Layout
    eq_name : {"equation", "difference"}
    times : sequence of float or None
        Only the samples nearest these instants (s); every sample when None.
    band : Prefilter
        Band every channel is filtered to first (inactive: none).
    names : tuple of str
        The runs' names, for the result.
    notes : list of str
        Repairs and choices so far, carried into the result.

    Returns
    -------
    Identification
        ``residual_rms`` is the RMS equation residual (N).
    """
    require_equation_memory(layout, experiment.source)
    d = layout.d
    acc = Accumulator(layout)
    if eq_name == "equation":
        for run in selected:
            s = _prepared(run, d, band)
            idx = _rows(run, s, times)
            dm = run.added_mass
            a, v, q = s["a"][idx], s["v"][idx], s["q"][idx]
            acc.add(a, v, q, v * dm, -a * dm)
    else:
        _difference_rows(experiment, selected, d, times, acc, band)
    theta, rank, condition, rss, cov = solve_equations(acc, eq_name, names)
    return identification_result(layout, theta, eq_name, acc.rows, rank, condition,
                   float(np.sqrt(rss / max(acc.rows, 1))), names, cov, notes)


def _prepared(run: RunData, d: int, band: Prefilter) -> dict[str, np.ndarray]:
    if not band.active and run.has("v1") and run.has("q1"):
        return _signals(run, d)
    return prepare_run(run, d, band)


def equation_residual(result: Identification, run: RunData) -> np.ndarray:
    """Residual of eq. (3) for the identified model on one run.

    ``r = (M + dM) a + (C + mu dM) v + K q`` per floor: the force (N) the
    identified model cannot explain; zero for a perfect model and perfect data.

    Returns
    -------
    ndarray, shape (n_samples, d)
    """
    d = result.storeys
    s = _prepared(run, d, Prefilter())
    dm = np.diag(run.added_mass)
    Mi = result.M + dm
    Ci = result.C + result.mu * dm
    return s["a"] @ Mi.T + s["v"] @ Ci.T + s["q"] @ result.K.T


def _difference_rows(experiment: Experiment, selected, d: int, times, acc: Accumulator,
                     band: Prefilter) -> None:
    refs = [r for r in selected if not np.any(r.added_mass)]
    if not refs:
        raise IdentificationError(
            f"{experiment.source}: the difference form needs a reference run without added mass "
            f"among {[r.name for r in selected]}"
        )
    ref = refs[0]
    s1 = _prepared(ref, d, band)
    if "zdd" not in s1:
        raise SensorDataError(f"run {ref.name!r}: the difference form needs the base acceleration zdd")
    z1 = s1["zdd"]
    peak = float(np.max(np.abs(z1))) or 1.0
    for run in selected:
        if run is ref:
            continue
        if run.n_samples != ref.n_samples or not np.allclose(run.time, ref.time, rtol=0, atol=1e-9):
            raise IdentificationError(
                f"{experiment.source}: run {run.name!r} and reference {ref.name!r} have different "
                f"sample times: the difference form needs the same clock; use estimator 'equation'"
            )
        si = _prepared(run, d, band)
        zi = si["zdd"]
        mismatch = float(np.max(np.abs(zi - z1)))
        if mismatch > 1e-6 * peak:
            raise IdentificationError(
                f"{experiment.source}: run {run.name!r} table acceleration differs from reference "
                f"{ref.name!r} by {mismatch:.3g} m/s^2 (peak {peak:.3g}): the difference form needs the "
                f"same table motion in every run; use estimator 'equation'"
            )
        idx = _rows(run, si, times)
        dm = run.added_mass
        rel_i = si["a"] - zi[:, None]
        rel_1 = s1["a"] - z1[:, None]
        acc.add((rel_i - rel_1)[idx], (si["v"] - s1["v"])[idx], (si["q"] - s1["q"])[idx],
                (si["v"] * dm)[idx], (-si["a"] * dm)[idx])


def identify_stream(path: str | os.PathLike, *, mass: str = "diagonal", return_structure: bool = False
                    ) -> Identification | tuple[Identification, Structure | None]:
    """Equation-form identification straight from a recording, block by block.

    Every sensor block is folded into per-run QR factors as it is read, so
    memory stays flat however long the record (an hour at 1 kHz included);
    runs the file does not complete are dropped with their factors.  Needs
    the channels ``a``, ``v``, ``q`` of every floor (ideal or reconstructed
    data); for noisy recordings use :func:`~momentid.estimation.identification.identify` (errors-in-variables).

    Returns
    -------
    Identification
        Or, with ``return_structure=True``, ``(Identification, Structure or
        None)``: the nominal model the recording states, from the same single
        pass over the file.
    """
    from momentid.io.recording_reader import stream_recording

    per_run: dict[str, tuple[Accumulator, np.ndarray]] = {}
    state: dict = {}

    def on_block(name, added, channels, first, t, values):
        if "layout" not in state:
            d = sum(1 for c in channels if c.startswith("a") and c[1:].isdigit())
            missing = [f"{g}{i + 1}" for g in "avq" for i in range(d) if f"{g}{i + 1}" not in channels]
            if missing:
                raise SensorDataError(f"{path}: run {name!r} lacks channels {', '.join(missing)}: streaming "
                                      f"identification needs a, v, q of every floor; use identify()")
            state["layout"] = Layout(d, mass)
            require_equation_memory(state["layout"], path)
            state["index"] = [np.array([channels.index(f"{g}{i + 1}") for i in range(d)]) for g in "avq"]
        if name not in per_run:
            per_run[name] = (Accumulator(state["layout"]), np.asarray(added, float))
        acc, dm = per_run[name]
        ia, iv, iq = state["index"]
        a, v, q = values[:, ia], values[:, iv], values[:, iq]
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(v)) and np.all(np.isfinite(q))):
            raise SensorDataError(f"{path}: run {name!r} has non-finite samples from sample {first}; "
                                  f"use identify(), which repairs or refuses them")
        acc.add(a, v, q, v * dm, -a * dm)

    with threadpool_limits(limits=1, user_api="blas"):
        experiment, complete, notes = stream_recording(path, on_block)
        if len(complete) < 2 or all(not np.any(per_run[n][1]) for n in complete):
            raise IdentificationError(f"{path}: complete runs {complete}: expected at least two, one with "
                                      f"added mass")
        layout = state["layout"]
        merged = Accumulator(layout)
        for j in range(layout.d):
            stacked = np.vstack([per_run[n][0].R[j] for n in complete])
            merged.R[j] = np.linalg.qr(stacked, mode="r")
        merged.rows = sum(per_run[n][0].rows for n in complete)
        names = tuple(complete)
        theta, rank, condition, rss, cov = solve_equations(merged, "equation", names)
    result = identification_result(layout, theta, "equation", merged.rows, rank, condition,
                     float(np.sqrt(rss / max(merged.rows, 1))), names, cov, notes)
    if not return_structure:
        return result
    from momentid.core.structure import Structure
    text = experiment.get("structure")
    return result, (Structure.from_dict(json.loads(text)) if text and text != "null" else None)
