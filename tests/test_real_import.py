"""`momentid import` on real lab exports: the shipped mini shake-table data (Xsens DOT CSVs).

The shipped folder ``data/mini_shake_table/flexible_3storey`` is imported as it is (five trials, the
last one with unsynchronised clocks and a reversed sensor).  Every data fault the import must name is
made on a doctored copy of one synchronised trial, and its import compared with the untouched copy's.
"""

from __future__ import annotations

import dataclasses
import gzip
import shutil
import tomllib
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from momentid.cli import main
from momentid.core.structure import LabStatement
from momentid.errors import ScenarioError, SensorDataError
from momentid.io.align import ALIGN_BAND, MIN_ALIGN_CORRELATION
from momentid.io.formats.xsens_dot import read_xsens_dot
from momentid.io.importer import import_folder
from momentid.io.recording import read_recording, write_experiment
from momentid.report import viewer

from conftest import data_file

rerun_chunk = pytest.importorskip("rerun.chunk")

FOLDER = data_file("mini_shake_table", "flexible_3storey")
SENSORS = ("Ground Floor", "1st Floor", "2nd Floor", "3rd Floor (Top floor)")
CHANNELS = ("zdd", "a1", "a2", "a3")
TABLE_MOTION = ("table_ay", "table_az", "table_wx", "table_wy", "table_wz")
SYNCHRONISED = ("northridge", "sine_1p0", "sine_1p5", "sine_2p0")
#: The trial doctored below: synchronised and the shortest of those (7308 rows per file).
TRIAL = "(Sine 1.5)"
#: Lines before the first data row of an Xsens DOT export (7 preamble lines + header).
HEADER_LINES = 8
#: Column indices in an Xsens DOT row.
CLOCK, ACC_X, ACC_Y, ACC_Z = 1, 5, 6, 7
STRUCTURE = "[structure]\nstoreys = 3\nmasses = [0.160, 0.160, 0.142]\n"


@pytest.fixture(scope="module")
def shipped():
    return import_folder(FOLDER)


def trial_files(trial: str) -> list[Path]:
    """The shipped files of ``trial``, table first."""
    return [next(p for p in sorted((FOLDER / s).iterdir()) if p.name.startswith(trial)) for s in SENSORS]


def write_trial(folder: Path, edit=None, structure: str = STRUCTURE) -> Path:
    """A lab folder holding TRIAL as plain CSV; ``edit(k, lines)`` may change sensor k's lines."""
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for k, src in enumerate(trial_files(TRIAL)):
        lines = gzip.decompress(src.read_bytes()).decode("utf-8").split("\n")
        if edit is not None:
            edit(k, lines)
        name = f"sensor{k}.csv"
        (folder / name).write_text("\n".join(lines), encoding="utf-8")
        names.append(name)
    floors = ", ".join(f'"{n}"' for n in names[1:])
    (folder / "experiment.toml").write_text(
        f'{structure}\n[sensors]\nformat = "xsens-dot"\n\n[[runs]]\nname = "trial"\n'
        f'table = "{names[0]}"\nfloors = [{floors}]\n')
    return folder


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    """TRIAL imported from an untouched plain-text copy."""
    return import_folder(write_trial(tmp_path_factory.mktemp("original"))).run("trial")


def rows(lines):
    """Indices of the data rows (the all-zero first row included) in ``lines``."""
    return range(HEADER_LINES, len(lines) - (lines[-1] == ""))


def set_cells(lines, row, columns, values):
    fields = lines[row].split(",")
    for c, v in zip(columns, values):
        fields[c] = v
    lines[row] = ",".join(fields)


def sensor(run, channel):
    return next(s for s in run.meta["sensors"] if s["channel"] == channel)


# ----------------------------------------------------------------------------- the shipped data

