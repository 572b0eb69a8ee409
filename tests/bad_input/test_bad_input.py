"""Every bad-input case ends in its promised outcome class (see tests/bad_input/_core.py).

A case marked ``xfail`` is a known defect in a module this suite does not own; the mark is strict,
so fixing the defect turns the case into a failure until the mark is removed.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from . import CASES, check, observe
from ._core import promised, table

RELIABILITY = Path(__file__).resolve().parents[2] / "docs" / "reliability.md"


def _param(case):
    marks = [pytest.mark.xfail(strict=True, reason=case.xfail)] if case.xfail else []
    return pytest.param(case, id=f"{case.group.name.lower()}:{case.id}", marks=marks)


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_bad_input_ends_as_promised(case, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = check(case, observe(case, tmp_path))
    assert problem is None, problem


def test_the_suite_covers_every_entry_point_with_enough_cases():
    """Issue 12 asks for at least 120 cases over six entry points."""
    groups = {c.group for c in CASES}
    ids = [(c.group, c.id) for c in CASES]
    assert len(groups) == 6 and len(CASES) >= 120
    assert len(set(ids)) == len(ids), "case ids must be unique within their entry point"


def test_the_reliability_guide_gives_the_suite_s_current_figures():
    """docs/reliability.md pastes the output of `python -m tests.bad_input --summary`; when every case
    ends as promised (the test above), that table is the one the case tables promise."""
    assert "\n".join(table(promised(CASES))) in RELIABILITY.read_text(encoding="utf-8"), (
        "docs/reliability.md is out of date: paste the table of `python -m tests.bad_input --summary`")
