"""momentid sweep: strict sweep files, local process pool, Dask in its local mode."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from momentid import cli
from momentid.errors import ScenarioError
from momentid.sweep import load_sweep, run_case, run_sweep, write_table

SPEC = """
[sweep]
base = "{base}"

[grid]
scenario.duration = [1.0]
scenario.seed = [0, 1]
sensors.accelerometer.relative_noise = [0.0, 0.01]
"""


@pytest.fixture
def spec(tmp_path):
    from conftest import SCENARIOS

    def write(text=SPEC, name="sweep.toml"):
        path = tmp_path / name
        path.write_text(text.format(base=(SCENARIOS / "default.toml").as_posix()))
        return path
    return write


def _numbers(rows):
    return [(r["case"], r["status"], r["identified"]) for r in rows]


def test_grid_is_every_combination_in_order(spec):
    sweep = load_sweep(spec())
    assert sweep.keys == ("scenario.duration", "scenario.seed", "sensors.accelerometer.relative_noise")
    assert [tuple(c.values.values()) for c in sweep.cases] == [
        (1.0, 0, 0.0), (1.0, 0, 0.01), (1.0, 1, 0.0), (1.0, 1, 0.01)]
    case = sweep.cases[3].scenario
    assert case.seed == 1 and case.duration == 1.0 and case.sensors.accelerometer.relative_noise == 0.01


@pytest.mark.parametrize("line, key, message", [
    ("excitation.sed = [1, 2]", "excitation.sed", "unknown key 'excitation.sed'"),
    ("structure.masses = [[1.0, -2.0, 3.0]]", "structure.masses", "positive"),
    ("runs.7.added_mass = [0.1]", "runs.7.added_mass", "index 0..2"),
    ('"scenario.name.x" = [1]', "scenario.name.x", "is a value, not a table"),   # quoted dotted key
    ("nonsense.key = [1]", "nonsense.key", "unknown key 'nonsense'"),
])
def test_bad_grid_key_or_value_names_file_key_and_value(spec, line, key, message):
    path = spec(SPEC.replace("scenario.seed = [0, 1]", line))
    with pytest.raises(ScenarioError) as err:
        load_sweep(path)
    text = str(err.value)
    assert text.startswith(str(path)) and f"'{key}'" in text and message in text


def test_grid_values_must_be_arrays(spec):
    with pytest.raises(ScenarioError, match="expected an array of values"):
        load_sweep(spec(SPEC.replace("scenario.seed = [0, 1]", "scenario.seed = 3")))
    with pytest.raises(ScenarioError, match=r"missing table \[grid\]"):
        load_sweep(spec("[sweep]\nbase = '{base}'\n"))


def test_local_pool_equals_serial_and_scores_every_case(spec, tmp_path):
    sweep = load_sweep(spec())
    rows = run_sweep(sweep, workers=2)
    serial = [run_case(c.index, c.values, c.scenario, sweep.estimator) for c in sweep.cases]
    # Exact equality: each worker process runs the same deterministic code on the same inputs.
    assert _numbers(rows) == _numbers(serial)
    assert [r["status"] for r in rows] == ["ok"] * 4
    clean = [r for r in rows if r["values"]["sensors.accelerometer.relative_noise"] == 0.0]
    noisy = [r for r in rows if r["values"]["sensors.accelerometer.relative_noise"] > 0.0]
    # Noise-free data: the project's 1e-6 identification bound (observed ~1e-11).
    assert all(r["max_rel_error"] < 1e-6 for r in clean)
    # 1 % accelerometer noise must show up as a visibly larger error; 1e-4 is far above round-off.
    assert all(r["max_rel_error"] > 1e-4 for r in noisy)
    # Different seeds, different noise.
    assert noisy[0]["identified"] != noisy[1]["identified"]

    table = write_table(rows, tmp_path / "out.csv")
    with open(table, newline="") as f:
        read = list(csv.DictReader(f))
    assert [int(r["case"]) for r in read] == [0, 1, 2, 3]
    for r in read:
        errors = {k[4:]: float(v) for k, v in r.items() if k.startswith("err:")}
        assert set(errors) == {k[3:] for k in r if k.startswith("id:")} == {k[3:] for k in r if k.startswith("an:")}
        # The row's score is its worst parameter; both are the same floats, written by repr: exact.
        assert float(r["max_rel_error"]) == max(errors.values())
        identified, analytic = float(r["id:K[1,1]"]), float(r["an:K[1,1]"])
        # Relative error of a non-zero entry, recomputed from the table's own columns (float division: exact).
        assert errors["K[1,1]"] == abs(identified - analytic) / abs(analytic)
    # The JSON table holds the same numbers, nested.
    as_json = json.loads(write_table(rows, tmp_path / "out.json").read_text())
    for r, j in zip(read, as_json):
        assert {k[4:]: float(v) for k, v in r.items() if k.startswith("err:")} == j["rel_error"]


def test_dask_local_cluster_runs_the_same_cases(spec):
    distributed = pytest.importorskip("distributed")
    sweep = load_sweep(spec())
    # Threads, not processes: the cluster lives in this test process.  Two threads per worker
    # exercise the lock that keeps MuJoCo's process-global control callback to one simulation.
    with distributed.LocalCluster(processes=False, n_workers=1, threads_per_worker=2,
                                  dashboard_address=None) as cluster:
        rows = run_sweep(sweep, address=cluster.scheduler_address)
    serial = [run_case(c.index, c.values, c.scenario, sweep.estimator) for c in sweep.cases]
    assert _numbers(rows) == _numbers(serial)   # exact: same code, same inputs


def test_cli_sweep_writes_table_and_refuses_bad_specs(spec, tmp_path, capsys):
    out = tmp_path / "table.json"
    path = spec(SPEC.replace("scenario.seed = [0, 1]", "scenario.seed = [5]")
                .replace("[0.0, 0.01]", "[0.0]"))
    assert cli.main(["sweep", str(path), "-o", str(out), "-j", "1"]) == 0
    rows = json.loads(out.read_text())
    assert len(rows) == 1 and rows[0]["status"] == "ok"
    assert "1 of 1 cases identified" in capsys.readouterr().out
    bad = spec(SPEC.replace("scenario.seed", "scenario.sed"), name="bad.toml")
    assert cli.main(["sweep", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {bad}: grid key 'scenario.sed' = 0:")
    assert np.isfinite(rows[0]["max_rel_error"])