def test_every_shipped_trial_imports_on_one_time_base(shipped):
    assert [r.name for r in shipped.runs] == [*SYNCHRONISED, "bonus_event"]
    assert shipped.structure is None
    assert shipped.statement == LabStatement(storeys=3, masses=(0.160, 0.160, 0.142),
                                             storey_heights=(0.1524,) * 3)
    for run in shipped.runs:
        records = [read_xsens_dot(p) for p in run.meta["source_files"]]
        assert run.channels == CHANNELS + TABLE_MOTION and run.time[0] == 0.0
        # The device clock steps 8333 us: the run's grid is that step, to float64 round-off of ~160 s.
        assert np.allclose(np.diff(run.time), records[0].step, rtol=1e-9, atol=0)
        assert np.all(np.isfinite(run.values))
        # Gravity and offsets are gone: every series has zero mean to round-off of ~2e4 samples.
        assert np.allclose(run.values.mean(axis=0), 0.0, atol=1e-12)
        # The whole record is kept: at most the few samples one sensor lacks at either end go
        # (one on a shared clock; up to 25 where a device ran 21 samples longer, bonus_event).
        assert run.n_samples >= min(r.acc.shape[0] for r in records) - 25
        assert run.added_mass.tolist() == [0.0, 0.0, 0.0]


def test_the_table_sensors_other_motions_are_its_file_s_other_columns(shipped):
    """The table's cross and vertical accelerations and its three angular rates come from the table's own
    file: on the run's samples, each is the file's column less its mean, the rates in rad/s."""
    run = shipped.run("northridge")
    table = read_xsens_dot(run.meta["source_files"][0])
    report = sensor(run, "zdd")
    assert (report["axis"], report["gravity_axis"]) == ("X", "Z")
    start = int(round(-report["start"] / table.step))       # the table's samples the common span skips
    span = slice(start, start + run.n_samples)
    expected = {"table_ay": table.acc[span, 1], "table_az": table.acc[span, 2], "table_wx": table.rates[span, 0],
                "table_wy": table.rates[span, 1], "table_wz": table.rates[span, 2]}
    for channel, x in expected.items():
        # the same samples less their mean, to float64 round-off
        assert np.allclose(run[channel], x - x.mean(), rtol=0, atol=1e-12), channel
    # the DOT writes deg/s: a table at rest turns far below 1 rad/s, and its rates are not all zero
    assert 0 < np.max(np.abs(run["table_wy"])) < 1.0


def test_synchronised_trials_keep_the_shared_clock(shipped):
    for name in SYNCHRONISED:
        run = shipped.run(name)
        records = [read_xsens_dot(p) for p in run.meta["source_files"]]
        first = max(r.time[0] for r in records)
        for k, channel in enumerate(CHANNELS):
            report = sensor(run, channel)
            assert (report["axis"], report["sign"]) == ("X", 1)
            assert report["alignment"] == ("reference" if k == 0 else "clock")
            # start on the table's grid = the device stamp minus the common first stamp, to 1 us.
            assert report["start"] == pytest.approx(records[k].time[0] - first, abs=1e-6)
            # the data confirm the clock: the floors' own lag in the band is under half a sample.
            if k:
                assert abs(report["clock_error"]) < 0.5 * records[0].step


def test_unsynchronised_trial_is_aligned_from_the_data_and_its_reversed_sensor_found(shipped):
    run = shipped.run("bonus_event")
    records = [read_xsens_dot(p) for p in run.meta["source_files"]]
    # The device clocks do not overlap the table's: the data must align them.
    assert all(r.time[-1] < records[0].time[0] or r.time[0] > records[0].time[-1] for r in records[1:])
    band = signal.butter(4, ALIGN_BAND, btype="band", fs=run.sample_rate, output="sos")
    table = signal.sosfiltfilt(band, run["zdd"])
    for channel in CHANNELS[1:]:
        report = sensor(run, channel)
        assert report["alignment"] == "data" and report["correlation"] >= MIN_ALIGN_CORRELATION
        floor = signal.sosfiltfilt(band, run[channel])
        # Aligned: below the first mode the floor follows the table, so the correlation is highest at
        # zero lag, not one sample either side.
        at = {lag: np.corrcoef(table[5:-5], np.roll(floor, lag)[5:-5])[0, 1] for lag in (-1, 0, 1)}
        assert at[0] > max(at[-1], at[1]) and at[0] > MIN_ALIGN_CORRELATION
    # The top floor's sensor is mounted reversed: its raw X runs against the table's.
    assert [sensor(run, c)["sign"] for c in CHANNELS] == [1, 1, 1, -1]
    assert "mounted reversed" in " ".join(sensor(run, "a3")["notes"])


