"""The command line: wrong paths, wrong options and damaged inputs, run in-process through
``momentid.cli.main``; every failure must be ``error: ...`` on one line, exit code 2, no traceback."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import momentid as mi

from ._core import Case, CliResult, Group, Outcome, cli
from .csv_import import lab_folder
from .faults import held
from .scenario import BASE, write

#: Three runs (two with added mass) of the tiny scenario: enough for every estimator.
THREE_RUNS = BASE + '\n[[runs]]\nname = "m2"\nadded_mass = [1.0, 0.0]\n'


@functools.cache
def recording_bytes(sensors: str = "") -> tuple[bytes, tuple[int, ...]]:
    """A simulated recording of the tiny scenario (ideal sensors unless ``sensors`` says otherwise)
    and the file size after each run; simulated once per process."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.toml"
        path.write_text(THREE_RUNS + sensors)
        experiment = mi.simulate(mi.load_scenario(path))
        out = Path(tmp) / "rec.mcap"
        sizes = []
        from momentid.io.recording import RecordingWriter
        with RecordingWriter(out, structure=experiment.structure, scenario=experiment.scenario,
                             scenario_text=experiment.scenario_text) as writer:
            for run in experiment.runs:
                writer.write_run(run)
                sizes.append(out.stat().st_size)
        return out.read_bytes(), tuple(sizes)


def recording_file(folder: Path, cut_after: int | None = None, sensors: str = "", flip_in: int | None = None) -> Path:
    """The simulated recording, cut after run ``cut_after`` or with a byte of run ``flip_in`` (1-based)
    flipped (a chunk CRC mismatch)."""
    data, sizes = recording_bytes(sensors)
    if cut_after is not None:
        data = data[:sizes[cut_after - 1]]
    if flip_in is not None:
        at = (sizes[flip_in - 2] + sizes[flip_in - 1]) // 2
        data = data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1:]
    path = folder / "rec.mcap"
    path.write_bytes(data)
    return path


def _with_rec(*argv, cut_after=None, sensors="", flip_in=None):
    """``momentid <argv>`` where ``REC`` stands for a fresh copy of the simulated recording."""
    def act(folder: Path) -> CliResult:
        rec = recording_file(folder, cut_after, sensors, flip_in)
        return cli(*(rec if a == "REC" else a for a in argv))
    return act


def _in(*argv, setup=None):
    """``momentid <argv>`` in the case's folder after ``setup(folder)``."""
    def act(folder: Path) -> CliResult:
        if setup is not None:
            setup(folder)
        return cli(*argv)
    return act


def _file(name: str, text: str = "keep me"):
    return lambda folder: (folder / name).write_text(text)


def _recording_stub(path: Path) -> None:
    """The first bytes of a recording (an interrupted one, say): momentid's own kind of file there."""
    from momentid.io.mcap_check import MCAP_MAGIC

    path.write_bytes(MCAP_MAGIC)


def _scenario(folder: Path):
    write(folder)


def _noisy_scenario(folder: Path) -> None:
    """The three-run scenario with 1 % sensor noise (a plan needs noise), as ``noisy.toml``."""
    (folder / "noisy.toml").write_text(THREE_RUNS + '[sensors]\nset = "accel+disp"\n[sensors.accelerometer]\n'
                                       'relative_noise = 0.01\n[sensors.displacement]\nrelative_noise = 0.01\n')


def _lab_with(r1: str):
    return lambda folder: lab_folder(folder, r1=r1)


def _json_notes(*argv, cut_after=None, flip_in=None):
    """``--json`` on a damaged recording: stdout must be one JSON object that carries the note of the
    lost run (a script reads only stdout)."""
    def act(folder: Path) -> CliResult:
        result = _with_rec(*argv, cut_after=cut_after, flip_in=flip_in)(folder)
        payload = json.loads(result.stdout)
        notes = payload.get("notes") or payload.get("lost_runs")
        if not notes:
            return CliResult(result.code, result.stdout, "")  # no note anywhere a script reads
        return CliResult(result.code, result.stdout, "note: " + json.dumps(notes))
    return act


