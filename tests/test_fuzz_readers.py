"""Property-based fuzzing of the readers (issue 12): whatever bytes a user hands momentid, a reader
either returns valid data or raises :class:`~momentid.errors.MomentidError`; never anything else.

Every test runs twice: with the ``fuzz-fast`` profile (bounded and derandomized, in the default run)
and with ``fuzz-slow`` (thousands of random examples, ``-m slow``); see tests/conftest.py.  Inputs are
well-formed files mutated by Hypothesis (a value replaced, a byte flipped, the file cut) plus raw
text or bytes, so most examples get past the first line of the parser.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import momentid as mi
from momentid.errors import MomentidError
from momentid.io.formats import MAX_ABS_SAMPLE
from momentid.io.formats.csv_run import read_csv_run
from momentid.io.formats.xsens_dot import read_xsens_dot
from momentid.io.importer import import_folder
from momentid.io.recording import read_recording

from bad_input import csv_import, imu_import, recording, scenario  # noqa: E402  (tests/ is on sys.path)

PROFILES = [pytest.param("fuzz-fast", id="fast"), pytest.param("fuzz-slow", id="long", marks=pytest.mark.slow)]

#: TOML values of every type a key might wrongly get.
TOML_VALUES = st.one_of(
    st.integers(-10**20, 10**20).map(str), st.floats(allow_nan=True, allow_infinity=True).map(
        lambda x: "nan" if x != x else ("inf" if x == float("inf") else "-inf" if x == float("-inf") else repr(x))),
    st.text(max_size=12).map(lambda s: '"' + s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'),
    st.booleans().map(lambda b: "true" if b else "false"), st.just("[]"), st.just("{}"), st.just("[1, [2]]"),
    st.just('["a", "b"]'), st.just("1979-05-27"), st.lists(st.floats(-1e9, 1e9), max_size=4).map(str),
)


def _mutated_toml(base: str) -> st.SearchStrategy[str]:
    """``base`` with the value of one of its ``key = value`` lines replaced, or a line dropped or
    duplicated, or ``base`` cut short."""
    lines = base.split("\n")
    assigned = [i for i, line in enumerate(lines) if " = " in line]

    def replace(i, value):
        out = list(lines)
        out[i] = out[i].split(" = ")[0] + " = " + value
        return "\n".join(out)

    return st.one_of(
        st.builds(replace, st.sampled_from(assigned), TOML_VALUES),
        st.integers(0, len(lines) - 1).map(lambda i: "\n".join(lines[:i] + lines[i + 1:])),
        st.integers(0, len(lines) - 1).map(lambda i: "\n".join(lines[:i + 1] + lines[i:])),
        st.integers(0, len(base)).map(lambda n: base[:n]),
        st.text(max_size=200),
    )


def _run_profile(profile: str, strategy, check) -> None:
    """Feed every example to ``check``; it must return data it has checked or raise MomentidError.
    Some examples must parse, or the fuzzing would only exercise the first refusal."""
    parsed = []

    @settings(settings.get_profile(profile))
    @given(strategy)
    def run(example):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # recovery notes are data here
            try:
                check(example)
            except MomentidError:
                return
        parsed.append(True)
    run()
    assert parsed, "no example parsed: the mutations never got past the reader's first check"


@pytest.mark.parametrize("profile", PROFILES)
def test_scenario_toml_parses_or_raises_momentid_error(profile, tmp_path):
    path = tmp_path / "s.toml"

    def check(text):
        path.write_bytes(text.encode("utf-8", errors="replace"))  # lone surrogates cannot be UTF-8
        loaded = mi.load_scenario(path)
        assert loaded.duration > 0 and loaded.sample_rate > 0 and len(loaded.runs) >= 1

    _run_profile(profile, _mutated_toml(scenario.BASE), check)


@pytest.mark.parametrize("profile", PROFILES)
def test_experiment_toml_parses_or_raises_momentid_error(profile, tmp_path):
    lab = csv_import.lab_folder(tmp_path)

    def check(text):
        (lab / "experiment.toml").write_bytes(text.encode("utf-8", errors="replace"))
        experiment = import_folder(lab)
        assert len(experiment.runs) >= 1

    _run_profile(profile, _mutated_toml(csv_import.EXPERIMENT), check)


def _mutated_lines(base: str, cells: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    """``base`` (comma-separated lines) with one cell replaced, a line dropped, or cut short."""
    lines = base.rstrip("\n").split("\n")

    def replace(i, j, value):
        out = list(lines)
        row = out[i].split(",")
        row[j % len(row)] = value
        out[i] = ",".join(row)
        return "\n".join(out) + "\n"

    return st.one_of(
        st.builds(replace, st.integers(0, len(lines) - 1), st.integers(0, 20), cells),
        st.integers(0, len(lines) - 1).map(lambda i: "\n".join(lines[:i] + lines[i + 1:])),
        st.integers(0, len(base)).map(lambda n: base[:n]),
        st.text(alphabet=st.sampled_from("0123456789.,-e+\n tnaiz"), max_size=300),
    )


CELLS = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers().map(str),
                  st.text(max_size=8), st.sampled_from(["", " ", "nan", "1e308", "-1e400", "0x10", "1_0", "١"]))


@pytest.mark.parametrize("profile", PROFILES)
def test_csv_run_parses_or_raises_momentid_error(profile, tmp_path):
    path = tmp_path / "r.csv"

    def check(text):
        path.write_bytes(text.encode("utf-8", errors="replace"))
        time, channels, values = read_csv_run(path, 2)
        assert values.shape == (time.size, len(channels)) and np.all(np.diff(time) > 0)
        assert not np.any(np.abs(values) > MAX_ABS_SAMPLE)  # nan compares False: a missing sample

    _run_profile(profile, _mutated_lines(csv_import.csv_text(1), CELLS), check)


@pytest.mark.parametrize("profile", PROFILES)
def test_xsens_dot_parses_or_raises_momentid_error(profile, tmp_path):
    path = tmp_path / "dot.csv"

    def check(text):
        path.write_bytes(text.encode("utf-8", errors="replace"))
        record = read_xsens_dot(path)
        assert record.acc.shape == (record.time.size, 3) and np.all(np.diff(record.time) > 0)
        assert not np.any(np.abs(record.acc) > MAX_ABS_SAMPLE)

    _run_profile(profile, _mutated_lines(imu_import.dot_text(), CELLS), check)


def _mutated_bytes(data: bytes) -> st.SearchStrategy[bytes]:
    """``data`` with bytes overwritten, a span deleted or inserted, or cut short; or random bytes
    behind the MCAP magic."""
    n = len(data)

    def overwrite(at, new):
        return data[:at] + new + data[at + len(new):]

    return st.one_of(
        st.builds(overwrite, st.integers(0, n - 1), st.binary(min_size=1, max_size=8)),
        st.builds(lambda a, k: data[:a] + data[a + k:], st.integers(0, n - 1), st.integers(1, 64)),
        st.builds(lambda a, b: data[:a] + b + data[a:], st.integers(0, n), st.binary(min_size=1, max_size=32)),
        st.integers(0, n).map(lambda k: data[:k]),
        st.binary(max_size=256).map(lambda b: data[:8] + b),
    )


@pytest.mark.parametrize("profile", PROFILES)
def test_recording_parses_or_raises_momentid_error(profile, tmp_path):
    (tmp_path / "good").mkdir()
    data = recording.good(tmp_path / "good", n_runs=2)[0].read_bytes()
    path = tmp_path / "fuzz.mcap"

    def check(blob):
        path.write_bytes(blob)
        experiment = read_recording(path)
        for run in experiment.runs:
            assert run.values.shape == (run.time.size, len(run.channels)) and np.all(np.diff(run.time) > 0)
        assert experiment.complete or experiment.notes  # damage is never silent

    _run_profile(profile, _mutated_bytes(data), check)
