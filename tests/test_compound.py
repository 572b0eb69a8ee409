"""Compound diagnoses (issue 13, item 1): two hidden mechanisms at once, both named, located and sized.

Each rig is the clean laboratory rig of ``scenarios/hidden/`` with two of the library's mechanisms
hidden in ``[truth]`` and ``[sensors.channel.*]``; ``diagnose`` sees only the recording.  The
single-mechanism rigs (one entry in ``mechanisms``) and the clean rig (none) are checked in
``test_discrepancy.py``.
"""

from __future__ import annotations

import json

import mujoco
import pytest

import momentid as mi
from benchmarks.diagnosis_compound import FAULT_KINDS, expected, scenario
from momentid import mechanisms
from momentid.diagnosis.added_mass.compound import STEP_SHORTLIST, shortlist
from momentid.diagnosis.dispatch import diagnose
from momentid.diagnosis.added_mass.screening import Candidate, Domain
from momentid.diagnosis.added_mass.selection import SHORTLIST_FLOOR
from momentid.core.processes import run_forked
from momentid.diagnosis.report import write_report
from momentid.mechanisms.place import Place, Target

FRICTION_LATE_TABLE = ([{"type": "coulomb_friction", "storey": 2, "force": 0.3}], {"zdd": {"clock_offset": 0.01}})
CUBIC_FLOOR_GAIN = ([{"type": "cubic_stiffness", "storey": 1, "k3": 3.5e7}], {"a1": {"gain": 1.05}})
DAMPER_PDELTA = ([{"type": "extra_damper", "storey": 3, "c": 3.0}, {"type": "p_delta", "storey": 1, "factor": 1.0}],
                 {})
FRICTION_CUBIC_SAME_STOREY = ([{"type": "coulomb_friction", "storey": 2, "force": 0.2},
                               {"type": "cubic_stiffness", "storey": 2, "k3": 4e7}], {})
FRICTION_PDELTA = ([{"type": "coulomb_friction", "storey": 3, "force": 0.4}, {"type": "p_delta", "storey": 1,
                                                                              "factor": 1.0}], {})
DAMPER_BIASED_TRANSDUCER = ([{"type": "extra_damper", "storey": 2, "c": 3.0}], {"q3": {"bias": 0.001}})


def _diagnosed(case):
    experiment = mi.simulate(scenario(*case))
    assert "truth" not in experiment.scenario_text and "sensors.channel" not in experiment.scenario_text
    return diagnose(experiment)


def _named(diag) -> dict:
    """{(mechanism, location as JSON): entry} of every named mechanism."""
    return {(m.mechanism, json.dumps(m.location, sort_keys=True)): m for m in diag.mechanisms}


def _check_pair(diag, case, tolerances: dict):
    """Both mechanisms named and located, nothing else; each parameter within its tolerance of the
    truth; the held-out run's NRMSE with the joint model near its noise level."""
    want = expected(*case)
    named = _named(diag)
    assert sorted(named) == sorted((m, json.dumps(loc, sort_keys=True)) for m, loc in want), diag.summary
    assert (diag.mechanism, diag.location) == (diag.mechanisms[0].mechanism, diag.mechanisms[0].location)
    truth, faults = case
    values = {(m["type"], json.dumps({"storey": m["storey"]})): m for m in truth}
    for channel, fault in faults.items():
        for field, v in fault.items():
            values[(FAULT_KINDS[field], json.dumps({"channel": channel}))] = {
                {"clock_offset": "delay"}.get(field, field): v}
    for key, (name, tol) in tolerances.items():
        got, true = named[key].parameters[name], values[key][name]
        assert abs(got - true) <= tol * abs(true), (key, name, got, true, diag.summary)
    # The joint model leaves the held-out run's misfit at least 3x lower (the single-mechanism target)
    # and near what sensor noise alone leaves in the training replays (within 3x: the held-out run has
    # its own noise realisation and the largest added mass, where P-Delta matters most).
    assert diag.nrmse_after * 3 <= diag.nrmse_before, diag.summary
    selection = diag.evidence.selection.after_correction or diag.evidence.selection
    assert diag.nrmse_after < 3 * selection.noise, diag.summary
    report = diag.to_dict()
    assert [m["mechanism"] for m in report["mechanisms"]] == [m.mechanism for m in diag.mechanisms]
    assert set(report["mechanisms"][0]) == {"mechanism", "location", "parameters", "std"}
    for m in diag.mechanisms:   # one sentence each in the summary
        assert m.mechanism.replace("_", " ") in diag.summary


