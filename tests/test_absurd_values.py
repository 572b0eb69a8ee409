"""Finite but absurd values (issue 22 point 6): a scenario mass or stiffness of 1e308 crashed
``momentid run`` with an eigen-solver's traceback.  The scenario reader refuses values outside
plausible ranges (the cases are in tests/bad_input/scenario.py); what it cannot see (a Scenario
built in code, a MuJoCo compile error, a simulation that blows up) ends in one line too."""

from __future__ import annotations

import dataclasses
import os

import mujoco
import numpy as np
import pytest

import momentid as mi
from momentid.errors import ModelError, SimulationError
from momentid.io import plausible
from momentid.lab.rig import build_spec, compile_model, mujoco_warnings_counted_not_printed

from conftest import SCENARIOS, scenario_files


def test_every_shipped_scenario_is_within_the_plausible_ranges():
    for path in scenario_files(recursive=True):
        mi.load_scenario(path)   # raises if a range refused a real rig


def test_the_ranges_hold_every_shipped_rig_with_room_to_spare():
    """The stiffness range follows from the mass and frequency ranges (k = m (2 pi f)^2)."""
    low, high = plausible.STIFFNESS_RANGE
    assert low == pytest.approx(1e-3 * (2 * np.pi * 1e-2) ** 2) and high == pytest.approx(1e7 * (2 * np.pi * 1e3) ** 2)
    for path in scenario_files(recursive=True):
        s = mi.load_scenario(path).structure
        # two decades inside every range: the ranges refuse slips, never a real rig
        assert 100 * plausible.MASS_RANGE[0] <= min(s.masses) and max(s.masses) <= plausible.MASS_RANGE[1] / 100
        assert 100 * low <= min(s.storey_stiffness) and max(s.storey_stiffness) <= high / 100


def test_a_scenario_built_in_code_with_overflowing_masses_is_refused_in_one_line():
    scenario = mi.load_scenario(SCENARIOS / "default.toml")
    huge = dataclasses.replace(scenario.structure, masses=(1e308,) * scenario.structure.storeys)
    with pytest.raises(SimulationError, match="structure.masses = 1e[+]308: expected a floor mass") as info:
        mi.simulate(dataclasses.replace(scenario, structure=huge))
    assert "\n" not in str(info.value)


def test_a_mujoco_compile_error_is_one_line():
    structure = mi.load_scenario(SCENARIOS / "default.toml").structure
    spec = build_spec(dataclasses.replace(structure, base_mass=1e-30))
    with pytest.raises(ModelError, match="mjMINVAL") as info:
        compile_model(spec)
    assert "\n" not in str(info.value) and "base" in str(info.value)


def test_mujoco_warnings_are_counted_not_printed_into_the_working_folder(tmp_path, monkeypatch, capfd):
    """MuJoCo wrote 'Nan, Inf or huge value in QPOS' on stdout and into MUJOCO_LOG.TXT in the user's
    folder; the command line reads the counters and says it in one line of its own."""
    monkeypatch.chdir(tmp_path)
    model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><body><joint type='slide'/>"
                                           "<geom size='0.1' mass='1'/></body></worldbody></mujoco>")
    data = mujoco.MjData(model)
    with mujoco_warnings_counted_not_printed():
        data.qpos[0] = np.nan
        mujoco.mj_step(model, data)
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQPOS].number == 1
    assert not os.path.exists(tmp_path / "MUJOCO_LOG.TXT") and "QPOS" not in capfd.readouterr().out
