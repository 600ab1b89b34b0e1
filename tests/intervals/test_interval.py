"""Soundness of the outward-rounded interval operations.

For random intervals (tiny, huge, degenerate, unbounded) and random points inside them, the
exact result of the point operation (rational arithmetic via ``fractions.Fraction`` where it
is exact, the libm value otherwise) must lie in the interval result.
"""

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from intervals import interval as ia
from intervals.errors import IntervalError

SETTINGS = settings(max_examples=250, deadline=None)

_finite = st.one_of(
    st.floats(-1e300, 1e300),
    st.floats(-1e-300, 1e-300),
    st.floats(-10.0, 10.0),
    st.sampled_from([0.0, -0.0, 1.0, -1.0, np.pi, -np.pi, 5e-324]),
)


@st.composite
def interval_and_point(draw, bounded=False, lo_min=None):
    """(interval (2,), finite point inside it): sorted triple, degenerate, or unbounded."""
    x = draw(_finite)
    kind = draw(
        st.sampled_from(
            ["sorted", "degenerate", "unbounded"] if not bounded else ["sorted", "degenerate"]
        )
    )
    if kind == "degenerate":
        lo = hi = x
    else:
        a, b = draw(_finite), draw(_finite)
        lo, _, hi = sorted([a, x, b])
        if kind == "unbounded":
            side = draw(st.sampled_from(["lo", "hi", "both"]))
            lo = -np.inf if side in ("lo", "both") else lo
            hi = np.inf if side in ("hi", "both") else hi
    if lo_min is not None:
        lo, x, hi = max(lo, lo_min), max(x, lo_min), max(hi, lo_min)
    return np.array([lo, hi]), x


def _inside_exact(value: Fraction, iv: np.ndarray) -> bool:
    lo, hi = iv
    return (lo == -np.inf or Fraction(lo) <= value) and (hi == np.inf or value <= Fraction(hi))


@SETTINGS
@given(interval_and_point(), interval_and_point())
def test_add_sub_mul_contain_exact_results(ax, by):
    (a, x), (b, y) = ax, by
    fx, fy = Fraction(x), Fraction(y)
    assert _inside_exact(fx + fy, ia.add(a, b))
    assert _inside_exact(fx - fy, ia.sub(a, b))
    assert _inside_exact(fx * fy, ia.mul(a, b))
    assert _inside_exact(-fx, ia.neg(a))


@SETTINGS
@given(interval_and_point(), interval_and_point())
def test_div_contains_exact_quotient(ax, by):
    (a, x), (b, y) = ax, by
    result = ia.div(a, b)
    if y != 0.0:
        assert _inside_exact(Fraction(x) / Fraction(y), result)
    if b[0] <= 0.0 <= b[1]:
        assert result[0] == -np.inf and result[1] == np.inf


@SETTINGS
@given(interval_and_point())
def test_sqr_and_sqrt_contain_exact_results(ax):
    a, x = ax
    assert _inside_exact(Fraction(x) ** 2, ia.sqr(a))
    r = ia.sqrt(a)
    if x >= 0:
        lo, hi = r
        assert lo >= 0.0
        assert Fraction(lo) ** 2 <= Fraction(x)
        assert hi == np.inf or Fraction(x) <= Fraction(hi) ** 2
    if a[1] < 0:
        assert ia.is_empty(r)


@SETTINGS
@given(interval_and_point())
def test_sin_cos_contain_point_values(ax):
    a, x = ax
    both = ia.cos_sin(a)
    for func, op, joint in ((np.sin, ia.sin, both[1]), (np.cos, ia.cos, both[0])):
        for lo, hi in (op(a), joint):
            assert -1.0 <= lo <= func(x) <= hi <= 1.0


