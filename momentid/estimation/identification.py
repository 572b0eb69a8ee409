"""Identify M, C, K and the Rayleigh coefficients from added-mass runs.

Unknowns ``theta = [M entries, C entries (symmetric), K entries (symmetric),
mu]``; M is diagonal (the shear model) or, with ``mass="full"``, symmetric
(the paper's general count ``3/2 d^2 + 3/2 d + 1``).  Estimators:

``"equation"`` (method.md eq. 3)
    Every run on its own, with the absolute floor accelerations ``a``::

        M a + C v + K q + mu dM v = -dM a

    The reference run (``dM = 0``) fixes the matrices up to scale, runs with
    added mass fix the scale and ``mu``.  Exact for noise-free data; does not
    need the table to repeat its motion between runs.

``"difference"`` (the paper's eq. 2 / 15)
    Each added-mass run minus the reference run, with relative accelerations
    ``q'' = a - z''``; requires the same table motion in every run::

        M (q_i'' - q_1'') + C (v_i - v_1) + K (q_i - q_1) + mu dM_i v_i = -dM_i a_i

``"eiv"`` (:mod:`momentid.estimation.eiv`)
    Errors-in-variables maximum likelihood in the frequency domain, started
    from the equation form on low-passed signals: unbiased by noise on every
    channel (table accelerometer included), with standard errors at the
    Cramér-Rao bound.

``"auto"`` (default)
    ``"equation"`` when the data satisfy eq. (3) to round-off (noise-free
    virtual data) or the recording says its sensors are ideal, ``"eiv"``
    otherwise.

The equation forms stream the samples in blocks through a QR update per
floor equation (each floor's equation touches only its own row of unknowns),
so memory stays flat for long records.  ``kappa`` follows from
``C = mu M + kappa K`` by least squares.
"""

from __future__ import annotations

import json

from dataclasses import dataclass, field, replace

import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.analytic import Modes, modal_properties
from momentid.core.series import Experiment, RunData
from momentid.errors import IdentificationError, SensorDataError
from momentid.estimation.reconstruct import Prefilter, prepare_run, suggest_band
from momentid.estimation.checks import check_run

__all__ = ["Identification", "identify", "equation_residual", "damping_models", "DampingFit", "ESTIMATORS",
           "MAX_CONDITION", "MAX_NOISE_EXCESS", "Layout", "equation_form_bytes", "require_equation_memory"]

ESTIMATORS = ("auto", "equation", "difference", "eiv", "modal")
#: Column-scaled condition numbers above this are refused: the data cannot
#: separate the unknowns (too little excitation, too few runs).
MAX_CONDITION = 1e10
_BLOCK = 4096


class Layout:
    """Where each unknown sits in ``theta``.

    Parameters
    ----------
    d : int
        Storeys.
    mass : {"diagonal", "full"}
        Diagonal (d unknowns) or symmetric (d(d+1)/2) mass matrix.
    """

    def __init__(self, d: int, mass: str = "diagonal"):
        if mass not in ("diagonal", "full"):
            raise IdentificationError(f"mass = {mass!r}: expected 'diagonal' or 'full'")
        self.d = d
        self.mass = mass
        pairs = [(i, j) for i in range(d) for j in range(i, d)]
        sym = np.zeros((d, d), dtype=int)
        for n, (i, j) in enumerate(pairs):
            sym[i, j] = sym[j, i] = n
        if mass == "diagonal":
            self.m = np.diag(np.arange(d))
            self.m_columns = np.arange(d)
            start = d
        else:
            self.m = sym.copy()
            self.m_columns = np.arange(len(pairs))
            start = len(pairs)
        self.c = start + sym
        self.k = start + len(pairs) + sym
        self.mu = start + 2 * len(pairs)
        self.p = self.mu + 1

    def floor_columns(self, j: int) -> np.ndarray:
        """The unknowns that floor ``j``'s equation involves, in regressor order."""
        m = [self.m[j, j]] if self.mass == "diagonal" else list(self.m[j])
        return np.concatenate([m, self.c[j], self.k[j], [self.mu]])

    def unpack(self, theta: np.ndarray):
        """``(M, C, K, mu)`` from ``theta``."""
        if self.mass == "diagonal":
            M = np.diag(theta[np.diag(self.m)])
        else:
            M = theta[self.m]
        return M, theta[self.c], theta[self.k], float(theta[self.mu])

    def pack(self, M, C, K, mu) -> np.ndarray:
        theta = np.zeros(self.p)
        for (idx, X) in ((self.m, M), (self.c, C), (self.k, K)):
            if X is M and self.mass == "diagonal":
                theta[np.diag(idx)] = np.diag(X)
            else:
                theta[idx] = X
        theta[self.mu] = mu
        return theta


