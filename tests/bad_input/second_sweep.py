"""A second sweep of issue 32's kind, with cases its first sweep had not tried: output paths that are
empty, hold a folder of an output's name or a user's file of its temporary name, a re-import onto a
full disk, results `view --result` is handed, a run name `--runs` cannot name, and doctored copies of
the shipped trials (empty lines, a last row cut short, a table file copied from another run, other
export dialects).  Each must end with no data loss, no traceback and no silent wrong answer."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from ._core import Case, CliResult, Group, Outcome, cli
from .cli import recording_file
from .csv_import import EXPERIMENT, lab_folder
from .faults import fill_disk_at
from .shipped_faults import _importing, _same_as_clean, shipped_lab

#: What a user keeps in a file of an output's temporary name (or of its own name).
PRECIOUS = "years of work"


def _kept(act, name: str):
    """``act``, then the user's file ``name`` (written with :data:`PRECIOUS` first) must be as it was."""
    def checked(folder: Path) -> CliResult:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(PRECIOUS)
        result = act(folder)
        if (folder / name).read_text() != PRECIOUS:
            raise AssertionError(f"{name} was overwritten")
        return result
    return checked


def _import_beside_a_users_partial(folder: Path) -> CliResult:
    """A re-import onto an earlier recording, with a user's file named rec.mcap.partial beside it (the
    name the new recording is written to first): it was truncated, then renamed over the recording."""
    lab_folder(folder)
    assert cli("import", "lab", "-o", "rec.mcap").code == 0
    return _kept(lambda _: cli("import", "lab", "-o", "rec.mcap"), "rec.mcap.partial")(folder)


def _output_folder_with_a_folder(folder: Path) -> CliResult:
    """`identify -o DIR --force` where DIR/report.html is a folder: it used to place some files, then fail
    naming its hidden staging folder (`.momentid-xxxx.partial/report.html: Is a directory`)."""
    rec = recording_file(folder)
    (folder / "id" / "report.html").mkdir(parents=True)
    result = cli("identify", rec, "-o", "id", "--force")
    if sorted(p.name for p in (folder / "id").iterdir()) != ["report.html"]:
        raise AssertionError(f"files placed before the refusal: {sorted((folder / 'id').iterdir())}")
    return result


def _users_report(folder: Path) -> CliResult:
    """`identify -o id` where id/report.html is the user's (written by :func:`_kept`)."""
    return cli("identify", recording_file(folder), "-o", "id")


def _folder_from_before_the_manifest(folder: Path) -> CliResult:
    rec = recording_file(folder)
    assert cli("identify", rec, "-o", "id").code == 0
    (folder / "id" / ".momentid.json").unlink()          # as a momentid older than the manifest left it
    return cli("identify", rec, "-o", "id")


