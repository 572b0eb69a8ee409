"""Cross-check an identification against the analytic model of the rig.

Every matrix entry is compared with its relative error; entries that are
zero in the analytic model are measured relative to the largest entry of
their matrix.  Natural frequencies and damping ratios of both models are
compared as well.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from momentid.core.analytic import Modes, modal_properties
from momentid.estimation.identified import Identification, damping_models
from momentid.core.structure import Structure

__all__ = ["Entry", "Comparison", "analytic_parameters", "compare"]


def analytic_parameters(structure: Structure) -> dict:
    """The analytic model in the keys and units of an identification.

    Parameters
    ----------
    structure : Structure
        The nominal shear building.

    Returns
    -------
    dict
        ``M``, ``C``, ``K`` (ndarray, shape (d, d); kg, N*s/m, N/m), ``mu``
        (1/s) and ``kappa`` (s), with ``C = mu M + kappa K``.
    """
    return {
        "M": structure.mass_matrix(),
        "C": structure.damping_matrix(),
        "K": structure.stiffness_matrix(),
        "mu": structure.rayleigh_mu,
        "kappa": structure.rayleigh_kappa,
    }


@dataclass(frozen=True)
class Entry:
    """One compared parameter: ``name`` like ``'K[1,2]'`` (1-based), its unit."""

    name: str
    unit: str
    identified: float
    analytic: float
    rel_error: float
    std: float | None = None

    @property
    def z_score(self) -> float | None:
        """(identified - analytic) / std, when a standard error is known."""
        if not self.std:
            return None
        return (self.identified - self.analytic) / self.std


@dataclass(frozen=True)
class Comparison:
    """Identified vs. analytic parameters and modes."""

    entries: tuple[Entry, ...]
    identified_modes: Modes
    analytic_modes: Modes
    identification: Identification
    analytic: dict

    @property
    def max_rel_error(self) -> float:
        """The largest relative error of the compared parameters."""
        return max(e.rel_error for e in self.entries)

    def entry(self, name: str) -> Entry:
        """The compared parameter ``name`` (``'K[1,2]'``, ``'mu'``, ...); a ``KeyError`` if none."""
        for e in self.entries:
            if e.name == name:
                return e
        raise KeyError(name)

    def table(self) -> str:
        """A plain-text table for the terminal."""
        r = self.identification
        residual = (f"residual RMS {r.residual_rms:.3g} N" if r.estimator != "eiv"
                    else f"residual at {r.residual_rms:.3g} x the noise level")
        has_std = any(e.std is not None for e in self.entries) and r.estimator == "eiv"
        lines = [
            f"identification: estimator {r.estimator}, runs {', '.join(r.runs)}",
            f"  {r.n_equations} equations, {r.n_unknowns} unknowns, rank {r.rank}, "
            f"condition {r.condition:.3g}, {residual}, Rayleigh misfit of C {r.damping_misfit:.2e}",
            "",
            f"{'parameter':<11} {'unit':<7} {'identified':>14} {'analytic':>14} {'rel. error':>11}"
            + (f" {'std. error':>11} {'z':>6}" if has_std else ""),
        ]
        for e in self.entries:
            line = (f"{e.name:<11} {e.unit:<7} {e.identified:>14.6g} {e.analytic:>14.6g} "
                    f"{e.rel_error:>11.2e}")
            if has_std and e.std is not None:
                line += f" {e.std:>11.3g} {e.z_score:>6.2f}"
            lines.append(line)
        lines += ["", f"{'mode':<5} {'f id (Hz)':>11} {'f an (Hz)':>11} {'zeta id':>10} {'zeta an':>10}"]
        mi, ma = self.identified_modes, self.analytic_modes
        for k in range(len(ma.frequency)):
            lines.append(f"{k + 1:<5} {mi.frequency[k]:>11.5f} {ma.frequency[k]:>11.5f} "
                         f"{mi.damping_ratio[k]:>10.5f} {ma.damping_ratio[k]:>10.5f}")
        lines += ["", f"{'damping model':<14} {'misfit':>9} {'chi2/dof':>10} {'p-value':>9}  coefficients"]
        for fit in damping_models(r):
            ratio = fit.chi2 / fit.dof if fit.dof else float("nan")
            coef = ", ".join(f"{k} = {v:.4g}" for k, v in fit.coefficients.items())
            lines.append(f"{fit.model:<14} {fit.misfit:>9.2e} {ratio:>10.3g} {fit.p_value:>9.3g}  {coef}")
        lines += ["", f"largest relative error: {self.max_rel_error:.2e}"]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-friendly: the identification plus ``analytic`` and ``errors``."""
        out = self.identification.to_dict()
        an = self.analytic
        out["analytic"] = {
            "M": an["M"].tolist(), "C": an["C"].tolist(), "K": an["K"].tolist(),
            "mu": an["mu"], "kappa": an["kappa"],
            "frequency_hz": self.analytic_modes.frequency.tolist(),
            "damping_ratio": self.analytic_modes.damping_ratio.tolist(),
        }
        out["rel_error"] = {e.name: e.rel_error for e in self.entries}
        if any(e.std is not None for e in self.entries):
            out["z_score"] = {e.name: e.z_score for e in self.entries}
        out["max_rel_error"] = self.max_rel_error
        out["damping_models"] = [asdict(f) for f in damping_models(self.identification)]
        return out


def _matrix_entries(name: str, unit: str, ident: np.ndarray, ref: np.ndarray, std, diagonal_only=False):
    scale = float(np.max(np.abs(ref))) or 1.0
    d = ref.shape[0]
    out = []
    for i in range(d):
        for j in range(i, d):
            if diagonal_only and i != j:
                continue
            a, b = float(ident[i, j]), float(ref[i, j])
            denom = abs(b) if b != 0 else scale
            s = None if std is None else float(std[i, j])
            out.append(Entry(f"{name}[{i + 1},{j + 1}]", unit, a, b, abs(a - b) / denom, s))
    return out


def compare(result: Identification, structure: Structure) -> Comparison:
    """Compare ``result`` with the analytic model of ``structure``.

    Parameters
    ----------
    result : Identification
        What :func:`momentid.identify` returned.
    structure : Structure
        The nominal model (``experiment.structure`` of a recording).

    Returns
    -------
    Comparison
        One entry per identified parameter (upper triangles of C and K, the
        masses, ``mu``, ``kappa``) with its analytic value, relative error
        (against the entry, or against the matrix's largest entry where the
        analytic value is 0) and standard error when the estimator gives
        one; the modes of both models; ``table()`` prints it all.
    """
    an = analytic_parameters(structure)
    std = result.std() or {}
    entries = (
        _matrix_entries("M", "kg", result.M, an["M"], std.get("M"), diagonal_only=result.mass == "diagonal")
        + _matrix_entries("C", "N*s/m", result.C, an["C"], std.get("C"))
        + _matrix_entries("K", "N/m", result.K, an["K"], std.get("K"))
    )
    for key, unit in (("mu", "1/s"), ("kappa", "s")):
        a, b = getattr(result, key), an[key]
        denom = abs(b) if b != 0 else 1.0
        entries.append(Entry(key, unit, a, b, abs(a - b) / denom, std.get(key)))
    return Comparison(
        entries=tuple(entries),
        identified_modes=result.modes(),
        analytic_modes=modal_properties(an["M"], an["C"], an["K"]),
        identification=result,
        analytic=an,
    )