def _aborted_rec(folder: Path) -> Path:
    """The simulated recording as a Ctrl-C'd `momentid run` leaves it: two of its three planned runs,
    then the writer's abort record."""
    import warnings

    from momentid.io.recording import RecordingWriter, read_recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        experiment = read_recording(recording_file(folder))
    path = folder / "aborted.mcap"
    try:
        with RecordingWriter(path, structure=experiment.structure, scenario=experiment.scenario,
                             scenario_text=THREE_RUNS) as writer:
            for run in experiment.runs[:2]:
                writer.write_run(run)
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass
    return path


def _aborted_notes(*argv):
    """``momentid identify <aborted recording> <argv> --json``: the note of the lost run must be in the
    JSON, worded as the whole-file read words it (one way to say it, streamed or not)."""
    def act(folder: Path) -> CliResult:
        path = _aborted_rec(folder)
        whole = json.loads(cli("identify", path, "--json").stdout).get("notes")
        result = cli("identify", path, *argv, "--json")
        notes = json.loads(result.stdout).get("notes")
        if not notes or notes != whole:
            return CliResult(result.code, result.stdout, "")   # no note, or another one than the whole read's
        return CliResult(result.code, result.stdout, "note: " + json.dumps(notes))
    return act


def _while_held(kind: str, output: str, *argv, setup=None, rec=False):
    """``momentid <argv>`` while another process holds ``output`` (``file``, ``whole`` or ``folder``:
    :func:`.faults.held`); ``REC`` in ``argv`` stands for the simulated recording."""
    def act(folder: Path) -> CliResult:
        if setup is not None:
            setup(folder)
        path = recording_file(folder) if rec else None
        with held(kind, folder / output):
            return cli(*(path if a == "REC" else a for a in argv))
    return act


def _edited(edit, *argv):
    """``momentid identify REC <argv>`` on the simulated recording with its runs edited by
    ``edit(run) -> RunData`` (a lab's slip: wrong units, swapped columns)."""
    def act(folder: Path) -> CliResult:
        import dataclasses
        import warnings

        from momentid.io.recording import read_recording, write_experiment

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            experiment = read_recording(recording_file(folder))
        runs = tuple(edit(r) for r in experiment.runs)
        path = write_experiment(folder / "edited.mcap", dataclasses.replace(experiment, runs=runs))
        return cli("identify", path, *argv)
    return act


def _scaled(run, channels, factor):
    import dataclasses

    values = run.values.copy()
    for c in channels:
        values[:, run.channels.index(c)] *= factor
    return dataclasses.replace(run, values=values)


def _floors_in_g(run):
    return _scaled(run, ("a1", "a2"), 1 / 9.80665)  # a lab that exported g, not m/s^2


def _grams(run):
    import dataclasses

    return dataclasses.replace(run, added_mass=run.added_mass * 1000)  # added masses typed in grams


def _swapped(run):
    import dataclasses

    order = [run.channels.index(c) for c in run.channels]
    i, j = run.channels.index("a1"), run.channels.index("a2")
    order[i], order[j] = j, i
    return dataclasses.replace(run, values=run.values[:, order])


_REFUSE = "needs momentid.estimation (identification/comparison): refuse or warn loudly when "

_ACCEL_ONLY = '\n[sensors]\nset = "accel"\n'
_XFAIL_ID = "needs momentid.estimation.identification"

