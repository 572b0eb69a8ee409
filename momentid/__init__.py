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

Subpackages, each importable on its own:

- :mod:`momentid.core`: ``Structure``, ``Mechanism``, ``RunData``/``Experiment``, analytic modes;
- :mod:`momentid.io`: strict TOML, the MCAP recording format, CSV import;
- :mod:`momentid.lab`: scenarios, excitation, the MuJoCo rig, simulation, sensor models;
- :mod:`momentid.estimation`: identification, reconstruction, errors-in-variables, design, comparison;
- :mod:`momentid.diagnosis`: missing physics, where the mismatch is, sensor consistency;
- :mod:`momentid.report`: the rerun viewer, ``report.html`` and the UFF files;

plus :mod:`momentid.sweep` (campaigns), :mod:`momentid.cli` and :mod:`momentid.errors`.
The names below are the ones most scripts need.
"""

from momentid.core.analytic import Modes, modal_properties, rayleigh_coefficients, shear_stiffness
from momentid.core.series import Experiment, RunData
from momentid.core.structure import LabStatement, Mechanism, Structure
from momentid.core.version import __version__ as __version__
from momentid.diagnosis.dispatch import Diagnosis, diagnose
from momentid.errors import (
    IdentificationError,
    ModelError,
    MomentidError,
    RecordingError,
    ScenarioError,
    SensorDataError,
    SimulationError,
    TruncatedRecordingError,
    ViewerError,
)
from momentid.estimation.comparison import Comparison, analytic_parameters, compare
from momentid.estimation.design import cramer_rao, plan
from momentid.estimation.identification import Identification, identify
from momentid.io.importer import import_folder, import_recording
from momentid.io.recording import RecordingWriter, read_recording, write_experiment
from momentid.lab.excitation import GroundMotion, ground_motion, read_at2
from momentid.lab.rig import build_spec, compile_model
from momentid.lab.scenario import Scenario, default_scenario_path, load_scenario
from momentid.lab.simulation import run_experiment, simulate, simulate_run
from momentid.report.viewer import view

__all__ = [
    # types
    "Comparison", "Diagnosis", "Experiment", "GroundMotion", "Identification", "LabStatement",
    "Mechanism", "Modes", "RecordingWriter", "RunData", "Scenario", "Structure",
    # scenario -> simulation -> recording
    "load_scenario", "default_scenario_path", "ground_motion", "read_at2", "build_spec", "compile_model",
    "simulate", "simulate_run", "run_experiment", "write_experiment", "read_recording",
    "import_folder", "import_recording",
    # identification, design, diagnosis, viewing
    "identify", "compare", "analytic_parameters", "modal_properties", "rayleigh_coefficients",
    "shear_stiffness", "cramer_rao", "plan", "diagnose", "view",
    # errors
    "MomentidError", "ScenarioError", "ModelError", "SimulationError", "RecordingError",
    "TruncatedRecordingError", "IdentificationError", "SensorDataError", "ViewerError",
]
