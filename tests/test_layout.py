"""The package's shape (issue 20 point 4): modules that read in a sitting, and no private name
borrowed across modules (a name with a leading underscore is its module's own business)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Longest module, in lines (issue 20: "no module over 600 lines; split each along its natural seams").
MAX_MODULE_LINES = 600
SOURCES = sorted(p for folder in ("momentid", "benchmarks") for p in (ROOT / folder).rglob("*.py"))
CHECKED = SOURCES + sorted((ROOT / "tests").rglob("*.py"))
#: Import roots that are this project's own code (tests import their helpers as top-level packages).
OWN = ("momentid", "benchmarks", "bad_input", "conftest", "tests")


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_over_the_limit(path):
    lines = len(path.read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_MODULE_LINES, f"{path.relative_to(ROOT)}: {lines} lines: split it along its seams"


def test_no_private_name_is_imported_from_another_module():
    borrowed = []
    for path in CHECKED:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in OWN:
                borrowed += [f"{path.relative_to(ROOT)}:{node.lineno}: {node.module}.{a.name}"
                             for a in node.names if a.name.startswith("_") and not a.name.startswith("__")]
    assert not borrowed, "private names imported across modules:\n" + "\n".join(borrowed)


def test_the_checks_see_the_code():
    # The walk above finds the package (a wrong ROOT would pass both tests vacuously).
    assert any(p.name == "cli.py" for p in SOURCES) and len(CHECKED) > 100
