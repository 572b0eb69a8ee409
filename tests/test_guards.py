"""Issue 12 regressions: jobs refused before they start, names that cannot leave their folder."""

from __future__ import annotations

import pytest

import momentid as mi
from momentid.core import resources
from momentid.errors import ResourceError, ScenarioError

_SCENARIO = """
[scenario]
name = "{name}"
duration = {duration}
sample_rate = {rate}
[structure]
masses = [1.0, 1.0]
storey_stiffness = [100.0, 100.0]
storey_height = 0.3
[structure.damping]
rayleigh_mu = 0.1
rayleigh_kappa = 0.001
[excitation]
type = "harmonic"
amplitude = 0.002
frequency = 1.0
[[runs]]
name = "{run}"
added_mass = [0.0, 0.0]
"""


def _write(tmp_path, name="g", duration=1.0, rate=100.0, run="reference"):
    path = tmp_path / "s.toml"
    path.write_text(_SCENARIO.format(name=name, duration=duration, rate=rate, run=run))
    return path


def test_an_absurd_sample_rate_is_refused_before_any_allocation(tmp_path):
    scenario = mi.load_scenario(_write(tmp_path, duration=20.0, rate=1e12))
    with pytest.raises(ResourceError, match=r"2e\+13 samples.*refused before starting") as info:
        mi.simulate(scenario)
    assert info.value.needed > info.value.available


def test_a_job_larger_than_the_machine_is_refused_with_its_size(tmp_path, monkeypatch):
    # 1 MB of "available" memory: a 20 s x 1 kHz run's arrays (some MB) cannot fit.
    monkeypatch.setattr(resources, "available_memory", lambda: 1e6)
    scenario = mi.load_scenario(_write(tmp_path, duration=20.0, rate=1000.0))
    with pytest.raises(ResourceError, match="needs about .* MB of memory, 500 KB is available"):
        mi.simulate(scenario)


def test_a_normal_job_passes_the_guard(tmp_path):
    experiment = mi.simulate(mi.load_scenario(_write(tmp_path)))
    assert experiment.runs[0].n_samples == 101


@pytest.mark.parametrize("key, value", [("name", "../../etc/evil"), ("name", ".hidden"), ("name", "a/b"),
                                        ("run", "../x"), ("run", "x y")])
def test_names_that_would_leave_their_folder_are_refused(tmp_path, key, value):
    path = _write(tmp_path, **{key: value})
    with pytest.raises(ScenarioError, match=r"key '(scenario|runs\[0\])\.name' = .*expected a plain name"):
        mi.load_scenario(path)