def test_the_recording_keeps_the_statement_and_the_per_sensor_reports(shipped, tmp_path):
    back = read_recording(write_experiment(tmp_path / "flex3.mcap", shipped))
    assert back.statement == shipped.statement and back.structure is None
    for run, got in zip(shipped.runs, back.runs):
        assert np.array_equal(got.values, run.values) and got.meta["notes"] == run.meta["notes"]
        for a, b in zip(got.meta["sensors"], run.meta["sensors"]):
            assert a.keys() == b.keys()
            assert all(a[k] == b[k] or (a[k] is None and np.isnan(b[k])) for k in a)


def test_the_cli_reports_every_sensor(tmp_path, capsys):
    assert main(["import", str(FOLDER), "-o", str(tmp_path / "flex3.mcap")]) == 0
    out = capsys.readouterr().out
    assert out.count("axis +X") + out.count("axis -X") == 4 * 5
    assert "a3: axis -X" in out and "mounted reversed" in out
    assert out.count("its clock does not overlap the table's: offset") == 3
    assert out.strip().splitlines()[-1].startswith(f"imported {FOLDER}: 5 runs")


# ----------------------------------------------------------------------------- doctored copies

def _empty_cells(first: int, count: int):
    """Sensor a2's accelerations blank on ``count`` data rows from data row ``first``."""
    def edit(k, lines):
        if k == 2:
            for row in range(HEADER_LINES + first, HEADER_LINES + first + count):
                set_cells(lines, row, (ACC_X, ACC_Y, ACC_Z), ("", "", ""))
    return edit


def test_a_short_nan_gap_is_interpolated_and_noted(tmp_path, original):
    run = import_folder(write_trial(tmp_path / "lab", _empty_cells(1000, 3))).run("trial")
    notes = " ".join(sensor(run, "a2")["notes"])
    # Line numbers: data row 1000 is line HEADER_LINES + 1000 + 1 = 1009.
    assert "rows 1009-1011" in notes and "interpolated linearly" in notes, notes
    assert sensor(run, "a2")["missing"] == 0 and np.all(np.isfinite(run.values))
    assert run.n_samples == original.n_samples
    # Only the three samples change, and with them the mean removed over the record (a constant):
    # 1e-9 m/s^2 is far above float64 round-off (1e-15) and far below the change of a sample (1e-3).
    diff = run["a2"] - original["a2"]
    assert np.flatnonzero(np.abs(diff - np.median(diff)) > 1e-9).tolist() == [999, 1000, 1001]


def test_a_long_nan_gap_is_one_line_naming_the_rows(tmp_path):
    with pytest.raises(SensorDataError, match=r"sensor2\.csv: rows 1009-1018, column 'Acc_X': 10 consecutive "
                                              r"samples missing; expected at most 5"):
        import_folder(write_trial(tmp_path / "lab", _empty_cells(1000, 10)))


def test_a_few_lost_rows_are_interpolated(tmp_path, original):
    def edit(k, lines):
        if k == 1:
            del lines[HEADER_LINES + 2000:HEADER_LINES + 2005]
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    assert run.n_samples == original.n_samples and sensor(run, "a1")["missing"] == 0
    assert "the 5 samples lost between rows 2008 and 2009" in " ".join(sensor(run, "a1")["notes"])


def test_more_lost_rows_than_can_be_interpolated_are_refused(tmp_path):
    def edit(k, lines):
        if k == 1:
            del lines[HEADER_LINES + 2000:HEADER_LINES + 2006]
    with pytest.raises(SensorDataError, match=r"sensor1\.csv: the 6 samples lost between rows 2008 and 2009"):
        import_folder(write_trial(tmp_path / "lab", edit))


def _lost_packet(lines, row):
    """The Xsens app's mark of a lost packet at data line ``row``: the stamp of the row before jumps two
    intervals, this row repeats it with nan/inf in every channel, PacketCounter runs on."""
    before = lines[row - 1].split(",")
    stamp = str(int(before[CLOCK]) + 8333)
    set_cells(lines, row - 1, (CLOCK,), (stamp,))
    cells = lines[row].split(",")
    lines[row] = ",".join([cells[0], stamp] + ["nan" if i % 2 else "inf" for i in range(len(cells) - 2)])