#: Float arrays of ``p x p`` (``p`` unknowns) the equation form's solve holds at its peak: the
#: triangular factor, its column-scaled copy, the SVD's workspace, its inverse, and the covariance.
_SQUARE_ARRAYS = 6


def equation_form_bytes(layout: Layout) -> float:
    """Peak memory (bytes) of the equation form's solve for ``layout``, however long the record.

    The per-floor triangular factors are stacked (``d (s + 1)`` rows of ``p + 1`` columns, ``s`` the
    unknowns one floor's equation involves), factored again (a second copy) and then inverted and
    decomposed (:data:`_SQUARE_ARRAYS` square arrays of ``p x p``).  It grows as ``d^4``: 16 unknowns
    for 3 storeys, 40,401 (and tens of GB) for 200.
    """
    p = layout.p
    rows = sum(len(layout.floor_columns(j)) + 1 for j in range(layout.d))
    return 8.0 * (2.0 * rows * (p + 1) + _SQUARE_ARRAYS * p * p)


def require_equation_memory(layout: Layout, source) -> None:
    """Refuse, before any work, an identification whose equation form cannot fit in memory.

    Raises
    ------
    ResourceError
        Naming the storeys, the unknowns, the estimate and the largest number of storeys that fits.
    """
    from momentid.core.resources import MEMORY_SHARE, available_memory, require_memory

    needed = equation_form_bytes(layout)
    fits = layout.d
    while fits > 1 and equation_form_bytes(Layout(fits, layout.mass)) > available_memory() * MEMORY_SHARE:
        fits = max(1, int(fits * 0.9))
    require_memory(needed, f"{source}: identification of {layout.d} storeys ({layout.p} unknowns, "
                   f"{layout.mass} mass matrix)",
                   f"its memory grows as the storeys^4: about {fits} storeys fit on this machine; "
                   f"identify a substructure (fewer floors) or a condensed model")


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
        ``||C - mu M - kappa K||_F / ||C||_F`` (0 for exact Rayleigh damping).
    estimator : str
    n_equations, n_unknowns, rank : int
        Size and numerical rank of the (linearised) least-squares problem.
    condition : float
        2-norm condition number of the column-scaled regressor matrix.
    residual_rms : float
        RMS of the equation residual (N) of the equation forms, or of the
        noise-weighted output residual (1 = at the noise level) for output error.
    runs : tuple of str
        The runs used.
    covariance : ndarray, shape (p, p), optional
        Covariance of ``theta`` (see :class:`Layout`); from the output-error
        Jacobian, or the least-squares formula for the equation forms (which
        ignores the bias that regressor noise causes).
    notes : tuple of str
        Repairs and choices made on the way (e.g. interpolated samples).
    warnings : tuple of str
        What the data contradict: non-positive masses, unstable modes, a fit
        stopped at its iteration cap.  The CLI prints each as ``WARNING:``.
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
    covariance: np.ndarray | None = None
    mass: str = "diagonal"
    notes: tuple[str, ...] = field(default=())
    warnings: tuple[str, ...] = field(default=())

    @property
    def storeys(self) -> int:
        return self.M.shape[0]

    @property
    def layout(self) -> Layout:
        return Layout(self.storeys, self.mass)

    @property
    def theta(self) -> np.ndarray:
        return self.layout.pack(self.M, self.C, self.K, self.mu)

    def modes(self) -> Modes:
        """Natural frequencies and damping ratios of the identified model."""
        return modal_properties(self.M, self.C, self.K)

    def std(self) -> dict | None:
        """One standard error per entry: ``{'M', 'C', 'K', 'mu', 'kappa'}`` (same shapes)."""
        if self.covariance is None:
            return None
        lay = self.layout
        var = np.clip(np.diag(self.covariance), 0.0, None)
        s = np.sqrt(var)
        M = s[lay.m] if self.mass == "full" else np.diag(s[np.diag(lay.m)])
        theta = self.theta
        g = np.zeros_like(theta)
        for i in range(theta.size):   # kappa(theta) is smooth: central differences
            step = 1e-6 * max(abs(theta[i]), 1e-12 + np.max(np.abs(theta)) * 1e-9)
            tp, tm = theta.copy(), theta.copy()
            tp[i] += step
            tm[i] -= step
            g[i] = (_kappa(lay, tp) - _kappa(lay, tm)) / (2 * step)
        return {"M": M, "C": s[lay.c], "K": s[lay.k], "mu": float(s[lay.mu]),
                "kappa": float(np.sqrt(max(g @ self.covariance @ g, 0.0)))}

    def to_dict(self) -> dict:
        """JSON-friendly dict: matrices as nested lists in SI units; ``std`` likewise."""
        modes = self.modes()
        out = {
            "M": self.M.tolist(), "C": self.C.tolist(), "K": self.K.tolist(),
            "mu": self.mu, "kappa": self.kappa,
            "damping_misfit": self.damping_misfit,
            "frequency_hz": modes.frequency.tolist(),
            "damping_ratio": modes.damping_ratio.tolist(),
            "estimator": self.estimator, "mass": self.mass,
            "n_equations": self.n_equations, "n_unknowns": self.n_unknowns,
            "rank": self.rank, "condition": self.condition,
            "residual_rms": self.residual_rms, "runs": list(self.runs),
            "notes": list(self.notes), "warnings": list(self.warnings),
        }
        std = self.std()
        if std is not None:
            out["std"] = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in std.items()}
        return out


