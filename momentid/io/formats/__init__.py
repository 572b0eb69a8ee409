"""Lab export formats: one module per format, each declaring itself in :data:`FORMATS`.

A format is one of two layouts (:class:`Layout`):

* ``RUN_FILE``: one file per run already in momentid's channel vocabulary
  (``t, zdd, a1..ad``, ...), read by ``read_run(path, storeys)`` ->
  ``(time (n,), channels, values (n, c))``; the import takes it as it is.
* ``SENSOR_FILES``: one file per sensor per run in the sensor's own terms
  (device clock, three-axis specific force in the sensor frame, gravity
  included), read by ``read_sensor(path)`` -> :class:`SensorRecord`; the
  import aligns the sensors and finds each one's shaking axis
  (:mod:`momentid.io.align`).

A new instrument brand is one new module here that calls :func:`register`
and is imported at the bottom of this file.
"""

from momentid.io.formats.base import (FORMATS, MAX_ABS_SAMPLE, ExportFormat, Layout, SensorRecord, first_absurd,
                                      get_format, read_text, register)
from momentid.io.formats import csv_run, xsens_dot  # noqa: E402,F401  (they register themselves)

__all__ = ["Layout", "ExportFormat", "SensorRecord", "FORMATS", "register", "get_format", "read_text",
           "MAX_ABS_SAMPLE", "first_absurd"]