def test_a_lost_packet_row_is_named_and_repaired(tmp_path, original):
    """Issue 18 point 6: the pattern of a real Xsens DOT export, which was refused as 'the clock went back'."""
    def edit(k, lines):
        if k == 3:
            _lost_packet(lines, HEADER_LINES + 3000)
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    notes = " ".join(sensor(run, "a3")["notes"])
    assert "row 3009: no acceleration (every cell empty, nan or inf: 1 lost packet)" in notes, notes
    assert "row 3009 repeats the stamp of the row before" in notes and "interpolated linearly" in notes
    assert run.n_samples == original.n_samples
    # The row before the lost one moved one sample later (by its stamp); the lost sample in between
    # is interpolated. Every other sample is the original's, up to the change of the removed mean
    # (a constant; 1e-9 m/s^2 separates float64 round-off from a changed sample).
    diff = run["a3"] - original["a3"]
    assert np.count_nonzero(np.abs(diff - np.median(diff)) > 1e-9) <= 2


def test_a_repeated_stamp_without_a_lost_packet_is_named_as_such(tmp_path):
    def edit(k, lines):
        if k == 2:
            stamp = lines[HEADER_LINES + 500].split(",")[CLOCK]
            set_cells(lines, HEADER_LINES + 501, (CLOCK,), (stamp,))
    with pytest.raises(SensorDataError, match=r"sensor2\.csv: row 510, column 'SampleTimeFine': \d+ us repeats "
                                              r"the stamp of row 509"):
        import_folder(write_trial(tmp_path / "lab", edit))


def test_an_export_in_g_is_converted_with_a_note(tmp_path, original):
    """Issue 22 point 2: an export in g (gravity ~1) was taken as m/s^2; it is converted, noted."""
    def edit(k, lines):
        if k == 1:
            for row in rows(lines)[1:]:
                cells = lines[row].split(",")
                set_cells(lines, row, (ACC_X, ACC_Y, ACC_Z),
                          [repr(float(cells[c]) / 9.80665) for c in (ACC_X, ACC_Y, ACC_Z)])
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    report = sensor(run, "a1")
    assert "accelerations in g (gravity reads 0.99" in " ".join(report["notes"])
    assert report["gravity"] == pytest.approx(sensor(original, "a1")["gravity"], rel=1e-12)
    # Dividing and multiplying by 9.80665 in float64 (17 printed digits) is exact to round-off.
    assert np.allclose(run["a1"], original["a1"], rtol=0, atol=1e-12)


def test_a_packet_counter_places_a_row_without_a_stamp(tmp_path, original):
    def edit(k, lines):
        if k == 2:
            set_cells(lines, HEADER_LINES + 700, (CLOCK,), ("",))
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    assert "row 709: no SampleTimeFine stamp; placed by PacketCounter (8333 us per packet)" in " ".join(
        sensor(run, "a2")["notes"])
    assert np.array_equal(run.values, original.values)


def test_a_duplicated_sensor_file_is_refused(tmp_path):
    copy = {}

    def edit(k, lines):
        if k == 1:
            copy["lines"] = list(lines)
        if k == 2:
            lines[:] = copy["lines"]
    with pytest.raises(SensorDataError, match=r"sensor2\.csv: the same accelerations as .*sensor1\.csv"):
        import_folder(write_trial(tmp_path / "lab", edit))


def test_a_reversed_sensor_is_found_and_flipped(tmp_path, original):
    def edit(k, lines):
        if k == 2:
            for row in rows(lines)[1:]:
                x = lines[row].split(",")[ACC_X]
                set_cells(lines, row, (ACC_X,), (x[1:] if x.startswith("-") else "-" + x,))
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    assert sensor(run, "a2")["sign"] == -1 and sensor(original, "a2")["sign"] == 1
    # Flipping the printed sign is exact, so the series is the original's to round-off of the mean.
    assert np.allclose(run["a2"], original["a2"], rtol=0, atol=1e-12)


def test_a_turned_sensor_is_found(tmp_path, original):
    def edit(k, lines):  # the top-floor sensor turned 90 degrees: X and Y swapped
        if k == 3:
            for row in rows(lines):
                fields = lines[row].split(",")
                set_cells(lines, row, (ACC_X, ACC_Y), (fields[ACC_Y], fields[ACC_X]))
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    assert sensor(run, "a3")["axis"] == "Y"
    assert np.array_equal(run["a3"], original["a3"])


