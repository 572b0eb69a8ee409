"""Issue 32: one output rule for every command; never lose a user's file.

Every command writes only the files it owns, each whole; it never overwrites or deletes a file it did
not write (without --force); it follows no symbolic link onto another file; its errors name the
user's path; it removes its own stale files.  Each data-loss case the issue lists is a test here.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import momentid as mi
from momentid.cli import main
from momentid.core.series import Experiment, run_name_problem
from momentid.errors import OutputRefusedError
from momentid.io.outputs import MANIFEST, OwnedFolder, check_file
from momentid.io.recording import write_experiment
from momentid.twin.plots import replay_file


def _refused(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def _files(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """The two-storey lab of test_twin (two simulated trials) as a recording, and its twin's folder."""
    from test_twin import as_recorded, lab, scenario

    runs = [as_recorded(mi.simulate(scenario(rms, seed)).runs[0], name, seed)
            for name, rms, seed in (("small", 0.3, 1), ("large", 0.8, 2))]
    folder = tmp_path_factory.mktemp("rig")
    return lab(runs), write_experiment(folder / "rig.mcap", lab(runs))


@pytest.fixture(scope="module")
def built(rig):
    return mi.twin.build_twin(rig[0])


# ------------------------------------------------------------------------------------------ twin -o

def test_twin_never_replaces_a_users_folder(tmp_path, rig, capsys):
    """Data loss 1: a folder holding the user's recording, thesis and a twin.json saved from `twin --json`
    was replaced whole, deleting everything else in it."""
    experiment, rec = rig
    folder = tmp_path / "work"
    folder.mkdir()
    (folder / "flex3.mcap").write_bytes(rec.read_bytes())
    (folder / "thesis.tex").write_text("\\chapter{Results}")
    (folder / "twin.json").write_text('{"saved": "from twin --json"}')
    before = _files(folder)
    error = _refused(capsys, ["twin", str(rec), "-o", str(folder), "--no-plots"])
    assert f"-o {folder}" in error and "twin.json" in error and "--force" in error, error
    assert _files(folder) == before
    # Without the colliding twin.json, the twin goes in beside the user's files, which stay as they were.
    (folder / "twin.json").unlink()
    assert main(["twin", str(rec), "-o", str(folder), "--no-plots"]) == 0
    assert (folder / "thesis.tex").read_text() == "\\chapter{Results}"
    assert (folder / "flex3.mcap").read_bytes() == rec.read_bytes()
    assert {"twin.json", "twin.xml", MANIFEST} <= set(os.listdir(folder))


def test_reusing_a_twin_folder_keeps_the_users_files(tmp_path, rig, built):
    """Data loss 2: a file the user added to a twin folder was deleted without a word by the next twin."""
    experiment, _ = rig
    out = tmp_path / "twin"
    mi.twin.write_twin(built, experiment, out, plots=False)
    (out / "notes.md").write_text("gain of a1 looks high")
    mi.twin.write_twin(built, experiment, out, plots=False)
    assert (out / "notes.md").read_text() == "gain of a1 looks high"
    # A twin file the user edited is no longer the command's: refused, kept, unless forced.
    (out / "twin.xml").write_text("<mujoco/> <!-- my edit -->")
    with pytest.raises(OutputRefusedError, match="twin.xml.*changed since momentid wrote it"):
        mi.twin.write_twin(built, experiment, out, plots=False)
    assert (out / "twin.xml").read_text() == "<mujoco/> <!-- my edit -->"
    mi.twin.write_twin(built, experiment, out, plots=False, force=True)
    assert (out / "twin.xml").read_text() == built.xml


