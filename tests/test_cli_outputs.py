"""Issue 12 regressions at the command line: output paths, OS failures and --json purity."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from momentid import cli


def _run(*argv: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "momentid", *argv], capture_output=True, text=True, cwd=cwd)


def test_output_into_an_impossible_folder_is_one_line(tmp_path):
    proc = _run("run", "-o", "/proc/momentid_cannot_exist")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.startswith("error: ") and "/proc/momentid_cannot_exist" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("argv", [("run", "-o", "existing_file"), ("run", "-o", "existing_file/sub"),
                                  ("diagnose", "rec.mcap", "-o", "existing_file")])
def test_output_onto_an_existing_file_is_refused(tmp_path, capsys, argv):
    (tmp_path / "existing_file").write_text("keep me")
    (tmp_path / "rec.mcap").write_bytes(b"")
    argv = [a if a in ("run", "diagnose", "-o") else str(tmp_path / a) for a in argv]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "existing_file" in err
    assert (tmp_path / "existing_file").read_text() == "keep me"


def test_json_mode_sends_native_writes_to_stderr():
    """Native code (LAPACK's xerbla) writes to file descriptor 1 directly; with --json those
    bytes must not reach stdout, which carries exactly one JSON object."""
    code = textwrap.dedent("""
        import json, os, sys
        from momentid.cli import only_json_on_stdout
        with only_json_on_stdout(True):
            os.write(1, b" ** On entry to DLASCL parameter number 4 had an illegal value\\n")
            print(json.dumps({"ok": 1}))
        print("after")
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    first, after = proc.stdout.strip().splitlines()
    assert json.loads(first) == {"ok": 1} and after == "after"
    assert "DLASCL" in proc.stderr


def test_view_save_on_a_full_disk_is_an_error_and_leaves_no_truncated_file(tmp_path, capsys, monkeypatch):
    """Issue 12: `view --save` on a full disk printed '-> x.rrd' and exit 0 over a truncated file
    (rerun's own file sink drops write errors); now the file is written whole or not at all."""
    import errno

    import momentid.io.exclusive as exclusive
    from momentid.io.recording import write_experiment
    from bad_input.recording import tiny_experiment

    rec = tmp_path / "rec.mcap"
    write_experiment(rec, tiny_experiment())
    locked = exclusive.open_locked

    def full(path):   # the .rrd's temporary file, on a disk that takes no more bytes
        f = locked(path)
        f.write = lambda data: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space left on device"))
        return f

    monkeypatch.setattr(exclusive, "open_locked", full)
    out = tmp_path / "v.rrd"
    assert cli.main(["view", str(rec), "--save", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("error: ") and "No space left on device" in captured.err
    assert len(captured.err.strip().splitlines()) == 1 and "->" not in captured.out
    assert not out.exists() and not list(tmp_path.glob("*.partial"))


def test_a_recovered_file_prints_one_note_line_and_no_source_line(tmp_path):
    """Issue 12: the recovery warning printed an internal source line (`experiment = read_recording(...)`)."""
    from momentid.io.recording import RecordingWriter
    from bad_input.recording import tiny_experiment

    rec = tmp_path / "rec.mcap"
    experiment = tiny_experiment()
    with RecordingWriter(rec, structure=experiment.structure, scenario=experiment.scenario) as writer:
        writer.write_run(experiment.runs[0])
        cut = rec.stat().st_size
        writer.write_run(experiment.runs[1])
    rec.write_bytes(rec.read_bytes()[:cut])
    proc = _run("view", str(rec), "--save", str(tmp_path / "v.rrd"))
    assert proc.returncode == 0, proc.stderr
    notes = [line for line in proc.stderr.splitlines() if "truncated after run" in line]
    assert len(notes) == 1 and notes[0].startswith("note: ")
    assert "read_recording(" not in proc.stderr and ".py:" not in proc.stderr


def test_import_onto_a_full_disk_is_one_line_and_keeps_the_completed_runs(tmp_path, capsys, monkeypatch):
    """Issue 12: disk full during import ended in three chained OSErrors."""
    import momentid.io.recording as recording
    from bad_input.csv_import import lab_folder
    from bad_input.faults import fill_disk_at

    lab = lab_folder(tmp_path)
    out = tmp_path / "lab.mcap"
    assert cli.main(["import", str(lab), "-o", str(tmp_path / "whole.mcap")]) == 0
    capsys.readouterr()
    from momentid.io.recording import read_recording
    whole = read_recording(tmp_path / "whole.mcap")
    room = (tmp_path / "whole.mcap").stat().st_size // 2 + 200  # the header and r1, not r2 (equal runs)
    assert len(whole.runs) == 2
    fill_disk_at(monkeypatch, recording, room)
    assert cli.main(["import", str(lab), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "cannot write run 'r2'" in err and "(r1)" in err
    monkeypatch.undo()
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert [r.name for r in read_recording(out).runs] == ["r1"]


def test_diagnose_json_names_the_runs_a_truncated_recording_lost(tmp_path):
    """Issue 12: the note of lost runs went only to stderr, not to `diagnose --json` or report.json."""
    from bad_input.cli import recording_file

    rec = recording_file(tmp_path, cut_after=2)
    proc = _run("diagnose", str(rec), "--json", "-o", str(tmp_path / "report"))
    payload = json.loads(proc.stdout)
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert any("m2" in n for n in payload.get("notes", [])) and any("m2" in n for n in report.get("notes", []))


def test_run_onto_a_full_disk_is_one_line_and_keeps_the_completed_runs(tmp_path, capsys, monkeypatch):
    """Issue 12: disk full during `momentid run` ended in three chained OSErrors (recording.py close)."""
    import warnings

    import momentid.io.recording as recording
    from bad_input.cli import THREE_RUNS, recording_bytes
    from bad_input.faults import fill_disk_at
    from bad_input.scenario import write
    from momentid.io.recording import read_recording

    _, sizes = recording_bytes()  # the same three-run scenario written whole: the size after each run
    scenario = write(tmp_path, text=THREE_RUNS)
    fill_disk_at(monkeypatch, recording, (sizes[0] + sizes[1]) // 2)  # full in the middle of run 2
    out = tmp_path / "out.mcap"
    assert cli.main(["run", str(scenario), "-q", "-j", "1", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "cannot write run 'm1'" in err and "(ref)" in err
    monkeypatch.undo()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert [r.name for r in read_recording(out).runs] == ["ref"]