def _reimport_onto_a_full_disk(folder: Path) -> CliResult:
    """A re-import that fails half-way keeps the earlier recording whole (it was written over from the
    first byte)."""
    import momentid.io.recording as recording

    lab_folder(folder)
    assert cli("import", "lab", "-o", "rec.mcap").code == 0
    before = (folder / "rec.mcap").read_bytes()
    with pytest.MonkeyPatch.context() as m:
        fill_disk_at(m, recording, len(before) // 2 + 200)    # the header and run r1, not r2
        result = cli("import", "lab", "-o", "rec.mcap")
    if (folder / "rec.mcap").read_bytes() != before:
        raise AssertionError("the earlier recording was changed")
    return result


def _result_file(payload) -> callable:
    """`view REC --result result.json` with ``payload`` in the file."""
    def act(folder: Path) -> CliResult:
        rec = recording_file(folder)
        (folder / "result.json").write_text(json.dumps(payload))
        return cli("view", rec, "--result", "result.json", "--save", "v.rrd")
    return act


#: A modal result (runs without added mass) whose shapes are of 2 modes where 2 frequencies are given:
#: every key is checked for its shape before the viewer draws.
MODAL = {"frequency_hz": [1.0, 2.0], "damping_ratio": [0.01, 0.02], "mode_shapes": [[1.0], [1.0]],
         "runs": ["reference"]}


def _empty_lines(k, header, rows):
    """Floor 3's export holds empty lines among its rows (an editor, a concatenation)."""
    if k == 3:
        rows.insert(300, "")
        rows.insert(800, "   ")


def _last_row_cut(k, header, rows):
    """Floor 3's export ends mid-row (copied while the app still wrote it): 3 of its 11 cells."""
    if k == 3:
        rows[-1] = ",".join(rows[-1].split(",")[:3])


def _one_sample_less(experiment):
    """The run ends a sample earlier than the clean one, every sensor the same up to its offset (a
    constant: each sensor removes its mean over the span it keeps)."""
    clean_folder = Path(experiment.runs[0].meta["source_files"][0]).parents[1] / "clean"
    clean_folder.mkdir()
    from momentid.io.importer import import_folder
    clean, cut = import_folder(shipped_lab(clean_folder)).runs[0], experiment.runs[0]
    if cut.n_samples != clean.n_samples - 1:
        raise AssertionError(f"{cut.n_samples} samples, expected {clean.n_samples - 1}")
    for ch in cut.channels:   # float rounding: 1e-12 m/s^2
        if np.ptp(clean[ch][:-1] - cut[ch]) > 1e-12:
            raise AssertionError(f"{ch} differs from the clean import by more than its offset")


def _table_copied_from_another_run(folder: Path):
    """The stiff rig with El Centro 2's table file a copy of El Centro 1's (saved over it)."""
    from momentid.io.importer import import_folder

    lab = folder / "stiff"
    shutil.copytree(Path(__file__).resolve().parents[2] / "data" / "mini_shake_table" / "stiff_1storey", lab)
    ground = lab / "Ground Floor"
    (ground / "(El Centro Trial 2) left leg_20250402_171438.csv.gz").write_bytes(
        (ground / "(El Centro Trial 1) left leg_20250402_171355.csv.gz").read_bytes())
    return import_folder(lab)


def _half_rate(k, header, rows):
    """Floor 3 exported at 60 Hz (the app's output rate set lower), the others at 120 Hz."""
    if k == 3:
        rows[:] = rows[::2]


def _quoted_cells(k, header, rows):
    """Floor 3's rows re-saved by a spreadsheet that quotes every cell."""
    if k == 3:
        rows[:] = [",".join(f'"{c}"' for c in row.split(",")) for row in rows]


def _header_lowercase(k, header, rows):
    if k == 3:
        header[-1] = header[-1].lower()


CASES = [
    # An unset shell variable: `-o ""` meant the current folder (import), the default folder (twin) or no
    # report at all (identify), without a word.
    Case(Group.CLI, "identify-output-empty", Outcome.ERROR,
         lambda folder: cli("identify", recording_file(folder), "-o", ""), ("-o ''", "an empty path")),
    Case(Group.CLI, "import-output-empty", Outcome.ERROR,
         lambda folder: (lab_folder(folder), cli("import", "lab", "-o", ""))[1], ("-o ''", "an empty path")),
    Case(Group.CLI, "view-save-empty", Outcome.ERROR,
         lambda folder: cli("view", recording_file(folder), "--save", ""), ("--save ''", "an empty path")),
    # A user's file of the name an output is written to first: a re-import (and `view --save`) truncated it.
    Case(Group.CLI, "import-beside-a-users-partial-file", Outcome.ERROR,
         _import_beside_a_users_partial,
         ("-o rec.mcap", "rec.mcap.partial beside it is not an MCAP recording", "move it away")),
    Case(Group.CLI, "view-save-beside-a-users-partial-file", Outcome.ERROR,
         _kept(lambda folder: cli("view", recording_file(folder), "--save", "v.rrd"), "v.rrd.partial"),
         ("--save v.rrd", "v.rrd.partial beside it is not a rerun recording")),
    Case(Group.CLI, "identify-output-holds-a-folder-of-its-name", Outcome.ERROR, _output_folder_with_a_folder,
         ("-o id", "holds a folder report.html", "never folders")),
    # identify -o joins the one output rule: a user's report.html is theirs; an older folder says so.
    Case(Group.CLI, "identify-output-holds-a-users-report", Outcome.ERROR,
         _kept(_users_report, "id/report.html"),
         ("-o id", "report.html", "no .momentid.json", "--force")),
    Case(Group.CLI, "identify-output-from-before-the-manifest", Outcome.ERROR, _folder_from_before_the_manifest,
         ("-o id", "no .momentid.json", "--force")),
    Case(Group.CLI, "reimport-onto-a-full-disk-keeps-the-earlier", Outcome.ERROR, _reimport_onto_a_full_disk,
         ("rec.mcap", "the file there is kept", "(r1) are in", "rec.mcap.partial")),
    # `view --result` reads a modal result key by key; a --per-run result is named as such.
    Case(Group.CLI, "view-result-modal-shapes-of-another-size", Outcome.ERROR, _result_file(MODAL),
         ("result.json", "key 'mode_shapes'", "shape (2, 2)")),
    Case(Group.CLI, "view-result-of-identify-per-run", Outcome.ERROR,
         _result_file({"runs": [dict(MODAL, runs=["reference"])] * 2}), ("result.json", "--per-run")),
    # "sine 1,5 Hz" could never be chosen: --runs splits it at the comma.
    Case(Group.CSV, "run-name-with-a-comma", Outcome.ERROR,
         lambda folder: cli("import", lab_folder(folder, EXPERIMENT.replace('name = "r1"', 'name = "sine 1,5 Hz"')),
                            "-o", "lab.mcap"),
         ("runs[0].name", "'sine 1,5 Hz'", "','", "--runs")),
    Case(Group.IMU, "shipped-empty-lines", Outcome.RECOVERY, _importing(_empty_lines, check=_same_as_clean),
         ("rows 309, 809: empty: skipped",)),
    Case(Group.IMU, "shipped-last-row-cut-short", Outcome.RECOVERY, _importing(_last_row_cut, check=_one_sample_less),
         ("row 7316: cut short (3 of 11 cells", "dropped")),
    # A table file copied from another run's used to be refused as "sensor a1's clock does not overlap the
    # table's and its data correlate weakly ... cannot align it", blaming the floor's file.
    Case(Group.IMU, "stiff-table-file-copied-from-another-run", Outcome.ERROR, _table_copied_from_another_run,
         ("(El Centro Trial 2) left leg", "holds the same samples as", "(El Centro Trial 1) left leg",
          "run 'el_centro_1', table", "copied")),
    Case(Group.IMU, "shipped-floor-at-half-the-rate", Outcome.ERROR, _importing(_half_rate),
         ("f3.csv", "sample interval 0.016666 s", "expected sensors at one rate")),
    Case(Group.IMU, "shipped-quoted-cells", Outcome.ERROR, _importing(_quoted_cells),
         ("f3.csv", "row 9", "'PacketCounter'", "'\"0\"' is not a number")),
    Case(Group.IMU, "shipped-header-in-lower-case", Outcome.ERROR, _importing(_header_lowercase),
         ("f3.csv", "no header line starting 'PacketCounter,SampleTimeFine'")),
]
