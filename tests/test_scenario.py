"""Scenario files are validated strictly: one-line errors naming file, key and value."""

from __future__ import annotations

import numpy as np
import pytest

import momentid as mi
from momentid.lab.scenario import Harmonics, parse_scenario

from conftest import SCENARIOS, load, scenario_files

#: The tests' tiny scenario (two storeys, 0.5 s at 200 Hz, two runs), and ``write(folder, old, new, text)``.
from bad_input.scenario import BASE, write  # noqa: E402  (tests/ is on sys.path)


def test_every_shipped_scenario_loads():
    names = [p.stem for p in scenario_files()]
    assert {"default", "paper_harmonic", "paper_three_harmonics", "paper_elcentro"} <= set(names)
    for name in names:
        sc = load(name)
        assert sc.structure.storeys >= 1 and len(sc.runs) >= 2


def test_default_scenario_is_embedded_and_shipped():
    embedded = mi.load_scenario(mi.default_scenario_path())
    shipped = mi.load_scenario(SCENARIOS / "default.toml")
    assert embedded.text == shipped.text


def test_minimal_scenario_and_defaults(tmp_path):
    # without the names: the scenario takes its file's, the runs run1, run2
    text = BASE.replace('name = "tiny"\n', "").replace('name = "ref"\n', "").replace('name = "m1"\n', "")
    sc = mi.load_scenario(write(tmp_path, text=text))
    assert sc.name == "s" and sc.n_samples == 101 and sc.timestep == 0.005
    assert isinstance(sc.excitation, Harmonics)
    assert sc.excitation.angular_frequencies == (6.2832,)
    assert sc.runs[1].name == "run2" and sc.structure.storey_heights == (0.3, 0.3)
    assert sc.sensors.channels(2) == ("zdd", "z", "zd", "a1", "a2", "q1", "q2", "v1", "v2")


def test_damping_ratios_give_rayleigh_coefficients(tmp_path):
    sc = mi.load_scenario(write(tmp_path, "rayleigh_mu = 0.05\nrayleigh_kappa = 0.001",
                                "damping_ratios = [0.02, 0.05]"))
    s = sc.structure
    modes = mi.modal_properties(s.mass_matrix(), s.damping_matrix(), s.stiffness_matrix())
    # The two modes' damping ratios are reproduced to round-off of a 2x2 solve and an eigensolve.
    assert np.allclose(modes.damping_ratio, [0.02, 0.05], rtol=1e-9)


@pytest.mark.parametrize(
    "old, new, key, fragment",
    [
        ("duration = 0.5", "duration = 0.5\ncolour = 3", "scenario.colour", "unknown key"),
        ("masses = [10.0, 12.0]", "masses = [10.0, -1.0]", "structure.masses[1]", "positive"),
        ("masses = [10.0, 12.0]", "masses = [10.0, 0.0]", "structure.masses[1]", "positive"),
        ("masses = [10.0, 12.0]", 'masses = "heavy"', "structure.masses", "array"),
        ("storey_stiffness = [2000.0, 1500.0]", "storey_stiffness = [2000.0]", "structure.storey_stiffness",
         "2 numbers"),
        ("duration = 0.5", 'duration = "long"', "scenario.duration", "a number"),
        ("duration = 0.5", "duration = 0.50001", "scenario.duration", "whole number of samples"),
        ('type = "harmonic"', 'type = "earthquake"', "excitation.type", "one of"),
        ("added_mass = [0.5, 0.5]", "added_mass = [0.5, -0.5]", "runs[1].added_mass[1]", ">= 0"),
        ("added_mass = [0.5, 0.5]", "added_mass = [0.5]", "runs[1].added_mass", "2 numbers"),
        ("rayleigh_mu = 0.05", "rayleigh_mu = 0.05\ndamping_ratios = [0.01, 0.01]",
         "structure.damping.damping_ratios", "not both"),
        ("angular_frequency = 6.2832", "angular_frequency = 6.2832\nfrequency = 1.0", "excitation", "exactly one"),
    ],
)
def test_bad_values_name_file_key_and_value(tmp_path, old, new, key, fragment):
    path = write(tmp_path, old, new)
    with pytest.raises(mi.ScenarioError) as info:
        mi.load_scenario(path)
    message = str(info.value)
    assert str(path) in message and key in message and fragment in message
    assert "\n" not in message


def test_missing_record_file_is_named(tmp_path):
    path = write(tmp_path, 'type = "harmonic"\namplitude = 0.002\nangular_frequency = 6.2832',
                 'type = "record"\nfile = "nowhere/quake.at2"')
    with pytest.raises(mi.ScenarioError, match=r"excitation.file.*nowhere/quake.at2.*not found"):
        mi.load_scenario(path)


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(mi.ScenarioError, match="file not found"):
        mi.load_scenario(tmp_path / "absent.toml")
    with pytest.raises(mi.ScenarioError, match="invalid TOML"):
        mi.load_scenario(write(tmp_path, text="[scenario\nduration = 1"))


def test_missing_section_and_no_runs(tmp_path):
    with pytest.raises(mi.ScenarioError, match="missing key 'excitation'"):
        parse_scenario({"scenario": {"duration": 1.0}, "structure": {"masses": [1.0], "storey_stiffness": 1.0,
                        "damping": {"rayleigh_mu": 0.0, "rayleigh_kappa": 0.0}}, "runs": [{"added_mass": 0.0}]},
                       source=tmp_path / "x.toml")
    text = "runs = []\n" + BASE.split("[[runs]]")[0]
    with pytest.raises(mi.ScenarioError, match=r"'runs'.*\[\[runs\]\]"):
        mi.load_scenario(write(tmp_path, text=text))


def test_overrides_are_validated_like_the_file(tmp_path):
    path = write(tmp_path)
    sc = mi.load_scenario(path, overrides={"scenario.duration": 2.0, "runs.1.added_mass": [0.2, 0.0],
                                          "sensors.accelerometer.relative_noise": 0.01})
    assert sc.n_samples == 401 and sc.runs[1].added_mass == (0.2, 0.0)
    assert sc.sensors.accelerometer.relative_noise == 0.01   # a table the file leaves out is created
    with pytest.raises(mi.ScenarioError, match=r"s\.toml.*unknown key 'excitation.sed'"):
        mi.load_scenario(path, overrides={"excitation.sed": 1})
    with pytest.raises(mi.ScenarioError, match=r"'runs' is an array of 2 tables: expected an index 0..1"):
        mi.load_scenario(path, overrides={"runs.2.added_mass": 0.0})
