"""What a modal fit may not print as an answer, and the extra modes it reports apart.

:func:`check` turns a :class:`~momentid.estimation.modal_select.ModeSelection` into the warnings and
notes of :class:`~momentid.estimation.scaled.ModalIdentification`:

* a floor sensor whose gain reached the 0.5 or 2 bound of the fit reads the table's motion wrongly
  (a turned sensor, a wrong unit or channel): the run is **refused** with the sensor named and its
  low-frequency ratio to the table (:func:`low_frequency_ratio`); so is one whose clock offset reached
  the 1.5-sample bound (clocks not aligned);
* a mode whose linear-fit (equivalent linear) damping ratio differs from the subspace estimate of the
  same data by more than :data:`DAMPING_DISAGREEMENT` is warned about with that cause named (the damping
  answer itself comes from :mod:`momentid.estimation.damping`);
* a capped fit (after its restarts), an unstable or a poorly determined mode, a suspect gain, shapes
  far from orthogonal with the stated masses: warnings, as before.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from momentid.core.series import RunData
from momentid.errors import IdentificationError
from momentid.estimation.modal import BOUND_TOLERANCE, at_offset_bound
from momentid.estimation.modal_model import GAIN_RANGE, OFFSET_BOUND

if TYPE_CHECKING:
    from momentid.estimation.modal_select import ModeSelection

__all__ = ["ExtraMode", "extra_modes", "check", "low_frequency_ratio", "DAMPING_DISAGREEMENT", "SUSPECT_GAIN",
           "POOR_FREQUENCY", "POOR_DAMPING", "ORTHOGONALITY_WARNING", "GAIN_BOUNDS"]

#: A mode whose frequency is uncertain by more than this fraction, or whose damping ratio by more than
#: half of itself, is reported as poorly determined.
POOR_FREQUENCY = 0.01
POOR_DAMPING = 0.5
#: A floor sensor whose fitted gain differs from the table sensor's by more than this fraction is
#: suspect (a real accelerometer is calibrated to ~1-2 %).
SUSPECT_GAIN = 0.05
#: The fit's gain bounds and clock-offset bound (samples, see
#: :meth:`~momentid.estimation.modal_model.ModalModel.bounds`); a sensor at one of them (within
#: :data:`~momentid.estimation.modal.BOUND_TOLERANCE`) is refused: a clock offset there only when the data
#: determine it (:func:`~momentid.estimation.modal.refine` fixes one they do not at 0).
GAIN_BOUNDS = GAIN_RANGE
OFFSET_BOUND_SAMPLES = OFFSET_BOUND
#: Shapes further than this from M-orthogonal (largest off-diagonal of the normalised modal mass
#: matrix) contradict the stated masses.
ORTHOGONALITY_WARNING = 0.2
#: A damping ratio this many times larger or smaller than the independent (subspace) estimate is not
#: an answer.
DAMPING_DISAGREEMENT = 2.0
#: The low-frequency ratio uses bins below this fraction of mode 1 (the floors move with the table to
#: within ~10 %) where the table moves.
LOW_FREQUENCY_FRACTION = 0.3


@dataclass(frozen=True)
class ExtraMode:
    """A resonance beyond the storey modes, fitted so that it does not distort them.

    Attributes
    ----------
    frequency, frequency_std : float
        Undamped natural frequency (Hz) and standard error.
    damping_ratio, damping_ratio_std : float
    residues, residues_std : ndarray, shape (d,)
        Per floor sensor: the mode's residue ``R_j`` (participation x shape; floor j's absolute
        acceleration per unit table acceleration is ``1 - sum R_ij H_i``) and standard error.
    seen_by : tuple of str
        Floor sensors whose residue exceeds 3 standard errors.
    damping_independent : float
        The subspace estimate's damping ratio near this frequency (NaN: none stable over orders).
    residues_quadrature : ndarray, shape (d,)
        Quadrature residues ``Q_j`` of a complex mode (zeros for a classical one): its floor j term is
        ``s^2 (R_j + Q_j s / w) / (s^2 + 2 zeta w s + w^2)``.
    """

    frequency: float
    frequency_std: float
    damping_ratio: float
    damping_ratio_std: float
    residues: np.ndarray
    residues_std: np.ndarray
    seen_by: tuple
    damping_independent: float = float("nan")
    residues_quadrature: np.ndarray | None = None

    def to_dict(self) -> dict:
        """The extra mode as a JSON-ready dict (frequency in Hz; a missing subspace estimate as None)."""
        return {"frequency_hz": self.frequency, "frequency_std": self.frequency_std,
                "damping_ratio": self.damping_ratio, "damping_ratio_std": self.damping_ratio_std,
                "residues": np.asarray(self.residues).tolist(), "residues_std": np.asarray(self.residues_std).tolist(),
                "seen_by": list(self.seen_by),
                "residues_quadrature": None if self.residues_quadrature is None else
                np.asarray(self.residues_quadrature).tolist(),
                "damping_ratio_subspace": None if np.isnan(self.damping_independent) else self.damping_independent}


def extra_modes(selection: ModeSelection) -> tuple[ExtraMode, ...]:
    """The :class:`ExtraMode` of every extra mode of a selection, ascending in frequency."""
    from momentid.estimation.modal_select import SEEN_SIGMAS

    model, fit = selection.model, selection.fit
    sd = np.sqrt(np.clip(np.diag(fit.covariance), 0, None))
    w, z, R = model.omega(fit.theta), model.zeta(fit.theta), model.residues(fit.theta)
    R_sd = sd[model.residue_slice].reshape(model.n, model.d)
    out = []
    for i in selection.extra:
        f = float(w[i] / (2 * np.pi))
        seen = tuple(f"a{j + 1}" for j in np.flatnonzero(np.abs(R[i]) > SEEN_SIGMAS * R_sd[i]))
        out.append(ExtraMode(frequency=f, frequency_std=f * float(sd[i]), damping_ratio=float(z[i]),
                             damping_ratio_std=float(sd[model.n + i]), residues=R[i].copy(),
                             residues_std=R_sd[i].copy(), seen_by=seen,
                             damping_independent=float(selection.independent[i]),
                             residues_quadrature=model.quadrature_residues(fit.theta)[i].copy()))
    return tuple(out)


def low_frequency_ratio(run: RunData, d: int, f1: float) -> np.ndarray:
    """Each floor sensor's reading per unit table acceleration below :data:`LOW_FREQUENCY_FRACTION` x
    mode 1 (``f1``, Hz), shape (d,); NaN when the table hardly moves there."""
    n = run.n_samples
    freq = np.fft.rfftfreq(n, 1.0 / run.sample_rate)
    band = (freq > 2.0 / (n / run.sample_rate)) & (freq < LOW_FREQUENCY_FRACTION * f1)
    U = np.fft.rfft(run["zdd"])[band]
    Y = np.fft.rfft(run.group("a", d), axis=0)[band]
    power = float(np.sum(np.abs(U) ** 2))
    if band.sum() < 3 or power == 0:
        return np.full(d, np.nan)
    return np.real(np.conj(U) @ Y) / power


def _sensor_refusal(runs, gain, offset, storey_f1: float) -> None:
    """Refuse a run whose floor sensor's gain or clock offset sits at the fit's bound."""
    lo, hi = np.log(GAIN_BOUNDS[0]), np.log(GAIN_BOUNDS[1])
    for r, run in enumerate(runs):
        g = np.log(gain[r])
        at = np.flatnonzero((np.abs(g - lo) < BOUND_TOLERANCE) | (np.abs(g - hi) < BOUND_TOLERANCE))
        if at.size:
            ratio = low_frequency_ratio(run, len(gain[r]), storey_f1)
            said = ", ".join(f"a{j + 1} ({gain[r][j]:.2f} at the bound; below {LOW_FREQUENCY_FRACTION:g} x mode 1 "
                             f"it reads {ratio[j]:.2f} x the table)" for j in at)
            reads_fine = np.all((ratio[at] > GAIN_BOUNDS[0]) & (ratio[at] < GAIN_BOUNDS[1]))
            cause = ("its reading at low frequency is no gain fault, so the modal model does not fit this sensor: a "
                     "sensor on another floor than stated (swapped files), or runs of different structures fitted "
                     "together (try --per-run)" if reads_fine else
                     "a sensor turned off the shaking axis, a wrong unit, or the wrong channel")
            raise IdentificationError(
                f"run {run.name!r}: refused: floor sensor(s) {said}: expected a gain within {GAIN_BOUNDS[0]:g}-"
                f"{GAIN_BOUNDS[1]:g} of the table sensor's: {cause}; check the import (axis, sign, unit, which "
                f"file is which floor)")
        late = np.flatnonzero(at_offset_bound(offset[r], run.sample_rate))
        if late.size:
            raise IdentificationError(
                f"run {run.name!r}: refused: the clock offset of floor sensor(s) "
                f"{', '.join(f'a{j + 1} ({1e3 * offset[r][j]:+.1f} ms)' for j in late)} reached the fit's bound of "
                f"{OFFSET_BOUND_SAMPLES:g} samples: expected the sensors aligned to the table's clock within about "
                f"a sample (a larger offset bends the damping ratios); align the clocks (`momentid import` aligns "
                f"separately clocked sensors from the data) or check which file is which floor")


def check(selection: ModeSelection, values: dict, std: dict, runs: Sequence[RunData], gain: np.ndarray,
          offset: np.ndarray, masses: Sequence[float] | None) -> tuple[list, list, np.ndarray]:
    """Warnings, notes and, per storey mode, whether its damping ratio is an answer.

    ``values`` and ``std``: the derived quantities and their standard errors (``frequency`` in Hz,
    ``damping_ratio``, ...); ``gain`` and ``offset`` (s): per run and floor sensor, each (runs, d);
    ``masses``: the stated floor masses (kg), or None.

    Raises
    ------
    IdentificationError
        A floor sensor's gain at the fit's bound (see the module docstring).
    """
    fit, storey = selection.fit, selection.storey
    f, z = values["frequency"], values["damping_ratio"]
    _sensor_refusal(runs, gain, offset, float(f[0]))
    out, notes = [], []
    independent = selection.independent[list(storey)]
    answer = np.ones(f.size, bool)
    for i in range(f.size):
        if z[i] <= 0:
            answer[i] = False
            out.append(f"mode {i + 1} at {f[i]:.4g} Hz is UNSTABLE (damping ratio {z[i]:.3g} <= 0): the data "
                       f"contradict a passive linear structure there (sensor fault, or the table barely "
                       f"excites this mode); do not use its damping")
            continue
        if std["frequency"][i] > POOR_FREQUENCY * f[i] or std["damping_ratio"][i] > POOR_DAMPING * z[i]:
            out.append(f"mode {i + 1} at {f[i]:.4g} Hz is poorly determined (frequency +- "
                       f"{std['frequency'][i]:.2g} Hz, damping ratio {z[i]:.3g} +- {std['damping_ratio'][i]:.2g}): "
                       f"the runs excite it too little")
        disagreement = _disagreement(z[i], independent[i])
        if disagreement:
            out.append(f"mode {i + 1} at {f[i]:.4g} Hz: the linear fit's (equivalent linear) damping ratio "
                       f"{100 * z[i]:.3g} % is not a figure to use: {disagreement}")
        elif np.isnan(independent[i]):
            notes.append(f"mode {i + 1} at {f[i]:.4g} Hz: no subspace pole is stable over model orders there, so "
                         f"its damping ratio has no second opinion from these data")
    for mode in extra_modes(selection):
        disagreement = _disagreement(mode.damping_ratio, mode.damping_independent)
        if disagreement:
            out.append(f"extra mode at {mode.frequency:.4g} Hz: damping ratio {100 * mode.damping_ratio:.3g} % "
                       f"is NOT AN ANSWER: {disagreement}")
    if fit.capped:
        out.append(f"the fit stopped at its evaluation cap from every start ({fit.nfev} evaluations in all) "
                   f"before converging: the results are not a minimum of the likelihood")
    for r, run in enumerate(runs):
        bad = np.flatnonzero(np.abs(gain[r] - 1) > SUSPECT_GAIN)
        if bad.size:
            out.append(f"run {run.name!r}: floor sensor(s) {', '.join(f'a{j + 1}' for j in bad)} read "
                       f"{', '.join(f'{gain[r][j]:.3f}' for j in bad)} x the table sensor at low frequency: "
                       f"expected within {SUSPECT_GAIN:.0%} (gain, mounting angle or a loose sensor?)")
    if masses is not None and values["orthogonality"] > ORTHOGONALITY_WARNING:
        out.append(f"the mode shapes are far from orthogonal with the stated masses {list(masses)} (largest "
                   f"off-diagonal modal mass {values['orthogonality']:.2f}, expected below "
                   f"{ORTHOGONALITY_WARNING}): K and C are the nearest consistent matrices, check the masses")
    return out, notes, answer


def _disagreement(zeta: float, independent: float) -> str:
    """Why ``zeta`` disagrees with the independent estimate ('' when it does not, or there is none)."""
    if np.isnan(independent) or zeta <= 0:
        return ""
    ratio = zeta / independent
    if 1 / DAMPING_DISAGREEMENT <= ratio <= DAMPING_DISAGREEMENT:
        return ""
    return (f"the subspace estimate of the same data says {100 * independent:.3g} % ({ratio:.2g} x apart, more "
            f"than {DAMPING_DISAGREEMENT:g} x): two modes closer than the fit resolves, a rig that is not linear "
            f"at this amplitude, or a mode the table barely excites")
