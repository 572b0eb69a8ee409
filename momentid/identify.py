"""Identify M, C, K and the Rayleigh coefficients from added-mass runs.

Two estimators, both linear least squares in the unknowns
``theta = [M entries, C entries (symmetric), K entries (symmetric), mu]``:

``"equation"`` (default, method.md eq. 3)
    Every run on its own, with the absolute floor accelerations ``a``::

        M a + C v + K q + mu dM v = -dM a

    The reference run (``dM = 0``) fixes the matrices up to scale, runs with
    added mass fix the scale and ``mu``.  It does not need the table to
    repeat its motion between runs.

``"difference"`` (the paper's eq. 2 / 15)
    Each added-mass run minus the reference run, with relative accelerations
    ``q'' = a - z''``; requires the same table motion in every run::

        M (q_i'' - q_1'') + C (v_i - v_1) + K (q_i - q_1) + mu dM_i v_i = -dM_i a_i

The samples are streamed in blocks through a QR update per floor equation
(each floor's equation touches only ``2d + 2`` of the unknowns), so memory
stays flat for long records and the problem is never formed as normal
equations.  ``kappa`` follows from ``C = mu M + kappa K`` by least squares.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .analytic import Modes, modal_properties
from .data import Experiment, RunData
from .errors import IdentificationError, SensorDataError

__all__ = ["Identification", "identify", "equation_residual", "ESTIMATORS", "MAX_CONDITION"]

ESTIMATORS = ("equation", "difference")
#: Column-scaled condition numbers above this are refused: the data cannot
#: separate the unknowns (too little excitation, too few runs).
MAX_CONDITION = 1e10
_BLOCK = 4096


@dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`.

    Attributes
    ----------
    M, C, K : ndarray, shape (d, d)
        Identified mass (kg), damping (N*s/m) and stiffness (N/m) matrices
        of the reference structure (no added mass).
    mu : float
        Mass-proportional damping coefficient (1/s), from the added-mass terms.
    kappa : float
        Stiffness-proportional coefficient (s), least squares of
        ``C - mu M = kappa K``.
    damping_misfit : float
        ``||C - mu M - kappa K||_F / ||C||_F``: how well Rayleigh damping
        explains the identified ``C`` (0 for an exact Rayleigh model).
    estimator : str
        ``"equation"`` or ``"difference"``.
    n_equations, n_unknowns, rank : int
        Size and numerical rank of the least-squares problem.
    condition : float
        2-norm condition number of the column-scaled regressor matrix.
    residual_rms : float
        RMS of the equation residual (N).
    runs : tuple of str
        The runs used.
    """

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    mu: float
    kappa: float
    damping_misfit: float
    estimator: str
    n_equations: int
    n_unknowns: int
    rank: int
    condition: float
    residual_rms: float
    runs: tuple[str, ...]
    notes: tuple[str, ...] = field(default=())

    @property
    def storeys(self) -> int:
        return self.M.shape[0]

    def modes(self) -> Modes:
        """Natural frequencies and damping ratios of the identified model."""
        return modal_properties(self.M, self.C, self.K)

    def to_dict(self) -> dict:
        """JSON-friendly dict: matrices as nested lists in SI units."""
        modes = self.modes()
        return {
            "M": self.M.tolist(), "C": self.C.tolist(), "K": self.K.tolist(),
            "mu": self.mu, "kappa": self.kappa,
            "damping_misfit": self.damping_misfit,
            "frequency_hz": modes.frequency.tolist(),
            "damping_ratio": modes.damping_ratio.tolist(),
            "estimator": self.estimator,
            "n_equations": self.n_equations, "n_unknowns": self.n_unknowns,
            "rank": self.rank, "condition": self.condition,
            "residual_rms": self.residual_rms, "runs": list(self.runs),
        }