def test_a_wrong_clock_is_overruled_by_the_data(tmp_path, original):
    shift = 60  # samples (0.5 s): the clocks still overlap but disagree with the data

    def edit(k, lines):
        if k == 1:
            for row in rows(lines):
                t = int(lines[row].split(",")[CLOCK])
                set_cells(lines, row, (CLOCK,), (str(t + shift * 8333),))
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    report = sensor(run, "a1")
    assert report["alignment"] == "data" and "disagrees with the data" in " ".join(report["notes"])
    # The clock was off by the shift: the data find it to within the floors' sub-sample phase lag.
    assert report["clock_error"] == pytest.approx(-shift * 8333e-6, abs=0.5 * 8333e-6)
    assert np.array_equal(run.values, original.values)


def test_a_clock_offset_is_estimated(tmp_path, original):
    shift = 60  # samples the floor-1 device started late, on a clock of its own

    def edit(k, lines):
        if k == 1:
            del lines[HEADER_LINES + 1:HEADER_LINES + 1 + shift]
            for row in rows(lines):
                t = int(lines[row].split(",")[CLOCK])
                set_cells(lines, row, (CLOCK,), (str(t + 3_000_000_000),))
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    report = sensor(run, "a1")
    assert report["alignment"] == "data" and report["start"] == pytest.approx(0.0)
    assert "offset +0.5000 s estimated" in " ".join(report["notes"])
    assert run.n_samples == original.n_samples - shift
    # The same samples as the original from its 60th on; only the removed mean differs.
    for c in CHANNELS:
        a, b = run[c], original[c][shift:]
        # float64 sums over 7000 samples: the difference is the constant change of the mean.
        assert np.allclose(a - a.mean(), b - b.mean(), rtol=0, atol=1e-12)


def test_unequal_lengths_keep_the_common_span(tmp_path, original):
    def edit(k, lines):
        if k == 2:
            del lines[-101:-1]
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    assert run.n_samples == original.n_samples - 100
    assert "sensors cover different spans" in run.meta["notes"][0]


def test_a_sensor_that_does_not_move_is_refused(tmp_path):
    rng = np.random.default_rng(0)

    def edit(k, lines):
        if k == 3:
            for row in rows(lines)[1:]:
                # gravity on Z plus 0.01 m/s^2 of noise, the level of an idle Xsens DOT
                x, y, z = rng.normal(0.0, 0.01, 3) + (0.0, 0.0, 9.81)
                set_cells(lines, row, (ACC_X, ACC_Y, ACC_Z), (f"{x:.6f}", f"{y:.6f}", f"{z:.6f}"))
    with pytest.raises(SensorDataError, match=r"sensor3\.csv: sensor a3 does not move"):
        import_folder(write_trial(tmp_path / "lab", edit))


def test_a_sample_rate_too_low_for_the_modes_is_noted(tmp_path):
    # Every 5th sample: 24 Hz, the 11 and 17 Hz modes at and beyond the 12 Hz Nyquist frequency (folded
    # peak 10.5 Hz). Every 6th (20 Hz) folds the 11 Hz mode to 9.5 Hz at 2.0 decades, on the threshold;
    # it used to pass only because the aligner put floor 1 6.7 samples off its shared clock, reversed.
    keep = 5

    def edit(k, lines):
        data = [lines[r] for r in rows(lines)]
        lines[HEADER_LINES:] = data[::keep] + [""]
    run = import_folder(write_trial(tmp_path / "lab", edit)).run("trial")
    assert any("sample rate is likely too low for the modes" in n for n in run.meta["notes"])


def test_a_stated_model_too_fast_for_the_rate_is_refused(tmp_path):
    model = STRUCTURE + "storey_stiffness = 1.0e6\nrayleigh_mu = 0.0\nrayleigh_kappa = 0.0\n"
    with pytest.raises(SensorDataError, match=r"too low for the stated model's highest mode"):
        import_folder(write_trial(tmp_path / "lab", structure=model))


