"""The public API, checked mechanically over every module of the package.

Issue 10 item 5: no public name that is also a module name, every ``__all__``
correct, and the top-level functions documented (numpydoc).
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
import types

import pytest

import momentid



def _modules() -> dict[str, types.ModuleType]:
    """Every module of the package, imported (``__main__`` runs the CLI, so it is left out)."""
    names = ["momentid"] + [m.name for m in pkgutil.walk_packages(momentid.__path__, "momentid.")
                            if not m.name.endswith(".__main__")]
    return {name: importlib.import_module(name) for name in names}


MODULES = _modules()
PACKAGES = {name: mod for name, mod in MODULES.items() if hasattr(mod, "__path__")}
#: The last part of every module name: a public attribute spelled like one of
#: these would shadow the module (``momentid.identify`` the function vs. a module).
MODULE_NAMES = {name.rsplit(".", 1)[-1] for name in MODULES}


def _public_attributes(mod: types.ModuleType) -> set[str]:
    return {n for n in vars(mod) if not n.startswith("_") and not isinstance(getattr(mod, n), types.ModuleType)}


@pytest.mark.parametrize("name", sorted(MODULES))
def test_every_name_in_all_exists_once(name):
    mod = MODULES[name]
    assert hasattr(mod, "__all__"), f"{name} has no __all__: say what it offers"
    missing = [n for n in mod.__all__ if not hasattr(mod, n)]
    assert not missing, f"{name}.__all__ names what the module lacks: {missing}"
    doubled = sorted({n for n in mod.__all__ if mod.__all__.count(n) > 1})
    assert not doubled, f"{name}.__all__ lists twice: {doubled}"


@pytest.mark.parametrize("name", sorted(PACKAGES))
def test_package_all_is_exactly_its_public_names(name):
    """A package's public attributes (what its ``__init__`` imports) are its ``__all__``, no more, no less."""
    mod = PACKAGES[name]
    assert hasattr(mod, "__all__"), f"{name} has no __all__"
    assert _public_attributes(mod) - {"__version__"} == set(mod.__all__)


@pytest.mark.parametrize("name", sorted(PACKAGES))
def test_no_public_name_is_also_a_module_name(name):
    mod = PACKAGES[name]
    clashes = sorted(_public_attributes(mod) & MODULE_NAMES)
    assert not clashes, f"{name} exports {clashes}, spelled like modules of momentid"


def test_top_level_names_are_their_modules_objects_under_the_same_name():
    """``momentid.X`` is the object its defining module calls X: no renamed re-exports."""
    for name in momentid.__all__:
        obj = getattr(momentid, name)
        home = inspect.getmodule(obj)
        if home is not None and home.__name__.startswith("momentid."):
            assert getattr(home, name) is obj


TOP_FUNCTIONS = sorted(n for n in momentid.__all__ if inspect.isfunction(getattr(momentid, n)))
_SECTION = re.compile(r"^(Parameters|Returns)\n-{3,}$", re.M)


@pytest.mark.parametrize("name", TOP_FUNCTIONS)
def test_top_level_function_has_a_numpydoc_docstring(name):
    """``help(momentid.X)`` explains itself: a summary line, and a Parameters section (or, for a
    function without parameters, a Returns section) naming every parameter."""
    func = getattr(momentid, name)
    doc = inspect.getdoc(func)
    assert doc, f"momentid.{name} has no docstring"
    sections = set(_SECTION.findall(doc))
    params = [p for p in inspect.signature(func).parameters if not p.startswith("_")]
    if not params:
        assert "Returns" in sections, f"momentid.{name}: no Returns section"
        return
    assert "Parameters" in sections, f"momentid.{name}: no numpydoc Parameters section"
    block = doc.split("Parameters\n----------", 1)[1]
    block = re.split(r"\n\n\S[^\n]*\n-{3,}", block, maxsplit=1)[0]
    documented = set(re.findall(r"^([A-Za-z_][\w, ]*?)\s*(?::|$)", block, re.M))
    named = {p.strip() for entry in documented for p in entry.split(",")}
    undocumented = [p for p in params if p not in named]
    assert not undocumented, f"momentid.{name}: parameters not in the docstring: {undocumented}"
