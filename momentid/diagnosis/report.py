"""Stage 7 of the diagnosis: the summary of a :class:`~momentid.diagnosis.result.Diagnosis` and its
report folder."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from momentid import mechanisms
from momentid.core.series import json_safe
from momentid.diagnosis.discovery import plot_discovered
from momentid.diagnosis.modal_discovery import ModalDiscovery, plot_modal_discovered
from momentid.diagnosis.result import AddedMassEvidence, Diagnosis, TwinEvidence
from momentid.diagnosis.thresholds import EXCESS, EXPLAINED
from momentid.diagnosis.verdict import Verdict
from momentid.io.outputs import OwnedFolder
from momentid.mechanisms.place import Place, location_words

__all__ = ["summary", "write_report", "report_folder", "REPORT_FILES"]


def summary(diag: Diagnosis) -> str:
    """The report's text: for a rig identified with added masses, residuals vs. noise, where, the
    sensor check, the verdict, the replay and the open search's force; for accelerometer-only
    recordings, :func:`momentid.diagnosis.twin_words.summary` (on the twin) or
    :func:`momentid.diagnosis.real.summary`.  A compound diagnosis names every mechanism,
    one sentence each."""
    evidence = diag.evidence
    if isinstance(evidence, TwinEvidence):
        from momentid.diagnosis.twin_words import summary as twin_summary
        return twin_summary(diag)
    if not isinstance(evidence, AddedMassEvidence):
        from momentid.diagnosis.real import summary as modal_summary
        return modal_summary(diag)
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
                     f"{part.candidate.mechanism.replace('_', ' ')} at {location_words(part.candidate.location)}, removes "
                     f"only {100 * max(selection.explained, 0):.0f} % of the training runs' misfit above noise "
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


#: Every file a report folder may hold (checked against the folder before the diagnosis runs).
REPORT_FILES = ("report.json", "summary.txt", "twin.xml", "model_augmented.xml", "replay.png", "diagnosis.rrd",
                "locate.png", "discovered.png", "report.html")


def report_folder(folder, *, force: bool = False) -> OwnedFolder:
    """The report folder under the one output rule (:mod:`momentid.io.outputs`)."""
    return OwnedFolder(folder, "diagnose", force=force)


def write_report(diag: Diagnosis, folder, *, force: bool = False, extra=None) -> tuple[str, ...]:
    """Write the report folder; returns the names of the files written, in this order:
    ``report.json``, ``summary.txt``, ``twin.xml`` (the linear twin, on the twin path),
    ``model_augmented.xml`` (when there is an augmented model), ``replay.png`` (recorded vs. linear vs.
    augmented) and ``diagnosis.rrd`` (the same for ``rerun``), ``locate.png`` (where the mismatch is,
    added-mass path) and ``discovered.png`` (the open search's force, when it found one).

    The folder follows the one output rule (:class:`momentid.io.outputs.OwnedFolder`): every file is
    built before any is put in place; files of these names that ``momentid diagnose`` did not write
    (the user's, a twin's) are refused unless ``force``; this command's files of an earlier report
    that the new one does not write (a stale ``discovered.png``) are removed; other files are left
    alone.  ``extra(staging)`` writes more files beside them (the report page of :mod:`momentid.report`,
    which this layer does not import) and returns their names."""
    def files(staging):
        return _write_files(diag, staging) + (list(extra(staging)) if extra is not None else [])

    return tuple(report_folder(folder, force=force).write(files))


def _write_files(diag: Diagnosis, folder: Path) -> list[str]:
    (folder / "report.json").write_text(json.dumps(json_safe(diag.to_dict()), indent=2))
    (folder / "summary.txt").write_text(diag.summary + "\n")
    written = ["report.json", "summary.txt"]
    twin = isinstance(diag.evidence, TwinEvidence)
    if twin:
        (folder / "twin.xml").write_text(diag.evidence.twin_xml)
        written.append("twin.xml")
    if diag.augmented_xml:
        (folder / "model_augmented.xml").write_text(diag.augmented_xml)
        written.append("model_augmented.xml")
    if diag.curves:
        if twin:
            from momentid.diagnosis.twin_words import plot_replay
            plot_replay(diag, folder / "replay.png")
        else:
            _plots(diag, folder)
        _rerun(diag, folder / "diagnosis.rrd")
        written += ["replay.png", "diagnosis.rrd"]
    if isinstance(diag.evidence, AddedMassEvidence):
        from momentid.diagnosis.locate import plot_localisation
        plot_localisation(diag.evidence.localisation.to_dict(), folder / "locate.png")
        written.append("locate.png")
    if diag.discovered is not None:
        plot = plot_modal_discovered if isinstance(diag.discovered, ModalDiscovery) else plot_discovered
        plot(diag.discovered, folder / "discovered.png")
        written.append("discovered.png")
    return written


def _rerun(diag: Diagnosis, path: Path) -> None:
    """Recorded, linear-model and augmented-model responses overlaid, for ``rerun diagnosis.rrd``."""
    import rerun as rr
    import rerun.blueprint as rrb

    c = diag.curves
    rec = rr.RecordingStream("momentid_diagnosis")
    views = []
    time = rr.TimeColumn("time", duration=np.asarray(c["time"], float))
    styles = {"recorded": [20, 20, 20], "linear": [31, 119, 180], "augmented": [214, 39, 40]}
    for g, unit in (("a", "m/s^2"), ("q", "m")):
        if g not in c["measured"]:
            continue
        for j in range(c["measured"][g].shape[1]):
            base = f"/{g}{j + 1}"
            for label, data in (("recorded", c["measured"]), ("linear", c["linear"]), ("augmented", c["augmented"])):
                entity = f"{base}/{label}"
                rec.log(entity, rr.SeriesLines(colors=[styles[label]], names=[f"{g}{j + 1} {label} ({unit})"]),
                        static=True)
                rec.send_columns(entity, indexes=[time], columns=rr.Scalars.columns(scalars=data[g][:, j]))
            views.append(rrb.TimeSeriesView(origin=base, name=f"{g}{j + 1} ({unit})"))
    rec.log("/report", rr.TextDocument(diag.summary.replace("\n", "\n\n"), media_type=rr.MediaType.MARKDOWN), static=True)
    layout = rrb.Horizontal(rrb.Grid(*views), rrb.TextDocumentView(origin="/report", name="diagnosis"),
                            column_shares=[3, 1])
    rec.save(str(path), default_blueprint=rrb.Blueprint(layout))
    rec.flush()


def _plots(diag: Diagnosis, folder: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = diag.curves
    t = c["time"]
    g = "q" if "q" in c["measured"] else "a"
    d = c["measured"][g].shape[1]
    fig, axes = plt.subplots(d, 2, figsize=(12, 2.4 * d), squeeze=False, sharex=True)
    unit = "m" if g == "q" else "m/s^2"
    for j in range(d):
        m, lin, aug = c["measured"][g][:, j], c["linear"][g][:, j], c["augmented"][g][:, j]
        ax = axes[j, 0]
        ax.plot(t, m, "k", lw=0.8, label="recorded")
        ax.plot(t, lin, "C0", lw=0.8, label="linear model")
        ax.plot(t, aug, "C3--", lw=0.8, label="augmented model")
        ax.set_ylabel(f"{g}{j + 1} ({unit})")
        ax = axes[j, 1]
        ax.plot(t, m - lin, "C0", lw=0.6, label="residual, linear")
        ax.plot(t, m - aug, "C3", lw=0.6, label="residual, augmented")
        ax.set_ylabel(f"{g}{j + 1} residual ({unit})")
    axes[0, 0].legend(fontsize=7)
    axes[0, 1].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    fig.suptitle(f"{diag.mechanism.replace('_', ' ')} at {location_words(diag.location)}: held-out NRMSE "
                 f"{100 * diag.nrmse_before:.2f} % -> {100 * diag.nrmse_after:.2f} %")
    fig.tight_layout()
    fig.savefig(folder / "replay.png", dpi=90)
    plt.close(fig)
