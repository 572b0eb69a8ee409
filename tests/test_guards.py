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


def _tall(tmp_path, storeys: int):
    """A tall, uniform building: one reference run and one with a mass on the top floor."""
    text = _SCENARIO.format(name="tall", duration=1.0, rate=200.0, run="reference")
    text = text.replace("masses = [1.0, 1.0]", f"masses = {[1.0] * storeys}")
    text = text.replace("storey_stiffness = [100.0, 100.0]", f"storey_stiffness = {[1e4] * storeys}")
    text = text.replace("added_mass = [0.0, 0.0]", f"added_mass = {[0.0] * storeys}")
    text += f'\n[[runs]]\nname = "top"\nadded_mass = {[0.0] * (storeys - 1) + [0.5]}\n'
    path = tmp_path / "tall.toml"
    path.write_text(text)
    return path


def test_identifying_200_storeys_is_refused_with_its_size_before_the_solve(tmp_path, monkeypatch):
    """Issue 12: a 200-storey recording was written, then identification grew to 24 GB and was killed."""
    from momentid.estimation.layout import Layout, equation_form_bytes

    # 200 storeys: 40,401 unknowns; the solve's p x p arrays alone are tens of GB (d^4 growth).  A 64 GB
    # machine, so that the figures in the message do not depend on this one's memory.
    monkeypatch.setattr(resources, "available_memory", lambda: 64e9)
    experiment = mi.simulate(mi.load_scenario(_tall(tmp_path, 200)))
    with pytest.raises(ResourceError, match=r"identification of 200 storeys \(40401 unknowns.*"
                                            r"refused before starting.*about \d+ storeys fit") as info:
        mi.identify(experiment, estimator="equation")
    assert info.value.needed == equation_form_bytes(Layout(200)) > info.value.available == 32e9


def test_identification_of_a_normal_building_passes_the_guard(tmp_path):
    result = mi.identify(mi.simulate(mi.load_scenario(_tall(tmp_path, 4))), estimator="equation")
    assert result.M.shape == (4, 4)


def test_an_eiv_fit_too_large_for_the_machine_is_refused(tmp_path, monkeypatch):
    # 200 KB "available" (100 KB to plan with): the 4-storey equation form (about 50 KB) fits, the
    # errors-in-variables fit's three dense Jacobians (20 s of noisy data: some MB) do not, so the
    # refusal comes from that stage, before its least squares start.
    text = _tall(tmp_path, 4).read_text().replace("duration = 1.0", "duration = 20.0").replace("10000.0", "100.0")
    text += "[sensors.accelerometer]\nrelative_noise = 0.01\n[sensors.displacement]\nrelative_noise = 0.01\n"
    path = tmp_path / "noisy.toml"
    path.write_text(text)
    experiment = mi.simulate(mi.load_scenario(path))
    monkeypatch.setattr(resources, "available_memory", lambda: 2e5)
    with pytest.raises(ResourceError, match=r"errors-in-variables fit of 25 unknowns .* refused before starting; "
                                            r"use estimator 'equation'"):
        mi.identify(experiment, estimator="eiv")


@pytest.mark.parametrize("K, what", [(-1e12, "mode with"), (float("nan"), "non-finite"), (1e300, "mode with")])
def test_an_absurd_trial_model_is_rejected_with_a_reason_before_expm(K, what):
    """Issue 12: a trial model that is unstable or absurd overflowed in expm and LAPACK (DLASCL lines on
    stdout, overflow warnings); it is now rejected where it arises, without a floating-point warning."""
    import warnings

    import numpy as np

    from momentid.errors import IdentificationError
    from momentid.estimation.linear import discretize

    with warnings.catch_warnings():
        warnings.simplefilter("error")   # any RuntimeWarning (overflow, invalid) fails the test
        with pytest.raises(IdentificationError, match=what):
            discretize(np.eye(2), np.zeros((2, 2)), np.array([[K, 0.0], [0.0, 1.0]]), 1e-3)


def test_the_eiv_fit_steps_back_from_an_absurd_trial_model_without_warnings():
    import warnings

    import numpy as np

    from momentid.errors import IdentificationError
    from momentid.estimation.eiv import spectra, whitened_residual
    from momentid.estimation.layout import Layout

    experiment = mi.simulate(mi.load_scenario(mi.default_scenario_path()))
    run = experiment.runs[0]
    d = run.added_mass.shape[0]
    layout = Layout(d)
    s = experiment.structure
    good = layout.pack(s.mass_matrix(), s.damping_matrix(), s.stiffness_matrix(), s.rayleigh_mu)
    sp = spectra(run, d, 40.0, sigma={c: 1e-3 for c in run.channels})
    bad = good.copy()
    bad[layout.k[0, 0]] = -1e15     # a storey with a huge negative stiffness: unstable far beyond Nyquist
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r_good, _ = whitened_residual(layout, good, sp)
        assert np.all(np.isfinite(r_good))
        with pytest.raises(IdentificationError, match="far faster than the sample rate"):
            whitened_residual(layout, bad, sp)


def _noisy_tall(tmp_path):
    """4 storeys under 20 s of band-limited random table motion, recorded with 1 % sensor noise."""
    text = _tall(tmp_path, 4).read_text().replace("duration = 1.0", "duration = 20.0").replace("10000.0", "100.0")
    text = text.replace('type = "harmonic"\namplitude = 0.002\nfrequency = 1.0',
                        'type = "noise"\nrms = 0.5\nband = [0.2, 10.0]')
    text += "[sensors.accelerometer]\nrelative_noise = 0.01\n[sensors.displacement]\nrelative_noise = 0.01\n"
    path = tmp_path / "noisy.toml"
    path.write_text(text)
    return mi.simulate(mi.load_scenario(path))


def test_a_wrong_added_mass_pattern_is_not_printed_as_an_answer_without_a_warning(tmp_path):
    """Issue 12: a wrong added-mass pattern gave plausible masses with a residual 3e5 x the noise, silently."""
    import dataclasses

    import numpy as np

    experiment = _noisy_tall(tmp_path)
    right = mi.identify(experiment, estimator="eiv")
    # the true pattern fits to the noise level: no warning (the threshold's margin is for this scatter)
    assert not any("noise level" in w for w in right.warnings)
    runs = tuple(dataclasses.replace(r, added_mass=np.roll(r.added_mass, 1)) for r in experiment.runs)
    wrong = mi.identify(dataclasses.replace(experiment, runs=runs), estimator="eiv")
    assert any("x the sensor noise level" in w and "added-mass pattern" in w for w in wrong.warnings)
