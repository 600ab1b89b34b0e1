"""Declared bounds and choices of settings records (``records``), against hand-made cases."""

from __future__ import annotations

import dataclasses
import math
from enum import StrEnum

import pytest

from validated_records import Bounds, bounded, choices, declared_bounds, validate_fields


class Colour(StrEnum):
    RED = "red"
    BLUE = "blue"


class RecordError(ValueError):
    pass


@dataclasses.dataclass(frozen=True)
class Sample:
    length_m: float = bounded(1.0, above=0.0, maximum=10.0)
    count: int = bounded(3, minimum=1, integer=True)
    colour: Colour = Colour.RED
    enabled: bool = True
    note: str = ""

    def __post_init__(self) -> None:
        validate_fields(self, RecordError)


@pytest.mark.parametrize(
    ("bounds", "value", "reason"),
    [
        (Bounds(above=0.0), 0.0, "must be > 0, got 0"),
        (Bounds(minimum=0.1), 1e-300, "must be >= 0.1, got 1e-300"),
        (Bounds(maximum=1.0), 1e300, "must be <= 1, got 1e+300"),
        (Bounds(below=math.pi / 2), 2.0, "must be < 1.5708, got 2"),
        (Bounds(), math.inf, "must be finite, got inf"),
        (Bounds(), math.nan, "must be finite, got nan"),
        (Bounds(maximum=1.0), 10**400, "must be finite, got 1" + "0" * 400),
        (Bounds(), "3", "must be a number, got '3'"),
        (Bounds(), True, "must be a number, got True"),
        (Bounds(integer=True), 2.0, "must be an integer, got 2.0"),
        (Bounds(integer=True), False, "must be an integer, got False"),
        (Bounds(integer=True, maximum=2**24), 2**62, f"must be <= 16777216, got {2**62}"),
    ],
)
def test_a_value_out_of_bounds_gets_its_reason(bounds, value, reason):
    assert bounds.problem(value) == reason


def test_values_on_the_inclusive_limits_are_in():
    closed = Bounds(minimum=0.0, maximum=1.0)
    assert closed.problem(0.0) is None and closed.problem(1.0) is None
    assert Bounds(above=0.0, below=1.0).problem(0.5) is None
    assert Bounds(minimum=1, integer=True).problem(1) is None


def test_scaled_bounds_are_the_same_limits_in_another_unit():
    degrees = Bounds(above=0.0, below=math.pi / 2).scaled(180.0 / math.pi)
    assert degrees.below == pytest.approx(90.0) and degrees.above == 0.0
    assert degrees.problem(90.0) == "must be < 90, got 90" and degrees.problem(89.0) is None


def test_a_record_checks_its_declared_bounds_choices_and_booleans_when_built():
    assert Sample().colour is Colour.RED
    assert Sample(colour="blue").colour is Colour.BLUE  # a value of the choice becomes its member
    for changes, message in (
        ({"length_m": -1.0}, "Sample.length_m must be > 0, got -1"),
        ({"count": 0}, "Sample.count must be >= 1, got 0"),
        ({"count": 1.5}, "Sample.count must be an integer, got 1.5"),
        ({"colour": "green"}, "Sample.colour must be one of 'red', 'blue', got 'green'"),
        ({"enabled": 1}, "Sample.enabled must be True or False, got 1"),
    ):
        with pytest.raises(RecordError) as refusal:
            Sample(**changes)
        assert str(refusal.value) == message
    assert Sample(note="anything").note == "anything"  # no declaration, no check


def test_declared_bounds_and_choices_are_read_back():
    assert declared_bounds(Sample, "length_m") == Bounds(above=0.0, maximum=10.0)
    assert declared_bounds(Sample(), "count") == Bounds(minimum=1, integer=True)
    assert declared_bounds(Sample, "colour") is None
    with pytest.raises(KeyError):
        declared_bounds(Sample, "width_m")
    assert choices(Colour) == ("red", "blue")