CASES = [
    Case(Group.CLI, "run-missing-scenario", Outcome.ERROR, _in("run", "none.toml"), ("none.toml",)),
    Case(Group.CLI, "run-bad-scenario-key", Outcome.ERROR,
         _in("run", "s.toml", setup=lambda f: write(f, "duration = 0.5", "duration = -2.0")),
         ("s.toml", "duration", "-2.0")),
    Case(Group.CLI, "run-output-in-proc", Outcome.ERROR,
         _in("run", "s.toml", "-q", "-o", "/proc/momentid_x", setup=_scenario), ("/proc/momentid_x",)),
    Case(Group.CLI, "run-output-is-a-file", Outcome.ERROR,
         _in("run", "s.toml", "-o", "taken", setup=lambda f: (_scenario(f), _file("taken")(f))), ("taken",)),
    # an existing recording is replaced (a simulation can be made again: same scenario, same seed), and said
    Case(Group.CLI, "run-output-exists", Outcome.RECOVERY,
         _in("run", "s.toml", "-q", "-o", "o.mcap", setup=lambda f: (_scenario(f), _recording_stub(f / "o.mcap"))),
         ("o.mcap: an existing file, replaced by this recording",)),
    # a file of the user's under a .mcap name is theirs: refused (issue 32), kept
    Case(Group.CLI, "run-output-is-a-users-file", Outcome.ERROR,
         _in("run", "s.toml", "-q", "-o", "o.mcap", setup=lambda f: (_scenario(f), _file("o.mcap")(f))),
         ("-o o.mcap", "not an MCAP recording", "--force")),
    Case(Group.CLI, "run-mass-1e308", Outcome.ERROR,
         _in("run", "s.toml", "-q", "-o", "o.mcap", setup=lambda f: write(f, "masses = [10.0, 12.0]",
                                                                           "masses = [1e308, 12.0]")),
         ("s.toml", "structure.masses[0]", "1e+308")),
    Case(Group.CLI, "run-stiffness-1e308", Outcome.ERROR,
         _in("run", "s.toml", "-q", "-o", "o.mcap", setup=lambda f: write(f, "storey_stiffness = [2000.0, 1500.0]",
                                                                           "storey_stiffness = [2000.0, 1e308]")),
         ("s.toml", "storey_stiffness[1]", "1e+308")),
    Case(Group.CLI, "run-workers-zero", Outcome.ERROR, _in("run", "-j", "0"), ("-j", "'0'")),
    Case(Group.CLI, "run-workers-word", Outcome.ERROR, _in("run", "-j", "many"), ("'many'",)),
    Case(Group.CLI, "run-sample-rate-1e12", Outcome.REFUSAL,
         _in("run", "s.toml", "-o", "out", setup=lambda f: write(f, "sample_rate = 200.0", "sample_rate = 1e12")),
         ("tiny", "refused")),
    Case(Group.CLI, "unknown-command", Outcome.ERROR, _in("simulate"), ("'simulate'",)),
    Case(Group.CLI, "identify-missing-file", Outcome.ERROR, _in("identify", "none.mcap"), ("none.mcap",)),
    Case(Group.CLI, "identify-garbage-file", Outcome.ERROR,
         _in("identify", "g.mcap", setup=_file("g.mcap", "not a recording")), ("g.mcap", "not an MCAP")),
    Case(Group.CLI, "identify-a-folder", Outcome.ERROR, _in("identify", "."), ("cannot open",)),
    Case(Group.CLI, "identify-estimator-unknown", Outcome.ERROR, _in("identify", "x.mcap", "--estimator", "svd"),
         ("'svd'",)),
    Case(Group.CLI, "identify-time-word", Outcome.ERROR, _in("identify", "x.mcap", "--time", "noon"), ("'noon'",)),
    Case(Group.CLI, "identify-unknown-run", Outcome.ERROR, _with_rec("identify", "REC", "--runs", "ref,nope"),
         ("nope",)),
    Case(Group.CLI, "identify-truncated", Outcome.RECOVERY, _with_rec("identify", "REC", cut_after=2),
         ("truncated after run 'm1'",)),
    Case(Group.CLI, "identify-truncated-json", Outcome.RECOVERY,
         _json_notes("identify", "REC", "--json", cut_after=2), ("truncated",)),
    Case(Group.CLI, "identify-stream-truncated", Outcome.RECOVERY,
         _with_rec("identify", "REC", "--stream", cut_after=2), ("m2",)),
    Case(Group.CLI, "identify-stream-truncated-json", Outcome.RECOVERY,
         _json_notes("identify", "REC", "--stream", "--json", cut_after=2), ("m2",)),
    Case(Group.CLI, "identify-crc-damaged", Outcome.RECOVERY, _with_rec("identify", "REC", flip_in=3),
         ("corrupted after run 'm1'", "(m2)")),
    Case(Group.CLI, "identify-stream-crc-damaged-json", Outcome.RECOVERY,
         _json_notes("identify", "REC", "--stream", "--json", flip_in=3), ("CRCValidationError", "m2")),
    # issue 22: a run named twice counted twice (every standard error shrank by sqrt 2)
    Case(Group.CLI, "identify-runs-twice", Outcome.ERROR, _with_rec("identify", "REC", "--runs", "ref,m1,ref"),
         ("--runs", "'ref'", "twice")),
    Case(Group.CLI, "identify-runs-empty-name", Outcome.ERROR, _with_rec("identify", "REC", "--runs", "ref,,m1"),
         ("--runs", "empty")),
    Case(Group.CLI, "identify-per-run-twice", Outcome.ERROR,
         _with_rec("identify", "REC", "--per-run", "--runs", "ref,ref"), ("'ref'", "twice")),
    Case(Group.CLI, "run-runs-unknown", Outcome.ERROR,
         _in("run", "s.toml", "-q", "--runs", "ref,nope", "-o", "o.mcap", setup=_scenario), ("'nope'", "s.toml")),
    # issue 22: after a Ctrl-C'd run, --stream said nothing of the lost run (the whole read did)
    Case(Group.CLI, "identify-aborted-json", Outcome.RECOVERY, _aborted_notes(), ("aborted", "(m2)")),
    Case(Group.CLI, "identify-stream-aborted-json", Outcome.RECOVERY, _aborted_notes("--stream"),
         ("aborted", "(m2)")),
    Case(Group.CLI, "identify-stream-estimator-eiv", Outcome.ERROR,
         _with_rec("identify", "REC", "--stream", "--estimator", "eiv"), ("--stream", "--estimator eiv")),
    Case(Group.CLI, "identify-stream-runs", Outcome.ERROR,
         _with_rec("identify", "REC", "--stream", "--runs", "ref,m1"), ("--stream", "--runs")),
    Case(Group.CLI, "identify-time-beyond-record", Outcome.ERROR, _with_rec("identify", "REC", "--time", "100"),
         ("--time", "100")),
    Case(Group.CLI, "identify-time-nan", Outcome.ERROR, _with_rec("identify", "REC", "--time", "nan"),
         ("--time", "nan")),
    # the same instant twice used to collapse silently into one equation (np.unique)
    Case(Group.CLI, "identify-time-twice", Outcome.ERROR,
         _with_rec("identify", "REC", "--estimator", "equation", "--time", "0.2", "--time", "0.2", "--time", "0.4"),
         ("--time 0.2 --time 0.2 --time 0.4", "0.2, 0.2 s pick the same sample", "expected distinct instants")),
    Case(Group.CLI, "identify-floors-in-g", Outcome.REFUSAL, _edited(_floors_in_g), ("refused",)),
    Case(Group.CLI, "identify-added-mass-in-grams", Outcome.REFUSAL, _edited(_grams), ("refused",)),
    Case(Group.CLI, "identify-swapped-floor-columns", Outcome.REFUSAL, _edited(_swapped), ("refused",)),
    Case(Group.CLI, "import-missing-folder", Outcome.ERROR, _in("import", "nowhere"), ("nowhere",)),
    Case(Group.CLI, "import-cell-1e308", Outcome.ERROR,
         _in("import", "lab", "-o", "out", setup=_lab_with(
             "t,zdd,a1,a2\n0.00,0,0,0\n0.01,0,1e308,0\n0.02,0,0,0\n0.03,0,0,0\n")),
         ("r1.csv", "row 3", "'a1'", "1e+308")),
    Case(Group.CLI, "import-output-is-a-file", Outcome.ERROR,
         _in("import", "lab", "-o", "taken/", setup=lambda f: (lab_folder(f), _file("taken")(f))), ("taken",)),
    Case(Group.CLI, "view-missing-file", Outcome.ERROR, _in("view", "none.mcap", "--save", "x.rrd"), ("none.mcap",)),
    Case(Group.CLI, "view-save-into-proc", Outcome.ERROR, _with_rec("view", "REC", "--save", "/proc/momentid_x/v.rrd"),
         ("/proc/momentid_x/v.rrd",)),
    Case(Group.CLI, "view-result-missing", Outcome.ERROR, _with_rec("view", "REC", "--save", "v.rrd", "--result",
                                                                    "none.json"), ("none.json",)),
    Case(Group.CLI, "view-result-not-json", Outcome.ERROR,
         lambda f: (_file("r.json", "{oops")(f),
                    _with_rec("view", "REC", "--save", "v.rrd", "--result", "r.json")(f))[1],
         ("r.json",)),
    Case(Group.CLI, "view-unknown-run", Outcome.ERROR, _with_rec("view", "REC", "--save", "v.rrd", "--run", "nope"),
         ("nope",)),
    Case(Group.CLI, "view-save-onto-its-recording", Outcome.ERROR, _with_rec("view", "REC", "--save", "REC"),
         ("rec.mcap", "MCAP recording")),
    Case(Group.CLI, "view-exaggeration-1e308", Outcome.ERROR,
         _with_rec("view", "REC", "--save", "v.rrd", "--exaggeration", "1e308"), ("exaggeration", "1e+308")),
    Case(Group.CLI, "view-exaggeration-word", Outcome.ERROR, _in("view", "x.mcap", "--exaggeration", "big"),
         ("'big'",)),
    Case(Group.CLI, "diagnose-missing-file", Outcome.ERROR, _in("diagnose", "none.mcap"), ("none.mcap",)),
    Case(Group.CLI, "diagnose-output-is-a-file", Outcome.ERROR,
         _with_rec("diagnose", "REC", "-o", "rec.mcap"), ("rec.mcap", "a file of that name exists")),
    # issue 22: two writers of one output both exited 0 and left an unreadable file
    Case(Group.CLI, "run-output-being-written", Outcome.ERROR,
         _while_held("file", "o.mcap", "run", "s.toml", "-q", "-o", "o.mcap", setup=_scenario),
         ("o.mcap", "another process is writing it")),
    Case(Group.CLI, "import-output-being-written", Outcome.ERROR,
         _while_held("file", "lab.mcap", "import", "lab", "-o", "lab.mcap", setup=lab_folder),
         ("lab.mcap", "another process is writing it")),
    Case(Group.CLI, "view-save-being-written", Outcome.ERROR,
         _while_held("whole", "v.rrd", "view", "REC", "--save", "v.rrd", rec=True),
         ("v.rrd", "another process is writing it")),
    Case(Group.CLI, "diagnose-folder-being-written", Outcome.ERROR,
         _while_held("folder", "report", "diagnose", "REC", "-o", "report", rec=True),
         ("report", "another process is writing it")),
    Case(Group.CLI, "sweep-table-being-written", Outcome.ERROR,
         _while_held("whole", "t.csv", "sweep", "w.toml", "-q", "-o", "t.csv", setup=lambda f: (_scenario(f), _file(
             "w.toml", '[sweep]\nbase = "s.toml"\n[grid]\n"scenario.seed" = [0]\n')(f))),
         ("t.csv", "another process is writing it")),
    Case(Group.CLI, "plan-missing-scenario", Outcome.ERROR, _in("plan", "none.toml"), ("none.toml",)),
    Case(Group.CLI, "plan-target-zero", Outcome.ERROR, _in("plan", "s.toml", "--target", "0"), ("'0'",)),
    Case(Group.CLI, "plan-target-nan", Outcome.ERROR, _in("plan", "s.toml", "--target", "nan"), ("'nan'",)),
    Case(Group.CLI, "plan-max-runs-zero", Outcome.ERROR, _in("plan", "s.toml", "--max-runs", "0"), ("'0'",)),
    # issue 22: plan --max-runs 1000000 ran for hours without a word
    Case(Group.CLI, "plan-max-runs-1e6", Outcome.REFUSAL,
         _in("plan", "noisy.toml", "--max-runs", "1000000", setup=_noisy_scenario), ("9999990 designs", "refused")),
    Case(Group.CLI, "plan-beyond-time-limit", Outcome.REFUSAL,
         _in("plan", "noisy.toml", "--max-runs", "5000", "--time-limit", "10", setup=_noisy_scenario),
         ("5000 runs", "--max-runs", "--time-limit", "refused")),
    Case(Group.CLI, "plan-max-runs-one", Outcome.ERROR,
         _in("plan", "noisy.toml", "--max-runs", "1", setup=_noisy_scenario), ("--max-runs 1",)),
    Case(Group.CLI, "sweep-missing-spec", Outcome.ERROR, _in("sweep", "none.toml"), ("none.toml",)),
    Case(Group.CLI, "sweep-grid-value-twice", Outcome.ERROR,
         _in("sweep", "w.toml", setup=lambda f: (_scenario(f), _file(
             "w.toml", '[sweep]\nbase = "s.toml"\n[grid]\n"scenario.seed" = [0, 1, 0]\n')(f))),
         ("w.toml", "scenario.seed", "twice")),
    Case(Group.CLI, "sweep-bad-spec", Outcome.ERROR,
         _in("sweep", "w.toml", setup=_file("w.toml", "[sweep]\nbase = 3\n")),
         ("w.toml", "base")),
]
