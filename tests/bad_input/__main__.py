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

from . import CASES, Group, Outcome, check, observe


def summary() -> int:
    counts: Counter = Counter()
    wrong = []
    for case in CASES:
        with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            problem = check(case, observe(case, Path(tmp)))
        if case.xfail:
            counts[case.group, "known defect"] += 1
            if problem is None:
                wrong.append(f"{case.group.name.lower()}:{case.id}: marked as a known defect but passes")
        else:
            counts[case.group, case.outcome] += 1
            if problem is not None:
                wrong.append(f"{case.group.name.lower()}:{case.id}: {problem}")
    columns = [*Outcome, "known defect"]
    names = [c.name.lower() if isinstance(c, Outcome) else c for c in columns]
    print(f"| entry point | {' | '.join(names)} | cases |")
    print("|---" * (len(columns) + 2) + "|")
    for group in Group:
        row = [counts[group, c] for c in columns]
        print(f"| {group.value} | {' | '.join(map(str, row))} | {sum(row)} |")
    totals = [sum(counts[g, c] for g in Group) for c in columns]
    print(f"| all | {' | '.join(map(str, totals))} | {sum(totals)} |")
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