def test_gzip_files_read_directly_and_a_broken_one_is_named(tmp_path, original):
    folder = write_trial(tmp_path / "lab")
    for k in range(4):
        plain = folder / f"sensor{k}.csv"
        plain.write_bytes(gzip.compress(plain.read_bytes(), mtime=0))  # same name, gzip content
    assert np.array_equal(import_folder(folder).run("trial").values, original.values)
    broken = folder / "sensor2.csv"
    broken.write_bytes(broken.read_bytes()[:5000])
    with pytest.raises(SensorDataError, match=r"sensor2\.csv: broken gzip file"):
        import_folder(folder)


BAD_FILES = {
    "no header": (lambda lines: lines.__setitem__(7, "a,b,c"), r"no header line starting 'PacketCounter"),
    "no Acc_X": (lambda lines: lines.__setitem__(7, lines[7].replace("Acc_X", "Acc_Q")),
                 r"row 8, column 'Acc_X': missing from the header"),
    "bad cell": (lambda lines: set_cells(lines, 20, (ACC_Z,), ("9.8x",)),
                 r"row 21, column 'Acc_Z': '9\.8x' is not a number"),
    "clock back": (lambda lines: set_cells(lines, 30, (CLOCK,), ("1",)),
                   r"row \d+, column 'SampleTimeFine': .*expected a whole number of sample intervals"),
}


@pytest.mark.parametrize("edit, message", BAD_FILES.values(), ids=BAD_FILES.keys())
def test_a_malformed_export_is_one_line_naming_file_row_and_column(tmp_path, edit, message):
    folder = write_trial(tmp_path / "lab", lambda k, lines: edit(lines) if k == 1 else None)
    with pytest.raises(SensorDataError, match=message) as info:
        import_folder(folder)
    assert str(info.value).startswith(str(folder / "sensor1.csv")) and "\n" not in str(info.value)


def test_floors_must_match_the_storeys(tmp_path):
    folder = write_trial(tmp_path / "lab")
    toml = folder / "experiment.toml"
    toml.write_text(toml.read_text().replace(', "sensor3.csv"', ""))
    with pytest.raises(ScenarioError, match=r"key 'runs\[0\]\.floors' = .*expected 3 files, one per floor"):
        import_folder(folder)


def test_the_shipped_files_are_compressed_and_small():
    files = [p for p in FOLDER.rglob("*") if p.is_file()]
    assert len(files) == 4 * 5 + 1  # 4 sensors x 5 trials, plus experiment.toml
    assert all(p.suffix == ".gz" for p in files if p.name != "experiment.toml")
    assert all(p.stat().st_size < 2_000_000 for p in files)  # the project's limit per file


# ----------------------------------------------------------------------------- viewing real data

def test_displacements_from_accelerations_are_drift_free():
    dt, T, f = 1 / 120.0, 20.0, 2.0
    t = np.arange(int(T / dt)) * dt
    x = 0.01 * np.sin(np.pi * t / T) ** 2 * np.sin(2 * np.pi * f * t)  # 1 cm, at rest at both ends
    freq = np.fft.rfftfreq(t.size, dt)
    a = np.fft.irfft(-(2 * np.pi * freq) ** 2 * np.fft.rfft(x), n=t.size)  # exact second derivative
    bias = 0.05 + 0.002 * t  # an IMU offset that wanders: doubly integrated it would drift by metres
    got = viewer.displacements_from_accelerations(a + bias, dt)
    # The detrend removes the bias and its drift, the 0.3 Hz high-pass passes the window's band
    # around 2 Hz to ~3e-7 relative: ~2e-7 m off.  1e-5 m (0.1 % of the amplitude) leaves room; plain
    # double integration of the bias alone would be off by 0.05 * 20^2 / 2 = 10 m.
    assert np.max(np.abs(got - x)) < 1e-5