def test_a_folder_from_before_the_manifest_says_how_to_proceed(tmp_path, rig, built, capsys):
    """A twin folder written before momentid kept .momentid.json (or files of the user's under the
    command's names) is refused in one line saying exactly that, and that --force proceeds; forced
    once, the folder keeps the list and the next run needs no --force."""
    experiment, rec = rig
    out = tmp_path / "twin"
    mi.twin.write_twin(built, experiment, out, plots=False)
    (out / MANIFEST).unlink()                                  # as an older momentid left it
    before = _files(out)
    error = _refused(capsys, ["twin", str(rec), "-o", str(out), "--no-plots"])
    assert error.startswith(f"error: -o {out}: the folder holds ") and "(and " in error, error
    assert f"and no {MANIFEST}, the list of the files momentid wrote there" in error, error
    assert "expected a new folder, or --force to overwrite these files once you know they are not yours" in error
    assert _files(out) == before
    assert main(["twin", str(rec), "-o", str(out), "--no-plots", "--force"]) == 0
    assert (out / MANIFEST).is_file()
    assert main(["twin", str(rec), "-o", str(out), "--no-plots"]) == 0


def test_plot_names_never_collide(tmp_path, rig, built):
    """Data loss 3: trials "trial 1", "trial_1" and "trial.1" all wrote replay_trial_1.png."""
    experiment, _ = rig
    names = ["trial 1", "trial_1", "trial.1"]
    runs = [dataclasses.replace(experiment.runs[i % 2], name=n) for i, n in enumerate(names)]
    lab = Experiment(runs=tuple(runs), statement=experiment.statement, source="lab.mcap")
    twin = mi.twin.build_twin(lab, ["trial 1", "trial_1"])
    written = mi.twin.write_twin(twin, lab, tmp_path / "twin")
    plots = [n for n in written if n.startswith("replay_")]
    assert len(plots) == 3 == len(set(plots)) and "replay_trial_1.png" in plots
    assert all((tmp_path / "twin" / n).is_file() for n in plots)


def test_twin_into_the_current_folder(tmp_path, rig, capsys, monkeypatch):
    """Messy refusal 2: `twin -o .` failed with "Device or resource busy" after the whole twin was built."""
    monkeypatch.chdir(tmp_path)
    assert main(["twin", str(rig[1]), "-o", ".", "--no-plots"]) == 0, capsys.readouterr().err
    assert {"twin.json", "twin.xml"} <= set(os.listdir(tmp_path))


def test_unwritable_folder_is_refused_before_the_work_naming_the_users_path(capsys):
    """Messy refusal 3: a read-only folder's error named the hidden `.twin.xxxx.partial`, after the work.
    /sys refuses new files even to root (the tests may run as root, whom permissions do not stop)."""
    out = "/sys/kernel/momentid_twin"
    if os.access("/sys/kernel", os.W_OK) and not Path("/sys/kernel").is_dir():
        pytest.skip("no /sys on this system")
    error = _refused(capsys, ["twin", "no_such_recording.mcap", "-o", out])
    assert error.startswith(f"error: -o {out}: cannot create files in /sys/kernel"), error
    assert ".partial" not in error   # and the recording was not even read: no "no_such_recording" error


# ----------------------------------------------------------------------------------- single files

def test_import_follows_no_symlink_onto_another_file(tmp_path, capsys):
    """Data loss 4: `import -o rec.mcap`, rec.mcap a link to an unrelated file, overwrote that file."""
    from bad_input.csv_import import lab_folder

    lab = lab_folder(tmp_path)
    precious = tmp_path / "thesis.tex"
    precious.write_text("years of work")
    link = tmp_path / "rec.mcap"
    link.symlink_to(precious)
    error = _refused(capsys, ["import", str(lab), "-o", str(link)])
    assert f"-o {link}: a symbolic link" in error, error
    assert precious.read_text() == "years of work" and link.is_symlink()
    # --force replaces the link itself with the recording; the file it pointed to is untouched.
    assert main(["import", str(lab), "-o", str(link), "--force"]) == 0
    assert not link.is_symlink() and precious.read_text() == "years of work"
    assert len(mi.read_recording(link).runs) == 2


