"""The virtual lab: scenario files, table motion, the MuJoCo rig, simulation and sensor models.

- :mod:`~momentid.lab.scenario`: the scenario TOML format, parsed into frozen dataclasses.
- :mod:`~momentid.lab.excitation`: ground motions (harmonics, AT2 records, band-limited noise).
- :mod:`~momentid.lab.rig`: the MJCF shear building on a driven slide-joint base (``MjSpec``).
- :mod:`~momentid.lab.simulation`: one run per added-mass pattern, ``mujoco.rollout``, recording.
- :mod:`~momentid.lab.sensors`: noise, bias, gain and delay of the instruments.
"""

from momentid.lab.scenario import Scenario, default_scenario_path, load_scenario
from momentid.lab.excitation import GroundMotion, ground_motion, read_at2
from momentid.lab.rig import build_spec, compile_model
from momentid.lab.simulation import run_experiment, simulate, simulate_run

__all__ = [
    "Scenario", "default_scenario_path", "load_scenario",
    "GroundMotion", "ground_motion", "read_at2",
    "build_spec", "compile_model",
    "run_experiment", "simulate", "simulate_run",
]