def _kappa(layout: Layout, theta: np.ndarray) -> float:
    M, C, K, mu = layout.unpack(theta)
    return float(np.sum(K * (C - mu * M)) / np.sum(K * K))


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


def _check_times(selected, times) -> None:
    """Chosen instants must be finite and inside every selected run's record."""
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


def _rows(run: RunData, signals: dict, times) -> np.ndarray:
    """Sample indices of ``run``'s equations in its prepared ``signals``: the chosen instants of a
    measured run, or every bump position of a weak form (accelerometer-only data)."""
    if signals["a"].shape[0] == run.n_samples:
        return _sample_index(run, times)
    if times is None:
        return np.arange(signals["a"].shape[0])
    raise IdentificationError(f"times = {list(times)}: chosen instants need measured displacements "
                              f"(run {run.name!r} has accelerations only)")


def _sample_index(run: RunData, times) -> np.ndarray:
    if times is None:
        return np.arange(run.n_samples)
    times = np.asarray(times, float)
    idx = np.clip(np.searchsorted(run.time, times), 1, run.n_samples - 1)
    left = run.time[idx - 1]
    idx = np.where(np.abs(times - left) <= np.abs(run.time[idx] - times), idx - 1, idx)
    return np.unique(idx)


class _Accumulator:
    """Streaming QR of ``[A | b]``, one small triangular factor per floor."""

    def __init__(self, layout: Layout):
        self.layout = layout
        self.cols = [layout.floor_columns(j) for j in range(layout.d)]
        self.R = [np.zeros((0, len(c) + 1)) for c in self.cols]
        self.rows = 0

    def add(self, acc, vel, disp, vel_mu, rhs) -> None:
        """Add ``n`` samples: regressor signals (n, d) and dM-terms (n, d)."""
        full = self.layout.mass == "full"
        for start in range(0, acc.shape[0], _BLOCK):
            sl = slice(start, start + _BLOCK)
            for j in range(self.layout.d):
                m = acc[sl] if full else acc[sl, j:j + 1]
                block = np.column_stack([m, vel[sl], disp[sl], vel_mu[sl, j], rhs[sl, j]])
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


def _solve(acc: _Accumulator, estimator: str, runs):
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


def _ideal(experiment: Experiment) -> bool:
    sensors = experiment.scenario.get("sensors") if experiment.scenario else None
    return bool(sensors and sensors.get("ideal"))


#: An errors-in-variables residual above this multiple of the noise level (its RMS, whitened: 1 when
#: the model explains the data down to the sensor noise) is a contradiction, printed with a WARNING.
#: A right model gives 1 to about 2.5 (noise levels estimated from a high band, a fit stopped at its
#: evaluation cap); a missing physics or a wrong added-mass pattern gives tens to millions.
MAX_NOISE_EXCESS = 5.0