def test_a_failed_reimport_keeps_the_previous_recording(tmp_path, capsys, monkeypatch):
    """`import -o rec.mcap` over an earlier recording wrote the new one in its place from the first byte:
    a failure half-way (a full disk, Ctrl-C) lost the earlier recording.  Now the new one is written
    beside it and renamed into place once complete; the completed runs of a failed one stay readable
    beside the kept file."""
    import momentid.io.recording as recording
    from bad_input.csv_import import lab_folder
    from bad_input.faults import fill_disk_at

    lab = lab_folder(tmp_path)
    out, partial = tmp_path / "rec.mcap", tmp_path / "rec.mcap.partial"
    assert main(["import", str(lab), "-o", str(out)]) == 0
    before = out.read_bytes()
    with monkeypatch.context() as m:     # a disk that takes the header and run r1 of the new file, not r2
        fill_disk_at(m, recording, len(before) // 2 + 200)
        error = _refused(capsys, ["import", str(lab), "-o", str(out)])
    assert f"{out}: cannot write run 'r2'" in error and "the file there is kept" in error, error
    assert f"the 1 completed run(s) (r1) are in {partial}" in error, error
    assert out.read_bytes() == before
    with pytest.warns(mi.errors.RecoveryWarning):
        assert [r.name for r in mi.read_recording(partial).runs] == ["r1"]
    with monkeypatch.context() as m:     # Ctrl-C after run r1
        write_run = recording.RecordingWriter.write_run
        m.setattr(recording.RecordingWriter, "write_run", lambda self, run, **k: (
            write_run(self, run, **k) if run.name == "r1" else (_ for _ in ()).throw(KeyboardInterrupt())))
        assert main(["import", str(lab), "-o", str(out)]) == 130
    err = capsys.readouterr().err
    assert f"note: {out}: not replaced, the file there is kept; the 1 completed run(s) of the new recording (r1) " \
           f"are in {partial}" in err and "error: interrupted" in err, err
    assert out.read_bytes() == before
    assert main(["import", str(lab), "-o", str(out)]) == 0          # complete: renamed into place
    assert "an existing file, replaced by this recording" in capsys.readouterr().err
    assert not partial.exists() and len(mi.read_recording(out).runs) == 2


def test_a_users_file_at_the_temporary_name_is_refused_unless_forced(tmp_path, capsys):
    """An output is written to `<name>.partial` first: a user's file of that name is refused (view --save
    used to truncate it and rename it over the output); --force removes it; what a killed writer of the
    same kind left there is written over."""
    from bad_input.csv_import import lab_folder

    lab = lab_folder(tmp_path)
    out, partial = tmp_path / "rec.mcap", tmp_path / "rec.mcap.partial"
    partial.write_text("years of work")
    error = _refused(capsys, ["import", str(lab), "-o", str(out)])
    assert f"-o {out}: {partial} beside it is not an MCAP recording" in error and "--force removes it" in error
    assert partial.read_text() == "years of work" and not out.exists()
    assert main(["import", str(lab), "-o", str(out), "--force"]) == 0
    assert not partial.exists() and len(mi.read_recording(out).runs) == 2
    partial.write_bytes(out.read_bytes()[:100])                      # a writer killed in the header
    assert main(["import", str(lab), "-o", str(out)]) == 0
    assert not partial.exists() and len(mi.read_recording(out).runs) == 2


def test_a_writer_killed_beside_a_recording_keeps_both(tmp_path):
    """SIGKILL while a new recording is written over an earlier one: the earlier one is whole, and the
    new one's completed runs read back from the partial file beside it, with a note."""
    import subprocess
    import sys

    from bad_input.recording import tiny_experiment

    out = tmp_path / "rec.mcap"
    write_experiment(out, tiny_experiment(1))
    before = out.read_bytes()
    script = ("import os, signal, sys; sys.path.insert(0, 'tests')\n"
              "from bad_input.recording import tiny_experiment\n"
              "from momentid.io.recording import RecordingWriter\n"
              "e = tiny_experiment(3)\n"
              f"w = RecordingWriter({str(out)!r}, structure=e.structure, scenario=e.scenario)\n"
              "w.write_run(e.runs[0]); w.write_run(e.runs[1])\n"
              "os.kill(os.getpid(), signal.SIGKILL)\n")
    proc = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).resolve().parents[1])
    assert proc.returncode == -9
    assert out.read_bytes() == before
    with pytest.warns(mi.errors.RecoveryWarning):
        kept = mi.read_recording(tmp_path / "rec.mcap.partial")
    assert [r.name for r in kept.runs] == ["r1", "r2"] and not kept.complete


