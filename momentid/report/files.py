"""The report files of ``identify -o``, ``twin -o`` and ``diagnose -o``: ``report.html`` (and for an
identification ``modes.uff``, ``frf.uff`` and ``identification.json``).

Writing a report never fails the command: :func:`report_html` puts a page together section by
section (a table or figure that cannot be made becomes a note in the page, :class:`~momentid.report.page.Page`),
and should the page itself fail, a page saying why takes its place.  The identification's folder follows
the one output rule (:class:`~momentid.io.outputs.OwnedFolder`), like the twin's and the diagnosis's.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
import os
from pathlib import Path
from typing import TYPE_CHECKING

from momentid.core.series import json_safe
from momentid.errors import MomentidError
from momentid.io.outputs import OwnedFolder
from momentid.report.page import Page, Provenance, missing_note, write_text_atomic

if TYPE_CHECKING:
    from momentid.core.series import Experiment
    from momentid.diagnosis.result import Diagnosis
    from momentid.estimation.comparison import Comparison
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import AmplitudeTrend, ModalIdentification
    from momentid.twin.build import Twin

__all__ = ["report_html", "identification_html_page", "twin_html_page", "diagnosis_html_page", "write_identification",
           "identification_folder", "REPORT_HTML", "MODES_UFF", "FRF_UFF", "IDENTIFICATION_JSON",
           "IDENTIFICATION_FILES"]

REPORT_HTML, MODES_UFF, FRF_UFF, IDENTIFICATION_JSON = "report.html", "modes.uff", "frf.uff", "identification.json"
#: Every file an identification folder may hold (checked against the folder before the identification).
IDENTIFICATION_FILES = (IDENTIFICATION_JSON, REPORT_HTML, MODES_UFF, FRF_UFF)


def report_html(build: Callable[[], Page], title: str, made: Provenance) -> str:
    """The HTML of the page ``build()`` returns; when that fails, a page with ``title`` that says why."""
    try:
        return build().html()
    except Exception as exc:   # a report never fails the command: the reason goes on the page
        page = Page(title, "The report could not be put together; the command's other outputs are complete.", made)
        page.answer(missing_note("the report", exc))
        return page.html()


def identification_html_page(result: Identification | ModalIdentification | tuple[ModalIdentification, ...],
                             experiment: Experiment, made: Provenance, *,
                             comparison: Comparison | None = None, trend: AmplitudeTrend | None = None) -> str:
    """``report.html`` of an identification (:func:`momentid.report.identify_page.identification_page`)."""
    from momentid.report.identify_page import identification_page
    return report_html(lambda: identification_page(result, experiment, made, comparison=comparison, trend=trend),
                       f"Identification of {experiment.name}", made)


def twin_html_page(twin: Twin, experiment: Experiment, made: Provenance) -> str:
    """``report.html`` of a twin (:func:`momentid.report.twin_page.twin_page`)."""
    from momentid.report.twin_page import twin_page
    return report_html(lambda: twin_page(twin, experiment, made), f"Twin of {experiment.name}", made)


def diagnosis_html_page(diag: Diagnosis, made: Provenance, source: str) -> str:
    """``report.html`` of a diagnosis (:func:`momentid.report.diagnosis_page.diagnosis_page`)."""
    from momentid.report.diagnosis_page import diagnosis_page
    return report_html(lambda: diagnosis_page(diag, made, source), f"Diagnosis of {source}", made)


def identification_folder(folder: str | os.PathLike, *, force: bool = False) -> OwnedFolder:
    """The folder of ``identify -o`` under the one output rule (:mod:`momentid.io.outputs`)."""
    return OwnedFolder(folder, "identify", force=force)


def write_identification(folder: str | os.PathLike,
                         result: Identification | ModalIdentification | tuple[ModalIdentification, ...],
                         experiment: Experiment, payload: dict, made: Provenance, *,
                         comparison: Comparison | None = None, trend: AmplitudeTrend | None = None,
                         force: bool = False) -> list[str]:
    """Write an identification's folder: ``identification.json`` (``payload``, what ``--json`` prints),
    ``report.html``, ``modes.uff`` and ``frf.uff`` (:mod:`momentid.report.exports`).

    The folder follows the one output rule (:class:`~momentid.io.outputs.OwnedFolder`): every file is
    built before any is put in place; files of these names that ``momentid identify`` did not write
    (the user's ``report.html``, a diagnosis's) are refused unless ``force``; this command's files of an
    earlier identification that this one does not write (a ``modes.uff`` it cannot write now) are
    removed; other files are left alone.

    Parameters
    ----------
    folder : str or Path
        Created when missing.
    result : ModalIdentification, Identification or tuple of ModalIdentification (one per run)
    experiment : Experiment
    payload : dict
    made : Provenance
    comparison : Comparison, optional
    trend : AmplitudeTrend, optional
    force : bool
        Overwrite files of these names that ``momentid identify`` did not write.

    Returns
    -------
    list of str
        The file names written.  A UFF file that cannot be written (a value that is not finite, runs
        without the table and floor sensors) is left out with a ``warning:`` line on stderr.

    Raises
    ------
    OutputRefusedError
        See :meth:`~momentid.io.outputs.OwnedFolder.write`.
    """
    from momentid.report.exports import frf_uff, modes_uff

    folder = Path(folder)
    runs = [r.runs[0] for r in result] if isinstance(result, tuple) else list(result.runs)

    def build(staging: Path) -> list:
        text = json.dumps(json_safe(payload), indent=2, allow_nan=False) + "\n"
        write_text_atomic(staging / IDENTIFICATION_JSON, text)
        write_text_atomic(staging / REPORT_HTML, identification_html_page(result, experiment, made,
                                                                         comparison=comparison, trend=trend))
        written = [IDENTIFICATION_JSON, REPORT_HTML]
        for name, make in ((MODES_UFF, lambda: modes_uff(result, experiment)),
                           (FRF_UFF, lambda: frf_uff(experiment, runs))):
            try:
                text = make()
            except MomentidError as exc:
                print(f"warning: {folder / name} not written: {exc}", file=sys.stderr)
                continue
            write_text_atomic(staging / name, text)
            written.append(name)
        return written

    return identification_folder(folder, force=force).write(build)
