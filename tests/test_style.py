"""The code stays in order (issue 30 point 6): clean under the project's linter (``ruff check`` with the
configuration in pyproject.toml ([tool.ruff]: line length 120, pycodestyle, pyflakes, bugbear,
pyupgrade) over the package, its tests and the benchmarks); every public function of the package
documented and typed; no function longer than a screen."""

from __future__ import annotations

import ast
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


# ---------------------------------------------------------------- documented, typed, one screen

PACKAGE_SOURCES = sorted((ROOT / "momentid").rglob("*.py"))
#: Longest function, in lines: from its ``def`` to its last line, its docstring not counted (issue 30
#: point 6: "functions read in one screen"; a numpydoc docstring documents the code, it does not make
#: the code longer to read).
MAX_FUNCTION_LINES = 80


def _docstring_lines(node: ast.AST) -> int:
    first = node.body[0] if node.body else None
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        return first.end_lineno - first.lineno + 1
    return 0


def public_functions(tree: ast.Module) -> list[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]]:
    """(qualified name, node) of every public function of a module: its own functions and the methods of
    its public classes (nested classes too) whose names do not start with ``_``; a function nested in
    another is that function's own business."""
    out = []

    def walk(body: list[ast.stmt], prefix: str) -> None:
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
                out.append((prefix + node.name, node))
            elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                walk(node.body, f"{prefix}{node.name}.")

    walk(tree.body, "")
    return out


def undocumented_or_untyped(source: str) -> list[str]:
    """What a module's public functions lack: a docstring, a parameter's annotation (``self`` and ``cls``
    as a method's first parameter excepted) or the return's."""
    found = []
    for name, node in public_functions(ast.parse(source)):
        args = node.args
        params = [*args.posonlyargs, *args.args, *args.kwonlyargs, *filter(None, (args.vararg, args.kwarg))]
        untyped = [p.arg for i, p in enumerate(params)
                   if p.annotation is None and not (i == 0 and p.arg in ("self", "cls"))]
        if not ast.get_docstring(node):
            found.append(f"{name}:{node.lineno}: no docstring")
        if untyped:
            found.append(f"{name}:{node.lineno}: untyped {', '.join(untyped)}")
        if node.returns is None:
            found.append(f"{name}:{node.lineno}: no return annotation")
    return found


def long_functions(source: str, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """Every function (nested ones and methods included) longer than ``limit`` lines, docstring apart."""
    return [f"{node.name}:{node.lineno}: {length} lines"
            for node in ast.walk(ast.parse(source)) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            for length in [node.end_lineno - node.lineno + 1 - _docstring_lines(node)] if length > limit]


def test_every_public_function_is_documented_and_typed():
    found = [f"{path.relative_to(ROOT)}: {what}" for path in PACKAGE_SOURCES
             for what in undocumented_or_untyped(path.read_text(encoding="utf-8"))]
    assert not found, "public functions without a docstring or a type:\n" + "\n".join(found)


def test_no_function_is_longer_than_a_screen():
    found = [f"{path.relative_to(ROOT)}: {what}" for path in PACKAGE_SOURCES
             for what in long_functions(path.read_text(encoding="utf-8"))]
    assert not found, f"functions over {MAX_FUNCTION_LINES} lines (split them into helpers):\n" + "\n".join(found)


def test_the_function_checks_can_fail():
    """A public function and a public method without docstring or types are found, private ones and a
    function nested in another are not; a long body is found, a long docstring is not."""
    source = (
        "def f(x, *, y: int = 1):\n    return x\n\n"
        "def _private(x):\n    return x\n\n"
        "class C:\n    def m(self, z) -> int:\n        '''Doc.'''\n        def inner(w):\n            return w\n"
        "        return z\n\n"
        "class _Hidden:\n    def m(self, z):\n        return z\n\n"
        "def documented(a: int) -> int:\n    '''Doc\n" + "    more\n" * 100 + "    '''\n    return a\n\n"
        "def long(a: int) -> int:\n    '''Doc.'''\n" + "    a += 1\n" * 80 + "    return a\n"
    )
    assert undocumented_or_untyped(source) == ["f:1: no docstring", "f:1: untyped x", "f:1: no return annotation",
                                               "C.m:8: untyped z"]
    long_at = source.split("\n").index("def long(a: int) -> int:") + 1
    assert long_functions(source) == [f"long:{long_at}: 82 lines"]