def test_run_and_import_refuse_a_file_that_is_not_a_recording(tmp_path, capsys):
    from bad_input.csv_import import lab_folder

    lab = lab_folder(tmp_path)
    notes = tmp_path / "notes.mcap"
    notes.write_text("not a recording")
    assert "not an MCAP recording" in _refused(capsys, ["import", str(lab), "-o", str(notes)])
    assert notes.read_text() == "not a recording"
    # A recording written before is the command's own kind: replaced, with a note.
    out = tmp_path / "lab.mcap"
    assert main(["import", str(lab), "-o", str(out)]) == 0
    assert main(["import", str(lab), "-o", str(out)]) == 0
    assert "an existing file, replaced" in capsys.readouterr().err


@pytest.mark.parametrize("target", ["twin.xml", "experiment.toml"])
def test_view_save_refuses_a_file_that_is_not_a_rerun_recording(tmp_path, capsys, target):
    """Data loss 7 and 8: `view --save DIR/twin.xml` replaced the MJCF with an .rrd, and `--save
    experiment.toml` that file; only .mcap targets were protected."""
    from bad_input.recording import tiny_experiment

    rec = write_experiment(tmp_path / "rec.mcap", tiny_experiment())
    path = tmp_path / target
    path.write_text("<mujoco model='mine'/>")
    error = _refused(capsys, ["view", str(rec), "--save", str(path)])
    assert error.startswith(f"error: --save {path}: an existing file that is not a rerun recording"), error
    assert path.read_text() == "<mujoco model='mine'/>"


def test_sweep_table_refuses_a_users_file(tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text("[sweep]\nbase = 'nowhere.toml'\n[grid]\n'scenario.seed' = [0]\n")
    table = tmp_path / "results.csv"
    table.write_text("my,own,numbers\n1,2,3\n")
    assert "not a result table" in _refused(capsys, ["sweep", str(spec), "-o", str(table)])
    assert table.read_text() == "my,own,numbers\n1,2,3\n"


# -------------------------------------------------------------------------------------- diagnose -o

@pytest.fixture(scope="module")
def diagnosis(tmp_path_factory):
    from bad_input.cli import recording_file

    rec = recording_file(tmp_path_factory.mktemp("diag"))
    return rec, mi.diagnose(mi.read_recording(rec))


def test_diagnose_never_overwrites_a_twins_files(tmp_path, rig, built, diagnosis, capsys):
    """Data loss 5: `diagnose -o <a twin folder>` overwrote the twin's twin.xml with another K and C."""
    experiment, _ = rig
    out = tmp_path / "twin"
    mi.twin.write_twin(built, experiment, out, plots=False)
    before = _files(out)
    # Refused before the diagnosis starts: the folder's twin.xml is the twin's, and a diagnosis may write one.
    error = _refused(capsys, ["diagnose", str(diagnosis[0]), "-o", str(out)])
    assert f"-o {out}: the folder holds twin.xml" in error and "`momentid twin` wrote it" in error, error
    assert _files(out) == before
    # A report that writes no twin.xml goes in beside the twin, whose files stay as they were.
    written = mi.diagnosis.write_report(diagnosis[1], out)
    assert "twin.xml" not in written
    assert all((out / n).read_bytes() == b for n, b in before.items() if n != MANIFEST)
    assert mi.twin.read_twin(out).K.tolist() == built.parameters.K.tolist()


def test_diagnose_never_overwrites_a_users_report(tmp_path, diagnosis, capsys):
    """Data loss 6: `diagnose -o DIR` overwrote a user's summary.txt and report.json without a word."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / "summary.txt").write_text("my summary")
    (out / "report.json").write_text("{}")
    error = _refused(capsys, ["diagnose", str(diagnosis[0]), "-o", str(out)])
    assert "summary.txt" in error or "report.json" in error
    assert (out / "summary.txt").read_text() == "my summary" and (out / "report.json").read_text() == "{}"


def test_reused_report_folder_loses_its_stale_plots(tmp_path, diagnosis):
    """Silent wrong 9: a reused `diagnose -o` folder kept stale plots beside the new report."""
    out = tmp_path / "report"
    first = mi.diagnosis.write_report(diagnosis[1], out)
    assert "replay.png" in first and "locate.png" in first
    (out / "my_plot.png").write_bytes(b"mine")
    second = mi.diagnosis.write_report(dataclasses.replace(diagnosis[1], curves=None), out)
    assert "replay.png" not in second
    assert not (out / "replay.png").exists() and not (out / "diagnosis.rrd").exists()
    assert (out / "my_plot.png").read_bytes() == b"mine"
    listed = set(json.loads((out / MANIFEST).read_text())["files"])
    assert listed == set(second)


# ------------------------------------------------------------------------------------- identify -o

IDENTIFY_FILES = ["frf.uff", "identification.json", "modes.uff", "report.html"]


def test_identify_never_overwrites_a_users_report(tmp_path, rig, capsys, monkeypatch):
    """`identify -o DIR` wrote report.html, modes.uff, frf.uff and identification.json over a user's files
    of those names: now refused before the work (without --force), beside the user's other files."""
    import momentid.estimation.identification as identification

    _, rec = rig
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "report.html").write_text("<p>my report</p>")
    (out / "thesis.tex").write_text("\\chapter{Results}")
    before = _files(out)
    with monkeypatch.context() as m:    # refused before the identification starts
        m.setattr(identification, "identify", lambda *a, **k: pytest.fail("identified before the refusal"))
        error = _refused(capsys, ["identify", str(rec), "-o", str(out)])
    assert f"-o {out}: the folder holds report.html, which `momentid identify` would overwrite" in error, error
    assert "--force" in error and _files(out) == before
    assert main(["identify", str(rec), "-o", str(out), "--force"]) == 0
    assert sorted(set(os.listdir(out)) - {"thesis.tex", MANIFEST}) == IDENTIFY_FILES
    assert (out / "thesis.tex").read_text() == "\\chapter{Results}"
    listed = set(json.loads((out / MANIFEST).read_text())["files"])
    assert listed == set(IDENTIFY_FILES)


