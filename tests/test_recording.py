"""Recordings: exact round trips, stock-tool decoding, crash recovery, refusal of bad data.

Comparisons are exact (``np.array_equal``, ``==``): a recording stores the
float64 bits verbatim (packed doubles, ``repr``-exact JSON), so any
difference at all is a bug, not round-off.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import re
import struct
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_protobuf.decoder import DecoderFactory

import momentid as mi
from momentid.core.series import Experiment, RunData
from momentid.errors import RecordingError, RecoveryWarning, TruncatedRecordingError
from momentid.io.recording import (SCHEMA_DATA, SCHEMA_NAME, SENSOR_BLOCK_PROTO, RecordingWriter,
                                SensorBlock, read_recording, write_experiment)
from momentid.io.recording_format import encode_block
from momentid.core.structure import Structure

from bad_input.faults import fill_disk_at

DOC = Path(__file__).resolve().parents[1] / "docs" / "recording-format.md"
CHANNELS = ("zdd", "a1", "a2", "q1", "q2")
STRUCTURE = Structure(masses=(10.0, 12.5), storey_stiffness=(2000.0, 1500.0),
                      storey_heights=(0.3, 0.3), rayleigh_mu=0.05, rayleigh_kappa=1e-3)
SCENARIO = {"name": "synthetic", "duration": 0.25, "sample_rate": 200.0,
            "excitation": {"type": "Harmonics", "amplitudes": [0.001]}}
SCENARIO_TEXT = '[scenario]\nname = "synthetic"\n# ünïcode survives too\n'


def make_run(i: int, n: int = 51, channels=CHANNELS) -> RunData:
    """Run ``r<i>``: n samples at 200 Hz of seeded noise, including awkward values."""
    rng = np.random.default_rng(i)
    values = rng.standard_normal((n, len(channels))) * 10.0 ** rng.integers(-9, 3, (n, len(channels)))
    values[0, 0] = -0.0
    values[1, 0] = 5e-324  # subnormal
    return RunData(f"r{i}", np.array([0.1 * i, 1.0 / 3.0]), np.arange(n) / 200.0 + 0.1 * i,
                   channels, values)


def experiment(n_runs: int = 3, n: int = 51) -> Experiment:
    return Experiment(tuple(make_run(i + 1, n) for i in range(n_runs)), STRUCTURE, SCENARIO,
                      SCENARIO_TEXT)


def assert_same_run(a: RunData, b: RunData) -> None:
    assert a.name == b.name and a.channels == b.channels
    for x, y in ((a.time, b.time), (a.values, b.values), (a.added_mass, b.added_mass)):
        assert x.dtype == y.dtype and np.array_equal(x, y)  # exact, see module docstring
    assert np.array_equal(np.signbit(a.values), np.signbit(b.values))  # -0.0 stays -0.0


def read_quietly(path) -> Experiment:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a clean file must not warn
        return read_recording(path)


# ----------------------------------------------------------------------------- round trip

def test_round_trip_is_exact(tmp_path):
    exp = experiment()
    path = tmp_path / "exp.mcap"
    with RecordingWriter(path, structure=STRUCTURE, scenario=SCENARIO, scenario_text=SCENARIO_TEXT,
                         extra_metadata={"operator": "test"}) as writer:
        for run in exp.runs:
            # block_size 7 does not divide 51: several blocks and a short last one
            writer.write_run(run, model_xml=f"<mujoco model='{run.name}'/>", block_size=7)
    got = read_quietly(path)
    assert got.complete and got.notes == () and got.source == str(path)
    assert got.structure == STRUCTURE
    assert got.scenario == SCENARIO and got.scenario_text == SCENARIO_TEXT
    assert [r.name for r in got.runs] == ["r1", "r2", "r3"]
    for a, b in zip(exp.runs, got.runs):
        assert_same_run(a, b)
        assert b.meta["model_xml"] == f"<mujoco model='{a.name}'/>"


def test_write_experiment_keeps_models_and_no_structure(tmp_path):
    exp = Experiment(tuple(make_run(i, channels=("zdd", "x")) for i in (1, 2)), None, {}, "")
    first = write_experiment(tmp_path / "a.mcap", exp, model_xml={"r2": "<mujoco/>"})
    again = write_experiment(tmp_path / "b.mcap", read_quietly(first))  # models come from run.meta
    got = read_quietly(again)
    assert got.structure is None and got.scenario == {}
    assert "model_xml" not in got.runs[0].meta and got.runs[1].meta["model_xml"] == "<mujoco/>"
    for a, b in zip(exp.runs, got.runs):
        assert_same_run(a, b)
    with pytest.raises(RecordingError, match="model_xml names run 'r9'"):
        write_experiment(tmp_path / "c.mcap", exp, model_xml={"r9": "<mujoco/>"})


def test_fast_block_encoder_matches_protobuf():
    run = make_run(1, n=10)
    args = dict(run="r1", first_sample=3, n_samples=10, channels=CHANNELS)
    expected = SensorBlock(**args, time=run.time, values=run.values.ravel()).SerializeToString()
    assert encode_block("r1", 3, CHANNELS, run.time, run.values) == expected


def test_stock_decoder_reads_every_block(tmp_path):
    exp = experiment(n_runs=2)
    write_experiment(tmp_path / "exp.mcap", exp)
    blocks: dict[str, list] = {}
    with open(tmp_path / "exp.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _, block in reader.iter_decoded_messages():
            assert schema.name == SCHEMA_NAME and channel.topic == f"/runs/{block.run}/sensors"
            assert type(block) is not SensorBlock  # built from the file's own schema
            blocks.setdefault(block.run, []).append(block)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert json.loads(meta["momentid.experiment"]["structure"]) == STRUCTURE.to_dict()
    for run in exp.runs:
        got = blocks[run.name]
        assert len(got) == 1 and got[0].n_samples == run.n_samples  # 51 samples < block_size 1000
        values = np.array(got[0].values).reshape(run.n_samples, len(got[0].channels))
        assert np.array_equal(values, run.values) and np.array_equal(np.array(got[0].time), run.time)


# ----------------------------------------------------------------------------- crashes

def write_with_sizes(path, runs) -> list[int]:
    """Write ``runs``; the file size after the header and after each run."""
    sizes = []
    with RecordingWriter(path, structure=STRUCTURE, scenario=SCENARIO) as writer:
        sizes.append(path.stat().st_size)
        for run in runs:
            writer.write_run(run)  # fsyncs, so the size on disk is exact
            sizes.append(path.stat().st_size)
    return sizes


def test_truncated_file_keeps_completed_runs(tmp_path):
    exp = experiment(n=400)
    path = tmp_path / "full.mcap"
    sizes = write_with_sizes(path, exp.runs)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: (sizes[2] + sizes[3]) // 2])  # inside run 3's data
    with pytest.warns(UserWarning, match=r"truncated after run 'r2'; recovered 2 of 2 runs") as rec:
        got = read_recording(cut)
    assert not got.complete and [r.name for r in got.runs] == ["r1", "r2"]
    assert got.notes == (str(rec[0].message),) and got.notes[0].startswith(f"{cut}: ")
    for a, b in zip(exp.runs, got.runs):
        assert_same_run(a, b)


def test_file_cut_inside_header_is_truncated(tmp_path):
    path = tmp_path / "full.mcap"
    sizes = write_with_sizes(path, experiment(n_runs=1).runs)
    for n in (0, 5, 20, sizes[0] - 1):  # empty, inside the magic, the header, the experiment record
        cut = tmp_path / f"cut{n}.mcap"
        cut.write_bytes(path.read_bytes()[:n])
        with pytest.raises(TruncatedRecordingError, match=re.escape(str(cut))):
            read_recording(cut)


def test_exception_inside_writer_keeps_finished_runs(tmp_path):
    exp = experiment()
    path = tmp_path / "crash.mcap"
    with pytest.raises(KeyError, match="boom"):
        with RecordingWriter(path, structure=STRUCTURE, scenario=SCENARIO) as writer:
            writer.write_run(exp.runs[0])
            writer.write_run(exp.runs[1])
            raise KeyError("boom")
    with pytest.warns(UserWarning, match=r"writer was aborted \(KeyError: 'boom'\); recovered 2 of 2"):
        got = read_recording(path)
    assert not got.complete and [r.name for r in got.runs] == ["r1", "r2"]
    with open(path, "rb") as f:  # the file was finished: the seeking reader works
        assert make_reader(f).get_summary().statistics.message_count == 2


# ----------------------------------------------------------------------------- bad files

def test_missing_file(tmp_path):
    path = tmp_path / "nowhere" / "rec.mcap"
    with pytest.raises(RecordingError, match=re.escape(str(path))):
        read_recording(path)


def test_garbage_file(tmp_path):
    path = tmp_path / "garbage.mcap"
    path.write_bytes(np.random.default_rng(0).bytes(4096))
    with pytest.raises(RecordingError, match=re.escape(f"{path}: not an MCAP file")):
        read_recording(path)


def write_raw(path, blocks, *, n_samples=None, complete=True, channels=("zdd", "a1")):
    """A one-storey recording with run 'r1' made of ``blocks`` = [(first, time, values)]."""
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        schema = writer.register_schema(SCHEMA_NAME, "protobuf", SCHEMA_DATA)
        writer.add_metadata("momentid.experiment", {"format_version": "1", "storeys": "1"})
        ch = writer.register_channel("/runs/r1/sensors", "protobuf", schema)
        for first, t, v in blocks:
            block = SensorBlock(run="r1", first_sample=first, n_samples=len(t), channels=channels,
                                time=t, values=v)
            writer.add_message(ch, 0, block.SerializeToString(), 0)
        if complete:
            total = sum(len(t) for _, t, _ in blocks) if n_samples is None else n_samples
            writer.add_metadata("momentid.run", {"name": "r1", "index": "0", "added_mass": "[0.5]",
                                                 "n_samples": str(total), "complete": "true"})
        writer.finish()


T = np.arange(4) * 0.01


@pytest.mark.parametrize("t, v, expected", [
    (T, np.zeros(7), "4 times and 7 values; expected n_samples = 4 times and 4 x 2 = 8 values"),
    (np.array([0.0, np.nan, 0.2, 0.3]), np.zeros(8), r"time\[1\] = nan; expected finite"),
    (np.array([0.0, 0.2, 0.1, 0.3]), np.zeros(8), r"time\[2\] = 0.1 follows 0.2; expected strictly"),
])
def test_bad_block_is_refused(tmp_path, t, v, expected):
    path = tmp_path / "bad.mcap"
    write_raw(path, [(0, T, np.zeros(8)), (4, t, v)])
    with pytest.raises(RecordingError, match=re.escape(f"{path}: run 'r1' block 1 (first_sample 4)")
                       + ".*" + expected):
        read_recording(path)


def test_blocks_out_of_order_are_sorted_and_gaps_are_incomplete(tmp_path):
    path = tmp_path / "ok.mcap"
    write_raw(path, [(4, T + 0.04, np.ones(8)), (0, T, np.zeros(8))])
    run = read_quietly(path).runs[0]
    assert np.array_equal(run.time, np.arange(8) * 0.01) and run["a1"].tolist() == [0] * 4 + [1] * 4
    write_raw(path, [(0, T, np.zeros(8)), (8, T + 0.08, np.zeros(8))], n_samples=12)
    with pytest.raises(TruncatedRecordingError, match="run 'r1' is missing samples 4..7"):
        read_recording(path)
    write_raw(path, [(0, T, np.zeros(8)), (2, T + 0.02, np.zeros(8))])
    with pytest.raises(RecordingError, match="block 1 starts at sample 2, expected 4; blocks overlap"):
        read_recording(path)


def test_not_a_momentid_recording(tmp_path):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        writer.finish()
    with pytest.raises(RecordingError, match="no 'momentid.experiment' metadata record"):
        read_recording(path)


def test_writer_refuses_what_the_reader_would(tmp_path):
    bad = RunData("r1", np.zeros(2), np.array([0.0, 0.2, 0.1]), ("zdd",), np.zeros((3, 1)))
    with RecordingWriter(tmp_path / "w.mcap", structure=STRUCTURE, scenario={}) as writer:
        with pytest.raises(RecordingError, match=r"run 'r1': time\[2\] = 0.1 follows 0.2"):
            writer.write_run(bad)
        writer.write_run(make_run(1))
        with pytest.raises(RecordingError, match="already used"):
            writer.write_run(make_run(1))
        with pytest.raises(RecordingError, match=r"added_mass = \[0.0\]; expected 2 finite"):
            writer.write_run(RunData("r9", np.zeros(1), T, ("zdd",), np.zeros((4, 1))))
    assert [r.name for r in read_quietly(tmp_path / "w.mcap").runs] == ["r1"]


# ----------------------------------------------------------------------------- the format doc

def test_doc_example_writes_a_readable_recording(tmp_path, monkeypatch):
    text = DOC.read_text()
    code = re.search(r"<!-- example: rig-writer -->\n```python\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, str(DOC), "exec"), {})
    got = read_quietly(tmp_path / "rig.mcap")
    assert [r.name for r in got.runs] == ["bare", "top_plus_5kg"] and got.storeys == 2
    assert got.scenario == {"name": "rig test", "sample_rate": 500.0}
    run = got.run("top_plus_5kg")
    assert run.values.shape == (2000, 3) and run.added_mass.tolist() == [0.0, 5.0]
    assert np.array_equal(run["a2"], 2.5 * run["zdd"])  # the example's a2 = (1.5 + 1) * zdd


def test_doc_gives_the_embedded_schema():
    proto = re.search(r"```proto\n(.*?)```", DOC.read_text(), re.S).group(1)
    assert proto == SENSOR_BLOCK_PROTO


def test_same_scenario_and_seed_give_the_same_bytes(tmp_path):
    """Determinism: nothing in a recording comes from the wall clock or the process
    (attachment times, CRCs and the footer follow from the data alone)."""
    scenario = mi.load_scenario(mi.default_scenario_path())
    first, second = tmp_path / "a.mcap", tmp_path / "b.mcap"
    mi.run_experiment(scenario, first)
    mi.run_experiment(scenario, second, workers=2)
    assert first.read_bytes() == second.read_bytes()


# ----------------------------------------------------------------------------- issue 12: faults

def read_noting(path) -> Experiment:
    """Read a damaged recording: its notes are checked, their warnings are not wanted here."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecoveryWarning)
        return read_recording(path)


