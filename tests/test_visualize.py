"""The rerun view: a .rrd written headlessly, read back and checked against the recording."""

from __future__ import annotations

import dataclasses
import json
import socket
import subprocess
import sys
from collections import defaultdict

import numpy as np
import pytest

import momentid as mi
from momentid.report import panels, viewer
from momentid.cli import main
from momentid.core.series import json_safe
from momentid.errors import ViewerError
from momentid.estimation.equation_form import equation_residual
from momentid.io.recording import write_experiment
from momentid.lab.scenario import default_scenario_path
from benchmarks.bench import scenario_variant_file
from conftest import DATA

rerun_chunk = pytest.importorskip("rerun.chunk")

X = 20.0  # the exaggeration the CLI is asked for


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    """A 1 s default-scenario recording, written by the CLI to a .rrd; both read back."""
    tmp = tmp_path_factory.mktemp("view")
    scenario = mi.load_scenario(default_scenario_path(), overrides={"scenario.duration": 1.0})
    mcap = write_experiment(tmp / "small.mcap", mi.simulate(scenario))
    rrd = tmp / "small.rrd"
    assert main(["view", str(mcap), "--save", str(rrd), "--exaggeration", f"{X:g}", "--run", "ends"]) == 0
    experiment = mi.read_recording(mcap)
    reader = rerun_chunk.RrdReader(rrd)
    chunks = defaultdict(list)
    for chunk in reader.store().stream().to_chunks():
        chunks[chunk.entity_path].append(chunk.to_record_batch())
    return dict(mcap=mcap, rrd=rrd, experiment=experiment, chunks=chunks, reader=reader)


def column(chunks, entity: str, name: str):
    """(time in s, values) of component column ``name`` of ``entity`` over all its temporal chunks."""
    times, values = [], []
    for batch in chunks[entity]:
        if name in batch.schema.names and "time" in batch.schema.names:
            times += batch.column("time").cast("int64").to_pylist()
            values += batch.column(name).to_pylist()
    order = np.argsort(times)
    return np.asarray(times, float)[order] / 1e9, np.array(values, float)[order].reshape(len(order), -1)


def static(chunks, entity: str, name: str):
    for batch in chunks[entity]:
        if name in batch.schema.names and "time" not in batch.schema.names:
            value = batch.column(name).to_pylist()[0]
            return value[0] if isinstance(value, list) and len(value) == 1 else value
    raise KeyError(f"{entity}:{name}")


def test_entity_paths(rec):
    e = rec["experiment"]
    expected = {"/experiment", "/identification/parameters", "/identification/modes", "/identification/rel_error"}
    for run in e.runs:
        root = f"/runs/{run.name}"
        expected |= {f"{root}/rig", f"{root}/rig/base", f"{root}/rig/scale"}
        expected |= {f"{root}/rig/base/{kind}{i}" for kind in ("floor", "storey") for i in (1, 2, 3)}
        expected |= {f"{root}/sensors/{c}" for c in run.channels}
        expected |= {f"{root}/residual/r{i}" for i in (1, 2, 3)}
    assert expected <= set(rec["chunks"])
    assert set(run.channels) == {"zdd", "z", "zd", "a1", "a2", "a3", "q1", "q2", "q3", "v1", "v2", "v3"}


def test_sensor_series_match_the_recording(rec):
    for run in rec["experiment"].runs:
        for channel in run.channels:
            entity = f"/runs/{run.name}/sensors/{channel}"
            t, values = column(rec["chunks"], entity, "Scalars:scalars")
            assert t.size == run.n_samples == 1001
            np.testing.assert_allclose(t, run.time, rtol=0, atol=1e-9)
            np.testing.assert_array_equal(np.ravel(values), run[channel])
            name = static(rec["chunks"], entity, "SeriesLines:names")
            assert name.startswith(channel) and f"({mi.core.channel_unit(channel)})" in name


def test_rig_moves_with_exaggerated_displacements(rec):
    e = rec["experiment"]
    h = np.asarray(e.structure.storey_heights)
    level = np.concatenate([[0.0], np.cumsum(h)])
    for run in e.runs:
        root = f"/runs/{run.name}/rig/base"
        idx = viewer.rig_samples(run)  # 1 kHz recording: every 10th sample, 100 Hz
        assert np.array_equal(idx, np.arange(0, 1001, 10))
        t, base = column(rec["chunks"], root, "Transform3D:translation")
        np.testing.assert_allclose(t, run.time[idx], rtol=0, atol=1e-9)
        np.testing.assert_allclose(base[:, 0], X * run["z"][idx], rtol=1e-6, atol=1e-12)
        q = run.group("q")[idx]
        for i in range(3):
            _, floor = column(rec["chunks"], f"{root}/floor{i + 1}", "Transform3D:translation")
            np.testing.assert_allclose(floor[:, 0], X * q[:, i], rtol=1e-6, atol=1e-12)
            np.testing.assert_allclose(floor[:, 2], level[i + 1], rtol=1e-6)
            _, shear = column(rec["chunks"], f"{root}/storey{i + 1}", "Transform3D:mat3x3")
            drift = q[:, i] - (q[:, i - 1] if i else 0.0)
            # Column-major 3x3: element 6 is row 0, column 2 (x sheared by height).
            np.testing.assert_allclose(shear[:, 6], X * drift / h[i], rtol=1e-5, atol=1e-10)
        assert f"x{X:g}" in static(rec["chunks"], f"/runs/{run.name}/rig/scale", "Arrows3D:labels")


