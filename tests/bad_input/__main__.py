"""``python -m tests.bad_input --summary``: run every case, print the count per entry point and
outcome class, and exit non-zero if any case ends in an outcome other than the promised one (a
known defect marked ``xfail`` must still fail: one that passes is reported too)."""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from collections import Counter
from pathlib import Path

from . import CASES, check, observe
from ._core import KNOWN_DEFECT, table


def summary() -> int:
    """Run every case; print the table of outcomes and every case that ended otherwise."""
    counts: Counter = Counter()
    wrong = []
    for case in CASES:
        with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            problem = check(case, observe(case, Path(tmp)))
        where = f"{case.group.name.lower()}:{case.id}"
        if case.xfail:
            counts[case.group, KNOWN_DEFECT] += 1
            if problem is None:
                wrong.append(f"{where}: marked as a known defect but passes")
        elif problem is None:
            counts[case.group, case.outcome] += 1
        else:
            wrong.append(f"{where}: {problem}")
    print("\n".join(table(counts)))
    print(f"\n{len(CASES) - len(wrong)} of {len(CASES)} cases end as promised "
          f"(known defects: still failing as recorded)")
    for line in wrong:
        print(f"  WRONG {line}")
    return 1 if wrong else 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(prog="python -m tests.bad_input", description=__doc__)
    parser.add_argument("--summary", action="store_true", help="run every case and print the counts")
    args = parser.parse_args()
    if not args.summary:
        parser.print_help()
        sys.exit(2)
    sys.exit(summary())
