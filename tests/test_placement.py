"""Sensors on other floors than listed (issue 18 point 5, issue 22 point 3): found from physics, relabelled
at import with a note (or refused), warned about by identify; and no false alarm on rigs that are right.

The shipped trials are the customer: four synchronised trials labelled right and ``bonus_event``, whose
floor-1 and floor-2 files sit in each other's folders.  Doctored copies relabel any run in every way;
simulated rigs (1-5 storeys, 60-200 Hz, 0.1-3 % damping, a mode beyond the storeys beside a storey mode,
sensor gains off by up to 5 %) check that right labels stay unflagged.
"""

from __future__ import annotations

import dataclasses
import itertools
import re

import numpy as np
import pytest

import momentid.estimation.identification as identification
import momentid.estimation.scaled as scaled
from momentid.core.series import Experiment, RunData
from momentid.errors import SensorDataError
from momentid.io.importer import import_folder
from momentid.io.placement import Fault, check_placement, corrected, placement_warnings

from bad_input.rigs import Rig, Sensors, record
from conftest import data_file
from test_real_import import write_trial

FOLDER = data_file("mini_shake_table", "flexible_3storey")
MASSES = (0.160, 0.160, 0.142)


@pytest.fixture(scope="module")
def shipped():
    return import_folder(FOLDER)


def relabelled(run: RunData, perm) -> RunData:
    """``run`` with column k of (zdd, a1..ad) taken from listed column perm[k] (the table sensor's other
    motions, after them, left as they are)."""
    values = run.values.copy()
    values[:, :len(perm)] = run.values[:, list(perm)]
    return dataclasses.replace(run, values=values)


def undo(perm) -> tuple[int, ...]:
    return tuple(int(i) for i in np.argsort(perm))


def findings(runs, masses=MASSES):
    return [(f.run, f.fault, f.permutation) for f in check_placement(runs, masses)]


# ----------------------------------------------------------------------------- the shipped data

def test_the_swapped_shipped_trial_is_found_and_relabelled_with_its_evidence(shipped):
    bonus = shipped.run("bonus_event")
    note = next(n for n in bonus.meta["notes"] if "appear swapped" in n)
    assert note.startswith("run 'bonus_event': the sensors of floor 1 and floor 2 appear swapped (2nd Floor/")
    # The evidence the code computed: the first mode reads floor 1 above floor 2 as listed, and the
    # swapped-back shapes match the four other trials (MAC printed before and after).
    assert "moves the channels -0.01, 0.83, 0.44, 1.00 (table first)" in note
    assert "relabelled: -0.01, 0.44, 0.83, 1.00" in note and "MAC 0.99 (was 0.68)" in note
    assert note.endswith(": relabelled")
    files = bonus.meta["source_files"]
    assert "2nd Floor" in files[1] and "1st Floor" in files[2]
    assert [s["file"] for s in bonus.meta["sensors"]] == files and bonus.meta["sensors"][1]["channel"] == "a1"
    # The four synchronised trials are right: no note, and the imported experiment is clean now.
    for run in shipped.runs[:4]:
        assert not any("appear" in n for n in run.meta.get("notes", ())), run.name
    assert check_placement(shipped.runs, MASSES) == ()
    assert placement_warnings(shipped) == ()


def test_each_synchronised_trial_alone_is_not_flagged(shipped):
    for run in shipped.runs:
        assert findings([run]) == [], run.name


def test_any_relabelling_of_any_run_is_found_and_undone(shipped):
    """Every permutation of the table and three floors (23 per run, the table included) in each of the
    five trials: exactly one finding, for that run, whose fix is the inverse permutation."""
    runs = list(shipped.runs)
    for k, perm in itertools.product(range(len(runs)), itertools.permutations(range(4))):
        if perm == (0, 1, 2, 3):
            continue
        doctored = runs[:k] + [relabelled(runs[k], perm)] + runs[k + 1:]
        assert findings(doctored) == [(runs[k].name, Fault.ORDER, undo(perm))], (runs[k].name, perm)


