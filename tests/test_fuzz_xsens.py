"""Property-based Xsens DOT exports (issue 22): lengths, sample rates, clocks and packet counters that
wrap, lost rows, the app's lost-packet rows, nan and empty cells, repeated or missing stamps, units in
g, column orders and preamble variants.  Whatever the export, the reader (and the import of a lab
folder built from such exports) returns valid data, with a note whenever it repaired or converted
anything, or raises one :class:`~momentid.errors.MomentidError` of one line naming the file; never
another exception.

The default run uses the ``fuzz-fast`` profile (150 derandomized exports, and 12 lab folders);
``pytest -m slow`` runs ``fuzz-slow`` (5000 random exports, 300 folders).  Profiles: tests/conftest.py.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from momentid.errors import MomentidError
from momentid.io.formats import MAX_ABS_SAMPLE
from momentid.io.formats.xsens_dot import read_xsens_dot
from momentid.io.importer import import_folder

from bad_input.import_faults import IMU_TOML, rig_motion

PROFILES = [pytest.param("fuzz-fast", id="fast"), pytest.param("fuzz-slow", id="long", marks=pytest.mark.slow)]
#: Lab folders per profile: each imports three sensor files of 30 s (~0.3 s apiece).
FOLDERS = {"fuzz-fast": 12, "fuzz-slow": 300}

COLUMNS = ("PacketCounter", "SampleTimeFine", "Euler_X", "Euler_Y", "Euler_Z", "Acc_X", "Acc_Y", "Acc_Z",
           "Gyr_X", "Gyr_Y", "Gyr_Z")
ACC = (5, 6, 7)
#: Sample intervals (us) of the DOT's output rates: 120, 60, 30, 10 and 1 Hz.
STEPS = (8333, 16667, 33333, 100000, 1000000)
PREAMBLES = (
    "sep=,\nDeviceTag:,Xsens DOT\nFirmwareVersion:,2.2.1\nAppVersion:,2023.6.0\n"
    "StartTime: ,2025-04-11_11:49:50_000 PDT\n"
    "\u00a9 Movella Technologies B. V. 2005-2025\n\n",
    "DeviceTag:,left leg\nStartTime: ,2025-03-06_12:21:16_000 PST\n\n",
    "",
    "sep=,\n\n\n",
    "sep=,\nsome note without a colon\nDeviceTag:,x,y,z\n",
)
FAULTS = ("gap", "lost-packet", "nan-cell", "empty-row", "repeat-stamp", "missing-stamp", "jitter", "inf-cell",
          "truncated-row", "g-units")


@dataclass(frozen=True)
class Export:
    """A generated export and whether it carries damage that a read must note (or refuse)."""

    text: str
    damaged: bool


@st.composite
def xsens_exports(draw, max_rows: int = 300) -> Export:
    """An Xsens DOT export as the app writes it, then with 0-3 faults from :data:`FAULTS`."""
    n = draw(st.integers(0, max_rows))
    step = draw(st.sampled_from(STEPS))
    start = draw(st.one_of(st.integers(0, 2 ** 32 - 1), st.just(2 ** 32 - 3 * step)))  # a clock that wraps
    first_packet = draw(st.one_of(st.integers(0, 65535), st.just(65533)))                # a counter that wraps
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    data = np.column_stack([(first_packet + np.arange(n)) % 65536, (start + step * np.arange(n)) % 2 ** 32,
                            rng.normal(0, 30, (n, 3)), 0.3 * rng.standard_normal((n, 2)),
                            9.81 + 0.1 * rng.standard_normal(n), rng.normal(0, 2, (n, 3))])
    if n:
        data[0, ACC[0]:ACC[-1] + 1] = 0.0  # the device writes its first row before it measures
    rows = [[f"{v:.0f}" if k < 2 else f"{v:.6f}" for k, v in enumerate(row)] for row in data]
    faults = sorted(draw(st.lists(st.sampled_from(FAULTS), max_size=3)), key=lambda f: f == "truncated-row")
    for fault in faults:
        if len(rows) < 4:
            break
        _apply(fault, rows, draw(st.integers(2, len(rows) - 2)), draw(st.integers(1, 8)), step)
    damaged = _must_note(rows) or ("g-units" in faults and len(rows) >= 4)
    order = list(range(len(COLUMNS)))
    if draw(st.booleans()):
        tail = order[2:]
        order = order[:2] + draw(st.permutations(tail))
    lines = [",".join(COLUMNS[k] for k in order)] + [",".join(r[k] for k in order if k < len(r)) for r in rows]
    text = draw(st.sampled_from(PREAMBLES)) + "\n".join(lines) + draw(st.sampled_from(["\n", "", "\n\n"]))
    if draw(st.booleans()):
        text = text.replace("\n", "\r\n")
    return Export(("\ufeff" if draw(st.booleans()) else "") + text, damaged)


def _must_note(rows: list[list[str]]) -> bool:
    """Whether a successful read of ``rows`` must say what it repaired: a missing acceleration, a row
    without a stamp, or packets lost between two rows (the counter skips; uint16)."""
    for i, row in enumerate(rows[1:], start=1):
        if len(row) < len(COLUMNS):
            return False  # a truncated row: the read must fail
        if row[1] == "" or any(row[k] in ("", "nan", "inf") for k in ACC):
            return True
        if (int(row[0]) - int(rows[i - 1][0])) % 65536 != 1:
            return True
    return False


def _apply(fault: str, rows: list[list[str]], at: int, size: int, step: int) -> None:
    """Apply ``fault`` at row ``at`` (``size`` rows where it spans several)."""
    if fault in ("lost-packet", "jitter") and "" in (rows[at - 1][1], rows[at][1]):
        return  # a stamp another fault removed: nothing to shift
    if fault == "gap":
        del rows[at:at + size]
    elif fault == "lost-packet":  # the app's mark: the stamp before jumps, this row repeats it, no data
        rows[at - 1][1] = str((int(rows[at - 1][1]) + step) % 2 ** 32)
        rows[at] = rows[at][:1] + [rows[at - 1][1]] + ["nan" if k % 2 else "inf" for k in range(9)]
    elif fault == "nan-cell":
        rows[at][ACC[size % 3]] = "nan"
    elif fault == "empty-row":
        for row in rows[at:at + size]:
            for k in ACC:
                row[k] = ""
    elif fault == "repeat-stamp":
        rows[at][1] = rows[at - 1][1]
    elif fault == "missing-stamp":
        rows[at][1] = ""
    elif fault == "jitter":
        rows[at][1] = str(int(rows[at][1]) + step // 3)
    elif fault == "inf-cell":
        rows[at][ACC[0]] = "-inf"
    elif fault == "truncated-row":
        del rows[at][size % 10 + 1:]
    elif fault == "g-units":
        for row in rows:
            for k in ACC:
                row[k] = repr(float(row[k]) / 9.80665) if row[k] not in ("", "nan", "inf") else row[k]


def _check_record(path, export: Export) -> None:
    record = read_xsens_dot(path)
    n = record.time.size
    assert record.acc.shape == (n, 3) and n >= 3
    assert np.all(np.isfinite(record.acc)) and not np.any(np.abs(record.acc) > MAX_ABS_SAMPLE)
    steps = np.diff(record.time)
    assert np.all(steps > 0) and np.allclose(steps, record.step, rtol=1e-6)
    assert record.notes or not export.damaged, "a repaired or converted export without a note"


def _one_line(exc: MomentidError, path) -> None:
    message = str(exc)
    assert "\n" not in message, message
    assert str(path) in message or "reading" in message, message


def _run(profile: str, strategy, check, examples: int | None = None) -> int:
    """Feed every example to ``check``; count the ones that parsed (some must, or the generator never
    gets past the reader's first refusal)."""
    parsed = []
    options = settings.get_profile(profile)
    if examples is not None:
        options = settings(options, max_examples=examples)

    @options
    @given(strategy)
    def run(example):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                check(example)
            except MomentidError as exc:
                _one_line(exc, "")
                return
        parsed.append(True)
    run()
    return len(parsed)


@pytest.mark.parametrize("profile", PROFILES)
def test_generated_xsens_exports_read_or_fail_in_one_line(profile, tmp_path):
    path = tmp_path / "dot.csv"
    seen = {"noted": 0}

    def check(export: Export):
        path.write_bytes(export.text.encode("utf-8"))
        try:
            _check_record(path, export)
        except MomentidError as exc:
            _one_line(exc, path)
            raise
        seen["noted"] += bool(read_xsens_dot(path).notes)

    assert _run(profile, xsens_exports(), check) > 0
    assert seen["noted"] > 0, "no generated export was repaired: the faults never reached the repair"


def _lab(tmp_path, faults: list[tuple[str, int, int]], counter: int) -> object:
    """A two-run lab of three-storey exports (tests/bad_input/import_faults.py) with ``faults`` applied
    to the file they name, then imported."""
    lab = tmp_path / f"lab{counter}"
    lab.mkdir()
    (lab / "experiment.toml").write_text(IMU_TOML)
    for r, run in enumerate(("run1", "run2")):
        x = rig_motion(3, r)
        for k, name in enumerate(("table", "f1", "f2", "f3")):
            n = x.shape[0]
            rows = [[str(i % 65536), str(1_000_000 * (r + 1) + i * 8333), "0", "0", "0",
                     f"{x[i, k]:.6f}" if i else "0", "0.001" if i else "0", "9.81" if i else "0", "0", "0", "0"]
                    for i in range(n)]
            for fault, file, at in faults:
                if file == 4 * r + k:
                    _apply(fault, rows, min(max(at, 2), len(rows) - 2), 1 + at % 7, 8333)
            text = "sep=,\nDeviceTag:,x\n\n" + ",".join(COLUMNS) + "\n" + "\n".join(",".join(c) for c in rows) + "\n"
            (lab / f"{run}_{name}.csv").write_text(text)
    return import_folder(lab)


@pytest.mark.parametrize("profile", PROFILES)
def test_generated_lab_folders_import_or_fail_in_one_line(profile, tmp_path):
    count = iter(range(10 ** 6))
    faults = st.lists(st.tuples(st.sampled_from(FAULTS), st.integers(0, 7), st.integers(0, 3600)), max_size=3)

    def check(example):
        experiment = _lab(tmp_path, example, next(count))
        for run in experiment.runs:
            assert np.all(np.isfinite(run.values)) and run.values.shape == (run.time.size, len(run.channels))
            assert run.channels[:4] == ("zdd", "a1", "a2", "a3")

    assert _run(profile, faults, check, FOLDERS[profile]) > 0
