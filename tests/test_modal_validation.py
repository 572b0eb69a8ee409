"""The modal identification judged on simulated rigs of the validation set (benchmarks/modal_validation.py).

Each case is simulated on the MuJoCo lab, recorded the way a real lab records it (IMU noise, biases,
a gain error and clock offset on every floor sensor, a quiet lead-in) and identified as ``identify``
does.  The criterion is the issue's, on every storey mode: frequency within 0.2 % and damping ratio
within 20 % (each, or the truth within 2 standard errors), no capped fit.  Three cases are
chosen to span the set (one storey with an appendage 1 % off its mode, three storeys under a sine test
at 60 Hz, five storeys under a record at 200 Hz with modes up to 35 % of the sample rate); the default run
holds the first two, ``-m slow`` the third and the committed set.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks import modal_validation as mv

#: Cases of the default run: dimensions fixed, the rest drawn from the seed like the benchmark's.
FAST = (
    ("close appendage", dict(storeys=1, sample_rate=120.0, excitation="record", appendage=False, duration=60.0)),
    ("3 storeys, sine, 60 Hz", dict(storeys=3, sample_rate=60.0, excitation="sine", appendage=False, duration=60.0)),
    ("5 storeys, record, 200 Hz", dict(storeys=5, sample_rate=200.0, excitation="record", appendage=False,
                                       duration=60.0)),
)


def _fast_case(k: int) -> mv.Case:
    name, fixed = FAST[k]
    case = mv.draw_case(1000 + k, 2025, **fixed)
    if name == "close appendage":
        f1 = mv.shear_modes(case.masses, case.stiffness)[0]
        # A 0.03 % mass tuned 1 % below the storey mode: two modes about 1 % apart, both ~0.2 % damped,
        # the blind 1-storey rig's situation (one mode fitted to both gave 5.3 % damping there).
        case = dataclasses.replace(case, damping=(0.0015, 0.0015),
                                   appendage=(1, 3e-4 * case.masses[0], 0.99 * f1, 0.003))
    return case


#: Cases of FAST under ``-m slow`` (five storeys: 11 s; five-storey rigs are in the committed set too).
SLOW = {"5 storeys, record, 200 Hz"}


@pytest.mark.parametrize("k", [pytest.param(k, marks=pytest.mark.slow) if name in SLOW else k
                               for k, (name, _) in enumerate(FAST)], ids=[name for name, _ in FAST])
def test_identification_meets_the_criterion(k):
    case = _fast_case(k)
    row = mv.evaluate(case)
    assert "error" not in row, row.get("error")
    assert row["ok"], (case.label(), row["frequency_error"], row["frequency_sigmas"], row["damping_error"],
                       row["damping_sigmas"], row["warnings"])
    assert not row["capped"]
    if case.appendage is not None:          # the extra mode is found and reported apart
        assert len(row["extra"]) == 1
        # Frequency of the extra mode within 0.2 % too (the criterion of the storey modes).
        assert abs(row["extra"][0] / row["true_extra"][0] - 1) < 0.002, (row["extra"], row["true_extra"])


def test_truth_splits_storey_and_appendage_modes():
    """The truth of a case with an appendage: d storey modes and one extra, the extra the mode whose
    kinetic energy sits mostly in the appendage (a light one: almost all of it)."""
    case = _fast_case(0)
    t = mv.truth(case)
    assert t.frequency.size == 1 and t.extra_frequency.size == 1
    f1 = mv.shear_modes(case.masses, case.stiffness)[0]
    # A 0.03 % mass moves the storey mode by a fraction of a percent and its own mode stays near its
    # tuning (1 % below): both within 0.5 % of where they were tuned.
    assert abs(t.frequency[0] / f1 - 1) < 0.005
    assert abs(t.extra_frequency[0] / (0.99 * f1) - 1) < 0.005


def test_cases_are_deterministic_and_cover_the_set():
    a, b = mv.draw_cases(48, 2025), mv.draw_cases(48, 2025)
    assert a == b
    assert {c.storeys for c in a} == set(mv.STOREYS)
    assert {c.sample_rate for c in a} == set(mv.SAMPLE_RATES)
    assert {c.excitation for c in a} == {"noise", "sine", "record"}
    assert sum(c.appendage is not None for c in a) >= 8
    damping = np.array([z for c in a for z in c.damping])
    assert damping.min() >= 0.001 and damping.max() <= 0.03


@pytest.mark.slow
def test_every_case_of_the_committed_set():
    """The committed table is what the code prints today: every case judged as committed (a case the
    table marks failed, refused with its reason, must fail the same way; any other is a regression)."""
    import json
    from concurrent.futures import ProcessPoolExecutor
    from pathlib import Path

    committed = json.loads((Path(mv.__file__).parent / "results" / "modal_validation.json").read_text())
    with ProcessPoolExecutor(max_workers=2) as pool:
        rows = list(pool.map(mv.evaluate, mv.draw_cases(len(committed["rows"]), committed["seed"])))
    changed = [(r["label"], r.get("error"), r.get("frequency_error"), r.get("damping_error"))
               for r, c in zip(rows, committed["rows"]) if r["ok"] != c["ok"]]
    assert not changed, changed
    assert sum(r["ok"] for r in rows) >= 0.95 * len(rows)      # the bar: nearly every case right
