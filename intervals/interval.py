"""Outward-rounded interval arithmetic on numpy arrays.

An interval is the last axis of length 2 of an array: ``x[..., 0]`` is the lower bound and
``x[..., 1]`` the upper bound, so an array ``(..., 2)`` holds many intervals and a box array
``(..., d, 2)`` holds boxes. Every function works elementwise with numpy broadcasting.

Conventions (fixed for the whole package):

* **Empty interval**: both bounds are NaN. NaN propagates through ``+ - * /`` and through
  ``np.minimum``/``np.maximum``, so an empty operand gives an empty result without extra
  branches. :func:`intersection` returns NaN bounds whenever ``lo > hi``.
* **Unbounded intervals**: bounds may be ``-inf`` (lower) and ``+inf`` (upper). A lower bound of
  ``+inf`` or an upper bound of ``-inf`` is not a set of reals and is not accepted.
* **Outward rounding**: IEEE 754 ``+ - * / sqrt`` are correctly rounded (round to nearest), so the
  exact result of an operation on two floats lies within one ulp of the computed one: moving the
  lower bound one ulp down (``np.nextafter(lo, -inf)``) and the upper bound one ulp up encloses
  the exact real result. Infinite bounds stay infinite.
* ``sin``, ``cos`` and ``atan2`` of the C library are not correctly rounded; glibc documents
  errors of at most 1 ulp for them on x86-64. We widen their results by at least
  ``LIBM_ULPS = 4`` ulps, four times that documented error: every value of sin/cos lies in
  ``[-1, 1]`` where an ulp is at most ``2^-52``, and of atan2 (shifted by up to 2 pi) in
  ``[-8, 8]`` (ulp at most
  ``2^-50``), so subtracting ``4 * 2^-52`` (resp. ``4 * 2^-50``) and rounding down once more
  (the subtraction itself rounds) covers 4 ulps with two array operations instead of eight.
  Results are then clamped to the function's exact range (``[-1, 1]``), which keeps a sound
  enclosure sound.
"""

from __future__ import annotations

import numpy as np

from intervals.errors import IntervalError

LIBM_ULPS = 4
"""Extra ulps by which results of libm ``sin``/``cos``/``atan2`` are widened (see module doc)."""

TRIG_EXACT_LIMIT_RAD = 2.0**20
"""Above this magnitude ``sin``/``cos`` return ``[-1, 1]``: the extremum search below uses a
float multiple of pi whose error grows with the argument; 2^20 rad keeps it below 1e-9 rad."""

_EXTREMUM_GUARD_RAD = 1e-7
"""An extremum of sin/cos within this distance outside an interval is counted as inside (only
widens the result); it dominates the float error of locating ``k pi`` for ``|x| < 2^20``."""

_TWO_PI = 2.0 * np.pi


def _down(x: np.ndarray | float) -> np.ndarray:
    """The float one ulp below each entry of ``x`` (an outward rounding of a lower bound)."""
    return np.nextafter(x, -np.inf)


def _up(x: np.ndarray | float) -> np.ndarray:
    """The float one ulp above each entry of ``x`` (an outward rounding of an upper bound)."""
    return np.nextafter(x, np.inf)


def _widen_down(x: np.ndarray, ulp_max: float) -> np.ndarray:
    """At least ``LIBM_ULPS`` ulps below ``x`` for ``|x|`` whose ulp is at most ``ulp_max``."""
    return _down(x - LIBM_ULPS * ulp_max)


def _widen_up(x: np.ndarray, ulp_max: float) -> np.ndarray:
    """At least ``LIBM_ULPS`` ulps above ``x`` (see :func:`_widen_down`)."""
    return _up(x + LIBM_ULPS * ulp_max)


