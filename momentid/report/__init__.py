"""Reports for people: the rerun viewer of recordings and identifications.

- :mod:`~momentid.report.viewer`: :func:`view` builds a ``.rrd`` with a blueprint.
"""

from momentid.report.viewer import view

__all__ = ["view"]
