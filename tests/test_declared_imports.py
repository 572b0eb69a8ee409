"""Every module-level import of the package and its tests is provided by a declared requirement.

A fresh machine installs only what pyproject.toml declares (`pip install -e ".[test]"`); an import that
works here only because this machine happens to hold the package breaks the README's test command there.
`.ci/run` proves it on a throwaway virtual environment; this test names the offending file and module.
"""

from __future__ import annotations

import ast
import importlib.metadata as metadata
import re
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Import names whose distribution is named otherwise, for modules not installed on this machine.
ALIASES = {"google": "protobuf", "rerun": "rerun-sdk", "mcap_protobuf": "mcap-protobuf-support"}


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement_names(requirements: list[str]) -> set[str]:
    return {_norm(re.split(r"[<>=!~\[;@ ]", r.strip(), maxsplit=1)[0]) for r in requirements if r.strip()}


def _module_level_imports(path: Path) -> set[str]:
    """Top-level names imported by the module body (not inside functions or try blocks: those are optional)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def _local_names() -> set[str]:
    local = {"momentid", "tests", "benchmarks", "conftest"}
    for folder in (ROOT, ROOT / "tests"):
        local |= {p.stem for p in folder.glob("*.py")}
        local |= {p.name for p in folder.iterdir() if p.is_dir()}
    return local


def _undeclared(folder: str, allowed: set[str]) -> list[str]:
    providers = metadata.packages_distributions()
    local = _local_names()
    problems = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for module in sorted(_module_level_imports(path)):
            if module in sys.stdlib_module_names or module in local:
                continue
            distributions = {_norm(d) for d in providers.get(module, [])} or {_norm(ALIASES.get(module, module))}
            if not distributions & allowed:
                problems.append(f"{path.relative_to(ROOT)}: '{module}' (from {sorted(distributions)})")
    return problems


@pytest.fixture(scope="module")
def declared() -> dict[str, set[str]]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    runtime = _requirement_names(project["dependencies"])
    test = runtime | _requirement_names(project["optional-dependencies"]["test"])
    return {"momentid": runtime, "tests": test}


@pytest.mark.parametrize("folder", ["momentid", "tests"])
def test_every_module_level_import_is_declared(folder, declared):
    problems = _undeclared(folder, declared[folder])
    assert not problems, f"imports no declared requirement of {folder}/ provides: {problems}"


def test_the_check_catches_an_undeclared_import(tmp_path, declared, monkeypatch):
    """The check itself can fail: a module importing an undeclared package is reported."""
    package = tmp_path / "momentid"
    package.mkdir()
    (package / "uses_pandas.py").write_text("import numpy\nimport pandas_is_not_declared\n", encoding="utf-8")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    (tmp_path / "tests").mkdir()
    problems = _undeclared("momentid", declared["momentid"])
    assert len(problems) == 1 and "pandas_is_not_declared" in problems[0]