def _result(layout, theta, estimator, rows, rank, condition, residual_rms, names, cov, notes, capped=False):
    M, C, K, mu = layout.unpack(theta)
    kappa = _kappa(layout, theta)
    misfit = float(np.linalg.norm(C - mu * M - kappa * K) / np.linalg.norm(C))
    return Identification(
        M=M, C=C, K=K, mu=mu, kappa=kappa, damping_misfit=misfit, estimator=estimator,
        n_equations=rows, n_unknowns=layout.p, rank=rank, condition=condition,
        residual_rms=residual_rms, runs=names, covariance=cov, mass=layout.mass, notes=tuple(notes),
        warnings=tuple(_warnings(M, C, K, capped) + _misfit_warning(estimator, residual_rms)),
    )


def _misfit_warning(estimator: str, excess: float) -> list[str]:
    """A residual far above the noise (errors-in-variables: ``residual_rms`` is in noise units)."""
    if estimator != "eiv" or excess <= MAX_NOISE_EXCESS:
        return []
    return [f"the residual is {excess:.3g} x the sensor noise level (above {MAX_NOISE_EXCESS:g}): the linear "
            f"model does not explain these data (a wrong added-mass pattern, a sensor fault, or physics the "
            f"model leaves out); `momentid diagnose` locates the mismatch"]


def _warnings(M, C, K, capped: bool) -> list[str]:
    """What an identified (M, C, K) says that no passive structure can do."""
    out = []
    masses = np.linalg.eigvalsh(0.5 * (M + M.T))
    if np.any(masses <= 0):
        out.append(f"the identified mass matrix is not positive definite (eigenvalues "
                   f"{', '.join(f'{m:.4g}' for m in masses)} kg): the data do not determine the masses")
    else:
        modes = modal_properties(M, C, K)
        for i, (f, z) in enumerate(zip(modes.frequency, modes.damping_ratio)):
            if z <= 0:
                out.append(f"mode {i + 1} at {f:.4g} Hz is UNSTABLE (damping ratio {z:.3g} <= 0): the data "
                           f"contradict a passive linear structure there")
    if capped:
        out.append("the errors-in-variables fit stopped at its evaluation cap before converging: the results "
                   "are not a minimum of the likelihood")
    return out