def test_a_campaign_listed_in_another_order_is_relabelled_in_every_run(shipped):
    for perm in [(0, 3, 2, 1), (1, 0, 2, 3), (0, 2, 3, 1)]:
        doctored = [relabelled(r, perm) for r in shipped.runs]
        assert sorted(findings(doctored)) == sorted((r.name, Fault.ORDER, undo(perm)) for r in shipped.runs), perm
    messages = [f.message for f in check_placement([relabelled(r, (0, 3, 2, 1)) for r in shipped.runs], MASSES)]
    assert all("the floor order appears reversed (the top floor listed first)" in m for m in messages)


def test_two_runs_relabelled_differently_are_each_fixed(shipped):
    runs = list(shipped.runs)
    runs[0], runs[3] = relabelled(runs[0], (0, 2, 1, 3)), relabelled(runs[3], (1, 0, 2, 3))
    assert findings(runs) == [("northridge", Fault.ORDER, (0, 2, 1, 3)), ("sine_2p0", Fault.ORDER, (1, 0, 2, 3))]


def test_corrected_restores_the_run_and_its_reports(shipped):
    run = shipped.run("sine_1p5")
    finding = check_placement([relabelled(run, (0, 3, 1, 2))], MASSES)[0]
    fixed = corrected(relabelled(run, (0, 3, 1, 2)), finding)
    assert np.array_equal(fixed.values, run.values)
    assert fixed.meta["notes"][-1] == finding.message + ": relabelled"


def test_doctored_files_listed_top_floor_first_are_relabelled_at_import_or_refused(tmp_path):
    """The shipped sine_1p5 files with experiment.toml listing the floors top first."""
    folder = write_trial(tmp_path / "lab")
    toml = folder / "experiment.toml"
    toml.write_text(toml.read_text().replace('"sensor1.csv", "sensor2.csv", "sensor3.csv"',
                                             '"sensor3.csv", "sensor2.csv", "sensor1.csv"'))
    run = import_folder(folder).run("trial")
    original = import_folder(write_trial(tmp_path / "plain")).run("trial")
    assert np.array_equal(run.values, original.values)
    assert "the floor order appears reversed" in run.meta["notes"][-1]
    assert [s.rsplit("/", 1)[1] for s in run.meta["source_files"]] == [f"sensor{k}.csv" for k in range(4)]
    with pytest.raises(SensorDataError, match=r"experiment\.toml: run 'trial': the floor order appears reversed.*"
                                              r"refused \(without --refuse-mislabelled"):
        import_folder(folder, relabel=False)


# ----------------------------------------------------------------------------- single sensors

def _runs(rig: Rig, rate: float, seconds: float, count: int, seed: int, gains=None) -> list[RunData]:
    out = []
    for k in range(count):
        x = record(rig, rate, seconds, Sensors(noise=0.01, seed=seed + k, gains=gains or ()))
        d = rig.storeys
        out.append(RunData(name=f"r{k}", added_mass=np.zeros(d), time=np.arange(x.shape[0]) / rate,
                           channels=("zdd", *(f"a{j + 1}" for j in range(d))), values=x))
    return out


RIG3 = Rig(masses=MASSES, stiffness=(160.0, 160.0, 160.0), damping=0.01)


def test_a_floor_sensor_mounted_reversed_is_flipped():
    runs = _runs(RIG3, 120.0, 30.0, 2, seed=1)
    flipped = dataclasses.replace(runs[1], values=runs[1].values * np.array([1, 1, -1, 1]))
    (finding,) = check_placement([runs[0], flipped], MASSES)
    assert finding.fault is Fault.REVERSED and finding.flips == (2,)
    # -1 and the floor's quasi-static amplification below the first mode (1.0-1.3).
    assert re.search(r"the sensor of floor 2 reads -1\.[0-3]\d of the table's motion .*: mounted reversed$",
                     finding.message), finding.message
    assert np.array_equal(corrected(flipped, finding).values, runs[1].values)