def test_view_draws_the_real_building_from_its_accelerations(shipped, tmp_path):
    one = dataclasses.replace(shipped, runs=(shipped.run("bonus_event"),))
    scene = viewer.prepare(one, exaggeration=2.0)
    z, q = scene.drawn(one.runs[0])
    assert z.shape == (one.runs[0].n_samples,) and q.shape == (one.runs[0].n_samples, 3)
    assert any("records accelerations only" in n for n in scene.notes)
    assert np.allclose(scene.heights, 0.1524)  # the lab's stated storey height
    rrd = viewer.write_rrd(scene, tmp_path / "bonus.rrd")
    chunks = defaultdict(list)
    for chunk in rerun_chunk.RrdReader(rrd).store().stream().to_chunks():
        chunks[chunk.entity_path].append(chunk.to_record_batch())
    root = "/runs/bonus_event"
    assert {f"{root}/sensors/{c}" for c in CHANNELS} <= set(chunks)
    assert {f"{root}/reconstructed/{c}" for c in ("z", "q1", "q2", "q3")} <= set(chunks)
    idx = viewer.rig_samples(one.runs[0])
    translations = []
    for batch in chunks[f"{root}/rig/base/floor3"]:
        if "Transform3D:translation" in batch.schema.names and "time" in batch.schema.names:
            translations += batch.column("Transform3D:translation").to_pylist()
    drawn = np.array(translations, float).reshape(-1, 3)[:, 0]
    # The top floor moves by the exaggerated reconstruction (float32 in the file: 1e-7 relative).
    assert np.allclose(np.sort(drawn), np.sort(2.0 * q[idx, 2]), rtol=1e-6, atol=1e-9)


def test_names_of_the_uncompressed_exports_find_the_shipped_gzip_files(tmp_path, shipped):
    folder = tmp_path / "flexible_3storey"
    shutil.copytree(FOLDER, folder)
    toml = folder / "experiment.toml"
    toml.write_text(toml.read_text().replace(".csv.gz", ".csv"))
    again = import_folder(folder)
    assert all(np.array_equal(a.values, b.values) for a, b in zip(again.runs, shipped.runs))



def _one_trial(folder: Path, name: str, late: int | None = None) -> Path:
    """Run ``name`` of the shipped rig alone as plain files in ``folder``; sensor ``late`` (0: the table)
    switched on 30 s late: its first 3600 rows (at 120 Hz) are gone."""
    text = (FOLDER / "experiment.toml").read_text()
    spec = tomllib.loads(text)
    run = next(r for r in spec["runs"] if r["name"] == name)
    names = ["table.csv", "f1.csv", "f2.csv", "f3.csv"]
    folder.mkdir()
    for k, (source, target) in enumerate(zip([run["table"], *run["floors"]], names)):
        lines = gzip.decompress((FOLDER / source).read_bytes()).decode("utf-8").splitlines()
        if k == late:
            first = next(i for i, line in enumerate(lines) if line.startswith("PacketCounter")) + 1
            del lines[first:first + 3600]
        (folder / target).write_text("\n".join(lines) + "\n")
    (folder / "experiment.toml").write_text(text.split("[[runs]]")[0] + f'[[runs]]\nname = "{name}"\ntable = '
                                            f'"table.csv"\nfloors = ["f1.csv", "f2.csv", "f3.csv"]\n')
    return folder


@pytest.mark.parametrize("trial, floor", [("northridge", 1), ("northridge", 2), ("sine_1p5", 3)])
def test_a_floor_file_that_starts_30_s_late_gets_no_drift(tmp_path, trial, floor):
    """Issue 32, silent wrong 3: a floor file that starts 30 s late got an invented drift ("drifts by -284
    ppm ... resampled", ending 1.8 samples off; before the fix, northridge's floor 1 read -236 ppm and
    floor 2 -445 ppm: the trial whose clocks are aligned from the data).  The run keeps the span every
    sensor covers, and there every sample is the clean import's, on the same clock."""
    clean = import_folder(_one_trial(tmp_path / "clean", trial)).runs[0]
    late = import_folder(_one_trial(tmp_path / "late", trial, floor)).runs[0]
    notes = " ".join([*late.meta["notes"], *(n for s in late.meta["sensors"] for n in s["notes"])])
    assert "drift" not in notes and "resampled" not in notes, notes
    k = clean.n_samples - late.n_samples          # the late file ends with the others
    assert f"kept the {late.n_samples} samples every sensor covers" in notes and k > 3500
    for ch in late.channels:
        diff = clean[ch][k:] - late[ch]
        # The same samples: they differ by the offset each sensor removes (its mean over the span it keeps),
        # a constant, to float rounding (1e-12 m/s^2).  A lag of 0.1 sample would leave ~1e-2 m/s^2 here
        # (floor accelerations of ~1 m/s^2 at 1.5 Hz and more), a drift more.
        assert np.ptp(diff) < 1e-12, (ch, np.ptp(diff))