class _Layout:
    """Column indices of the unknowns (diagonal M, symmetric C and K, mu)."""

    def __init__(self, d: int):
        self.d = d
        self.m = np.arange(d)
        pairs = [(i, j) for i in range(d) for j in range(i, d)]
        sym = np.zeros((d, d), dtype=int)
        for n, (i, j) in enumerate(pairs):
            sym[i, j] = sym[j, i] = n
        self.c = d + sym
        self.k = d + len(pairs) + sym
        self.mu = d + 2 * len(pairs)
        self.p = self.mu + 1

    def floor_columns(self, j: int) -> np.ndarray:
        """The unknowns that floor ``j``'s equation involves, in row order."""
        return np.concatenate([[self.m[j]], self.c[j], self.k[j], [self.mu]])

    def unpack(self, theta: np.ndarray):
        M = np.diag(theta[self.m])
        return M, theta[self.c], theta[self.k], float(theta[self.mu])


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
    return out


def _sample_index(run: RunData, times) -> np.ndarray:
    if times is None:
        return np.arange(run.n_samples)
    idx = np.searchsorted(run.time, np.asarray(times, float))
    idx = np.clip(idx, 1, run.n_samples - 1)
    left = run.time[idx - 1]
    idx = np.where(np.abs(np.asarray(times) - left) <= np.abs(run.time[idx] - np.asarray(times)), idx - 1, idx)
    return np.unique(idx)


class _Accumulator:
    """Streaming QR of ``[A | b]``, one small triangular factor per floor."""

    def __init__(self, layout: _Layout):
        self.layout = layout
        self.cols = [layout.floor_columns(j) for j in range(layout.d)]
        self.R = [np.zeros((0, len(c) + 1)) for c in self.cols]
        self.rows = 0

    def add(self, acc, vel, disp, vel_mu, rhs) -> None:
        """Add ``n`` samples: regressor signals (n, d) and dM-terms (n, d)."""
        for start in range(0, acc.shape[0], _BLOCK):
            sl = slice(start, start + _BLOCK)
            for j in range(self.layout.d):
                block = np.column_stack([acc[sl, j], vel[sl], disp[sl], vel_mu[sl, j], rhs[sl, j]])
                self.R[j] = np.linalg.qr(np.vstack([self.R[j], block]), mode="r")
            self.rows += acc[sl].shape[0] * self.layout.d

    def solve(self):
        p = self.layout.p
        stacked = []
        rss = 0.0
        for j, cols in enumerate(self.cols):
            R = self.R[j]
            s = len(cols)
            full = np.zeros((R.shape[0], p + 1))
            full[:, cols] = R[:, :s]
            full[:, p] = R[:, s]
            if R.shape[0] > s:
                rss += float(R[s, s] ** 2)
                full = full[:s]
            stacked.append(full)
        R = np.linalg.qr(np.vstack(stacked), mode="r")
        A, b = R[:p, :p], R[:p, p]
        rss += float(R[p, p] ** 2) if R.shape[0] > p else 0.0
        return A, b, rss


def _solve(acc: _Accumulator, estimator: str, runs) -> tuple[np.ndarray, int, float, float]:
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
    if rank < p or condition > MAX_CONDITION:
        raise IdentificationError(
            f"estimator {estimator!r} on runs {list(runs)}: the equations determine only {rank} of "
            f"{p} unknowns (condition number {condition:.3g}, refusing above {MAX_CONDITION:.0e}): "
            f"expected a richer excitation (more frequencies than storeys) or more added-mass runs"
        )
    theta_s, *_ = np.linalg.lstsq(As, b, rcond=None)
    return theta_s / norms, rank, condition, rss


