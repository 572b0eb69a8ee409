"""Strict reading of TOML tables: every error names the file, key and value.

Scenario files and experiment descriptions are both read through
:class:`Table`, so unknown keys, wrong types and out-of-range values give the
same one-line messages everywhere.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

from momentid.errors import ScenarioError

__all__ = ["Table", "load_toml"]

_MISSING = object()


def load_toml(path: Path, text: str | None = None) -> dict[str, Any]:
    """Parse a TOML file (or ``text`` attributed to ``path``)."""
    try:
        if text is None:
            text = Path(path).read_text(encoding="utf-8")
        return tomllib.loads(text)
    except FileNotFoundError:
        raise ScenarioError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise ScenarioError(f"{path}: is a directory, expected a TOML file") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: invalid TOML: {exc}") from None


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "float"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "table"
    return type(value).__name__


class Table:
    """A TOML table being validated; ``prefix`` is its dotted key path."""

    def __init__(self, data: Any, file: Path | str, prefix: str = ""):
        self.file = str(file)
        self.prefix = prefix
        if not isinstance(data, dict):
            self._fail(prefix or "<top>", data, "a table")
        self.data = data
        self._used: set[str] = set()

    # -- messages -----------------------------------------------------------
    def key(self, name: str) -> str:
        """The dotted key path of ``name`` in this table, as error messages name it."""
        return f"{self.prefix}.{name}" if self.prefix else name

    def _fail(self, key: str, value: Any, expected: str) -> None:
        raise ScenarioError(
            f"{self.file}: key '{key}' = {value!r} ({_type_name(value)}): expected {expected}"
        )

    def error(self, name: str, expected: str) -> ScenarioError:
        """An error about key ``name`` of this table (to raise)."""
        value = self.data.get(name, "<missing>")
        return ScenarioError(
            f"{self.file}: key '{self.key(name)}' = {value!r}: expected {expected}"
        )

    def has(self, name: str) -> bool:
        """Whether the table holds key ``name`` (it is not marked as read)."""
        return name in self.data

    # -- typed getters ------------------------------------------------------
    def _get(self, name: str, default: Any) -> Any:
        self._used.add(name)
        if name in self.data:
            return self.data[name]
        if default is _MISSING:
            raise ScenarioError(f"{self.file}: missing key '{self.key(name)}'")
        return default

    def number(self, name: str, default: Any = _MISSING, *, positive: bool = False,
               nonnegative: bool = False) -> float:
        """Key ``name`` as a finite float (``positive``: > 0, ``nonnegative``: >= 0); ``default`` when absent.

        Without ``default`` a missing key is refused; every refusal is a
        :class:`~momentid.errors.ScenarioError` naming the file, the key and what was expected.
        """
        value = self._get(name, default)
        if value is default and default is not _MISSING:
            return value
        return self._check_number(self.key(name), value, positive, nonnegative)

    def _check_number(self, key: str, value: Any, positive: bool, nonnegative: bool) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self._fail(key, value, "a number")
        value = float(value)
        if not math.isfinite(value):
            self._fail(key, value, "a finite number")
        if positive and not value > 0:
            self._fail(key, value, "a positive number")
        if nonnegative and value < 0:
            self._fail(key, value, "a number >= 0")
        return value

    def integer(self, name: str, default: Any = _MISSING, *, minimum: int | None = None) -> int:
        """Key ``name`` as an integer (not a boolean), at least ``minimum``; ``default`` when absent."""
        value = self._get(name, default)
        if value is default and default is not _MISSING:
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            self._fail(self.key(name), value, "an integer")
        if minimum is not None and value < minimum:
            self._fail(self.key(name), value, f"an integer >= {minimum}")
        return value

    def string(self, name: str, default: Any = _MISSING, *, choices: tuple[str, ...] | None = None) -> str:
        """Key ``name`` as a string, one of ``choices`` when given; ``default`` when absent."""
        value = self._get(name, default)
        if value is default and default is not _MISSING:
            return value
        if not isinstance(value, str):
            self._fail(self.key(name), value, "a string")
        if choices is not None and value not in choices:
            self._fail(self.key(name), value, "one of " + ", ".join(repr(c) for c in choices))
        return value

    def boolean(self, name: str, default: Any = _MISSING) -> bool:
        """Key ``name`` as ``true`` or ``false``; ``default`` (which must be a bool) when absent."""
        value = self._get(name, default)
        if not isinstance(value, bool):
            self._fail(self.key(name), value, "true or false")
        return value

    def numbers(self, name: str, default: Any = _MISSING, *, length: int | None = None,
                positive: bool = False, nonnegative: bool = False,
                scalar_ok: bool = False) -> tuple[float, ...]:
        """An array of numbers (a scalar broadcasts when ``scalar_ok`` and ``length``)."""
        value = self._get(name, default)
        if value is default and default is not _MISSING:
            return value
        key = self.key(name)
        if scalar_ok and isinstance(value, (int, float)) and not isinstance(value, bool):
            if length is None:
                self._fail(key, value, "an array of numbers")
            value = [value] * length
        if not isinstance(value, list) or not value:
            what = f"an array of {length} numbers" if length else "a non-empty array of numbers"
            self._fail(key, value, what + (" (or one number)" if scalar_ok else ""))
        if length is not None and len(value) != length:
            self._fail(key, value, f"an array of {length} numbers (one per floor/storey), got {len(value)}")
        out = []
        for i, item in enumerate(value):
            if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
                self._fail(f"{key}[{i}]", item, "a finite number")
            if positive and not item > 0:
                self._fail(f"{key}[{i}]", item, "a positive number")
            if nonnegative and item < 0:
                self._fail(f"{key}[{i}]", item, "a number >= 0")
            out.append(float(item))
        return tuple(out)

    def integers(self, name: str, default: Any = _MISSING, *, length: int | None = None,
                 minimum: int | None = None) -> tuple[int, ...]:
        """An array of integers (of ``length`` when given, each at least ``minimum``)."""
        value = self._get(name, default)
        if value is default and default is not _MISSING:
            return value
        key = self.key(name)
        what = f"an array of {length} integers" if length else "an array of integers"
        if (not isinstance(value, list) or (length is not None and len(value) != length)
                or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
            self._fail(key, value, what)
        for i, item in enumerate(value):
            if minimum is not None and item < minimum:
                self._fail(f"{key}[{i}]", item, f"an integer >= {minimum}")
        return tuple(value)

    def strings(self, name: str, default: Any = _MISSING) -> tuple[str, ...]:
        """Key ``name`` as an array of strings; ``default`` when absent."""
        value = self._get(name, default)
        if value is default and default is not _MISSING:
            return value
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            self._fail(self.key(name), value, "an array of strings")
        return tuple(value)

    def table(self, name: str, default: Any = _MISSING) -> Table | None:
        """Sub-table ``name`` as a :class:`Table` to validate; None when absent and ``default`` is None."""
        value = self._get(name, default)
        if value is None:
            return None
        if not isinstance(value, dict):
            self._fail(self.key(name), value, "a table")
        return Table(value, self.file, self.key(name))

    def tables(self, name: str) -> list[Table]:
        """Array of tables ``name`` (``[[name]]``, at least one), each as a :class:`Table`."""
        value = self._get(name, _MISSING)
        if not isinstance(value, list) or not value or not all(isinstance(v, dict) for v in value):
            self._fail(self.key(name), value, f"one or more [[{self.key(name)}]] tables")
        return [Table(v, self.file, f"{self.key(name)}[{i}]") for i, v in enumerate(value)]

    def finish(self) -> None:
        """Refuse keys that nobody read."""
        unknown = [k for k in self.data if k not in self._used]
        if unknown:
            k = unknown[0]
            raise ScenarioError(
                f"{self.file}: unknown key '{self.key(k)}' = {self.data[k]!r}: expected one of "
                + ", ".join(sorted(self._used))
            )
