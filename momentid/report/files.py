"""The report files of ``identify -o``, ``twin -o`` and ``diagnose -o``: ``report.html`` (and for an
identification ``modes.uff``, ``frf.uff`` and ``identification.json``).

Writing a report never fails the command: :func:`report_html` puts a page together section by
section (a table or figure that cannot be made becomes a note in the page, :class:`~momentid.report.page.Page`),
and should the page itself fail, a page saying why takes its place.  Each file is written through a
temporary file renamed into place (:func:`~momentid.report.page.write_text_atomic`).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path

from momentid.core.series import json_safe
from momentid.errors import MomentidError
from momentid.report.page import Page, Provenance, missing_note, write_text_atomic

__all__ = ["report_html", "identification_html_page", "twin_html_page", "diagnosis_html_page", "write_identification",
           "REPORT_HTML", "MODES_UFF", "FRF_UFF", "IDENTIFICATION_JSON"]

REPORT_HTML, MODES_UFF, FRF_UFF, IDENTIFICATION_JSON = "report.html", "modes.uff", "frf.uff", "identification.json"


def report_html(build: Callable[[], Page], title: str, made: Provenance) -> str:
    """The HTML of the page ``build()`` returns; when that fails, a page with ``title`` that says why."""
    try:
        return build().html()
    except Exception as exc:   # a report never fails the command: the reason goes on the page
        page = Page(title, "The report could not be put together; the command's other outputs are complete.", made)
        page.answer(missing_note("the report", exc))
        return page.html()


def identification_html_page(result, experiment, made: Provenance, *, comparison=None, trend=None) -> str:
    """``report.html`` of an identification (:func:`momentid.report.identify_page.identification_page`)."""
    from momentid.report.identify_page import identification_page
    return report_html(lambda: identification_page(result, experiment, made, comparison=comparison, trend=trend),
                       f"Identification of {experiment.name}", made)


def twin_html_page(twin, experiment, made: Provenance) -> str:
    """``report.html`` of a twin (:func:`momentid.report.twin_page.twin_page`)."""
    from momentid.report.twin_page import twin_page
    return report_html(lambda: twin_page(twin, experiment, made), f"Twin of {experiment.name}", made)


def diagnosis_html_page(diag, made: Provenance, source: str) -> str:
    """``report.html`` of a diagnosis (:func:`momentid.report.diagnosis_page.diagnosis_page`)."""
    from momentid.report.diagnosis_page import diagnosis_page
    return report_html(lambda: diagnosis_page(diag, made, source), f"Diagnosis of {source}", made)


def write_identification(folder, result, experiment, payload: dict, made: Provenance, *, comparison=None,
                         trend=None) -> list:
    """Write an identification's folder: ``identification.json`` (``payload``, what ``--json`` prints),
    ``report.html``, ``modes.uff`` and ``frf.uff`` (:mod:`momentid.report.exports`).

    Parameters
    ----------
    folder : str or Path
        Created when missing; files of other names in it are left alone.
    result : ModalIdentification, Identification or tuple of ModalIdentification (one per run)
    experiment : Experiment
    payload : dict
    made : Provenance
    comparison : Comparison, optional
    trend : AmplitudeTrend, optional

    Returns
    -------
    list of str
        The file names written.  A UFF file that cannot be written (a value that is not finite, runs
        without the table and floor sensors) is left out with a ``warning:`` line on stderr.
    """
    from momentid.report.exports import frf_uff, modes_uff

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_text_atomic(folder / IDENTIFICATION_JSON, json.dumps(json_safe(payload), indent=2, allow_nan=False) + "\n")
    written = [IDENTIFICATION_JSON]
    write_text_atomic(folder / REPORT_HTML, identification_html_page(result, experiment, made, comparison=comparison,
                                                                     trend=trend))
    written.append(REPORT_HTML)
    runs = [r.runs[0] for r in result] if isinstance(result, tuple) else list(result.runs)
    for name, build in ((MODES_UFF, lambda: modes_uff(result, experiment)), (FRF_UFF, lambda: frf_uff(experiment, runs))):
        try:
            text = build()
        except MomentidError as exc:
            print(f"warning: {folder / name} not written: {exc}", file=sys.stderr)
            continue
        write_text_atomic(folder / name, text)
        written.append(name)
    return written
