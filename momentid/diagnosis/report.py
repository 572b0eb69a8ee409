"""The report folder of a :class:`~momentid.diagnosis.result.Diagnosis`, whatever its path: the summary
and ``report.json``, the models, the replay (a figure and a rerun file), the path's own figures and the
open search's law.  What each holds is its evidence's (:class:`~momentid.diagnosis.result.Evidence`)."""

from __future__ import annotations

from collections.abc import Callable
import json
import os
from pathlib import Path

import numpy as np

from momentid.core.processes import run_forked
from momentid.core.series import json_safe
from momentid.diagnosis.result import Diagnosis
from momentid.io.outputs import OwnedFolder

__all__ = ["write_report", "report_folder", "REPORT_FILES"]


#: Every file a report folder may hold (checked against the folder before the diagnosis runs).
REPORT_FILES = ("report.json", "summary.txt", "twin.xml", "model_augmented.xml", "replay.png", "diagnosis.rrd",
                "locate.png", "discovered.png", "report.html")


def report_folder(folder: str | os.PathLike, *, force: bool = False) -> OwnedFolder:
    """The report folder under the one output rule (:mod:`momentid.io.outputs`)."""
    return OwnedFolder(folder, "diagnose", force=force)


def write_report(diag: Diagnosis, folder: str | os.PathLike, *, force: bool = False,
                 extra: Callable[[Path], list[str]] | None = None) -> tuple[str, ...]:
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
        # drawing is most of the time (matplotlib, rerun): the replay's files and the rest, side by side
        jobs = [lambda: _write_files(diag, staging), lambda: _write_figures(diag, staging, extra)]
        first, rest = run_forked(lambda job: job(), jobs)
        return first + rest

    return tuple(report_folder(folder, force=force).write(files))


def _write_files(diag: Diagnosis, folder: Path) -> list[str]:
    (folder / "report.json").write_text(json.dumps(json_safe(diag.to_dict()), indent=2))
    (folder / "summary.txt").write_text(diag.summary + "\n")
    written = ["report.json", "summary.txt"]
    for name, xml in diag.evidence.models().items():
        (folder / name).write_text(xml)
        written.append(name)
    if diag.augmented_xml:
        (folder / "model_augmented.xml").write_text(diag.augmented_xml)
        written.append("model_augmented.xml")
    if diag.curves:
        diag.evidence.plot_replay(diag, folder / "replay.png")
        _rerun(diag, folder / "diagnosis.rrd")
        written += ["replay.png", "diagnosis.rrd"]
    return written


def _write_figures(diag: Diagnosis, folder: Path, extra: Callable[[Path], list[str]] | None) -> list[str]:
    written = list(diag.evidence.figures(diag, folder))
    if diag.discovered is not None:
        diag.discovered.draw(folder / "discovered.png")
        written.append("discovered.png")
    return written + (list(extra(folder)) if extra is not None else [])


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
    rec.log("/report", rr.TextDocument(diag.summary.replace("\n", "\n\n"), media_type=rr.MediaType.MARKDOWN),
            static=True)
    layout = rrb.Horizontal(rrb.Grid(*views), rrb.TextDocumentView(origin="/report", name="diagnosis"),
                            column_shares=[3, 1])
    rec.save(str(path), default_blueprint=rrb.Blueprint(layout))
    rec.flush()