@pytest.mark.slow
def test_friction_and_a_late_table_accelerometer(tmp_path):
    diag = _diagnosed(FRICTION_LATE_TABLE)
    # Friction 0.3 N (observed within 0.1 %) on data corrected by the fitted delay: 2 %, as the
    # single-mechanism case.  The 10 ms delay from the kinematic check (observed within 0.2 %): 2 %.
    _check_pair(diag, FRICTION_LATE_TABLE, {
        ("coulomb_friction", json.dumps({"storey": 2})): ("force", 0.02),
        ("sensor_delay", json.dumps({"channel": "zdd"})): ("delay", 0.02)})
    write_report(diag, tmp_path)
    xml = (tmp_path / "model_augmented.xml").read_text()
    assert "<mujoco" in xml
    saved = json.loads((tmp_path / "report.json").read_text())
    assert {m["mechanism"] for m in saved["mechanisms"]} == {"coulomb_friction", "sensor_delay"}


@pytest.mark.slow
def test_cubic_stiffness_and_a_floor_accelerometer_gain():
    diag = _diagnosed(CUBIC_FLOOR_GAIN)
    # k3 3.5e7 N/m^3 on data corrected by the fitted gain (observed within 0.2 %): 2 %, as the
    # single-mechanism case.  The gain 1.05 from the kinematic check (observed within 0.01 %): 0.5 %
    # (a tenth of the fault).
    _check_pair(diag, CUBIC_FLOOR_GAIN, {
        ("cubic_stiffness", json.dumps({"storey": 1})): ("k3", 0.02),
        ("sensor_gain", json.dumps({"channel": "a1"})): ("gain", 0.005)})


@pytest.mark.slow    # a minute on 2 cores; the compound matrix (python -m benchmarks.diagnosis_compound) holds it too
def test_extra_damper_and_p_delta_in_another_storey(tmp_path):
    diag = _diagnosed(DAMPER_PDELTA)
    # The damper 3 N s/m from the damping pattern of a C refitted with the P-Delta force (observed
    # within 1 %; the single case is tested to 5 %): 5 %.  P-Delta factor 1 (observed within 0.1 %,
    # standard error 0.1 %): 2 %.
    _check_pair(diag, DAMPER_PDELTA, {
        ("extra_damper", json.dumps({"storey": 3})): ("c", 0.05),
        ("p_delta", json.dumps({"storey": 1})): ("factor", 0.02)})
    write_report(diag, tmp_path)
    # One MuJoCo model carries both: storey tendons have damping kappa k_i (Rayleigh) but storey 3 adds
    # the damper (c / k_3 = 3 / 2100, 1.5x kappa = 9.5e-4 s) and storey 1 loses g x 4 kg / 0.3 m = 6 % of
    # its stiffness to the held-out run's weight (damping / stiffness up 6 %); storey 2 is plain Rayleigh.
    model = mujoco.MjModel.from_xml_string((tmp_path / "model_augmented.xml").read_text())
    ratio = {i: model.tendon_damping[model.tendon(f"storey{i}").id] / model.tendon_stiffness[
        model.tendon(f"storey{i}").id] for i in (1, 2, 3)}
    assert ratio[3] > 2 * ratio[2] and ratio[1] > 1.03 * ratio[2], ratio


def _candidate(mechanism, storey, explained, domain=Domain.EQUATION):
    return Candidate(mechanisms.get(mechanism), Place(Target.STOREY, storey), {}, {}, explained, domain)


def test_compound_shortlist_takes_weak_kinds_and_frictions_beside_a_pattern_damper():
    # What a found mechanism leaves is partly its own misfit, so a second mechanism may explain well
    # under half of it: the best of each kind above the floor goes to the replay, one per kind.
    ranked = [_candidate("extra_damper", 3, 0.9, Domain.PARAMETERS), _candidate("cubic_stiffness", 1, 0.4),
              _candidate("cubic_stiffness", 2, 0.3), _candidate("p_delta", 2, SHORTLIST_FLOOR + 0.01),
              _candidate("coulomb_friction", 1, SHORTLIST_FLOOR - 0.01), _candidate("coulomb_friction", 3, 0.02)]
    picked = [(c.mechanism, c.place.index) for c in shortlist(ranked)]
    assert picked[:STEP_SHORTLIST] == [("extra_damper", 3), ("cubic_stiffness", 1), ("p_delta", 2)]
    # ... and a friction the identified C took in as viscous damping screens near zero: beside the
    # pattern's damper, the friction at the damper's storey (not the better-screening one elsewhere).
    assert picked[STEP_SHORTLIST:] == [("coulomb_friction", 3)]
    # Below the floor and without a pattern damper: nothing.
    assert shortlist([_candidate("cubic_stiffness", 1, SHORTLIST_FLOOR - 0.01)]) == []


