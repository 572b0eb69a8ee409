"""Reports for people: the rerun viewer of recordings and identifications, and one self-contained HTML
page per result.

- :mod:`~momentid.report.viewer`: :func:`view` builds a ``.rrd`` with a blueprint.
- :mod:`~momentid.report.scene`: what is shown (identification, residuals, reconstructed
  displacements, exaggeration), computed without rerun.
- :mod:`~momentid.report.panels`: the text panels (parameters, modes, experiment) as markdown.
- :mod:`~momentid.report.page`: ``report.html``'s builder (answer, tables, figures, provenance);
  :mod:`~momentid.report.identify_page`, :mod:`~momentid.report.twin_page`,
  :mod:`~momentid.report.diagnosis_page` fill it; :mod:`~momentid.report.figures` draws as SVG.
- :mod:`~momentid.report.exports`: ``modes.uff`` and ``frf.uff``; :mod:`~momentid.report.files`: the
  files ``identify``, ``twin`` and ``diagnose -o`` write (see docs/reports.md).
"""

from momentid.report.viewer import view

__all__ = ["view"]
