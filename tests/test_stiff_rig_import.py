"""Issue 32: the stiff 1-storey rig (data/mini_shake_table/stiff_1storey) imports with its clocks from
the data.

Measured from the raw files aligned by their stamps (which share an origin), the floor's data lag the
table's by a pure delay of about 19.5 ms (2.3 samples at 120 Hz) in every trial, and the floor moves
with the table below its 21.9 Hz mode (low-frequency gain +1.00 to +1.05): no sensor is reversed.
"""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from conftest import DATA
from momentid.io.importer import import_folder

RIG = DATA / "mini_shake_table" / "stiff_1storey"


@pytest.fixture(scope="module")
def experiment():
    return import_folder(RIG)


def _a1(run) -> dict:
    return next(s for s in run.meta["sensors"] if s["channel"] == "a1")


def test_no_floor_sensor_is_flipped(experiment):
    """el_centro_2 was flipped on a correlation of -0.60 the data could not confirm; sine_2 on a half
    period of its 2 Hz sine."""
    assert [_a1(run)["sign"] for run in experiment.runs] == [1] * 6
    for run in experiment.runs:   # below the mode the floor moves with the table, not against it
        zdd, a1 = run["zdd"], run["a1"]
        assert np.dot(zdd, a1) / np.dot(zdd, zdd) > 0.5, run.name


def test_one_floor_delay_in_every_trial(experiment):
    """One delay of the floor's data behind its stamps, read alike where the data align it and applied
    the same way in all six trials (sine_2 was put +28.4 samples off, a half period plus a flip)."""
    delays, starts = [], set()
    for run in experiment.runs:
        note = " ".join(_a1(run)["notes"])
        found = re.search(r"its data lag its stamps by ([-+][\d.]+) ms .* applied to its stamps in every run", note)
        assert found, (run.name, note)
        delays.append(float(found.group(1)))
        starts.add(round(_a1(run)["start"] - next(s for s in run.meta["sensors"] if s["channel"] == "zdd")["start"], 6))
    # 18-21 ms: the 19.5 ms measured from the transfer function's phase, read here as the median of the
    # trials' sub-sample cross-correlation lags (2.30-2.33 samples of 8.33 ms)
    assert len(set(delays)) == 1 and -21.0 < delays[0] < -18.0, delays
    assert len(starts) == 1, starts   # the same placement against the table in every trial


@pytest.mark.parametrize("swapped", ["every run", "el_centro_2"])
def test_swapped_table_and_floor_files_are_found_on_a_one_storey_rig(tmp_path, experiment, swapped):
    """Silent wrong 5: a 1-storey rig's table and floor files swapped went unnoticed.  Relabelled, each
    run is aligned again with the floor's common delay read over the runs in their final roles (it was
    aligned without it: el_centro_2, whose data cannot confirm its clock, kept its stamps alone, without
    the floor's -19.2 ms), so the import is the clean one's, sample for sample."""
    lab = tmp_path / "lab"
    shutil.copytree(RIG, lab)
    text = (lab / "experiment.toml").read_text()
    blocks = text.split("[[runs]]")
    for i, block in enumerate(blocks[1:], 1):
        if swapped == "every run" or f'name = "{swapped}"' in block:
            blocks[i] = re.sub(r'table = "(.*?)"\nfloors = \["(.*?)"\]', r'table = "\2"\nfloors = ["\1"]', block)
    assert "[[runs]]".join(blocks) != text
    (lab / "experiment.toml").write_text("[[runs]]".join(blocks))
    relabelled = import_folder(lab)
    for run, clean in zip(relabelled.runs, experiment.runs):
        notes = " ".join(run.meta["notes"])
        if swapped in ("every run", run.name):
            assert "the table's sensor and floor 1's appear swapped" in notes and notes.endswith("relabelled"), notes
        else:
            assert "swapped" not in notes, notes
        assert run.meta["source_files"][0].split("/")[-2] == "Ground Floor"
        assert _a1(run)["sign"] == 1 and _a1(run)["notes"] == _a1(clean)["notes"]
        assert np.array_equal(run.values, clean.values) and np.array_equal(run.time, clean.time), run.name
