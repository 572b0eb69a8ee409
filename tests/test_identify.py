"""Identification on noise-free virtual data, and refusals when data cannot identify."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import momentid as mi
from momentid.estimation.comparison import compare
from momentid.core.series import Experiment
from momentid.estimation.identification import identify

from conftest import load, scenario_files


@pytest.mark.parametrize("path", scenario_files(), ids=lambda p: p.stem)
def test_noise_free_identification_is_exact(simulated, path):
    sc = load(path.stem)
    result = identify(simulated(path.stem, ideal=True))
    assert result.estimator == "equation"   # auto: the data satisfy eq. (3) to round-off
    comparison = compare(result, sc.structure)
    # Noise-free data satisfy eq. (3) to integration round-off; 1e-6 is the acceptance bound
    # (observed: ~1e-11), relative to the entry or, for zero entries, to the matrix's largest entry.
    assert comparison.max_rel_error < 1e-6, comparison.table()
    assert result.rank == result.n_unknowns
    assert result.damping_misfit < 1e-8   # Rayleigh damping explains C exactly here
    # Modal properties agree as well (derived from the matrices above).
    assert np.allclose(comparison.identified_modes.frequency, comparison.analytic_modes.frequency, rtol=1e-8)
    assert np.allclose(comparison.identified_modes.damping_ratio, comparison.analytic_modes.damping_ratio,
                       rtol=1e-6)


def test_tall_building_has_121_unknowns(simulated):
    result = identify(simulated("tall_noise"))
    assert result.storeys == 10 and result.n_unknowns == 10 + 2 * 55 + 1


def test_difference_form_on_all_samples(simulated):
    sc = load("paper_harmonic")
    comparison = compare(identify(simulated("paper_harmonic"), estimator="difference"), sc.structure)
    assert comparison.max_rel_error < 1e-6   # same bound as above; observed ~1e-11


def test_added_mass_estimators_refuse_a_single_run(simulated):
    with pytest.raises(mi.IdentificationError, match="at least two"):
        identify(simulated("default"), runs=["reference"], estimator="eiv")


def test_added_mass_estimators_refuse_runs_without_added_mass(simulated):
    ex = simulated("default")
    ref = ex.runs[0]
    twin = replace(ref, name="again")
    with pytest.raises(mi.IdentificationError, match="no run .* adds mass.*use estimator 'modal'"):
        identify(Experiment(runs=(ref, twin), structure=ex.structure), estimator="equation")
    with pytest.raises(mi.IdentificationError, match="fits runs without added mass"):
        identify(ex, estimator="modal")


def test_modal_estimator_on_the_reference_run(simulated):
    """The reference run alone (no added mass, noise-free, every channel): modes from the modal fit."""
    sc = load("default")
    result = identify(simulated("default"), runs=["reference"], estimator="modal")
    assert result.estimator == "modal-eiv"
    truth = mi.modal_properties(sc.structure.mass_matrix(), sc.structure.damping_matrix(),
                                sc.structure.stiffness_matrix())
    # Noise-free data: exact to the integration round-off (observed ~1e-8), the 1e-6 bound.
    assert np.allclose(result.frequency, truth.frequency, rtol=1e-6, atol=0)
    assert np.allclose(result.damping_ratio, truth.damping_ratio, rtol=1e-6, atol=0)
    assert result.masses == sc.structure.masses               # the nominal model's masses scale K and C
    assert np.allclose(result.K, sc.structure.stiffness_matrix(), rtol=1e-6, atol=1e-6 * np.max(result.K))


def test_identify_explains_itself():
    doc = identify.__doc__.lower()
    for needed in ("parameters", "returns", "raises", "no run adds mass", "stated", "warnings"):
        assert needed in doc, needed


def test_refuses_too_little_excitation(simulated):
    # Three runs of three floors at one instant: 9 equations for 16 unknowns.
    with pytest.raises(mi.IdentificationError, match=r"9 equations for 16 unknowns"):
        identify(simulated("default"), times=[5.0])
    # Times outside the record, or not numbers, are refused as such (not blamed on the excitation).
    with pytest.raises(mi.IdentificationError, match=r"\[100.0\] s lies outside run 'reference'"):
        identify(simulated("default"), times=[100.0])
    with pytest.raises(mi.IdentificationError, match="expected finite instants"):
        identify(simulated("default"), times=[float("nan")])
    # A structure that never moves.
    ex = simulated("default")
    still = tuple(replace(r, values=np.zeros_like(r.values)) for r in ex.runs)
    with pytest.raises(mi.IdentificationError, match="never appear"):
        identify(Experiment(runs=still, structure=ex.structure))


def test_difference_form_needs_identical_table_motion(simulated):
    ex = simulated("default")
    runs = list(ex.runs)
    values = runs[1].values.copy()
    values[:, runs[1].channels.index("zdd")] *= 1.01
    runs[1] = replace(runs[1], values=values)
    with pytest.raises(mi.IdentificationError, match="same table motion"):
        identify(Experiment(runs=tuple(runs), structure=ex.structure), estimator="difference")


def test_bad_sensor_data_is_named_or_repaired(simulated):
    ex = simulated("default")
    r = ex.runs[1]
    values = r.values.copy()
    values[123:173, r.channels.index("a2")] = np.nan          # 50 missing samples: not repairable
    with pytest.raises(mi.SensorDataError, match=r"channel a2 is missing 50 samples from t = 0.123 s"):
        identify(Experiment(runs=(ex.runs[0], replace(r, values=values))), estimator="equation")
    values = r.values.copy()
    values[123, r.channels.index("a2")] = np.nan               # one sample: interpolated and reported
    result = identify(Experiment(runs=(ex.runs[0], replace(r, values=values))), estimator="equation")
    assert any("a2: interpolated 1 missing samples" in n for n in result.notes)
    keep = [i for i, c in enumerate(r.channels) if c != "v3"]
    cut = replace(r, channels=tuple(r.channels[i] for i in keep), values=r.values[:, keep])
    with pytest.raises(mi.SensorDataError, match="no channel 'v3'"):
        identify(Experiment(runs=(ex.runs[0], cut)), estimator="equation", prefilter=None)


def test_unknown_estimator():
    with pytest.raises(mi.IdentificationError, match="expected one of auto, equation, difference, eiv"):
        identify(Experiment(runs=()), estimator="magic")


def test_a_few_milliseconds_say_ill_conditioned_not_rank_deficient(simulated):
    """Issue 12: a 3 ms record reached full rank but was reported as 'only 16 of 16 unknowns'."""
    ex = simulated("default", ideal=True)
    short = tuple(replace(r, time=r.time[:4], values=r.values[:4]) for r in ex.runs)
    with pytest.raises(mi.MomentidError, match=r"(only with condition number|equations for 16 unknowns|"
                                                 r"samples are too few)") as info:
        identify(Experiment(runs=short, structure=ex.structure), estimator="equation")
    assert "only 16 of 16" not in str(info.value)


def test_difference_form_on_accelerometer_only_runs(tmp_path):
    """Issue 12: `--estimator difference` on accelerometer-only data ended in an IndexError."""
    scenario = mi.load_scenario(mi.default_scenario_path(), overrides={"sensors": {"set": "accel"}})
    result = identify(mi.simulate(scenario), estimator="difference")
    # The weak form of reconstructed signals is not exact: the identified masses land within a
    # few percent of the nominal ones (2e-3 relative was observed on a 2-storey rig).
    assert np.allclose(np.diag(result.M), scenario.structure.masses, rtol=0.05)


def test_a_window_of_a_run_is_a_run_of_its_own():
    """``RunData.window``: the samples asked for, the time from 0, the same channels and added masses, the
    name given (or the run's); a stop past the end ends at the end."""
    t = np.arange(10) * 0.01 + 3.0
    run = mi.RunData(name="r", added_mass=np.array([0.5]), time=t, channels=("zdd", "a1"),
                     values=np.column_stack([np.arange(10.0), -np.arange(10.0)]))
    w = run.window(4, 7, name="r@0.04s")
    assert w.name == "r@0.04s" and w.channels == run.channels and np.array_equal(w.added_mass, run.added_mass)
    np.testing.assert_allclose(w.time, [0.0, 0.01, 0.02], atol=1e-12)     # round-off of 3.04 - 3.04 etc.
    assert np.array_equal(w["zdd"], [4.0, 5.0, 6.0]) and np.array_equal(w["a1"], [-4.0, -5.0, -6.0])
    tail = run.window(8, 99)
    assert tail.name == "r" and tail.n_samples == 2 and tail.time[0] == 0.0
    for start, stop in ((10, None), (-1, 5), (5, 5)):
        with pytest.raises(mi.SensorDataError, match=rf"run 'r': window of samples {start}:{stop}; expected"):
            run.window(start, stop)