def identify(experiment: Experiment, *, estimator: str = "auto", mass: str = "diagonal", runs=None,
             times=None, prefilter: Prefilter | str | None = "auto"):
    """Identify a shear building's dynamics from shake-table runs.

    What comes out depends on what the runs hold:

    * **Runs with added mass** (the Majcher 2025 method): M, C, K, the Rayleigh
      coefficients mu and kappa, with standard errors (:class:`Identification`).
    * **No run adds mass** (most real labs): the table-to-floor transfer fixes
      M^-1 K and M^-1 C only.  Natural frequencies, damping ratios and mode
      shapes with standard errors, M^-1 K and M^-1 C; with floor masses stated
      by the lab (``experiment.statement.masses``, or the nominal model's)
      also K and C in SI units
      (:class:`~momentid.estimation.scaled.ModalIdentification`, see
      :mod:`momentid.estimation.modal`).  Accelerometers only suffice, at any
      sample rate above ~2.4 x the top mode.

    Sensor noise levels come from :func:`momentid.estimation.noise.estimate_noise`:
    stated by the lab, the quiet seconds before the table moves, or a band above
    the structure's response (high-rate recordings); the result says which.

    Parameters
    ----------
    experiment : Experiment
        Runs with the table acceleration ``zdd`` and floor accelerations
        ``a1..ad`` (m/s^2), plus displacements/velocities where measured (the
        added-mass estimators reconstruct missing ones, see
        :mod:`momentid.estimation.reconstruct`).
    estimator : {"auto", "equation", "difference", "eiv", "modal"}
        ``"auto"`` (default): ``"modal"`` when no run of the experiment adds
        mass; otherwise ``"equation"`` for noise-free data, ``"eiv"`` for noisy
        data (select only reference runs of an added-mass experiment with
        ``"modal"`` explicitly).
        ``"equation"``: method.md eq. (3) by least squares, every run on its
        own.  ``"difference"``: the paper's eq. (2), each run minus the
        reference run (same table motion needed).  ``"eiv"``: errors-in-variables
        maximum likelihood, unbiased by noise on every channel.  ``"modal"``:
        the modal errors-in-variables fit for runs without added mass.
    mass : {"diagonal", "full"}
        Shape of the identified mass matrix (added-mass estimators).
    runs : sequence of str, optional
        Names of the runs to use (all by default).
    times : sequence of float, optional
        Equation forms only: use just the samples nearest these times (s).
        ``times=[5.0]`` with ``estimator="difference"`` is the paper's system.
    prefilter : Prefilter, "auto" or None
        Band applied to every channel before the equation forms.  "auto":
        none for ideal (noise-free) recordings, else a zero-phase low-pass
        just above the structure's response band.

    Returns
    -------
    Identification or ModalIdentification
        Both have ``modes()``, ``to_dict()`` (with ``frequency_hz`` and
        ``damping_ratio`` lists, mode 1 first), ``notes`` and ``warnings``.
        ``warnings`` lists what the data contradict or cannot support
        (unstable modes, non-positive masses, a fit stopped at its iteration
        cap, poorly excited modes, sensors that physics places on other floors
        than listed: :func:`momentid.io.placement.placement_warnings`); the CLI
        prints each as ``WARNING:``.

    Raises
    ------
    IdentificationError
        The runs cannot identify the unknowns: a single run with added mass,
        too little excitation, no source for the noise level.
    SensorDataError
        A needed channel is missing, or data are unusable (gaps, clipping).

    Examples
    --------
    >>> result = identify(experiment)                      # doctest: +SKIP
    >>> result.modes().frequency, result.to_dict()["damping_ratio"]   # doctest: +SKIP
    """
    # The work is thousands of small dense products: BLAS threads only add
    # synchronisation (300x slower for 8x8 expm on a busy 2-core machine).
    with threadpool_limits(limits=1, user_api="blas"):
        if estimator == "modal" or (estimator == "auto" and not _adds_mass(experiment, None)):
            result = _identify_modal(experiment, runs, times)
        else:
            result = _identify(experiment, estimator=estimator, mass=mass, runs=runs, times=times,
                               prefilter=prefilter)
    from momentid.io.placement import placement_warnings  # sensors on other floors than listed (issue 18)
    return replace(result, warnings=(*placement_warnings(experiment), *result.warnings))


def _adds_mass(experiment: Experiment, runs) -> bool:
    selected = experiment.select(runs)
    return any(np.any(r.added_mass) for r in selected)


def _identify_modal(experiment: Experiment, runs, times):
    from momentid.estimation.scaled import identify_modal

    if times is not None:
        raise IdentificationError(f"times = {list(times)}: chosen instants work only with the equation forms, "
                                  f"which need runs with added mass")
    if _adds_mass(experiment, runs):
        raise IdentificationError(
            f"{experiment.source}: estimator 'modal' fits runs without added mass, but some selected runs "
            f"add mass: select the reference runs (--runs) or use 'eiv'")
    return identify_modal(experiment, runs)


