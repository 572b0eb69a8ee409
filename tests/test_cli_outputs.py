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
        from momentid.cli import _only_json_on_stdout
        with _only_json_on_stdout(True):
            os.write(1, b" ** On entry to DLASCL parameter number 4 had an illegal value\\n")
            print(json.dumps({"ok": 1}))
        print("after")
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    first, after = proc.stdout.strip().splitlines()
    assert json.loads(first) == {"ok": 1} and after == "after"
    assert "DLASCL" in proc.stderr