# Friction and cubic stiffness in one storey: observed within 0.2 % (friction) and 0.2 % (k3) of the
# truth: 3 % each, the single-mechanism figure (2 %) with room for the two forces trading a little of
# each other in one storey.
# Friction the identified damping took in, P-Delta elsewhere: stage 6 alone calls this unexplained
# (P-Delta grown to 1.7x absorbs the friction); the descent on the nominal model sizes both: observed
# within 0.3 % (friction) and 0.03 % (factor): 3 % each.
# A damper that won stage 6's replay, the biased transducer beside it: the damper from the pattern of C
# identified on corrected data (observed within 0.3 %): 5 %, as the single case; the 1 mm bias from
# screening (observed within 0.01 %): 1 %.
@pytest.mark.slow
@pytest.mark.parametrize("case, tolerances", [
    (FRICTION_CUBIC_SAME_STOREY, {("coulomb_friction", json.dumps({"storey": 2})): ("force", 0.03),
                                  ("cubic_stiffness", json.dumps({"storey": 2})): ("k3", 0.03)}),
    (FRICTION_PDELTA, {("coulomb_friction", json.dumps({"storey": 3})): ("force", 0.03),
                       ("p_delta", json.dumps({"storey": 1})): ("factor", 0.03)}),
    (DAMPER_BIASED_TRANSDUCER, {("extra_damper", json.dumps({"storey": 2})): ("c", 0.05),
                                ("sensor_bias", json.dumps({"channel": "q3"})): ("bias", 0.01)}),
], ids=["friction_and_cubic_in_one_storey", "friction_taken_in_as_damping_and_p_delta",
        "damper_and_biased_transducer"])
def test_pairs_the_first_mechanism_hides(case, tolerances):
    _check_pair(_diagnosed(case), case, tolerances)

def test_forked_trials_keep_their_order_and_return_their_results():
    seen = []

    def job(x):
        seen.append(x)                 # in a worker: a copy of the caller's state, lost with the worker
        return x + 1, x * x            # everything the caller needs comes back as the value

    assert run_forked(job, [3, 1, 2]) == [(4, 9), (2, 1), (3, 4)]
    assert seen == []                  # nothing but the values came back
    assert run_forked(job, [5]) == [(6, 25)] and seen == [5]   # one task: in process


def test_a_failed_partial_start_gives_way_to_its_two_best_newcomers(monkeypatch):
    """Beside a wrong partial start no newcomer earns its place; the two that replayed best beside it
    (storey forces at two places: not a damper of the pattern, not the same place twice) are tried
    together without it, by the descent."""
    from momentid.diagnosis.added_mass import compound as compound
    start = compound.Entry(mechanisms.get("extra_damper"), Place(Target.STOREY, 3), {"c": 30.0})

    def trial(c, score):
        task = compound._Task(c, compound._How.JOINT, (start, compound.Entry(c.kind, c.place, c.parameters)),
                              ({}, {}))
        return compound._Trial(task, score, None, task.entries, task.stds, (), None)
    trials = [trial(_candidate("extra_damper", 4, 0.3, Domain.PARAMETERS), 0.12),   # best, but a damper
              trial(_candidate("p_delta", 5, 0.9), 0.13), trial(_candidate("cubic_stiffness", 5, 0.5), 0.14),
              trial(_candidate("coulomb_friction", 4, 0.8), 0.15)]
    seen = []
    monkeypatch.setattr(compound, "_run", lambda stages, tasks: seen.extend(tasks) or [
        compound._Trial(tasks[0], 0.01, None, tasks[0].entries, tasks[0].stds, (), None)])
    got = compound._pair(None, trials)
    assert len(seen) == 1 and seen[0].how is compound._How.DESCENT and got.score == 0.01
    assert [(e.kind.name, e.place.index) for e in seen[0].entries] == [("p_delta", 5), ("coulomb_friction", 4)]
    # Fewer than two storey forces at two places: nothing to try.
    assert compound._pair(None, trials[:3]) is None