def _identify(experiment: Experiment, *, estimator: str, mass: str, runs, times,
              prefilter) -> Identification:
    """The added-mass estimators of :func:`identify`."""
    if estimator not in ESTIMATORS:
        raise IdentificationError(f"estimator = {estimator!r}: expected one of {', '.join(ESTIMATORS)}")
    ideal = _ideal(experiment)
    selected = experiment.select(runs)
    names = tuple(r.name for r in selected)
    if len(selected) < 2:
        raise IdentificationError(
            f"{experiment.source}: {len(selected)} run(s) {list(names)}: expected at least two "
            f"(a reference run and a run with added mass), or estimator 'modal' for the modes of runs "
            f"without added mass"
        )
    d = selected[0].added_mass.shape[0]
    if all(not np.any(r.added_mass) for r in selected):
        raise IdentificationError(
            f"{experiment.source}: no run among {list(names)} adds mass: estimator {estimator!r} fixes M, C, K "
            f"only up to scale; use estimator 'modal' (or 'auto'), which identifies the modes and, with stated "
            f"masses, K and C"
        )
    notes: list[str] = []
    checked = []
    for run in selected:
        if run.has("a1") and not ideal:
            run, repairs = check_run(run, experiment.source)
            notes.extend(repairs)
        checked.append(run)
    selected = tuple(checked)
    _check_times(selected, times)
    layout = Layout(d, mass)
    if estimator == "auto" and times is not None:
        estimator = "equation"
    if estimator == "eiv" and times is not None:
        raise IdentificationError(f"times = {list(times)}: only the equation forms work at chosen instants; "
                                  f"use estimator 'equation' or 'difference'")
    if estimator == "auto":
        exact = _equation_form(experiment, selected, layout, "equation", times, Prefilter(), names, notes)
        if ideal or exact.residual_rms <= _ROUNDOFF * _force_scale(exact, selected):
            return exact
        estimator = "eiv"
        notes.append(f"equation residual {exact.residual_rms:.3g} N is above round-off: the data carry "
                     f"noise, so the errors-in-variables estimator is used")
    if prefilter == "auto":
        band = (Prefilter() if ideal or estimator == "difference" or times is not None
                else Prefilter(high=suggest_band(selected[0], d)))
    else:
        band = prefilter or Prefilter()
    if band.active:
        notes.append(f"equation form on signals filtered to {band.low:g}-{band.high or 'inf'} Hz")
    eq_name = "difference" if estimator == "difference" else "equation"
    try:
        start = _equation_form(experiment, selected, layout, eq_name, times, band, names, notes)
    except IdentificationError as exc:
        if estimator != "eiv":
            raise
        raise IdentificationError(f"estimator 'eiv' starts from the equation form, which failed: {exc}") from None
    if estimator != "eiv":
        return start
    from momentid.estimation.eiv import fit_eiv
    f_top = float(start.modes().frequency.max())
    f_max = max(band.high or 0.0, 2.0 * f_top)
    stated = dict(experiment.statement.noise) if experiment.statement is not None else None
    fit = fit_eiv(layout, selected, start.theta, f_max=f_max, stated=stated)
    if fit.scale > 1.5 and experiment.structure is not None and layout.mass == "diagonal":
        # The residual sits well above the noise: the equation-form start (biased by noise, badly so
        # for accelerometer-only data) may have led to a local minimum. Try the lab's nominal model.
        s0 = experiment.structure
        nominal = layout.pack(s0.mass_matrix(), s0.damping_matrix(), s0.stiffness_matrix(), s0.rayleigh_mu)
        second = fit_eiv(layout, selected, nominal, stated=stated, f_max=max(f_max, 2.0 * float(
            modal_properties(s0.mass_matrix(), s0.damping_matrix(), s0.stiffness_matrix()).frequency.max())))
        if second.cost < fit.cost:
            fit = second
            notes.append("errors-in-variables fit restarted from the nominal model (lower cost)")
    notes.append(f"errors-in-variables fit over 0-{f_max:.3g} Hz: {fit.nfev} model evaluations, "
                 f"residual variance factor {fit.scale:.3g} (1 = at the noise level)")
    notes.append(f"noise levels: {'; '.join(fit.noise_sources)}")
    return _result(layout, fit.theta, "eiv", fit.n_residuals, start.rank, start.condition,
                   float(np.sqrt(fit.scale)), names, fit.covariance, notes, capped=fit.capped)


#: Relative equation residual below which data count as noise-free.
_ROUNDOFF = 1e-8


def _force_scale(result: Identification, runs) -> float:
    """RMS inertia force M a of the runs (N): the scale equation residuals are judged on."""
    total, count = 0.0, 0
    for run in runs:
        f = run.group("a", result.storeys) @ result.M.T
        total += float(np.sum(f ** 2))
        count += f.size
    return float(np.sqrt(total / max(count, 1)))