def test_identify_reuses_its_folder_and_drops_its_stale_files(tmp_path, rig, capsys, monkeypatch):
    """A second `identify -o` into its own folder needs no --force; a file it no longer writes (a
    modes.uff that cannot be written now) goes, a user's file stays; a diagnosis's report.html is not
    the identification's to replace."""
    import momentid.report.exports as exports
    from momentid.errors import MomentidError

    _, rec = rig
    out = tmp_path / "id"
    assert main(["identify", str(rec), "-o", str(out)]) == 0
    (out / "notes.md").write_text("mode 2 looks odd")

    def fails(*args, **kwargs):
        raise MomentidError("a mode shape that is not finite")
    monkeypatch.setattr(exports, "modes_uff", fails)
    capsys.readouterr()
    assert main(["identify", str(rec), "-o", str(out)]) == 0
    assert f"warning: {out / 'modes.uff'} not written" in capsys.readouterr().err
    assert not (out / "modes.uff").exists() and (out / "notes.md").read_text() == "mode 2 looks odd"
    assert set(json.loads((out / MANIFEST).read_text())["files"]) == set(IDENTIFY_FILES) - {"modes.uff"}
    report = tmp_path / "report"
    OwnedFolder(report, "diagnose").write(lambda staging: [(staging / "report.html").write_text("x") and "report.html"])
    error = _refused(capsys, ["identify", str(rec), "-o", str(report)])
    assert "report.html" in error and "`momentid diagnose` wrote it" in error, error


# ----------------------------------------------------------------------------- run names, properties

def test_run_names_that_break_reports_are_refused(tmp_path, capsys):
    """Messy refusal 5: run names with newlines, tabs, "/" or ".." broke the printed report lines."""
    from bad_input.csv_import import lab_folder

    for i, bad in enumerate(("trial\n1", "trial\t1", "trial/1", "../up")):
        (tmp_path / str(i)).mkdir()
        lab = lab_folder(tmp_path / str(i))
        text = (lab / "experiment.toml").read_text()
        (lab / "experiment.toml").write_text(text.replace('name = "r1"', f"name = {json.dumps(bad)}", 1))
        assert json.dumps(bad) in (lab / "experiment.toml").read_text()
        error = _refused(capsys, ["import", str(lab), "-o", str(tmp_path / "x.mcap")])
        assert "a run name of one printable line" in error
    assert not (tmp_path / "x.mcap").exists()