def test_identification_documents_and_residual(rec):
    e = rec["experiment"]
    result = mi.identify(e)
    comparison = mi.compare(result, e.structure)
    text = static(rec["chunks"], "/identification/parameters", "TextDocument:text")
    assert all(f"| {entry.name} |" in text for entry in comparison.entries)
    modes = static(rec["chunks"], "/identification/modes", "TextDocument:text")
    assert f"{comparison.analytic_modes.frequency[0]:.5f}" in modes
    bars = static(rec["chunks"], "/identification/rel_error", "BarChart:values")
    np.testing.assert_allclose(np.ravel(bars["buffer"] if isinstance(bars, dict) else bars),
                               [entry.rel_error for entry in comparison.entries], rtol=1e-12)
    assert f"drawn x{X:g}" in static(rec["chunks"], "/experiment", "TextDocument:text")
    for run in e.runs:
        expected = equation_residual(result, run)
        for i in range(3):
            t, r = column(rec["chunks"], f"/runs/{run.name}/residual/r{i + 1}", "Scalars:scalars")
            assert t.size == run.n_samples
            np.testing.assert_allclose(np.ravel(r), expected[:, i], rtol=0, atol=1e-12)


def test_blueprint_names_views_and_opens_the_chosen_run(rec):
    reader = rec["reader"]
    names, active = {}, []
    for chunk in reader.store(store=reader.blueprints()[0]).stream().to_chunks():
        batch = chunk.to_record_batch()
        for col in batch.schema.names:
            if col.endswith("display_name"):
                names[chunk.entity_path.lstrip("/")] = batch.column(col).to_pylist()[0][0]
            if col.endswith("active_tab"):
                active.append(batch.column(col).to_pylist()[0][0])
    titles = set(names.values())
    for run in rec["experiment"].runs:
        assert f"run {run.name}" in titles
        assert f"{run.name}: building, displacements drawn x{X:g}" in titles
        assert f"{run.name}: floor absolute accelerations a (m/s^2)" in titles
        assert f"{run.name}: equation residual of the identified model (N)" in titles
    assert "run ends" in [names.get(a) for a in active]


def test_result_json_round_trip(rec, tmp_path, capsys):
    assert main(["identify", str(rec["mcap"]), "--json", "--runs", "reference,uniform"]) == 0
    path = tmp_path / "result.json"
    path.write_text(capsys.readouterr().out)
    result = viewer.load_result(path, rec["experiment"])
    assert result.runs == ("reference", "uniform") and result.M.shape == (3, 3)
    scene = viewer.prepare(rec["experiment"], result=result)
    assert scene.result is result and "runs reference, uniform" in panels.parameters_markdown(scene)


