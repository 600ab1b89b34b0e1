"""Reading one TOML table with checked types and bounds, refusing keys nobody asked for.

``Table`` wraps the ``dict`` ``tomllib`` gives for one table. Each ``take_*`` call removes a
key, checks its type, finiteness and bounds, and returns a Python value (or the default when
the key is absent); ``finish()`` then refuses whatever is left, so a typo never passes
silently. Every failure is a ``ScenarioError(file, "table.key", reason)``.
"""

from __future__ import annotations

import difflib
import math
from typing import Any, TypeGuard

import numpy as np

from scenarios.errors import ScenarioError
from validated_records import Bounds

#: Returned by ``take_*`` when a key is absent and has no default: the caller must decide.
REQUIRED = object()


def _is_number(value: object) -> TypeGuard[int | float]:
    """True for a TOML integer or float (a bool is not a number here)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class Table:
    """One table of a scenario file, read key by key.

    ``source`` is the file (for messages), ``path`` the dotted table name (``"sensors.sonar"``,
    ``""`` for the top level), ``data`` what tomllib read.
    """

    def __init__(self, source: str, path: str, data: object):
        self.source = source
        self.path = path
        if not isinstance(data, dict):
            raise ScenarioError(source, path or None, f"must be a table, got {_type_name(data)}")
        self._data: dict[str, Any] = dict(data)
        self._known: list[str] = []

    # -- naming and errors -------------------------------------------------------------
    def key(self, name: str) -> str:
        """The dotted name of ``name`` in this table, as the messages show it."""
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, reason: str) -> ScenarioError:
        """A ``ScenarioError`` about key ``name`` of this table."""
        return ScenarioError(self.source, self.key(name), reason)

    def has(self, name: str) -> bool:
        """Whether the file sets key ``name`` (not yet taken)."""
        return name in self._data

    def keys(self) -> list[str]:
        """The keys the file sets that are not taken yet."""
        return list(self._data)

    def peek(self, name: str) -> Any:
        """The raw value of key ``name`` (None when absent), without taking it."""
        return self._data.get(name)

    def mention(self, name: str) -> None:
        """Count ``name`` as a key of this table (for the typo hints) without reading it."""
        self._known.append(name)

    def _pop(self, name: str, default: Any) -> tuple[bool, Any]:
        self._known.append(name)
        if name in self._data:
            return True, self._data.pop(name)
        if default is REQUIRED:
            raise self.error(name, "missing (this key is required)")
        return False, default

    # -- scalars -------------------------------------------------------------------------
    def take_float(
        self,
        name: str,
        default: Any = REQUIRED,
        *,
        bounds: Bounds | None = None,
        minimum: float | None = None,
        above: float | None = None,
        maximum: float | None = None,
        below: float | None = None,
    ) -> Any:
        """A finite number (TOML integer or float) within ``bounds`` (a field's declared
        :class:`records.Bounds`) or the given limits, as ``float``.

        ``minimum``/``maximum`` are inclusive bounds, ``above``/``below`` exclusive ones.
        """
        present, value = self._pop(name, default)
        if not present:
            return value
        if bounds is None:
            bounds = Bounds(minimum=minimum, above=above, maximum=maximum, below=below)
        return _check_float(self, name, value, bounds)

    def take_int(
        self,
        name: str,
        default: Any = REQUIRED,
        *,
        bounds: Bounds | None = None,
        minimum: int | None = None,
    ) -> Any:
        """A TOML integer within ``bounds`` (a field's declared :class:`records.Bounds`), or at
        least ``minimum`` when given."""
        present, value = self._pop(name, default)
        if not present:
            return value
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.error(name, f"must be an integer, got {_type_name(value)}")
        if bounds is None:
            bounds = Bounds(minimum=minimum, integer=True)
        reason = bounds.problem(value)
        if reason is not None:
            raise self.error(name, reason)
        return value

    def take_bool(self, name: str, default: Any = REQUIRED) -> Any:
        """A TOML boolean."""
        present, value = self._pop(name, default)
        if present and not isinstance(value, bool):
            raise self.error(name, f"must be true or false, got {_type_name(value)}")
        return value

    def take_str(self, name: str, default: Any = REQUIRED, *, choices: tuple[str, ...] = ()) -> Any:
        """A TOML string, one of ``choices`` when given."""
        present, value = self._pop(name, default)
        if not present:
            return value
        if not isinstance(value, str):
            raise self.error(name, f"must be a string, got {_type_name(value)}")
        if choices and value not in choices:
            raise self.error(name, f"must be one of {', '.join(map(repr, choices))}, got {value!r}")
        return value

    def take_raw(self, name: str, default: Any = REQUIRED) -> Any:
        """The value of key ``name`` as tomllib read it, whatever its type (the caller checks it)."""
        return self._pop(name, default)[1]

    # -- arrays --------------------------------------------------------------------------
    def take_array(self, name: str, shape: tuple[int | None, ...], default: Any = REQUIRED) -> Any:
        """A nested array of finite numbers of ``shape`` (``None`` = any length >= 1), float64."""
        present, value = self._pop(name, default)
        if not present:
            return value
        return _to_array(self, name, value, shape)

    def take_tables(self, name: str) -> list[Table]:
        """An array of tables (``[[table.name]]``); empty when absent."""
        present, value = self._pop(name, [])
        if not present:
            return []
        if not isinstance(value, list):
            raise self.error(name, f"must be an array of tables, got {_type_name(value)}")
        return [Table(self.source, f"{self.key(name)}[{i}]", item) for i, item in enumerate(value)]

    def take_table(self, name: str) -> Table:
        """A sub-table (``[table.name]``); an empty one when absent."""
        _, value = self._pop(name, {})
        return Table(self.source, self.key(name), value)

    # -- the end -------------------------------------------------------------------------
    def finish(self) -> None:
        """Refuse any key that no ``take_*`` call asked for (a typo must not pass silently)."""
        for name in self._data:
            hint = difflib.get_close_matches(name, self._known, n=1)
            known = (
                f"did you mean {hint[0]!r}?" if hint else f"known keys: {', '.join(self._known)}"
            )
            raise self.error(name, f"unknown key ({known})" if self._known else "unknown key")


def _type_name(value: object) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "an array",
        dict: "a table",
    }.get(type(value), type(value).__name__)


def _check_float(table: Table, name: str, value: object, bounds: Bounds) -> float:
    if not _is_number(value):
        raise table.error(name, f"must be a number, got {_type_name(value)}")
    number = float(value)
    reason = bounds.problem(number)
    if reason is not None:
        raise table.error(name, reason)
    return number


def _to_array(table: Table, name: str, value: object, shape: tuple[int | None, ...]) -> np.ndarray:
    """Check a nested list against ``shape`` level by level, naming the first bad element."""

    def walk(item: object, level: int, where: str) -> None:
        if level == len(shape):
            if not _is_number(item):
                raise table.error(where, f"must be a number, got {_type_name(item)}")
            if not math.isfinite(float(item)):
                raise table.error(where, f"must be finite, got {float(item)}")
            return
        if not isinstance(item, list):
            raise table.error(where, f"must be an array, got {_type_name(item)}")
        want = shape[level]
        if want is None and not item:
            raise table.error(where, "must not be empty")
        if want is not None and len(item) != want:
            raise table.error(where, f"must have {want} elements, got {len(item)}")
        for i, sub in enumerate(item):
            walk(sub, level + 1, f"{where}[{i}]")

    walk(value, 0, name)
    return np.asarray(value, dtype=np.float64)
