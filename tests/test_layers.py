"""The package's layers, enforced (issue 30 point 1): no module imports a layer above its own, and no
two modules import each other, directly or round a loop.

Layers, lowest first (a module may import its own layer's package and any lower layer)::

    core (with errors)  <  io, mechanisms (independent of each other)  <  lab  <  estimation  <  twin
        <  diagnosis  <  report  <  cli (with the package's front: momentid/__init__, sweep, cli_*)

Every import counts: at the top of a module, inside a function, under ``if TYPE_CHECKING`` and
``importlib.import_module("momentid....")`` with a literal name.  The graph is drawn from the source
(``ast``), so it needs no import of the package and sees imports that never run in the suite.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "momentid"

#: The layer of each top-level part of the package.
LAYER_OF = {"core": "core", "errors": "core", "io": "io", "mechanisms": "mechanisms", "lab": "lab",
            "estimation": "estimation", "twin": "twin", "diagnosis": "diagnosis", "report": "report",
            "cli": "cli", "cli_commands": "cli", "cli_output": "cli", "cli_values": "cli", "sweep": "cli",
            "__main__": "cli", "": "cli"}
#: Rank of each layer, lowest first; layers of one rank are independent of each other.
RANK = {"core": 0, "io": 1, "mechanisms": 1, "lab": 2, "estimation": 3, "twin": 4, "diagnosis": 5, "report": 6,
        "cli": 7}


def module_names(root: Path) -> dict[str, Path]:
    """Dotted name -> file of every module of the package under ``root``."""
    out = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _imported(node: ast.AST, name: str, is_package: bool, modules: dict) -> list[str]:
    """The package's modules ``node`` imports (``from a import b`` is module ``a.b`` when there is one)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        base = node.module or ""
        if node.level:
            here = name.split(".")[:len(name.split(".")) - (0 if is_package else 1)]
            here = here[:len(here) - (node.level - 1)]
            base = ".".join(here + ([node.module] if node.module else []))
        return [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
    if (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module"
            and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
        return [node.args[0].value]
    return []


def import_graph(root: Path = ROOT) -> dict[str, dict[str, int]]:
    """module -> {imported module of the package: first line}, every import of every module."""
    modules = module_names(root)
    graph: dict[str, dict[str, int]] = {}
    for name, path in modules.items():
        edges = graph.setdefault(name, {})
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            for target in _imported(node, name, path.name == "__init__.py", modules):
                while target not in modules and "." in target:      # a name from a module: the module
                    target = target.rsplit(".", 1)[0]
                if target in modules and target != name and target.split(".")[0] == PACKAGE:
                    edges.setdefault(target, node.lineno)
    return graph


def part(module: str) -> str:
    """The top-level part of the package a module belongs to (``""``: the package's ``__init__``)."""
    return module.split(".")[1] if "." in module else ""


def upward(graph: dict[str, dict[str, int]]) -> list[str]:
    """Every import of a module from a layer above its own, or from an independent layer of its rank."""
    out = []
    for source, edges in graph.items():
        mine = LAYER_OF[part(source)]
        for target, line in edges.items():
            theirs = LAYER_OF[part(target)]
            if theirs != mine and RANK[theirs] >= RANK[mine]:
                out.append(f"{source}:{line} imports {target} (layer {theirs} is not below {mine})")
    return out


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected sets of two modules or more (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.append(member)
                    if member == node:
                        break
                if len(group) > 1:
                    found.append(sorted(group))
    return found


def test_every_part_has_a_layer():
    unknown = sorted({part(m) for m in module_names(ROOT)} - set(LAYER_OF))
    assert not unknown, f"parts of the package with no layer in tests/test_layers.py: {unknown}"


def test_no_module_imports_a_layer_above_its_own():
    found = upward(import_graph())
    assert not found, "imports from a layer above:\n" + "\n".join(found)


def test_no_import_cycles():
    found = cycles(import_graph())
    assert not found, "modules that import each other:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_the_checks_can_fail(tmp_path):
    """A lower layer importing a higher one (inside a function, relatively) and a loop of two are found."""
    files = {
        "__init__.py": "",
        "core/__init__.py": "",
        "core/a.py": "def f():\n    from ..lab import b\n",
        "lab/__init__.py": "",
        "lab/b.py": "from momentid.lab import c\n",
        "lab/c.py": "import importlib\nimportlib.import_module('momentid.lab.b')\n",
        "io/d.py": "from momentid.mechanisms.e import X\n",
        "mechanisms/e.py": "X = 1\n",
    }
    for name, text in files.items():
        (tmp_path / PACKAGE / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / PACKAGE / name).write_text(text, encoding="utf-8")
    graph = import_graph(tmp_path)
    assert [u.split(" ")[0] for u in upward(graph)] == ["momentid.core.a:2", "momentid.io.d:1"]
    assert cycles(graph) == [["momentid.lab.b", "momentid.lab.c"]]


def test_the_graph_sees_the_package():
    graph = import_graph()
    assert len(graph) > 100 and "momentid.lab.rig" in graph["momentid.lab.simulation"]
