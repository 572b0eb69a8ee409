"""The one exception hierarchy of momentid.

Every error a user can cause derives from :class:`MomentidError`; the CLI
prints ``error: <message>`` for these and exits non-zero.  Messages name the
file, key and value involved and say what was expected.
"""

from __future__ import annotations

__all__ = [
    "MomentidError",
    "ScenarioError",
    "ModelError",
    "SimulationError",
    "RecordingError",
    "TruncatedRecordingError",
    "IdentificationError",
    "SensorDataError",
    "ViewerError",
    "ResourceError",
    "TimeLimitError",
    "OutputBusyError",
    "OutputRefusedError",
    "RecoveryWarning",
]


class MomentidError(Exception):
    """Base class of every error momentid raises on purpose."""


class ScenarioError(MomentidError, ValueError):
    """A scenario or experiment description is invalid (file, key, value)."""


class ModelError(MomentidError):
    """The MuJoCo model could not be built or compiled."""


class SimulationError(MomentidError):
    """A simulation diverged or produced MuJoCo warnings."""


class RecordingError(MomentidError):
    """A recording could not be written or read."""


class TruncatedRecordingError(RecordingError):
    """A recording ended early and no completed run could be recovered."""


class IdentificationError(MomentidError):
    """The data cannot identify the unknowns (rank, conditioning, input)."""


class SensorDataError(MomentidError):
    """Sensor data are unusable as given (NaN, gaps, clipping, missing channel)."""


class ViewerError(MomentidError):
    """The rerun viewer could not be started or fed."""


class ResourceError(MomentidError):
    """A job would not fit the machine; estimated before the work starts.

    Attributes
    ----------
    what : str
        The job (``"simulation of scenario 'x'"``).
    needed, available : float
        Estimated and available bytes of memory.
    hint : str
        What would fit (a shorter record, fewer storeys, ``--stream``).
    """

    def __init__(self, what: str, needed: float, available: float, hint: str):
        self.what, self.needed, self.available, self.hint = what, needed, available, hint
        super().__init__(f"{what} needs about {_size(needed)} of memory, {_size(available)} is available: "
                         f"refused before starting; {hint}")


class TimeLimitError(ResourceError):
    """A job would run longer than its time limit; estimated (from a measured part of it) before
    the rest starts.  ``needed`` and ``available`` are seconds here."""

    def __init__(self, what: str, needed: float, available: float, hint: str):
        self.what, self.needed, self.available, self.hint = what, needed, available, hint
        MomentidError.__init__(self, f"{what} would take about {_duration(needed)} on this machine, the limit is "
                                     f"{_duration(available)}: refused before starting; {hint}")


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def _size(nbytes: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(nbytes) < 1000 or unit == "PB":
            return f"{nbytes:.3g} {unit}"
        nbytes /= 1000
    return f"{nbytes:.3g} PB"


class OutputBusyError(MomentidError):
    """Another process is writing the same output (file or folder) now: one writer per output."""


class OutputRefusedError(MomentidError):
    """An output path the command must not write: another kind of file, a file the command did not
    write, a symbolic link, or a place it cannot write.

    Parameters
    ----------
    option : str
        The option as the user gave it (``-o``, ``--save``).
    path : str
        The path the user gave, or a file inside the folder they gave.
    found : str
        What stands there.
    expected : str
        What was expected (and how to proceed).
    """

    def __init__(self, option: str, path: str, found: str, expected: str):
        self.option, self.path, self.found, self.expected = option, str(path), found, expected
        super().__init__(f"{option} {path}: {found}; expected {expected}")


class RecoveryWarning(UserWarning):
    """Data were recovered from a damaged input; the message says what was kept and what was lost.

    The same text is in the result's ``notes``; the CLI prints it as one ``note:`` line.
    """
