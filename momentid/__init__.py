"""momentid: a virtual shake-table laboratory (Majcher 2025 identification)."""

from .errors import (
    IdentificationError,
    MomentidError,
    ModelError,
    RecordingError,
    ScenarioError,
    SensorDataError,
    SimulationError,
    TruncatedRecordingError,
    ViewerError,
)
from .scenario import Scenario, Structure, load_scenario, default_scenario_path
from .data import Experiment, RunData

__version__ = "0.1.0"
