"""The values the ``momentid`` command's options take: argparse types for positive numbers, times
and counts (a bad value is argparse's one-line usage error), and the ``--runs`` list."""

from __future__ import annotations

import argparse
import math

from momentid.errors import MomentidError

__all__ = ["positive_float", "finite_time", "positive_int", "run_names"]


def _float(text: str, accept, expected: str) -> float:
    """``text`` as a float that ``accept`` takes (a non-number never is), else argparse's usage error."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not accept(value):
        raise argparse.ArgumentTypeError(f"{text!r}: expected {expected}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a positive finite number."""
    return _float(text, lambda v: v > 0 and math.isfinite(v), "a positive number")


def finite_time(text: str) -> float:
    """argparse type: a finite time (s), at least 0."""
    return _float(text, lambda v: math.isfinite(v) and v >= 0, "a finite time in seconds, at least 0")


def positive_int(text: str) -> int:
    """argparse type: an integer of at least 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 1")
    return value


def run_names(text: str | None) -> list[str] | None:
    """``--runs a,b``: the names, each once (a run named twice would count its data twice)."""
    if text is None:
        return None
    names = [n.strip() for n in text.split(",")]
    if not all(names):
        raise MomentidError(f"--runs {text!r}: expected comma-separated run names, got an empty one")
    twice = [n for i, n in enumerate(names) if n in names[:i]]
    if twice:
        raise MomentidError(f"--runs {text}: run {twice[0]!r} is named twice; expected each run once (the same "
                            f"data counted twice would shrink every standard error by sqrt(2))")
    return names

