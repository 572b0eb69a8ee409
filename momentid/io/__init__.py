"""File formats: strict TOML, MCAP recordings, and lab exports to import.

- :mod:`~momentid.io.toml_reader`: TOML with one-line errors naming file, key and value.
- :mod:`~momentid.io.recording`: the MCAP recording format (write, read, stream, recover).
- :mod:`~momentid.io.importer`: a folder of lab CSV files plus ``experiment.toml`` to a recording.
"""

from momentid.io.recording import RecordingWriter, read_recording, write_experiment
from momentid.io.importer import import_folder, import_recording

__all__ = ["RecordingWriter", "read_recording", "write_experiment", "import_folder", "import_recording"]
