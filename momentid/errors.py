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
