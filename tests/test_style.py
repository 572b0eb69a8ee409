"""The code stays clean under the project's linter (issue 30 point 6): ``ruff check`` with the
configuration in pyproject.toml ([tool.ruff]: line length 120, pycodestyle, pyflakes, bugbear,
pyupgrade) over the package, its tests and the benchmarks."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _ruff(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def test_ruff_finds_nothing():
    done = _ruff("momentid", "tests", "benchmarks")
    assert done.returncode == 0, f"ruff check momentid tests benchmarks:\n{done.stdout}{done.stderr}"


def test_ruff_reads_the_project_configuration(tmp_path):
    """The check can fail: a line of 121 characters and an unused import, under the project's settings."""
    bad = tmp_path / "bad.py"
    bad.write_text("import os\n\nX = " + repr("x" * 115) + "\n", encoding="utf-8")   # a line of 121
    done = _ruff("--config", str(ROOT / "pyproject.toml"), str(bad), cwd=tmp_path)
    assert done.returncode == 1 and "F401" in done.stdout and "E501" in done.stdout, done.stdout
