"""Runs simulated in forked worker processes equal the serial path bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

import momentid as mi
from momentid.errors import SimulationError
from momentid.lab.scenario import default_scenario_path, load_scenario


def _short_default(duration: float = 0.5) -> mi.Scenario:
    return load_scenario(default_scenario_path(), overrides={"scenario.duration": duration})


def test_parallel_equals_serial_in_run_order():
    scenario = _short_default()
    seen = []
    serial = mi.simulate(scenario, workers=1)
    parallel = mi.simulate(scenario, workers=2, on_run=lambda r: seen.append(r.name))
    names = [r.name for r in scenario.runs]
    assert seen == names and [r.name for r in parallel.runs] == names
    for a, b in zip(serial.runs, parallel.runs):
        assert a.channels == b.channels
        # Exact equality, no tolerance: the workers run the same code on the same inputs.
        assert np.array_equal(a.values, b.values) and np.array_equal(a.time, b.time)
        assert a.meta == b.meta


def test_run_experiment_in_parallel_records_every_run(tmp_path):
    scenario = _short_default()
    path = tmp_path / "parallel.mcap"
    simulated = mi.run_experiment(scenario, path, workers=None)   # one worker per core
    recorded = mi.read_recording(path)
    assert recorded.complete and [r.name for r in recorded.runs] == [r.name for r in scenario.runs]
    for a, b in zip(simulated.runs, recorded.runs):
        assert np.array_equal(a.values, b.values)


@pytest.mark.parametrize("workers", [0, -1, 1.5, True])
def test_bad_worker_count_is_refused(workers):
    with pytest.raises(SimulationError, match="workers"):
        mi.simulate(_short_default(0.01), workers=workers)


@pytest.mark.parametrize("name", ["boucwen_storey1", "friction_storey2", "pounding_floor3"])
def test_runs_with_native_callback_forces_on_threads_equal_serial(name):
    """Hidden physics whose forces run as native code (a state, a friction, a contact): its runs go to
    threads side by side, each model with its own forces, and equal the serial runs bit for bit."""
    from momentid.lab import native_forces
    from conftest import ROOT

    scenario = load_scenario(ROOT / "scenarios" / "hidden" / f"{name}.toml", overrides={"scenario.duration": 0.5})
    assert native_forces.applies(scenario.truth)
    serial = mi.simulate(scenario, workers=1)
    parallel = mi.simulate(scenario, workers=2)
    for a, b in zip(serial.runs, parallel.runs):
        assert np.array_equal(a.values, b.values)
