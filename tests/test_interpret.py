"""What a discovered force is, in an engineer's words (momentid.diagnosis.discovered_physics), on hand-made terms."""

from __future__ import annotations

import pytest

from momentid.core.structure import Structure
from momentid.diagnosis.discovered_physics import LOUD, describe, linear_stiffness, physics
from momentid.mechanisms.place import Place, Target

FLOOR_3 = Place(Target.FLOOR_TABLE, 3)   # floor 3 against the table
STRUCTURE = Structure(masses=(10.0, 10.0, 20.0), storey_stiffness=(2000.0, 3000.0, 6000.0),
                      storey_heights=(0.3, 0.3, 0.3), rayleigh_mu=0.1, rayleigh_kappa=0.001)


def _terms(*extra, x=0.0, v=0.0):
    return [{"term": "x", "coefficient": x}, {"term": "v", "coefficient": v}, *extra]


def _gap(term, delta, c):
    return {"term": term, "coefficient": c, f"{term}_delta": delta}


def test_a_one_sided_stop_reads_as_a_stop():
    terms = _terms(_gap("gap_neg", 0.003, 4e4))
    assert physics(FLOOR_3, terms) == {"class": "stop", "side": "-", "gap_neg": 0.003, "stiffness": 4e4}
    words = describe(FLOOR_3, terms, STRUCTURE, 0.005)
    # floor 3 against the table: the storeys below in series, 1 / (1/2000 + 1/3000 + 1/6000) = 1000 N/m
    assert linear_stiffness(FLOOR_3, STRUCTURE) == pytest.approx(1000.0, rel=1e-12)
    assert "floor 3 meets a stop on the - side: gap -3.0 mm" in words and "contact stiffness 4e+04 N/m" in words
    assert "40 x the frame's 1e+03 N/m" in words and "WARNING" not in words   # a contact, not a correction


def test_stops_on_both_sides_and_a_floor_dead_zone_are_two_sided_stops():
    both = physics(Place(Target.FLOOR_TABLE, 2), _terms(_gap("gap_pos", 0.004, 2e4), _gap("gap_neg", 0.002, 3e4)))
    assert both == {"class": "stop", "side": "both", "gap_pos": 0.004, "gap_neg": 0.002, "stiffness": 3e4}
    dead = physics(Place(Target.FLOOR_TABLE, 2), _terms(_gap("dead_zone", 0.002, 2e4)))
    assert dead["class"] == "stop" and dead["side"] == "both" and dead["gap_pos"] == dead["gap_neg"] == 0.002


def test_a_storey_dead_zone_reads_as_a_gap_not_a_cubic():
    terms = _terms(_gap("dead_zone", 0.0012, 2500.0), x=50.0)
    assert physics(Place(Target.STOREY, 2), terms) == {"class": "gap", "gap": 0.0012, "stiffness": 2500.0}
    words = describe(Place(Target.STOREY, 2), terms, STRUCTURE, 0.004)
    assert "storey 2 engages a brace beyond a gap of +/-1.2 mm of drift, stiffness 2.5e+03 N/m" in words
    assert "cubic" not in words


def test_hysteresis_switch_and_mixtures():
    hyst = {"term": "hysteretic", "coefficient": -500.0, "hysteretic_yield": 0.001, "hysteretic_exponent": 2.0}
    assert physics(Place(Target.STOREY, 1), _terms(hyst))["class"] == "hysteresis"
    switch = {"term": "switch", "coefficient": -800.0, "switch_time": 6.0}
    assert physics(Place(Target.STOREY, 1), _terms(switch)) == {"class": "stiffness change", "time": 6.0}
    words = describe(Place(Target.STOREY, 1), _terms(switch), STRUCTURE, 0.003)
    assert "loses 40 % of its stiffness from t = 6.0 s" in words
    mixed = physics(Place(Target.FLOOR_TABLE, 2), _terms(_gap("gap_pos", 0.004, 2e4), switch))
    assert mixed == {"class": "mixed", "terms": ["gap_pos", "switch"]}
    assert physics(Place(Target.STOREY, 1), _terms()) == {"class": "linear"}


def test_a_hysteresis_that_puts_energy_in_is_not_described_as_one():
    # the sign of a dissipating hysteretic term (positive: loops of positive area) reversed
    hyst = {"term": "hysteretic", "coefficient": -500.0, "hysteretic_yield": 0.001, "hysteretic_exponent": 2.0}
    words = describe(Place(Target.STOREY, 1), _terms(hyst), STRUCTURE, 0.003)
    assert "negative area" in words and "not a physical hysteresis" in words
    assert "softening" not in words
    normal = describe(Place(Target.STOREY, 1), _terms(dict(hyst, coefficient=500.0)), STRUCTURE, 0.003)
    assert "negative area" not in normal and "loops of area" in normal


def test_a_term_larger_than_the_linear_force_is_flagged():
    # storey 1: 2000 N/m; at the peak 5 mm the linear force is 10 N.  A cubic -683 % of the stiffness
    # at the peak (k3 x^2 = -6.83 x 2000) is 68 N there: far above LOUD x 10 N.
    k3 = -6.83 * 2000.0 / 0.005 ** 2
    words = describe(Place(Target.STOREY, 1), _terms({"term": "x3", "coefficient": k3, "meaning": "x^3 (cubic)",
                                            "unit": "N/m^3"}), STRUCTURE, 0.005)
    assert "-683 % of its stiffness" in words and "WARNING" in words and "6.8 x the linear force" in words
    small = describe(Place(Target.STOREY, 1), _terms({"term": "x3", "coefficient": 0.5 * LOUD * 2000.0 / 0.005 ** 2,
                                            "meaning": "x^3 (cubic)", "unit": "N/m^3"}), STRUCTURE, 0.005)
    assert "WARNING" not in small
