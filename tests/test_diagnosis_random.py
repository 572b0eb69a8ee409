"""The randomised diagnosis benchmark (benchmarks/diagnosis_random.py): its draws and its judging, and
(under ``-m slow``) a few of its cases diagnosed blind."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks.diagnosis_random import CATEGORIES, SEED, described, draw_case, draw_rig, run_case


def test_rigs_are_drawn_by_seed_within_their_ranges():
    rigs = [draw_rig(np.random.default_rng([SEED, 0, i])) for i in range(40)]
    again = draw_rig(np.random.default_rng([SEED, 0, 7]))
    assert json.dumps(again) == json.dumps(rigs[7])   # the same seed, the same rig
    assert {len(r["structure"]["masses"]) for r in rigs} == {3, 4, 5}
    assert {r["excitation"]["type"] for r in rigs} == {"noise", "chirp", "record"}
    assert all(0.005 <= r["_noise"] <= 0.02 for r in rigs)
    assert all(len(r["runs"]) == 4 and not any(r["runs"][0]["added_mass"]) for r in rigs)


def test_a_clean_case_draws_no_physics():
    case = draw_case("clean", 3)
    assert case["truth"] == [] and case["faults"] == {} and case["expected"] == {"named": []}


STOP = {"class": "stop", "side": "-", "gap_pos": 0.0, "gap_neg": 0.004}


@pytest.mark.parametrize("found, right", [
    ({"class": "stop", "side": "-", "gap_neg": 0.0042, "stiffness": 1e4}, True),
    # the gap within GAP_TOLERANCE (25 %) of the truth's, and on its side
    ({"class": "stop", "side": "-", "gap_neg": 0.0052, "stiffness": 1e4}, False),
    ({"class": "stop", "side": "+", "gap_pos": 0.004, "stiffness": 1e4}, False),
    ({"class": "stop", "side": "both", "gap_pos": 0.004, "gap_neg": 0.004, "stiffness": 1e4}, False),
    ({"class": "mixed", "terms": ["gap_neg", "x3"]}, False),
])
def test_a_stop_is_right_with_its_side_and_gap(found, right):
    assert described(found, STOP) is right


def test_other_classes_are_judged_by_their_numbers():
    assert described({"class": "gap", "gap": 0.0011, "stiffness": 3e3}, {"class": "gap", "gap": 0.001})
    assert not described({"class": "polynomial", "terms": ["x3"]}, {"class": "gap", "gap": 0.001})
    assert described({"class": "stiffness change", "time": 6.3}, {"class": "stiffness change", "time": 6.0})
    assert not described({"class": "stiffness change", "time": 7.0}, {"class": "stiffness change", "time": 6.0})
    assert described({"class": "hysteresis", "yield_drift": 1e-3, "exponent": 2.0}, {"class": "hysteresis"})
    # a two-sided stop at floor 1 is a dead zone of storey 1 (the same place): read as a gap
    both = {"class": "stop", "side": "both", "gap_pos": 0.003, "gap_neg": 0.0032}
    assert described({"class": "gap", "gap": 0.0031, "stiffness": 1e4}, both)


#: Cases of the committed table diagnosed blind again (about a minute each on 2 cores): a gap brace the
#: library took for cubic stiffness, a one-sided stop once taken for a two-sided gap; a storey damper
#: named first whose dissipation the friction found later does (the re-test drops it), a damper beside
#: a friction sized without it (re-sized beside the damper), a biased table accelerometer that only a
#: friction in the model shows (sized by re-simulation with it), a P-Delta beside a strong cubic spring
#: that only the lab's nominal model shows (the identified K takes in the floors' weight); a stiffness
#: loss whose linear refit diverged on the held-out run (the diagnosis stopped with an error); a stop whose
#: linear fit made two storeys all but rigid (a 63 Hz mode the data do not hold opened the band to noise,
#: and the open search lost the stop).
SLOW_CASES = [("gap_brace", 0), ("stop", 9), ("two_storey", 0), ("two_storey", 4), ("two_storey", 5),
              ("library_fault", 5), ("stiffness_change", 7), ("stop", 8)]


@pytest.mark.slow
@pytest.mark.parametrize("category, index", SLOW_CASES)
def test_benchmark_cases_are_diagnosed_right(category, index):
    assert category in CATEGORIES
    row = run_case(category, index)
    assert row["right"], row["why"]
    assert not row["false_alarm"]
