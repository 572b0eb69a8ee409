"""File formats: strict TOML, MCAP recordings, and lab exports to import.

- :mod:`~momentid.io.toml_reader`: TOML with one-line errors naming file, key and value.
- :mod:`~momentid.io.recording`: the MCAP recording format: writing; reading, streaming and recovery in
  :mod:`~momentid.io.recording_reader`, record names and the sensor-block schema in
  :mod:`~momentid.io.recording_format`.
- :mod:`~momentid.io.importer`: a lab folder (``experiment.toml`` plus its data files) to a recording.
- :mod:`~momentid.io.formats`: the export formats the importer reads (one module each, a registry).
- :mod:`~momentid.io.align`: one file per sensor -> one run (clocks, shaking axis, sign, gravity).
- :mod:`~momentid.io.rate`: is the sample rate high enough for the modes?
- :mod:`~momentid.io.structure_table`: the one parser of ``[structure]`` (scenarios and imports).
"""

from momentid.io.recording import RecordingWriter, read_recording, write_experiment
from momentid.io.importer import import_folder, import_recording

__all__ = ["RecordingWriter", "read_recording", "write_experiment", "import_folder", "import_recording"]