@SETTINGS
@given(interval_and_point(), interval_and_point())
def test_atan2_contains_angle_modulo_two_pi(ax, by):
    (a, x), (b, y) = ax, by
    lo, hi = ia.atan2(b, a)
    angle = np.arctan2(y + 0.0, x + 0.0)
    assert hi - lo <= 2 * np.pi + 1e-12
    assert (lo <= angle <= hi) or (lo <= angle + 2 * np.pi <= hi)


@SETTINGS
@given(interval_and_point(), interval_and_point())
def test_min_max_hull_intersection(ax, by):
    (a, x), (b, y) = ax, by
    assert ia.contains(ia.minimum(a, b), min(x, y))
    assert ia.contains(ia.maximum(a, b), max(x, y))
    h = ia.hull(a, b)
    assert ia.contains(h, x) and ia.contains(h, y)
    inter = ia.intersection(a, b)
    both = ia.contains(a, y) and ia.contains(b, y)
    assert bool(ia.contains(inter, y)) == both
    assert ia.is_empty(inter) == (max(a[0], b[0]) > min(a[1], b[1]))


def test_vectorised_operations_contain_random_points():
    """100 000 random intervals at once: the array path equals the scalar path."""
    rng = np.random.default_rng(1)
    n = 100_000
    scale = 10.0 ** rng.integers(-8, 8, size=(n, 1))
    bounds = np.sort(rng.normal(size=(n, 2, 2)) * scale[:, :, None], axis=-1)
    u = rng.uniform(size=(n, 2))
    pts = bounds[..., 0] + u * (bounds[..., 1] - bounds[..., 0])
    pts = np.clip(pts, bounds[..., 0], bounds[..., 1])
    a, b, x, y = bounds[:, 0], bounds[:, 1], pts[:, 0], pts[:, 1]
    for op, val in (
        (ia.add(a, b), x + y),
        (ia.sub(a, b), x - y),
        (ia.mul(a, b), x * y),
        (ia.sqr(a), x * x),
        (ia.sin(a), np.sin(x)),
        (ia.cos(a), np.cos(x)),
        (ia.cos_sin(a)[0], np.cos(x)),
        (ia.cos_sin(a)[1], np.sin(x)),
    ):
        assert np.all(ia.contains(op, val))
    nz = ~((b[:, 0] <= 0) & (b[:, 1] >= 0))
    assert np.all(ia.contains(ia.div(a, b)[nz], (x / y)[nz]))
    ang = np.arctan2(y, x)
    r = ia.atan2(b, a)
    assert np.all(ia.contains(r, ang) | ia.contains(r, ang + 2 * np.pi))


def test_empty_propagates_and_unbounded_products():
    e = ia.empty()
    one = ia.interval(1.0, 2.0)
    for op in (ia.add, ia.sub, ia.mul, ia.div, ia.intersection):
        assert ia.is_empty(op(e, one))
    assert ia.is_empty(ia.sqrt(e)) and ia.is_empty(ia.sin(e)) and ia.is_empty(ia.atan2(e, one))
    np.testing.assert_array_equal(ia.hull(e, one), one)
    zero_times_entire = ia.mul(ia.interval(0.0), ia.entire())
    assert zero_times_entire[0] <= 0.0 <= zero_times_entire[1] and zero_times_entire[1] < 1e-300
    assert ia.entire((3,)).shape == (3, 2) and ia.empty((2, 3)).shape == (2, 3, 2)


def test_outward_rounding_is_strict_for_inexact_sums():
    r = ia.add(ia.interval(0.1), ia.interval(0.2))
    assert r[0] < 0.1 + 0.2 < r[1]
    assert _inside_exact(Fraction(0.1) + Fraction(0.2), r)


def test_invalid_intervals_are_refused():
    with pytest.raises(IntervalError, match="lower bound above"):
        ia.interval(2.0, 1.0)
    with pytest.raises(IntervalError, match="one NaN"):
        ia.interval(np.nan, 1.0)
    with pytest.raises(IntervalError, match="shape"):
        ia.check(np.zeros((3, 3)))
