"""What a diagnosis of accelerometer-only recordings by the modal model
(:mod:`~momentid.diagnosis.modal.path`) shows beside its verdict, and says in words."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from momentid.diagnosis import figures
from momentid.diagnosis.modal.open_search import MIN_GAIN
from momentid.diagnosis.result import Diagnosis, Evidence
from momentid.diagnosis.thresholds import EXCESS, EXPLAINED
from momentid.diagnosis.verdict import Verdict
from momentid.mechanisms.place import location_words

if TYPE_CHECKING:
    from momentid.diagnosis.modal.check import AmplitudeModel
    from momentid.diagnosis.modal.open_search import ModalDiscovery

__all__ = ["ModalEvidence", "summary"]


@dataclass(frozen=True)
class ModalEvidence(Evidence):
    """What a diagnosis of accelerometer-only recordings (no added mass) shows beside its verdict.

    Attributes
    ----------
    channel_nrmse : dict
        Per floor sensor: held-out NRMSE before and after.
    training : dict
        The pooled modal model of the training runs: modes, damping, sensor gains and clock offsets.
    candidate : dict
        The amplitude model tried: its trend, its prediction for the held-out run, the share explained.
    findings : tuple of str
        Sensor findings and the recording's stated limits.
    trend : AmplitudeModel or None
        The fitted amplitude model (None when it could not be fitted).
    amplitude : float or None
        The held-out run's response amplitude (m/s^2).
    searched : bool
        Whether the open search ran (a run held out, a mismatch, at least two training runs).
    """

    channel_nrmse: dict
    training: dict
    candidate: dict
    findings: tuple[str, ...]
    trend: AmplitudeModel | None = None
    amplitude: float | None = None
    searched: bool = False

    def to_dict(self) -> dict:
        """The modal path's entries of ``report.json``: channel NRMSE, training, candidate, findings."""
        return {"channel_nrmse": self.channel_nrmse, "training": self.training, "candidate": self.candidate,
                "findings": list(self.findings), "path": "modal (no added mass)"}

    def words(self, diag: Diagnosis) -> str:
        """The report's text: :func:`summary` of ``diag``."""
        return summary(diag)

    def plot_replay(self, diag: Diagnosis, path: Path) -> None:
        """``replay.png``: :func:`momentid.diagnosis.figures.plot_replay`."""
        figures.plot_replay(diag, path)


def summary(diag: Diagnosis) -> str:
    """The report's text of a diagnosis without added mass: the linear modal model's held-out misfit
    against noise, the amplitude model and the verdict, the sensor findings, and the open search."""
    evidence = diag.evidence
    lines = _summary_lines(diag.verdict, diag.location, diag.held_out, diag.nrmse_before, diag.nrmse_after,
                           diag.noise_nrmse, evidence.candidate["explained"], evidence.trend, evidence.amplitude,
                           evidence.findings)
    if evidence.searched:
        lines.append(_open_search_line(diag.discovered))
    return "\n".join(lines)


def _summary_lines(verdict, location, held, before, after, noise, explained, trend, amplitude, findings) -> list[str]:
    lines = [f"Held-out run {held}: floor-acceleration NRMSE of the linear modal model {100 * before:.2f} % "
             f"({before / noise:.1f} x the {100 * noise:.2f} % noise alone leaves)."]
    if trend is not None:
        slopes = ", ".join(f"mode {i + 1} {f:+.3g} +- {fs:.2g} Hz and {100 * z:+.3g} +- {100 * zs:.2g} % damping"
                           for i, (f, fs, z, zs) in enumerate(zip(trend.frequency_coef[:, 1], trend.frequency_slope_std,
                                                                  trend.damping_coef[:, 1], trend.damping_slope_std)))
        lines.append(f"Amplitude dependence fitted on the training runs (per m/s^2 of response): {slopes}; "
                     f"held-out NRMSE {100 * before:.2f} % -> {100 * after:.2f} % "
                     f"({100 * explained:.0f} % of the misfit above noise removed, {100 * EXPLAINED:.0f} % needed).")
        if not trend.amplitude_range[0] <= amplitude <= trend.amplitude_range[1]:
            lines.append(f"WARNING: the held-out run's response amplitude ({amplitude:.3g} m/s^2) is outside the "
                         f"training runs' ({trend.amplitude_range[0]:.3g}-{trend.amplitude_range[1]:.3g} m/s^2): "
                         f"the amplitude model extrapolates.")
    else:
        lines.append("Amplitude dependence not tested: it needs at least two training runs of different amplitudes.")
    if verdict is Verdict.NONE:
        lines.append(f"No missing physics: the linear modal model explains the held-out run to within "
                     f"{EXCESS:g} x the noise level.")
    elif verdict is Verdict.MECHANISM:
        lines.append(f"Verdict: amplitude dependence (modes shift with the response amplitude); the held-out misfit "
                     f"left is largest at {location_words(location)}.")
        if after > EXCESS * noise:
            lines.append(f"WARNING: amplitude dependence explains only part of the mismatch: the held-out NRMSE is "
                         f"still {100 * after:.2f} % ({after / noise:.1f} x noise); the rest is unexplained.")
    else:
        lines.append(f"Verdict: unexplained mismatch at {location_words(location)} (the worst floor sensor, and the "
                     f"band around that mode holding that share of its residual power).")
    lines += [f"Finding: {f}" for f in findings]
    return lines


def _open_search_line(discovered: ModalDiscovery | None) -> str:
    """One line: what the open search found on the misfit's mode, and whether it beats the linear model."""
    if discovered is None:
        return (f"Open search: on no mode does a term of the function library earn its place (lower the "
                f"leave-one-run-out equation error by {100 * MIN_GAIN:.0f} %, a dissipative term staying "
                f"dissipative): nothing beyond the linear model.")
    training = discovered.checks["training_nrmse"]
    numbers = (f"held-out NRMSE {100 * discovered.nrmse_before:.2f} % -> {100 * discovered.nrmse_after:.2f} % "
               f"(the linear model refitted on the training runs the same way: "
               f"{100 * discovered.checks['held_out_nrmse_linear_refitted']:.2f} %; training runs "
               f"{100 * training['linear']:.2f} % -> {100 * training['law']:.2f} %, refitted linear "
               f"{100 * training['linear (refitted)']:.2f} %)")
    if discovered.beats_linear:
        return (f"Open search: {discovered.description}; {numbers}: it beats the linear model on the held-out run "
                f"(a data-driven law, not a named mechanism; the verdict is unchanged).")
    return (f"Open search: {discovered.description}; {numbers}: it does NOT beat the linear model on the held-out "
            f"run (the verdict is unchanged).")