#: Run names as a user might type them, or as a broken export might carry them.
run_names = st.text(st.characters(codec="utf-8"), min_size=1, max_size=30) | st.sampled_from(
    ["El Centro Trial 1", "trial 1", "trial_1", "trial.1", "a/b", "..", " x", "x\n", "x\ty", "c:\\d"])


@given(st.lists(run_names, min_size=1, max_size=6, unique=True))
@settings(max_examples=200, deadline=None)
def test_any_accepted_run_names_give_distinct_plain_plot_files(names):
    """Every run name momentid accepts gives its own replay plot, a plain file name."""
    accepted = [n for n in names if run_name_problem(n) is None]
    files = [replay_file(n) for n in accepted]
    assert len(set(files)) == len(files)
    assert all(Path(f).name == f and "\n" not in f and not f.startswith(".") for f in files)
    for n in accepted:   # one printed line, and no path inside it
        assert n == n.strip() and not {"\n", "\r", "\t", "/", "\\"} & set(n) and ".." not in n


#: What may already stand at an output path: nothing, a user's file, a folder, a link to a user's file.
occupants = st.sampled_from(["nothing", "text", "empty", "folder", "link", "recording"])
#: Output names as a user might give them (relative, in the test's folder).
out_names = st.sampled_from(["rec.mcap", "sub/rec.mcap", "a b.mcap", "x.rrd", "table.csv", "twin"]) | st.text(
    st.characters(codec="ascii", categories=("L", "N")), min_size=1, max_size=12).map(lambda s: s + ".mcap")


@given(out_names, occupants, st.booleans())
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_check_file_never_passes_a_users_file_without_force(tmp_path, name, occupant, force):
    """For any output path and whatever stands there, check_file either refuses (one error naming the
    path the user gave) or the path is new, empty, the command's own kind, or forced."""
    folder = Path(tmp_path) / f"case{abs(hash((name, occupant, force))) % 10**8}"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    precious = folder / "precious.txt"
    precious.write_text("mine")
    if not path.exists() and not path.is_symlink():
        if occupant == "text":
            path.write_text("mine")
        elif occupant == "empty":
            path.write_bytes(b"")
        elif occupant == "folder":
            path.mkdir()
        elif occupant == "link":
            path.symlink_to(precious)
        elif occupant == "recording":
            path.write_bytes(b"\x89MCAP0\r\n")
    try:
        check_file(path, "recording", force=force)
    except OutputRefusedError as exc:
        assert str(exc).startswith(f"-o {path}: ") and "\n" not in str(exc)
    else:
        assert (not path.exists() or path.is_symlink() and force or path.stat().st_size == 0
                or path.read_bytes().startswith(b"\x89MCAP") or force)
        assert not path.is_dir()
    assert precious.read_text() == "mine"


@given(st.lists(st.sampled_from(["report.json", "summary.txt", "twin.xml", "notes.txt", "replay.png"]),
                unique=True), st.booleans())
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_an_owned_folder_never_touches_another_file(tmp_path, users, force):
    """Whatever user files stand in the folder, writing the command's files changes none of them,
    unless forced and of the command's names."""
    folder = Path(tmp_path) / f"f{abs(hash((tuple(users), force))) % 10**8}"
    folder.mkdir(parents=True, exist_ok=True)
    for n in users:
        (folder / n).write_text(f"user's {n}")
    ours = ["report.json", "summary.txt"]

    def build(staging):
        for n in ours:
            (staging / n).write_text("momentid")
        return ours

    try:
        OwnedFolder(folder, "diagnose", force=force).write(build)
    except OutputRefusedError as exc:
        assert not force and set(users) & set(ours) and str(exc).startswith(f"-o {folder}: ")
    for n in users:
        expected = "momentid" if force and n in ours else f"user's {n}"
        assert (folder / n).read_text() == expected
    assert not [p for p in folder.iterdir() if p.name.endswith(".partial")]


