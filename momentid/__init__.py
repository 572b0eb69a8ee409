"""momentid: a virtual shake-table laboratory.

Identify the mass, damping and stiffness matrices of a shear building from
added-mass shake-table runs (Majcher 2025, input-output method with system
momentum change), with MuJoCo standing in for the rig::

    import momentid as mi
    scenario = mi.load_scenario("scenarios/paper_harmonic.toml")
    mi.run_experiment(scenario, "out/paper_harmonic.mcap")      # simulate + record
    experiment = mi.read_recording("out/paper_harmonic.mcap")   # read it back
    result = mi.identify(experiment)                            # M, C, K, mu, kappa
    print(mi.compare(result, experiment.structure).table())     # vs. the analytic model

One module per pipeline stage: ``scenario`` (files), ``excitation`` (table
motion), ``model`` (MJCF rig), ``simulate``, ``recording`` (MCAP),
``identify`` (with ``reconstruct``, ``linear``, ``eiv``), ``analytic`` and
``compare``, ``design`` (Cramér-Rao bounds), ``discrepancy`` (missing
physics), ``importer`` (CSV folders), ``visualize`` (rerun), ``cli``.
"""

from .analytic import Modes, modal_properties, rayleigh_coefficients, shear_stiffness
from .compare import Comparison, analytic_parameters, compare
from .data import Experiment, RunData
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
from .excitation import GroundMotion, ground_motion, read_at2
from .identify import Identification, identify
from .model import build_spec, compile_model
from .recording import RecordingWriter, read_recording, write_experiment
from .scenario import Scenario, Structure, default_scenario_path, load_scenario
from .simulate import run_experiment, simulate, simulate_run
from .design import cramer_rao, plan
from .discrepancy import Diagnosis, diagnose
from .importer import import_folder, import_recording

__version__ = "0.1.0"

__all__ = [
    "Comparison", "Experiment", "GroundMotion", "Identification", "Modes", "RunData", "Scenario",
    "Structure", "RecordingWriter",
    "analytic_parameters", "build_spec", "compare", "compile_model", "default_scenario_path",
    "ground_motion", "identify", "load_scenario", "modal_properties", "rayleigh_coefficients",
    "read_at2", "read_recording", "run_experiment", "shear_stiffness", "simulate", "simulate_run",
    "write_experiment", "cramer_rao", "plan", "Diagnosis", "diagnose", "import_folder", "import_recording",
    "MomentidError", "ScenarioError", "ModelError", "SimulationError", "RecordingError",
    "TruncatedRecordingError", "IdentificationError", "SensorDataError", "ViewerError",
]
