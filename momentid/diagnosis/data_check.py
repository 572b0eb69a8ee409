"""What the recorded channels show by themselves, with no model: the diagnosis's first look.

A sensor-fault kind may say what a recorded channel shows of it alone
(:meth:`~momentid.mechanisms.base.SensorFault.inspect`): a saturation's flat runs at the channel's
extreme.  Such a finding needs no model, and it spoils every model-based stage (an identification refuses
a clipped channel, :func:`momentid.io.run_checks.check_run`): :func:`diagnose_data` names it at its
channel, with its parameters as the recording holds them, and checks it on the last run by replaying the
lab's nominal model (the recording's statement) with and without the fault applied to the model's reading.
The data checks report what they find as candidates the diagnosis names, not only as refusals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from momentid import mechanisms
from momentid.core.series import Experiment, channel_unit
from momentid.diagnosis import figures
from momentid.diagnosis.added_mass.augmented import measured_groups
from momentid.diagnosis.added_mass.residuals import nrmse
from momentid.diagnosis.result import Diagnosis, Evidence
from momentid.diagnosis.verdict import Named, Verdict
from momentid.errors import SimulationError
from momentid.estimation.reconstruct import Prefilter
from momentid.mechanisms.place import Place, Target

__all__ = ["DataEvidence", "Finding", "inspect_channels", "diagnose_data"]


@dataclass(frozen=True)
class Finding:
    """One fault a recorded channel shows by itself: its kind, its channel, its parameters (from the
    run where it holds most samples), the share of the channel's samples it holds over every run, and the
    runs it is in."""

    kind: object
    place: Place
    parameters: dict
    share: float
    runs: tuple[str, ...]

    def to_dict(self) -> dict:
        """The finding as ``report.json`` lists it."""
        return {"mechanism": self.kind.name, "location": self.place.location, "parameters": self.parameters,
                "share": self.share, "runs": list(self.runs)}


@dataclass(frozen=True)
class DataEvidence(Evidence):
    """What the diagnosis shows when the recorded channels name a fault by themselves."""

    findings: tuple[Finding, ...]
    run: str

    def words(self, diag: Diagnosis) -> str:
        """Per finding: the fault the channel shows, its size and share of the samples; then why the model-based
        stages did not run, and the nominal model's replay with the fault.
        """
        lines = []
        for f in self.findings:
            unit = f.kind.fitted.unit if f.kind.fitted.unit != "channel unit" else channel_unit(f.place.index)
            value = ", ".join(f"{k} = {v:.6g}" for k, v in f.parameters.items())
            lines.append(f"Channel {f.place.index} shows a {f.kind.name.replace('_', ' ')} by itself ({value} {unit}; "
                         f"{100 * f.share:.2f} % of its samples, in runs {', '.join(f.runs)}).")
            lines.append(f.kind.describe(f.place, f.parameters, {}))
        lines.append("The model-based stages need channels without it: they did not run (re-record with a larger "
                     "range, or drop the channel).")
        if math.isfinite(diag.nrmse_before):
            lines.append(f"Run {self.run} through the lab's nominal model: NRMSE {100 * diag.nrmse_before:.2f} % -> "
                         f"{100 * diag.nrmse_after:.2f} % with the fault on its reading.")
        return "\n".join(lines)

    def plot_replay(self, diag: Diagnosis, path: Path) -> None:
        """``replay.png``: :func:`momentid.diagnosis.figures.plot_replay`."""
        figures.plot_replay(diag, path)

    def to_dict(self) -> dict:
        """The findings, as ``report.json`` lists them."""
        return {"findings": [f.to_dict() for f in self.findings], "path": "data check"}


def inspect_channels(experiment: Experiment) -> tuple[Finding, ...]:
    """Every fault a sensor-fault kind of the library finds in a recorded channel by itself."""
    out = []
    kinds = [k for k in mechanisms.library() if k.target is Target.CHANNEL]
    channels = [c for c in experiment.runs[0].channels if all(r.has(c) for r in experiment.runs)]
    for kind in kinds:
        for channel in channels:
            seen = [(run, kind.inspect(run, channel)) for run in experiment.runs]
            seen = [(run, got) for run, got in seen if got is not None]
            if not seen:
                continue
            params = max(seen, key=lambda pair: pair[1][1])[1][0]
            held = sum(got[1] * run.n_samples for run, got in seen)
            share = held / sum(run.n_samples for run in experiment.runs)
            out.append(Finding(kind, Place(Target.CHANNEL, channel), params, float(share),
                               tuple(run.name for run, _ in seen)))
    return tuple(out)


def diagnose_data(experiment: Experiment) -> Diagnosis | None:
    """The diagnosis of a recording whose channels show a fault by themselves (:func:`inspect_channels`),
    or None when none does.

    Returns
    -------
    Diagnosis or None
        Verdict ``MECHANISM``, one named mechanism per finding (the first the primary); ``nrmse_before``
        and ``nrmse_after``: the last run replayed through the recording's nominal model without and with
        the faults on the model's reading (NaN without a nominal model); a :class:`DataEvidence`.
    """
    findings = inspect_channels(experiment)
    if not findings:
        return None
    run = experiment.runs[-1]
    before = after = float("nan")
    curves = {}
    if experiment.structure is not None:
        from momentid.lab.simulation import replay
        d = experiment.storeys
        measured = measured_groups(run, d)
        try:
            linear = replay(experiment.structure, (), run, run["zdd"])
        except SimulationError:
            linear = None
        if linear is not None and measured:
            read = {g: linear[g].copy() for g in measured}
            for f in findings:
                group, j = str(f.place.index)[0], str(f.place.index)[1:]
                if group in read and j.isdigit():
                    read[group][:, int(j) - 1] = f.kind.distort(run.time, read[group][:, int(j) - 1], f.parameters)
            band = Prefilter()
            before = nrmse(linear, measured, run.sample_rate, band)
            after = nrmse(read, measured, run.sample_rate, band)
            curves = {"time": run.time, "measured": measured, "linear": linear, "augmented": read}
    named = tuple(Named(f.kind.name, f.place.location, f.parameters, {}) for f in findings)
    first = findings[0]
    return Diagnosis(verdict=Verdict.MECHANISM, mechanism=first.kind.name, location=first.place.location,
                     parameters=first.parameters, std={}, mechanisms=named, held_out=f"{run.name} (nothing fitted)",
                     nrmse_before=before, nrmse_after=after, noise_nrmse=float("nan"),
                     evidence=DataEvidence(findings, run.name), curves=curves, notes=tuple(experiment.notes))