def test_a_floor_sensor_reading_another_axis_is_named_not_relabelled():
    runs = _runs(RIG3, 120.0, 30.0, 2, seed=3)
    rng = np.random.default_rng(0)
    turned = runs[1].values.copy()
    turned[:, 2] = 0.05 * turned[:, 2] + rng.normal(0.0, 0.01, turned.shape[0])  # the transverse axis
    got = check_placement([runs[0], dataclasses.replace(runs[1], values=turned)], MASSES)
    assert [f.fault for f in got] == [Fault.GAIN]
    assert re.match(r"run 'r1': floor 2's sensor reads 0\.0\d of the table's motion", got[0].message)
    assert not got[0].fixable


def test_runs_settle_a_swap_the_first_mode_cannot_and_two_runs_only_disagree():
    """A top storey twice as stiff: floors 2 and 3 move within the margin of each other in the first
    mode, so a swap of them shows only in the higher modes' shapes, against the other runs'."""
    rig = Rig(MASSES, (160.0, 160.0, 320.0), 0.005)
    runs = _runs(rig, 120.0, 60.0, 3, seed=11)
    swapped = relabelled(runs[1], (0, 1, 3, 2))
    assert findings([runs[0], swapped, runs[2]]) == [("r1", Fault.ORDER, (0, 1, 3, 2))]
    (finding,) = check_placement([runs[0], swapped], MASSES)
    assert finding.fault is Fault.DISAGREE and not finding.fixable
    # Two runs are symmetric: either may be the wrong one, and the warning says which relabelling would
    # make them agree.
    assert finding.message.startswith("runs 'r0', 'r1' disagree on which sensor is on which floor: run 'r")
    assert "(the sensors of floor 2 and floor 3 appear swapped in it)" in finding.message
    assert findings(runs) == []


# ----------------------------------------------------------------------------- rigs that are right

def _rig(storeys: int, rate: float, damping: float, extra: str | None, rng) -> Rig:
    """A shear building whose top mode sits at 35 % of the sample rate (a 1-storey rig: 10 %), with a
    mode beyond the storeys 1-3 % from a storey mode: residues growing with height (torsion seen by
    sensors on one side) or of mixed signs (sensors on both sides)."""
    k = np.full(storeys, 1000.0)
    masses = tuple(rng.uniform(0.8, 1.2, storeys))
    f = Rig(masses, tuple(k), damping).modes()[0]
    k = k * ((0.35 * rate / f[-1]) ** 2 if storeys > 1 else (0.1 * rate / f[0]) ** 2)
    rig = Rig(masses, tuple(k), damping)
    if extra is None:
        return rig
    f, _, R = rig.modes()
    i = int(rng.integers(storeys))
    size = 0.3 * np.abs(R[i]).max()
    residues = size * (np.linspace(0.3, 1.0, storeys) if extra == "same" else rng.uniform(-1, 1, storeys))
    return dataclasses.replace(rig, extra=(f[i] * rng.choice([0.97, 0.99, 1.01, 1.03]), max(damping / 3, 0.001),
                                           tuple(residues)))


VALIDATION = [(d, rate, damping, extra) for d in (1, 2, 3, 5) for rate in (60.0, 120.0, 200.0)
              for damping in (0.001, 0.005, 0.03) for extra in (None, "same", "mixed")]