def _full_disk_after(monkeypatch, room: int) -> None:
    """Every file the recording module opens sits on a disk with ``room`` bytes."""
    import momentid.io.recording as recording

    fill_disk_at(monkeypatch, recording, room)


def _room_for_two_runs(tmp_path) -> int:
    """Bytes a recording of ``experiment(3)`` holds after its second run (the writer's own sizes)."""
    path = tmp_path / "sizes.mcap"
    with RecordingWriter(path, structure=STRUCTURE, scenario=SCENARIO) as writer:
        for run in experiment(3).runs[:2]:
            writer.write_run(run)
        size = path.stat().st_size
    return size


def test_a_full_disk_is_one_error_naming_the_runs_kept(tmp_path, monkeypatch):
    """Issue 12: disk full while writing gave three chained OSErrors; now one RecordingError that says
    which completed runs are on disk, and those read back with a note."""
    room = _room_for_two_runs(tmp_path)
    _full_disk_after(monkeypatch, room + 100)  # a little room: run r3 fails part-way
    path = tmp_path / "full.mcap"
    with pytest.raises(RecordingError) as info:
        write_experiment(path, experiment(3))
    message = str(info.value)
    assert "\n" not in message and info.value.__suppress_context__  # no chained traceback
    assert "cannot write run 'r3'" in message and "(r1, r2)" in message and os.strerror(errno.ENOSPC) in message
    got = read_noting(path)
    assert [r.name for r in got.runs] == ["r1", "r2"] and not got.complete and "truncated" in got.notes[0]