def test_modal_result_of_the_shipped_rig(tmp_path, capsys):
    """Issue 32: `view --result FILE` reads what `identify --json` prints for runs without added mass
    (the shipped rig): every key of it, and shows its modes."""
    rec, path, rrd = tmp_path / "flex3.mcap", tmp_path / "result.json", tmp_path / "view.rrd"
    assert main(["import", str(DATA / "mini_shake_table" / "flexible_3storey"), "-o", str(rec)]) == 0
    capsys.readouterr()
    assert main(["identify", str(rec), "--runs", "sine_2p0", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    path.write_text(json.dumps(printed))
    assert main(["view", str(rec), "--result", str(path), "--save", str(rrd)]) == 0
    result = viewer.load_result(path, mi.read_recording(rec))
    assert json.loads(json.dumps(json_safe(result.to_dict()))) == printed      # nothing lost or changed
    assert [m.source for m in result.damping] == [m["source"] for m in printed["damping"]]
    chunks = defaultdict(list)
    for chunk in rerun_chunk.RrdReader(rrd).store().stream().to_chunks():
        chunks[chunk.entity_path].append(chunk.to_record_batch())
    panel = static(chunks, "/identification/parameters", "TextDocument:text")
    assert result.table() in panel and "masses (stated, kg): [0.1" in panel
    modes = static(chunks, "/identification/modes", "TextDocument:text")
    for k, (f, z) in enumerate(zip(printed["frequency_hz"], printed["damping_ratio_equivalent"])):
        assert f"| {k + 1} | {f:.5f} | n/a | {z:.5f} | n/a |" in modes     # the linear model C replays


def test_auto_exaggeration_is_a_nice_factor(rec):
    e = rec["experiment"]
    x = viewer.auto_exaggeration(e, e.structure.storey_heights)
    peak = max(np.abs(r["z"][:, None] + r.group("q")).max() for r in e.runs)
    mantissa = x / 10 ** np.floor(np.log10(x))
    assert np.isclose(mantissa, [1, 2, 5]).any()
    assert 0.08 <= x * peak / sum(e.structure.storey_heights) <= 0.2


def test_shows_what_it_can_without_identification_or_structure(rec, tmp_path):
    e = rec["experiment"]
    one = dataclasses.replace(e, runs=e.runs[:1])
    entities = {c.entity_path for c in
                rerun_chunk.RrdReader(viewer.write_rrd(one, tmp_path / "one.rrd")).store().stream().to_chunks()}
    assert "/runs/reference/sensors/a1" in entities and "/runs/reference/rig/base/floor3" in entities
    assert not {"/identification/modes", "/identification/rel_error", "/runs/reference/residual/r1"} & entities
    assert "not identified" in panels.experiment_markdown(viewer.prepare(one))
    scene = viewer.prepare(dataclasses.replace(e, structure=None))
    assert scene.result is not None and scene.comparison is None and len(scene.residuals) == 3
    assert "n/a" in panels.modes_markdown(scene) and "no analytic comparison" in " ".join(scene.notes)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_no_viewer_suggests_save(rec, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(viewer.sys, "platform", "linux")
    with pytest.raises(ViewerError, match="--save") as info:
        viewer.view(rec["experiment"], port=_free_port())
    assert str(rec["mcap"]) in str(info.value)


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["view", "missing.mcap"], "missing.mcap"),
        (["view", "{bad}"], "bad.mcap"),
        (["view", "{rec}", "--result", "{other}"], "4 storeys"),
        (["view", "{rec}", "--result", "{renamed}"], "step9 are not in"),
        (["view", "{rec}", "--result", "{bad}"], "bad.mcap: not a JSON result"),
        (["view", "{rec}", "--result", "nowhere.json"], "nowhere.json: result file not found"),
        (["view", "{rec}", "--result", "{modal}"], "modal.json: key 'mode_shapes': [[1.0, 0.0], [0.0, 1.0]]; "
                                                    "expected numbers of shape (3, 3)"),
        (["view", "{rec}", "--result", "{per_run}"], "identify --per-run --json` (one fit per run)"),
        (["view", "{rec}", "--run", "nope"], "no run named 'nope'"),
        (["view", "{rec}", "--exaggeration", "-1"], "positive"),
        (["view", "{rec}", "--save", "{bad}/x.rrd"], "cannot write"),
    ],
)
def test_mistakes_are_one_line_errors(rec, tmp_path, capsys, argv, fragment):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file")
    payload = {"M": np.eye(3).tolist(), "C": np.eye(3).tolist(), "K": np.eye(3).tolist(),
               "mu": 0.1, "kappa": 0.001, "runs": ["reference", "step9"]}
    renamed = tmp_path / "renamed.json"
    renamed.write_text(json.dumps(payload))
    other = tmp_path / "other.json"
    other.write_text(json.dumps(dict(payload, M=np.eye(4).tolist(), C=np.eye(4).tolist(), K=np.eye(4).tolist())))
    modal = tmp_path / "modal.json"      # runs without added mass: a mode shape matrix of 2 modes for 3
    modal.write_text(json.dumps({"frequency_hz": [1.0, 2.0, 3.0], "damping_ratio": [0.01] * 3,
                                 "mode_shapes": np.eye(2).tolist(), "runs": ["reference"]}))
    per_run = tmp_path / "per_run.json"
    per_run.write_text(json.dumps({"runs": [payload, payload]}))
    subs = {"{rec}": str(rec["mcap"]), "{bad}": str(bad), "{renamed}": str(renamed), "{other}": str(other),
            "{modal}": str(modal), "{per_run}": str(per_run)}
    for key, value in subs.items():
        argv = [a.replace(key, value) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and fragment in err


def test_run_view_shows_the_new_recording(tmp_path, monkeypatch, capsys):
    shown = []
    monkeypatch.setattr(viewer, "show", lambda scene, **kw: shown.append(scene))
    scenario = scenario_variant_file(tmp_path / "short.toml", {"scenario.duration": 0.5})
    assert main(["run", str(scenario), "-o", str(tmp_path), "-q", "-j", "1", "--view",
                 "--runs", "reference,ends"]) == 0
    (scene,) = shown
    assert scene.experiment.source.endswith("default.mcap") and scene.result.runs == ("reference", "ends")


def test_momentid_does_not_import_rerun():
    code = "import sys, momentid, momentid.cli, momentid.report.viewer; print('rerun' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
