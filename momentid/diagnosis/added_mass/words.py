"""What a diagnosis of a rig identified with added masses shows beside its verdict, and says in words."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from momentid import mechanisms
from momentid.diagnosis import figures
from momentid.diagnosis.result import Diagnosis, Evidence
from momentid.diagnosis.thresholds import EXCESS, EXPLAINED
from momentid.diagnosis.verdict import Verdict
from momentid.mechanisms.place import Place, location_words

if TYPE_CHECKING:
    from momentid.diagnosis.added_mass.locate import Localisation
    from momentid.diagnosis.added_mass.screening import Candidate
    from momentid.diagnosis.added_mass.selection import Selection

__all__ = ["AddedMassEvidence", "summary"]


@dataclass(frozen=True)
class AddedMassEvidence(Evidence):
    """What a diagnosis on an identified M, C, K (runs with added mass) shows beside its verdict.

    Attributes
    ----------
    run : str
        The run the before/after replay is shown on.
    held : bool
        Whether ``run`` was held out (with two runs there is none to hold out: the last is shown).
    excess_equation, excess_replay : dict
        Per floor: equation residual RMS over the noise-only RMS; per channel: replay residual over noise.
    candidates : tuple of Candidate
        The best screened candidates, best first.
    parameter_pattern : dict
        The damping-pattern fits of the identified C.
    sensor_check : dict
        The kinematic check ``a_j = zdd + q_j''``: excess per floor, the best fits.
    selection : Selection
        What stage 6 (and a compound diagnosis) re-simulated and why it decided.
    localisation : Localisation
        Where the mismatch is: storey, runs, time windows, amplitude, bands, shape, in words.
    """

    run: str
    held: bool
    excess_equation: dict
    excess_replay: dict
    candidates: tuple[Candidate, ...]
    parameter_pattern: dict
    sensor_check: dict
    selection: Selection
    localisation: Localisation

    def to_dict(self) -> dict:
        """The added-mass path's entries of ``report.json``: excesses, sensor check, selection, localisation,
        candidates.
        """
        return {"excess_equation": self.excess_equation, "excess_replay": self.excess_replay,
                "parameter_pattern": self.parameter_pattern, "sensor_check": self.sensor_check,
                "selection": self.selection.to_dict(), "localisation": self.localisation.to_dict(),
                "candidates": [c.to_dict() for c in self.candidates], "path": "added mass"}

    def words(self, diag: Diagnosis) -> str:
        """The report's text: :func:`summary` of ``diag``."""
        return summary(diag)

    def plot_replay(self, diag: Diagnosis, path: Path) -> None:
        """``replay.png``: :func:`momentid.diagnosis.figures.plot_replay`."""
        figures.plot_replay(diag, path)

    def figures(self, diag: Diagnosis, folder: Path) -> list[str]:
        """``locate.png``: where the mismatch is
        (:func:`~momentid.diagnosis.added_mass.locate.plot_localisation`)."""
        from momentid.diagnosis.added_mass.locate import plot_localisation
        plot_localisation(self.localisation.to_dict(), folder / "locate.png")
        return ["locate.png"]


def summary(diag: Diagnosis) -> str:
    """The report's text of a rig identified with added masses: residuals vs. noise, where, the sensor
    check, the verdict, the replay and the open search's force.  A compound diagnosis names every
    mechanism, one sentence each."""
    evidence = diag.evidence
    excess_eq, excess_rep, selection = evidence.excess_equation, evidence.excess_replay, evidence.selection
    worst = max(excess_eq, key=excess_eq.get)
    lines = ["Equation residual vs. noise: " + ", ".join(f"{k} {v:.2f}x" for k, v in excess_eq.items()) + ".",
             "Replay residual vs. noise: " + ", ".join(f"{k} {v:.2f}x" for k, v in excess_rep.items()) + "."]
    if max(excess_eq.values()) > EXCESS:
        lines.append(evidence.localisation.words)
    if evidence.sensor_check:
        check = evidence.sensor_check
        verdict = "consistent" if check["consistent"] else "INCONSISTENT"
        lines.append("Sensors against each other (a = zdd + q''): " + ", ".join(
            f"{k} {v:.2f}x" for k, v in check["excess"].items()) + f" of noise ({verdict}).")
    loc = diag.location
    if diag.verdict is Verdict.NONE:
        lines.append("No missing physics: the linear model explains the recordings to the noise level.")
    elif diag.verdict is Verdict.UNEXPLAINED and selection.outside_library is not None:
        out = selection.outside_library
        lines.append(f"Unexplained by the library at {location_words(loc)}: its best model, "
                     f"{out.mechanism.replace('_', ' ')} at {location_words(out.location)}, leaves training NRMSE "
                     f"{100 * out.named:.2f} % (noise alone {100 * out.noise:.2f} %); the force below, outside the "
                     f"library, {100 * out.discovered:.2f} %.")
    elif diag.verdict is Verdict.UNEXPLAINED and selection.partial is not None:
        part = selection.partial
        lines.append(f"Unexplained mismatch at {location_words(loc)}: the best candidate, "
                     f"{part.candidate.mechanism.replace('_', ' ')} at {location_words(part.candidate.location)}, "
                     f"removes only {100 * max(selection.explained, 0):.0f} % of the training runs' misfit above noise "
                     f"(NRMSE {100 * selection.linear:.2f} % -> {100 * selection.augmented:.2f} %, noise alone "
                     f"{100 * selection.noise:.2f} %); the model is left linear.")
    elif diag.verdict is Verdict.UNEXPLAINED:
        lines.append(f"Unexplained mismatch at {location_words(loc)} (largest at {worst}); no candidate mechanism "
                     f"explains at least {int(EXPLAINED * 100)} % of it.")
    else:
        if len(diag.mechanisms) > 1:
            lines.append(f"{len(diag.mechanisms)} mechanisms together, refitted jointly in one model (the primary "
                         f"first):")
        for n in diag.mechanisms:
            kind = mechanisms.get(n.mechanism)
            line = kind.describe(Place.at(kind.target, n.location), n.parameters, n.std)
            lines.append("  " + line if len(diag.mechanisms) > 1 else line)
    before, after, discovered = diag.nrmse_before, diag.nrmse_after, diag.discovered
    which = f"held-out run {evidence.run}" if evidence.held else f"run {evidence.run}"
    if math.isfinite(before):
        lines.append(f"{which} NRMSE {100 * before:.2f} % -> {100 * after:.2f} %.")
    if discovered is not None:
        lines.append(f"{discovered.description} With it, {which} NRMSE {100 * discovered.nrmse_before:.2f} % -> "
                     f"{100 * discovered.nrmse_after:.2f} % (a data-driven model, not a named mechanism).")
    elif diag.verdict is Verdict.UNEXPLAINED and math.isfinite(before):
        lines.append("Open search: no force from the function library lowers the held-out misfit enough to report.")
    return "\n".join(lines)