def _equation_form(experiment, selected, layout, eq_name, times, band, names, notes) -> Identification:
    require_equation_memory(layout, experiment.source)
    d = layout.d
    acc = _Accumulator(layout)
    if eq_name == "equation":
        for run in selected:
            s = _prepared(run, d, band)
            idx = _rows(run, s, times)
            dm = run.added_mass
            a, v, q = s["a"][idx], s["v"][idx], s["q"][idx]
            acc.add(a, v, q, v * dm, -a * dm)
    else:
        _difference_rows(experiment, selected, d, times, acc, band)
    theta, rank, condition, rss, cov = _solve(acc, eq_name, names)
    return _result(layout, theta, eq_name, acc.rows, rank, condition,
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


def _difference_rows(experiment: Experiment, selected, d: int, times, acc: _Accumulator,
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


@dataclass(frozen=True)
class DampingFit:
    """How well one damping model explains the identified C.

    Attributes
    ----------
    model : str
        ``"rayleigh"`` (a M + b K), ``"mass"`` (a M), ``"stiffness"`` (b K) or
        ``"general"`` (any symmetric C: the identified C itself).
    coefficients : dict
        ``{"a": 1/s, "b": s}`` as fitted.
    misfit : float
        ``||C - C_model||_F / ||C||_F``.
    chi2, dof : float, int
        Weighted by the covariance of the identified C entries; ``chi2 / dof``
        near 1 means the model explains C within its uncertainty.
    p_value : float
        Probability of a chi2 at least this large if the model were right.
    """

    model: str
    coefficients: dict
    misfit: float
    chi2: float
    dof: int
    p_value: float


def damping_models(result: Identification) -> list[DampingFit]:
    """Test Rayleigh, mass-only, stiffness-only and general damping against C.

    The identified matrices M and K serve as the bases; the C entries are
    weighted by their covariance, so the verdict accounts for how well the
    experiment determined C (the paper's conclusion proposes exactly this
    use of the method).
    """
    from scipy.stats import chi2 as chi2_dist

    d = result.storeys
    iu = np.triu_indices(d)
    c = result.C[iu]
    lay = result.layout
    cov = None
    if result.covariance is not None:
        idx = lay.c[iu]
        cov = result.covariance[np.ix_(idx, idx)]
        # Floor at 1e-9 of the largest entry: noise-free data are exact only to round-off.
        cov = cov + np.eye(c.size) * (1e-9 * float(np.max(np.abs(c)))) ** 2
    W = np.linalg.inv(cov) if cov is not None else np.eye(c.size)
    bases = {"rayleigh": {"a": result.M[iu], "b": result.K[iu]}, "mass": {"a": result.M[iu]},
             "stiffness": {"b": result.K[iu]}}
    out = []
    for name, basis in bases.items():
        A = np.column_stack(list(basis.values()))
        coef = np.linalg.solve(A.T @ W @ A, A.T @ W @ c)
        r = c - A @ coef
        chi2 = float(r @ W @ r) if cov is not None else float("nan")
        dof = c.size - A.shape[1]
        model = sum(k * X for k, X in zip(coef, (result.M, result.K) if name == "rayleigh"
                                          else ((result.M,) if name == "mass" else (result.K,))))
        misfit = float(np.linalg.norm(result.C - model) / np.linalg.norm(result.C))
        p = float(chi2_dist.sf(chi2, dof)) if cov is not None else float("nan")
        out.append(DampingFit(name, dict(zip(basis, map(float, coef))), misfit, chi2, dof, p))
    out.append(DampingFit("general", {}, 0.0, 0.0, 0, 1.0))
    return out


def identify_stream(path, *, mass: str = "diagonal", return_structure: bool = False):
    """Equation-form identification straight from a recording, block by block.

    Every sensor block is folded into per-run QR factors as it is read, so
    memory stays flat however long the record (an hour at 1 kHz included);
    runs the file does not complete are dropped with their factors.  Needs
    the channels ``a``, ``v``, ``q`` of every floor (ideal or reconstructed
    data); for noisy recordings use :func:`identify` (errors-in-variables).

    Returns
    -------
    Identification
        Or, with ``return_structure=True``, ``(Identification, Structure or
        None)``: the nominal model the recording states, from the same single
        pass over the file.
    """
    from momentid.io.recording import stream_recording

    per_run: dict[str, tuple[_Accumulator, np.ndarray]] = {}
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
            per_run[name] = (_Accumulator(state["layout"]), np.asarray(added, float))
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
        merged = _Accumulator(layout)
        for j in range(layout.d):
            stacked = np.vstack([per_run[n][0].R[j] for n in complete])
            merged.R[j] = np.linalg.qr(stacked, mode="r")
        merged.rows = sum(per_run[n][0].rows for n in complete)
        names = tuple(complete)
        theta, rank, condition, rss, cov = _solve(merged, "equation", names)
    result = _result(layout, theta, "equation", merged.rows, rank, condition,
                     float(np.sqrt(rss / max(merged.rows, 1))), names, cov, notes)
    if not return_structure:
        return result
    from momentid.core.structure import Structure
    text = experiment.get("structure")
    return result, (Structure.from_dict(json.loads(text)) if text and text != "null" else None)
