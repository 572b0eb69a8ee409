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

from momentid.core.analytic import Modes, modal_properties, rayleigh_coefficients, shear_stiffness
from momentid.estimation.comparison import Comparison, analytic_parameters, compare
from momentid.core.series import Experiment, RunData
from momentid.errors import (
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
from momentid.lab.excitation import GroundMotion, ground_motion, read_at2
from momentid.estimation.identification import Identification, identify
from momentid.lab.rig import build_spec, compile_model
from momentid.io.recording import RecordingWriter, read_recording, write_experiment
from momentid.core.structure import Structure
from momentid.lab.scenario import Scenario, default_scenario_path, load_scenario
from momentid.lab.simulation import run_experiment, simulate, simulate_run
from momentid.estimation.design import cramer_rao, plan
from momentid.diagnosis.pipeline import Diagnosis, diagnose
from momentid.io.importer import import_folder, import_recording

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
