"""The result of the added-mass estimators (:class:`Identification`), the warnings it carries
when the data contradict a passive structure, and the tests of damping models against its C
(:func:`damping_models`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from momentid.core.analytic import Modes, modal_properties
from momentid.estimation.layout import Layout

__all__ = ["Identification", "identification_result", "rayleigh_kappa", "MAX_NOISE_EXCESS", "DampingFit",
           "damping_models"]


@dataclass(frozen=True)
class Identification:
    """Result of :func:`~momentid.estimation.identification.identify` on runs with added mass.

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
        """Number of storeys ``d``."""
        return self.M.shape[0]

    @property
    def layout(self) -> Layout:
        """The unknowns' layout of this result (its storeys and mass form)."""
        return Layout(self.storeys, self.mass)

    @property
    def theta(self) -> np.ndarray:
        """The identified unknowns as one vector (p,) of :attr:`layout`."""
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
            g[i] = (rayleigh_kappa(lay, tp) - rayleigh_kappa(lay, tm)) / (2 * step)
        return {"M": M, "C": s[lay.c], "K": s[lay.k], "mu": float(s[lay.mu]),
                "kappa": float(np.sqrt(max(g @ self.covariance @ g, 0.0)))}

    def _repr_html_(self) -> str:
        """A notebook's summary: the words of the report page's answer
        (:func:`momentid.estimation.summary_html.identification_html`)."""
        from momentid.estimation.summary_html import identification_html
        return identification_html(self)

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


def rayleigh_kappa(layout: Layout, theta: np.ndarray) -> float:
    """The stiffness-proportional coefficient (s): least squares of ``C - mu M = kappa K`` for the
    matrices in ``theta`` (shape (p,), see :class:`Layout`)."""
    M, C, K, mu = layout.unpack(theta)
    return float(np.sum(K * (C - mu * M)) / np.sum(K * K))


#: An errors-in-variables residual above this multiple of the noise level (its RMS, whitened: 1 when
#: the model explains the data down to the sensor noise) is a contradiction, printed with a WARNING.
#: A right model gives 1 to about 2.5 (noise levels estimated from a high band, a fit stopped at its
#: evaluation cap); a missing physics or a wrong added-mass pattern gives tens to millions.
MAX_NOISE_EXCESS = 5.0


def identification_result(layout: Layout, theta: np.ndarray, estimator: str, rows: int, rank: int, condition: float,
                          residual_rms: float, names: tuple[str, ...], cov: np.ndarray | None, notes: Sequence[str],
                          capped: bool = False) -> Identification:
    """The :class:`Identification` of the unknowns ``theta`` (shape (p,), see :class:`Layout`), with
    ``kappa``, the damping misfit and the warnings (non-positive masses, unstable modes, a fit
    stopped at its cap, an errors-in-variables residual above :data:`MAX_NOISE_EXCESS`) derived from
    it; the other arguments are stored as the fields of the same meaning."""
    M, C, K, mu = layout.unpack(theta)
    kappa = rayleigh_kappa(layout, theta)
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
