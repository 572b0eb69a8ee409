"""Reports for people: the rerun viewer of recordings and identifications.

- :mod:`~momentid.report.viewer`: :func:`view` builds a ``.rrd`` with a blueprint.
- :mod:`~momentid.report.scene`: what is shown (identification, residuals, reconstructed
  displacements, exaggeration), computed without rerun.
- :mod:`~momentid.report.panels`: the text panels (parameters, modes, experiment) as markdown.
"""

from momentid.report.viewer import view

__all__ = ["view"]