def _pack(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    out = np.empty((*np.broadcast_shapes(np.shape(lo), np.shape(hi)), 2))
    out[..., 0] = lo
    out[..., 1] = hi
    return out


def interval(lo, hi=None) -> np.ndarray:
    """Interval array ``(..., 2)`` from bounds (``hi`` defaults to ``lo``: degenerate intervals).

    Raises :class:`IntervalError` when ``lo > hi``, a lower bound is ``+inf`` or an upper bound
    ``-inf``; NaN bounds (the empty interval) are accepted when both bounds are NaN.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = lo if hi is None else np.asarray(hi, dtype=np.float64)
    x = _pack(lo, hi)
    check(x, "interval")
    return x


def check(x: np.ndarray, name: str = "interval") -> None:
    """Raise :class:`IntervalError` unless ``x`` is a valid interval array ``(..., 2)``."""
    x = np.asarray(x)
    if x.ndim < 1 or x.shape[-1] != 2:
        raise IntervalError(f"{name}: expected shape (..., 2), got {x.shape}")
    lo, hi = x[..., 0], x[..., 1]
    if np.any(np.isnan(lo) != np.isnan(hi)):
        raise IntervalError(f"{name}: an interval has exactly one NaN bound (empty is NaN, NaN)")
    if np.any(lo > hi):
        raise IntervalError(f"{name}: lower bound above upper bound")
    if np.any(lo == np.inf) or np.any(hi == -np.inf):
        raise IntervalError(f"{name}: lower bound +inf or upper bound -inf")


def empty(shape=()) -> np.ndarray:
    """Array of empty intervals of shape ``shape + (2,)``."""
    return np.full((*np.empty(shape).shape, 2), np.nan)


def entire(shape=()) -> np.ndarray:
    """Array of ``[-inf, inf]`` intervals of shape ``shape + (2,)``."""
    out = np.empty((*np.empty(shape).shape, 2))
    out[..., 0], out[..., 1] = -np.inf, np.inf
    return out


def is_empty(x: np.ndarray) -> np.ndarray:
    """``(...,)`` bool: the interval is empty (NaN bounds)."""
    return np.isnan(np.asarray(x)[..., 0])


def width(x: np.ndarray) -> np.ndarray:
    """``(...,)`` widths ``hi - lo`` rounded up (NaN for empty, inf for unbounded)."""
    return _up(x[..., 1] - x[..., 0])


def contains(x: np.ndarray, value) -> np.ndarray:
    """``(...,)`` bool: ``value`` lies in the closed interval ``x`` (False when empty)."""
    return (x[..., 0] <= value) & (value <= x[..., 1])


def add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a + b`` rounded outward."""
    return _pack(_down(a[..., 0] + b[..., 0]), _up(a[..., 1] + b[..., 1]))


def sub(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` rounded outward."""
    return _pack(_down(a[..., 0] - b[..., 1]), _up(a[..., 1] - b[..., 0]))


def neg(a: np.ndarray) -> np.ndarray:
    """``-a`` (exact)."""
    return _pack(-a[..., 1], -a[..., 0])


def _product_range(a_bounds, b_bounds, empty_mask):
    """Min and max of the four endpoint products; ``0 * inf`` (NaN) counts as 0, the value of
    ``0 * x`` for every real ``x``, except where an operand is empty (NaN stays NaN)."""
    lo = hi = None
    with np.errstate(over="ignore", invalid="ignore"):
        for p in a_bounds:
            for q in b_bounds:
                r = p * q
                r = np.where(np.isnan(r) & ~empty_mask, 0.0, r)
                lo = r if lo is None else np.minimum(lo, r)
                hi = r if hi is None else np.maximum(hi, r)
    return lo, hi


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a * b`` rounded outward; ``0 * [-inf, inf]`` is ``[0, 0]`` (widened by rounding)."""
    empty_mask = is_empty(a) | is_empty(b)
    lo, hi = _product_range((a[..., 0], a[..., 1]), (b[..., 0], b[..., 1]), empty_mask)
    return _pack(_down(lo), _up(hi))


def div(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a / b`` rounded outward.

    Zero in the divisor: when ``b`` contains 0 (including ``b = [0, 0]``) the result is the
    whole line ``[-inf, inf]``: it encloses every quotient ``x / y`` with ``x in a``,
    ``y in b, y != 0`` (a superset of the exact hull, which can be two half-lines).
    """
    a, b = np.broadcast_arrays(a, b)
    empty_mask = is_empty(a) | is_empty(b)
    zero_in_b = (b[..., 0] <= 0.0) & (b[..., 1] >= 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        quots = np.stack(
            [p / q for p in (a[..., 0], a[..., 1]) for q in (b[..., 0], b[..., 1])], axis=-1
        )
    # inf / inf (NaN) only arises with both operands unbounded and 0 not in b: the quotient set
    # then covers a half-line through 0; the other quotients already bound it except for the
    # infinite side, which we open explicitly.
    nan_q = np.isnan(quots) & ~empty_mask[..., None]
    lo = np.where(np.any(nan_q, axis=-1), -np.inf, np.min(np.where(nan_q, np.inf, quots), -1))
    hi = np.where(np.any(nan_q, axis=-1), np.inf, np.max(np.where(nan_q, -np.inf, quots), -1))
    lo = np.where(zero_in_b, -np.inf, lo)
    hi = np.where(zero_in_b, np.inf, hi)
    lo = np.where(empty_mask, np.nan, lo)
    hi = np.where(empty_mask, np.nan, hi)
    return _pack(_down(lo), _up(hi))


def sqr(a: np.ndarray) -> np.ndarray:
    """``a ** 2`` rounded outward (lower bound never below 0)."""
    with np.errstate(over="ignore"):
        lo_sq, hi_sq = a[..., 0] * a[..., 0], a[..., 1] * a[..., 1]
    straddles = (a[..., 0] <= 0.0) & (a[..., 1] >= 0.0)
    lo = np.where(straddles, 0.0, np.minimum(lo_sq, hi_sq))
    hi = np.maximum(lo_sq, hi_sq)
    return _pack(np.maximum(_down(lo), 0.0), _up(hi))


def sqrt(a: np.ndarray) -> np.ndarray:
    """``sqrt(a ∩ [0, inf])`` rounded outward; empty when ``a`` lies below 0."""
    with np.errstate(invalid="ignore"):
        lo = np.sqrt(np.maximum(a[..., 0], 0.0))
        hi = np.sqrt(a[..., 1])  # NaN (empty) when hi < 0
    lo = np.where(np.isnan(hi), np.nan, lo)
    return _pack(np.maximum(_down(lo), 0.0), _up(hi))


def _periodic_range(a: np.ndarray, func, phase_max: float) -> np.ndarray:
    """Range of a 2 pi-periodic ``func`` (sin or cos) over ``a``: maximum +1 at
    ``phase_max + 2 k pi``, minimum -1 at ``phase_max + pi + 2 k pi``, monotone between."""
    lo_x, hi_x = a[..., 0], a[..., 1]
    with np.errstate(invalid="ignore"):  # sin(inf) is NaN; such intervals are "too wide"
        f_lo, f_hi = func(lo_x), func(hi_x)
    lo = _widen_down(np.minimum(f_lo, f_hi), 2.0**-52)
    hi = _widen_up(np.maximum(f_lo, f_hi), 2.0**-52)

    def hits(phase):
        # an extremum phase + 2 k pi inside [lo_x - guard, hi_x + guard]
        k = np.ceil((lo_x - _EXTREMUM_GUARD_RAD - phase) / _TWO_PI)
        return phase + k * _TWO_PI <= hi_x + _EXTREMUM_GUARD_RAD

    with np.errstate(invalid="ignore"):
        hi = np.where(hits(phase_max), 1.0, hi)
        lo = np.where(hits(phase_max + np.pi), -1.0, lo)
        too_wide = ~(np.abs(lo_x) < TRIG_EXACT_LIMIT_RAD) | ~(np.abs(hi_x) < TRIG_EXACT_LIMIT_RAD)
        too_wide |= hi_x - lo_x >= _TWO_PI
    lo = np.where(too_wide, -1.0, np.maximum(lo, -1.0))
    hi = np.where(too_wide, 1.0, np.minimum(hi, 1.0))
    empty_mask = is_empty(a)
    return _pack(np.where(empty_mask, np.nan, lo), np.where(empty_mask, np.nan, hi))


def sin(a: np.ndarray) -> np.ndarray:
    """``sin(a)`` rounded outward (see the module doc for the libm error budget)."""
    return _periodic_range(a, np.sin, np.pi / 2.0)


def cos(a: np.ndarray) -> np.ndarray:
    """``cos(a)`` rounded outward."""
    return _periodic_range(a, np.cos, 0.0)


def cos_sin(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cos(a), sin(a))`` in one pass, rounded outward like :func:`cos` and :func:`sin`.

    Both functions have their extrema on the quarter points ``j pi/2``: cos +1 at
    ``j = 0 mod 4``, sin +1 at ``1``, cos -1 at ``2``, sin -1 at ``3``. The quarter indices in
    ``[lo - guard, hi + guard] / (pi/2)`` are found once; a residue ``r`` occurs among the
    ``n`` consecutive indices from ``j0`` iff ``(r - j0) mod 4 < n``.
    """
    lo_x, hi_x = a[..., 0], a[..., 1]
    with np.errstate(invalid="ignore"):
        c_lo, c_hi, s_lo, s_hi = np.cos(lo_x), np.cos(hi_x), np.sin(lo_x), np.sin(hi_x)
        j0 = np.ceil((lo_x - _EXTREMUM_GUARD_RAD) / (np.pi / 2.0))
        count = np.floor((hi_x + _EXTREMUM_GUARD_RAD) / (np.pi / 2.0)) - j0 + 1.0
        too_wide = ~(np.abs(lo_x) < TRIG_EXACT_LIMIT_RAD) | ~(np.abs(hi_x) < TRIG_EXACT_LIMIT_RAD)
        too_wide |= hi_x - lo_x >= _TWO_PI
    empty_mask = is_empty(a)

    def bounds(f_lo, f_hi, residue_max):
        with np.errstate(invalid="ignore"):  # unbounded: j0 infinite, and too_wide anyway
            reaches_max = too_wide | (np.mod(residue_max - j0, 4.0) < count)
            reaches_min = too_wide | (np.mod(residue_max + 2.0 - j0, 4.0) < count)
        lo = np.where(
            reaches_min, -1.0, np.maximum(_widen_down(np.minimum(f_lo, f_hi), 2.0**-52), -1.0)
        )
        hi = np.where(
            reaches_max, 1.0, np.minimum(_widen_up(np.maximum(f_lo, f_hi), 2.0**-52), 1.0)
        )
        return _pack(np.where(empty_mask, np.nan, lo), np.where(empty_mask, np.nan, hi))

    return bounds(c_lo, c_hi, 0.0), bounds(s_lo, s_hi, 1.0)


def atan2(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Angle interval of the vectors ``(x, y)`` with ``x in x, y in y`` (radians).

    Returns ``[lo, hi]`` with ``-pi <= lo`` (up to rounding) and ``hi - lo <= 2 pi``; every angle
    of the set is equal modulo ``2 pi`` to a member of the interval. Three cases:

    * the box contains the origin: ``[-pi, pi]`` (every direction);
    * the box meets the negative x axis (``x_lo < 0``, ``y_lo < 0 <= y_hi`` ... straddling the
      branch cut): angles are taken in ``[0, 2 pi)``, so the result lies in ``[pi/2, 3 pi/2]``;
    * otherwise the range of ``atan2`` over the four corners. For a convex set not containing
      the origin the extreme directions are attained at extreme points, i.e. corners (infinite
      corners give the limit directions, which enclose the open range).

    Rounded outward by ``LIBM_ULPS`` ulps (and the ``+ 2 pi`` shift by one more ulp).
    """
    x, y = np.broadcast_arrays(x + 0.0, y + 0.0)  # + 0.0 turns -0.0 into +0.0 (branch cut)
    empty_mask = is_empty(x) | is_empty(y)
    xs = (x[..., 0], x[..., 1], x[..., 0], x[..., 1])
    ys = (y[..., 0], y[..., 0], y[..., 1], y[..., 1])
    with np.errstate(invalid="ignore"):
        ang = np.stack([np.arctan2(yy, xx) for xx, yy in zip(xs, ys, strict=True)], axis=-1)
    contains_origin = (x[..., 0] <= 0) & (x[..., 1] >= 0) & (y[..., 0] <= 0) & (y[..., 1] >= 0)
    # straddles the cut: some point with x < 0 and y = 0, or y on both sides with x < 0
    cut = (x[..., 0] < 0) & (y[..., 0] < 0) & (y[..., 1] >= 0)
    shifted = np.where(ang < 0, _up(ang + _TWO_PI), ang)
    # a corner on the cut itself (y == 0, x < 0) gives +pi, which is right in the shifted frame
    lo = np.where(cut, np.min(shifted, -1), np.min(ang, -1))
    hi = np.where(cut, np.max(shifted, -1), np.max(ang, -1))
    lo = _widen_down(lo, 2.0**-50)
    hi = _widen_up(hi, 2.0**-50)
    lo = np.where(contains_origin, _down(-np.pi), lo)
    hi = np.where(contains_origin, _up(np.pi), hi)
    return _pack(np.where(empty_mask, np.nan, lo), np.where(empty_mask, np.nan, hi))


def minimum(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Elementwise ``min(a, b)`` (exact)."""
    return _pack(np.minimum(a[..., 0], b[..., 0]), np.minimum(a[..., 1], b[..., 1]))


def maximum(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Elementwise ``max(a, b)`` (exact)."""
    return _pack(np.maximum(a[..., 0], b[..., 0]), np.maximum(a[..., 1], b[..., 1]))


def hull(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest interval holding ``a`` and ``b`` (an empty operand is ignored)."""
    return _pack(np.fmin(a[..., 0], b[..., 0]), np.fmax(a[..., 1], b[..., 1]))


def intersection(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a ∩ b``; empty (NaN, NaN) where the intervals do not meet or either is empty."""
    lo = np.maximum(a[..., 0], b[..., 0])
    hi = np.minimum(a[..., 1], b[..., 1])
    with np.errstate(invalid="ignore"):
        disjoint = ~(lo <= hi)
    return _pack(np.where(disjoint, np.nan, lo), np.where(disjoint, np.nan, hi))
