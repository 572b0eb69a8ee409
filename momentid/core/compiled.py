"""numba's on-disk cache where the machine allows one, and the same compiled code without it where not.

``cache=True`` makes numba keep compiled code beside the module (its ``__pycache__``) or in the user's
cache directory (``NUMBA_CACHE_DIR``).  When neither can be written (a read-only install, a home without
a cache directory), numba refuses the decorator outright (``RuntimeError: cannot cache function ...: no
locator available``), so every command that replays a callback force would stop with a traceback.
:func:`disk_cached` falls back to compiling without the cache, and says so once per process.  This
module takes the decorator as an argument: it never imports numba itself.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

__all__ = ["disk_cached", "CacheUnavailableWarning"]


class CacheUnavailableWarning(UserWarning):
    """numba found no writable cache location: compiled code is compiled again in every process."""


_said = False


def disk_cached(decorator: Callable, *args: Any, **options: Any) -> Callable[[Callable], Any]:
    """``decorator(*args, cache=True, **options)``, or without ``cache`` when numba has nowhere to keep it.

    Parameters
    ----------
    decorator : callable
        ``numba.njit`` or ``numba.cfunc``.
    *args, **options
        Its arguments (a ``cfunc``'s signature, ``inline``, ``nogil``, ...), ``cache`` left out.

    Returns
    -------
    callable
        A decorator: function -> compiled function.
    """
    def wrap(fn: Callable) -> Any:
        try:
            return decorator(*args, cache=True, **options)(fn)
        except RuntimeError as exc:
            if "no locator available" not in str(exc):
                raise
            _say_once()
            return decorator(*args, **options)(fn)
    return wrap


def _say_once() -> None:
    global _said
    if not _said:
        _said = True
        warnings.warn("numba finds no writable cache directory (neither momentid's __pycache__ nor its user "
                      "cache): the compiled forces are compiled again in every process (a few seconds each); "
                      "set NUMBA_CACHE_DIR to a writable folder to keep them", CacheUnavailableWarning, stacklevel=3)
