"""The planner's guards (issue 22 point 8): ``plan --max-runs 1000000`` ran for hours with no output;
now its time is estimated from its first candidate run and its memory from its size, and a plan
beyond either is refused before the rest starts, saying what fits and how to go past the limit."""

from __future__ import annotations

import time

import pytest

import momentid as mi
from momentid.cli import main
from momentid.errors import ResourceError, TimeLimitError
from momentid.estimation.design import plan

from bad_input.cli import THREE_RUNS
from conftest import SCENARIOS

#: The tiny three-run scenario (0.5 s at 200 Hz) with 1 % sensor noise: a plan of it takes seconds.
NOISY_TINY = THREE_RUNS + ('[sensors]\nset = "accel+disp"\n[sensors.accelerometer]\nrelative_noise = 0.01\n'
                           '[sensors.displacement]\nrelative_noise = 0.01\n')


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(NOISY_TINY)
    return mi.load_scenario(path)


def test_a_plan_beyond_its_time_limit_is_refused_before_it_starts(tiny):
    start = time.perf_counter()
    with pytest.raises(TimeLimitError) as info:
        plan(tiny, max_runs=5000, time_limit=10.0)
    elapsed = time.perf_counter() - start
    # refused after timing one candidate run (well under a second here), not after 2 x 5 x 4999 of them:
    # 10 s leaves room for a loaded machine
    assert elapsed < 10.0, elapsed
    message = str(info.value)
    assert "\n" not in message and "5000 runs" in message and "--max-runs" in message and "--time-limit" in message
    fit = int(message.split("--max-runs ")[1].split(")")[0])
    assert 2 <= fit < 5000


def test_a_plan_too_big_for_memory_is_refused_before_it_starts(tiny):
    with pytest.raises(ResourceError, match="plan of 9999990 designs"):
        plan(tiny, max_runs=1_000_000, time_limit=None)


def test_a_plan_within_its_limits_reports_its_progress_and_a_short_record_works(tiny):
    """The 0.5 s scenario also checks the planner's noise excitation on a short record (its 1 s ramp
    was refused as 'excitation.taper', a key the user never wrote)."""
    seen = []
    designs, _ = plan(tiny, max_runs=3, progress=lambda done, total: seen.append((done, total)))
    assert len(designs) == 20 and seen[-1] == (20, 20)   # two excitations x five patterns x 2 or 3 runs
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)


def test_the_command_line_says_it_in_one_line(capsys):
    code = main(["plan", str(SCENARIOS / "lab_noisy.toml"), "--max-runs", "1000", "--time-limit", "1"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1 and "refused before starting" in err
    assert main(["plan", str(SCENARIOS / "lab_noisy.toml"), "--max-runs", "1"]) == 2
    assert "--max-runs 1: expected at least 2" in capsys.readouterr().err
