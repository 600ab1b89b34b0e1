"""Declared bounds of the fields of frozen settings records, shared by every package.

A setting is a field of a frozen dataclass in the package that uses it; its bounds are
declared beside it, once::

    @dataclass(frozen=True)
    class RobotParams:
        mass_kg: float = bounded(8.0, minimum=0.1, maximum=10_000.0)

        def __post_init__(self) -> None:
            validate_fields(self, RobotsimError)

and the same declaration serves both the record's own validation (:func:`validate_fields`,
so a record built in code is checked too) and the scenario reader
(:func:`declared_bounds`), which refuses a bad value with the file and key before the
record is built. This module imports nothing of the project: ``robotsim``, ``intervals``,
``localization`` and ``scenarios`` may all use it without breaking their import direction.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable
from enum import Enum
from typing import Any

_BOUNDS_KEY = "bounds"


@dataclasses.dataclass(frozen=True)
class Bounds:
    """The values a number may take: finite, between optional inclusive (``minimum``,
    ``maximum``) and exclusive (``above``, ``below``) limits; ``integer``: a whole number
    (an ``int``, never a ``bool``)."""

    minimum: float | None = None
    above: float | None = None
    maximum: float | None = None
    below: float | None = None
    integer: bool = False

    def problem(self, value: object) -> str | None:
        """Why ``value`` is out of bounds (``"must be > 0, got -1"``), or None when it is in."""
        if self.integer:
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                return f"must be an integer, got {value!r}"
        elif isinstance(value, bool) or not isinstance(value, numbers.Real):
            return f"must be a number, got {value!r}"
        try:
            number = int(value) if self.integer else float(value)  # type: ignore[call-overload]
        except OverflowError:  # an integer beyond every float
            return f"must be finite, got {value}"
        if not math.isfinite(number):
            return f"must be finite, got {number}"
        shown = f"{number}" if self.integer else f"{number:g}"
        checks = (
            (self.minimum, ">=", lambda limit: number >= limit),
            (self.above, ">", lambda limit: number > limit),
            (self.maximum, "<=", lambda limit: number <= limit),
            (self.below, "<", lambda limit: number < limit),
        )
        for limit, sign, holds in checks:
            if limit is not None and not holds(limit):
                written = f"{int(limit)}" if self.integer else f"{limit:g}"
                return f"must be {sign} {written}, got {shown}"
        return None

    def scaled(self, factor: float) -> Bounds:
        """The same bounds in another unit (``factor > 0`` units per unit of the field)."""

        def scale(limit: float | None) -> float | None:
            return None if limit is None else limit * factor

        return Bounds(
            scale(self.minimum), scale(self.above), scale(self.maximum), scale(self.below)
        )


def bounded(
    default: Any = dataclasses.MISSING,
    *,
    minimum: float | None = None,
    above: float | None = None,
    maximum: float | None = None,
    below: float | None = None,
    integer: bool = False,
) -> Any:
    """A dataclass field (``default`` optional) with its :class:`Bounds` declared beside it."""
    bounds = Bounds(minimum, above, maximum, below, integer)
    return dataclasses.field(default=default, metadata={_BOUNDS_KEY: bounds})


def declared_bounds(record_type: Any, name: str) -> Bounds | None:
    """The bounds declared for field ``name`` of the dataclass ``record_type`` (or of a
    record), None when it declares none."""
    for field in dataclasses.fields(record_type):
        if field.name == name:
            return field.metadata.get(_BOUNDS_KEY)
    raise KeyError(f"{record_type!r} has no field {name!r}")


def choices(choice_type: type[Enum]) -> tuple[str, ...]:
    """The values of a choice (a ``StrEnum``), in declaration order: what a file may write."""
    return tuple(str(member.value) for member in choice_type)


def validate_fields(record: Any, error: Callable[[str], Exception]) -> None:
    """Check the fields of the frozen dataclass ``record`` (call it from ``__post_init__``):

    - a field with declared :class:`Bounds` must lie within them;
    - a field whose default is a member of an ``Enum`` (a choice) must be one of its values,
      and is stored as the member (so ``"ukf"`` and ``Filter.UKF`` give the same record);
    - a field whose default is a ``bool`` must be a ``bool``.

    The first failure raises ``error("<Record>.<field> <reason>")``.
    """
    owner = type(record).__name__
    for field in dataclasses.fields(record):
        value = getattr(record, field.name)
        bounds = field.metadata.get(_BOUNDS_KEY)
        reason = None if bounds is None else bounds.problem(value)
        if isinstance(field.default, Enum):
            choice_type = type(field.default)
            try:
                object.__setattr__(record, field.name, choice_type(value))
            except ValueError:
                allowed = ", ".join(map(repr, choices(choice_type)))
                reason = f"must be one of {allowed}, got {value!r}"
        elif isinstance(field.default, bool) and not isinstance(value, bool):
            reason = f"must be True or False, got {value!r}"
        if reason is not None:
            raise error(f"{owner}.{field.name} {reason}")