def test_check_file_sees_a_kind_by_its_bytes(tmp_path):
    rrd, text = tmp_path / "v.rrd", tmp_path / "t.rrd"
    rrd.write_bytes(b"RRF2rest")
    text.write_text("text")
    assert check_file(rrd, "rerun") == rrd
    with pytest.raises(OutputRefusedError, match="not a rerun recording"):
        check_file(text, "rerun")
    with pytest.raises(OutputRefusedError, match="not an MCAP recording"):
        check_file(rrd, "recording")
    assert rrd.read_bytes() == b"RRF2rest" and text.read_text() == "text"


# ------------------------------------------------------------------------ view --twin checks the twin

@pytest.fixture(scope="module")
def twin_folder(tmp_path_factory, rig, built):
    out = tmp_path_factory.mktemp("twin") / "twin"
    mi.twin.write_twin(built, rig[0], out, plots=False)
    return out


def _doctored(tmp_path, twin_folder, edit) -> Path:
    out = tmp_path / "doctored"
    out.mkdir()
    data = json.loads((twin_folder / "twin.json").read_text())
    edit(data)
    (out / "twin.json").write_text(json.dumps(data))
    return out


@pytest.mark.parametrize("edit, words", [
    (lambda d: d["K_N_m"][0].__setitem__(0, float("nan")), "key 'K_N_m'"),          # traceback 2: eigh on NaN
    (lambda d: d["sensors"]["nominal"].__setitem__("gain", [1e308, 1.0]), "sensors.nominal.gain"),
    (lambda d: d.__setitem__("masses_kg", [0.5, -0.4]), "positive floor masses"),
    (lambda d: d["K_N_m"][1].__setitem__(0, 5e3), "a symmetric matrix"),
])
def test_view_twin_refuses_values_no_rig_has(tmp_path, rig, twin_folder, capsys, edit, words):
    """Traceback 2 and silent wrong 8: `view --twin` with NaN in twin.json's K ended in eigh's
    ValueError; a gain of 1e308 was drawn."""
    folder = _doctored(tmp_path, twin_folder, edit)
    error = _refused(capsys, ["view", str(rig[1]), "--twin", str(folder), "--save", str(tmp_path / "v.rrd")])
    assert words in error and "twin.json" in error, error
    assert not (tmp_path / "v.rrd").exists()


def test_view_twin_refuses_the_twin_of_another_recording(tmp_path, rig, twin_folder, capsys):
    """Silent wrong 8: the simulated paper_harmonic twin was overlaid on the real rig without a word,
    although twin.json records what it was calibrated on."""
    experiment, _ = rig
    other = Experiment(runs=tuple(dataclasses.replace(r, name=f"other_{r.name}") for r in experiment.runs),
                       statement=experiment.statement)
    rec = write_experiment(tmp_path / "other.mcap", other)
    error = _refused(capsys, ["view", str(rec), "--twin", str(twin_folder), "--save", str(tmp_path / "v.rrd")])
    assert "no trial named 'small'" in error and "twin of another recording" in error, error
    heavier = dataclasses.replace(experiment.statement, masses=(0.6, 0.4))
    rec = write_experiment(tmp_path / "heavier.mcap", dataclasses.replace(experiment, statement=heavier))
    error = _refused(capsys, ["view", str(rec), "--twin", str(twin_folder), "--save", str(tmp_path / "v.rrd")])
    assert "floor masses" in error and "states [0.6, 0.4]" in error, error


# ------------------------------------------------------------------- smaller: units of the modal JSON

def test_modal_json_says_the_unit_of_every_matrix(rig):
    """The modal `identify --json` gave K, C, M and M^-1 K with no unit in the key or a units table."""
    payload = mi.identify(rig[0]).to_dict()
    assert payload["units"]["K"] == "N/m" and payload["units"]["C"] == "N s/m" and payload["units"]["M"] == "kg"
    assert payload["units"]["M^-1 K"] == "1/s^2" and payload["units"]["M^-1 C"] == "1/s"
    assert all(key in payload for key in payload["units"])   # a unit for a key the payload has
