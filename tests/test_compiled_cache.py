"""Compiled code where numba has nowhere to keep its disk cache: compiled all the same, said once."""

import subprocess
import sys
import warnings

import pytest

from momentid.core import compiled


def _decorator(calls):
    def decorator(*args, cache=False, **options):
        calls.append(cache)
        if cache:
            raise RuntimeError("cannot cache function 'f': no locator available for file '/ro/f.py'")
        return lambda fn: ("compiled", fn, args, options)
    return decorator


def test_no_cache_location_compiles_without_the_cache_and_says_so_once(monkeypatch):
    monkeypatch.setattr(compiled, "_said", False)
    calls = []
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        first = compiled.disk_cached(_decorator(calls), "sig", nogil=True)(len)
        compiled.disk_cached(_decorator(calls), "sig")(abs)
    assert first == ("compiled", len, ("sig",), {"nogil": True}) and calls == [True, False, True, False]
    assert len(said) == 1 and issubclass(said[0].category, compiled.CacheUnavailableWarning)
    assert "NUMBA_CACHE_DIR" in str(said[0].message)


def test_any_other_error_of_numba_is_not_hidden():
    def decorator(*args, **options):
        raise RuntimeError("something else")
    with pytest.raises(RuntimeError, match="something else"):
        compiled.disk_cached(decorator)(len)


def test_the_native_forces_compile_where_numba_can_cache_nothing():
    """A process whose numba finds no cache location (as a read-only install and home would give):
    the dispatch, the linear replay's loop and a law's force still compile, and run."""
    code = """
import numba.core.caching as caching
for locator in caching.CacheImpl._locator_classes:
    locator.from_function = classmethod(lambda cls, *a, **k: None)
import warnings
warnings.simplefilter("error")
try:
    import momentid.lab.native_dispatch
except Exception as exc:
    print(type(exc).__name__)
warnings.simplefilter("ignore")
import momentid.lab.native_dispatch, momentid.lab.linear_replay
from momentid import mechanisms
from momentid.mechanisms.native import compiled
kind = mechanisms.get("coulomb_friction")
force, _ = compiled(kind.native_law())
print("compiled", force.address > 0)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["CacheUnavailableWarning", "compiled", "True"], out.stdout