def identify(experiment: Experiment, *, estimator: str = "equation", runs=None,
             times=None) -> Identification:
    """Identify M, C, K, mu and kappa from the runs of a recording.

    Parameters
    ----------
    experiment : Experiment
        Runs with channels ``a1..ad``, ``q1..qd``, ``v1..vd`` (and ``zdd`` for
        the difference form), e.g. from :func:`momentid.read_recording`.
    estimator : {"equation", "difference"}
        See the module docstring.
    runs : sequence of str, optional
        Names of the runs to use (all by default).
    times : sequence of float, optional
        Use only the samples nearest these times (s); all samples by default.
        ``times=[5.0]`` with ``estimator="difference"`` is the paper's system.

    Raises
    ------
    IdentificationError
        When the runs cannot identify the unknowns: fewer than two runs, no
        added mass, too little excitation.
    SensorDataError
        A needed channel is missing or not finite.
    """
    if estimator not in ESTIMATORS:
        raise IdentificationError(f"estimator = {estimator!r}: expected one of {', '.join(ESTIMATORS)}")
    selected = experiment.runs if runs is None else tuple(experiment.run(n) for n in runs)
    names = tuple(r.name for r in selected)
    if len(selected) < 2:
        raise IdentificationError(
            f"{experiment.source}: {len(selected)} run(s) {list(names)}: expected at least two "
            f"(a reference run and a run with added mass)"
        )
    d = selected[0].added_mass.shape[0]
    dms = [r.added_mass for r in selected]
    if all(not np.any(dm) for dm in dms):
        raise IdentificationError(
            f"{experiment.source}: no run among {list(names)} adds mass: the equations are "
            f"homogeneous and fix M, C, K only up to scale; expected at least one run with added mass"
        )
    layout = _Layout(d)
    acc = _Accumulator(layout)
    if estimator == "equation":
        for run in selected:
            s = _signals(run, d)
            idx = _sample_index(run, times)
            dm = run.added_mass
            a, v, q = s["a"][idx], s["v"][idx], s["q"][idx]
            acc.add(a, v, q, v * dm, -a * dm)
    else:
        _difference_rows(experiment, selected, d, times, acc)
    theta, rank, condition, rss = _solve(acc, estimator, names)
    M, C, K, mu = layout.unpack(theta)
    kappa = float(np.sum(K * (C - mu * M)) / np.sum(K * K))
    misfit = float(np.linalg.norm(C - mu * M - kappa * K) / np.linalg.norm(C))
    return Identification(
        M=M, C=C, K=K, mu=mu, kappa=kappa, damping_misfit=misfit, estimator=estimator,
        n_equations=acc.rows, n_unknowns=layout.p, rank=rank, condition=condition,
        residual_rms=float(np.sqrt(rss / max(acc.rows, 1))), runs=names,
    )


def _difference_rows(experiment: Experiment, selected, d: int, times, acc: _Accumulator) -> None:
    refs = [r for r in selected if not np.any(r.added_mass)]
    if not refs:
        raise IdentificationError(
            f"{experiment.source}: the difference form needs a reference run without added mass "
            f"among {[r.name for r in selected]}"
        )
    ref = refs[0]
    s1 = _signals(ref, d)
    z1 = ref["zdd"]
    peak = float(np.max(np.abs(z1))) or 1.0
    for run in selected:
        if run is ref:
            continue
        if run.n_samples != ref.n_samples or not np.allclose(run.time, ref.time, rtol=0, atol=1e-9):
            raise IdentificationError(
                f"{experiment.source}: run {run.name!r} and reference {ref.name!r} have different "
                f"sample times: the difference form needs the same clock; use estimator 'equation'"
            )
        zi = run["zdd"]
        mismatch = float(np.max(np.abs(zi - z1)))
        if mismatch > 1e-6 * peak:
            raise IdentificationError(
                f"{experiment.source}: run {run.name!r} table acceleration differs from reference "
                f"{ref.name!r} by {mismatch:.3g} m/s^2 (peak {peak:.3g}): the difference form needs the "
                f"same table motion in every run; use estimator 'equation'"
            )
        si = _signals(run, d)
        idx = _sample_index(run, times)
        dm = run.added_mass
        rel_i = si["a"] - zi[:, None]
        rel_1 = s1["a"] - z1[:, None]
        acc.add((rel_i - rel_1)[idx], (si["v"] - s1["v"])[idx], (si["q"] - s1["q"])[idx],
                (si["v"] * dm)[idx], (-si["a"] * dm)[idx])


def equation_residual(result: Identification, run: RunData) -> np.ndarray:
    """Residual of eq. (3) for the identified model on one run.

    ``r = (M + dM) a + (C + mu dM) v + K q`` per floor: the force (N) the
    identified model cannot explain; zero for a perfect model and perfect data.

    Returns
    -------
    ndarray, shape (n_samples, d)
    """
    d = result.storeys
    s = _signals(run, d)
    dm = np.diag(run.added_mass)
    Mi = result.M + dm
    Ci = result.C + result.mu * dm
    return s["a"] @ Mi.T + s["v"] @ Ci.T + s["q"] @ result.K.T