def _validate(cases, seed: int) -> tuple[int, int, int, int]:
    """(rigs flagged, swaps found, swaps missed, wrong fixes) over ``cases``: three runs of 20-120 s
    each, noise 0.2-3 % of the table's RMS, gains within 5 %; then one pair swapped in run r1."""
    rng = np.random.default_rng(seed)
    flagged = found = missed = wrong = 0
    for d, rate, damping, extra in cases:
        rig = _rig(d, rate, damping, extra, rng)
        runs = []
        for k in range(3):
            x = record(rig, rate, float(rng.choice([20.0, 60.0, 120.0])),
                       Sensors(noise=float(rng.choice([0.002, 0.01, 0.03])),
                               gains=tuple(rng.uniform(0.95, 1.05, d + 1)),
                               seed=int(rng.integers(10 ** 6))))
            runs.append(RunData(name=f"r{k}", added_mass=np.zeros(d), time=np.arange(x.shape[0]) / rate,
                                channels=("zdd", *(f"a{j + 1}" for j in range(d))), values=x))
        masses = rig.masses
        flagged += bool(check_placement(runs, masses))
        if d < 2:
            continue
        perm = list(range(d + 1))
        a, b = sorted(rng.choice(d + 1, 2, replace=False))
        perm[a], perm[b] = perm[b], perm[a]
        got = findings([runs[0], relabelled(runs[1], perm), runs[2]], masses)
        if got == [("r1", Fault.ORDER, tuple(perm))]:
            found += 1
        elif any(fault is Fault.ORDER and p != tuple(perm) for _, fault, p in got):
            wrong += 1
        else:
            missed += 1
    return flagged, found, missed, wrong


def test_rigs_that_are_right_are_not_flagged_and_a_swap_is_found():
    """A sample of the validation set (the whole set is the slow test below)."""
    cases = [(1, 120.0, 0.001, "mixed"), (2, 60.0, 0.005, "same"), (2, 200.0, 0.03, "mixed"),
             (3, 120.0, 0.01, None), (5, 200.0, 0.001, "mixed"), (5, 60.0, 0.005, None)]
    flagged, found, missed, wrong = _validate(cases, seed=7)
    assert (flagged, wrong) == (0, 0)
    # The swap in the 2-storey rig at 3 % damping is not named: a mode beyond the storeys shares its
    # first peak (two modes under one peak say nothing about the order), so it is left alone.
    assert (found, missed) == (4, 1)


@pytest.mark.slow
def test_the_validation_rigs_raise_no_false_alarm_and_no_wrong_fix():
    """108 rigs x 3 runs, each run right and then with one pair swapped.  Measured on this seed: no
    rig flagged, 79 of 81 swaps found, 2 missed (one named as a disagreement of the runs), none fixed
    wrongly; on the development battery (540 rigs, three seeds, stiff-top and soft-bottom rigs
    too): 0 flagged, 378 of 405 found, 0 wrong.  The misses are floors whose first-mode amplitudes
    differ by less than the margin, or first peaks shared with a mode beyond the storeys."""
    flagged, found, missed, wrong = _validate(VALIDATION, seed=5)
    assert flagged == 0 and wrong == 0
    # At least 90 % found: the measured 98 % less the few borderline swaps a change of BLAS could tip.
    assert found >= 0.9 * (found + missed)


# ----------------------------------------------------------------------------- identification

def test_identify_warns_about_sensors_on_other_floors(shipped, monkeypatch):
    """The hook in identify(): whatever the estimator returns gets the placement warnings first."""
    @dataclasses.dataclass(frozen=True)
    class Result:
        warnings: tuple = ("an estimator's own warning",)

    monkeypatch.setattr(scaled, "identify_modal", lambda experiment, runs: Result())
    runs = list(shipped.runs)
    runs[2] = relabelled(runs[2], (0, 1, 3, 2))
    warned = identification.identify(Experiment(runs=tuple(runs), statement=shipped.statement)).warnings
    assert warned[0].startswith("run 'sine_1p5': the sensors of floor 2 and floor 3 appear swapped")
    assert warned[0].endswith("(sensor placement check; not changed)") and warned[1] == "an estimator's own warning"
    assert identification.identify(shipped).warnings == ("an estimator's own warning",)