def test_a_disk_full_before_the_header_keeps_nothing_and_says_so(tmp_path, monkeypatch):
    _full_disk_after(monkeypatch, 0)
    with pytest.raises(RecordingError, match="cannot write the header .* no run was completed"):
        write_experiment(tmp_path / "full.mcap", experiment(1))


@pytest.fixture
def tiny_disk(tmp_path):
    """A real 64 KiB tmpfs (root only; skipped elsewhere)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)],
                                           capture_output=True).returncode != 0:
        pytest.skip("mounting a tmpfs needs root")
    yield mount
    subprocess.run(["umount", str(mount)], check=True)


def test_a_real_full_disk_keeps_the_completed_runs(tiny_disk):
    """The same on a real full file system (ENOSPC from the kernel, not a stand-in)."""
    runs = tuple(make_run(i + 1, n=1000) for i in range(4))  # ~45 KB each: the 64 KiB disk fills in run 2
    path = tiny_disk / "full.mcap"
    with pytest.raises(RecordingError, match=r"cannot write run 'r2' .*the 1 completed run\(s\) \(r1\)"):
        write_experiment(path, Experiment(runs, STRUCTURE, SCENARIO, SCENARIO_TEXT))
    got = read_noting(path)
    assert [r.name for r in got.runs] == ["r1"] and got.notes


def _with_summary(tmp_path, mangle) -> Experiment:
    path = tmp_path / "rec.mcap"
    write_experiment(path, experiment(2))
    data = bytearray(path.read_bytes())
    mangle(data)
    path.write_bytes(bytes(data))
    return read_noting(path)


FOOTER = 8 + 29  # the footer record and the closing magic, from the end of the file


def _summary_start(data) -> int:
    return struct.unpack_from("<Q", data, len(data) - FOOTER + 9)[0]


def test_a_damaged_summary_crc_is_read_whole_with_a_note(tmp_path):
    """docs/recording-format.md: damage only in the summary or footer returns all runs, complete, with
    a note (issue 12: the note was missing)."""
    def flip_crc(data):
        data[len(data) - 8 - 4] ^= 0xFF

    got = _with_summary(tmp_path, flip_crc)
    assert got.complete and [r.name for r in got.runs] == ["r1", "r2"]
    assert len(got.notes) == 1 and "summary CRC mismatch" in got.notes[0]


@pytest.mark.parametrize("opcode, name", [(0x08, "ChunkIndex"), (0x0D, "MetadataIndex")])
def test_an_index_pointing_astray_is_named_even_without_a_summary_crc(tmp_path, opcode, name):
    """A writer may leave the summary CRC 0 (unchecked); an index whose offset points at no such
    record is still reported."""
    def misdirect(data):
        struct.pack_into("<I", data, len(data) - 8 - 4, 0)  # summary CRC 0: not checked
        at = _summary_start(data)
        while data[at] != opcode:
            at += 9 + struct.unpack_from("<Q", data, at + 1)[0]
        offset_field = at + 9 + (16 if opcode == 0x08 else 0)  # chunk_start_offset / offset
        struct.pack_into("<Q", data, offset_field, 1)

    got = _with_summary(tmp_path, misdirect)
    assert got.complete and len(got.runs) == 2
    assert len(got.notes) == 1 and f"{name} points at byte 1" in got.notes[0]


def test_notes_name_the_planned_runs_a_truncated_file_lost(tmp_path):
    """The scenario text stored in the file lists the runs planned: a truncated file's note names the
    ones that never arrived (issue 12: 'must say which runs were lost')."""
    text = SCENARIO_TEXT + "".join(f'[[runs]]\nname = "r{i}"\n' for i in (1, 2, 3))
    exp = dataclasses.replace(experiment(3), scenario_text=text)
    path = tmp_path / "rec.mcap"
    with RecordingWriter(path, structure=STRUCTURE, scenario=SCENARIO, scenario_text=text) as writer:
        writer.write_run(exp.runs[0])
        cut = path.stat().st_size
        writer.write_run(exp.runs[1])
    path.write_bytes(path.read_bytes()[:cut])
    got = read_noting(path)
    assert [r.name for r in got.runs] == ["r1"]
    assert "lost 2 of the 3 planned runs (r2, r3)" in got.notes[0]


def test_a_huge_length_field_inside_a_record_is_damage_not_memory_error(tmp_path):
    """Fuzzing found it: a chunk whose inner data-length field claims 2**57 bytes made the stock reader
    allocate them (MemoryError); reading now stops there as at any damage."""
    path = tmp_path / "rec.mcap"
    write_experiment(path, experiment(2))
    data = bytearray(path.read_bytes())
    chunk = data.index(b"\x06", 8 + 9 + 4)  # the first chunk record after the header
    # chunk body: start(8) end(8) uncompressed_size(8) crc(4) compression "" (4 + 0) then data length (8)
    struct.pack_into("<Q", data, chunk + 9 + 8 + 8 + 8 + 4 + 4, 2**57)
    path.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="no completed run to recover"):
        read_noting(path)
