"""Box arrays ``(N, d, 2)`` and subpavings.

A box is an array ``(d, 2)`` of intervals (``[:, 0]`` lower, ``[:, 1]`` upper bounds); many
boxes are an array ``(N, d, 2)``. Pose boxes are ``(N, 3, 2)`` for ``(x_m, y_m, theta_rad)``.

To compare a heading width with position widths, widths are multiplied by a per-axis
``scale`` (metres per unit of the axis: 1 for x and y, ``heading_scale_m_per_rad`` for theta).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np

from intervals.errors import IntervalError
from intervals.union_area import union_area

DEFAULT_HEADING_SCALE_M_PER_RAD = 1.0
"""Default metres per radian of the heading axis: a heading error of 1 rad moves a point 1 m
away from the sensor by 1 m, the order of the distances the sonar belt measures."""


def pose_scale(
    heading_scale_m_per_rad: float = DEFAULT_HEADING_SCALE_M_PER_RAD,
) -> np.ndarray:
    """Per-axis scale ``(3,)`` for pose boxes ``(x, y, theta)``: ``(1, 1, heading scale)``."""
    return np.array([1.0, 1.0, float(heading_scale_m_per_rad)])


def as_boxes(boxes, name: str = "boxes") -> np.ndarray:
    """Validated float64 box array ``(N, d, 2)`` (a single box ``(d, 2)`` becomes ``(1, d, 2)``).

    Raises :class:`IntervalError` for a wrong shape, NaN bounds or ``lo > hi``.
    """
    b = np.asarray(boxes, dtype=np.float64)
    if b.ndim == 2:
        b = b[None]
    if b.ndim != 3 or b.shape[-1] != 2 or b.shape[1] == 0:
        raise IntervalError(f"{name}: expected boxes of shape (N, d, 2) or (d, 2), got {b.shape}")
    if np.any(np.isnan(b)):
        raise IntervalError(f"{name}: a box has NaN bounds (empty box)")
    if np.any(b[..., 0] > b[..., 1]):
        raise IntervalError(f"{name}: a box has a lower bound above its upper bound")
    return b


def widths(boxes: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """``(..., d)`` widths ``hi - lo``, multiplied by ``scale (d,)`` when given."""
    w = boxes[..., 1] - boxes[..., 0]
    return w if scale is None else w * scale


def max_width(boxes: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """``(...,)`` largest scaled width of each box."""
    return np.max(widths(boxes, scale), axis=-1)


def centres(boxes: np.ndarray) -> np.ndarray:
    """``(..., d)`` box centres."""
    return boxes[..., 0] + (boxes[..., 1] - boxes[..., 0]) / 2.0


def bisect(
    boxes: np.ndarray, scale: np.ndarray | None = None, idle: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Bisect every box ``(N, d, 2)`` at the middle of its widest scaled dimension, among its
    axes not ``idle (N, d)`` when given (among all when every axis of a box is idle).

    Returns ``(left, right)``, each ``(N, d, 2)``; they share the cut value, so their union is
    exactly the parent box. Compiled (:func:`bisect_into`): the values of the numpy
    expressions ``widths``, ``np.argmax`` and ``centres``, bit for bit, about five times faster
    on the tightening's few hundred boxes a call.
    """
    boxes = np.ascontiguousarray(boxes, dtype=np.float64)
    left, right = np.empty_like(boxes), np.empty_like(boxes)
    bisect_into(
        boxes,
        np.ones(boxes.shape[1]) if scale is None else np.asarray(scale, dtype=np.float64),
        scale is not None,
        np.zeros((0, 0), dtype=bool) if idle is None else np.ascontiguousarray(idle, dtype=bool),
        idle is not None,
        left,
        right,
    )
    return left, right


@numba.njit(cache=True)
def bisect_into(boxes, scale, scaled, idle, has_idle, left, right):
    """:func:`bisect` of ``boxes (N, d, 2)`` written into ``left, right (N, d, 2)``, compiled, for
    callers that are compiled too (:func:`intervals.tighten.tighten`'s rounds of cuts): per box
    the widths ``hi - lo`` (times ``scale (d,)`` when ``scaled``), ``-1`` on the axes ``idle
    (N, d)`` (when ``has_idle``; else ``idle`` is not read) unless every axis is idle, the first
    largest (a NaN width first, as ``np.argmax``), cut at ``lo + (hi - lo) / 2``."""
    n, d = boxes.shape[0], boxes.shape[1]
    for b in range(n):
        all_idle = has_idle
        if has_idle:
            for a in range(d):
                all_idle = all_idle and idle[b, a]
        best, best_w = 0, -np.inf
        for a in range(d):
            w = boxes[b, a, 1] - boxes[b, a, 0]
            if scaled:
                w = w * scale[a]
            if has_idle and idle[b, a] and not all_idle:
                w = -1.0
            if w != w:  # NaN: np.argmax's pick
                best = a
                break
            if a == 0 or w > best_w:
                best, best_w = a, w
        for a in range(d):
            left[b, a, 0], left[b, a, 1] = boxes[b, a, 0], boxes[b, a, 1]
            right[b, a, 0], right[b, a, 1] = boxes[b, a, 0], boxes[b, a, 1]
        lo, hi = boxes[b, best, 0], boxes[b, best, 1]
        cut = lo + (hi - lo) / 2.0
        left[b, best, 1] = cut
        right[b, best, 0] = cut


def inflate(boxes: np.ndarray, margin) -> np.ndarray:
    """Boxes grown by ``margin (d,)`` on each side, rounded outward (e.g. the reachable poses
    after one epoch: ``(v_max dt, v_max dt, omega_max dt)``, the prediction by physical limits
    of paper 002 section 3)."""
    margin = np.asarray(margin, dtype=np.float64)
    if np.any(~(margin >= 0)):
        raise IntervalError(f"inflate: margins must be >= 0, got {margin}")
    return np.stack(
        [
            np.nextafter(boxes[..., 0] - margin, -np.inf),
            np.nextafter(boxes[..., 1] + margin, np.inf),
        ],
        axis=-1,
    )


@numba.njit(cache=True)
def copy_box(source, i, target, j):
    """Row ``i`` of ``source (N, d, 2)`` copied into row ``j`` of ``target (M, d, 2)``, bound
    by bound (in the compiled loops: several times faster than a row assignment, which builds
    array views)."""
    for a in range(source.shape[1]):
        target[j, a, 0], target[j, a, 1] = source[i, a, 0], source[i, a, 1]


@numba.njit(cache=True)
def _nudged(x, direction, ulps):
    """``x`` (a float or an array) moved ``ulps`` floats towards ``direction * inf``."""
    for _ in range(ulps):
        x = np.nextafter(x, direction * np.inf)
    return x


def _shift_turns(boxes: np.ndarray, turns: np.ndarray, axis: int) -> np.ndarray:
    """Boxes with the heading axis moved by ``-turns * 2 pi``; moved bounds are rounded outward
    by 2 ulps, more than the error of the float ``2 pi`` times a few turns plus the rounding of
    the subtraction."""
    out = boxes.copy()
    moved = turns != 0
    shift = turns * (2.0 * np.pi)
    out[:, axis, 0] = np.where(moved, _nudged(boxes[:, axis, 0] - shift, -1, 2), boxes[:, axis, 0])
    out[:, axis, 1] = np.where(moved, _nudged(boxes[:, axis, 1] - shift, 1, 2), boxes[:, axis, 1])
    return out


def unwrap_headings(
    boxes: np.ndarray, reference_rad: float | np.ndarray, axis: int = 2
) -> np.ndarray:
    """The same poses, each box moved by whole turns in heading so that its centre lies within
    ``pi`` of ``reference_rad`` (one for all, or one per box ``(N,)``; lets the hull of a set
    span the +-pi cut tightly)."""
    centre = (boxes[:, axis, 0] + boxes[:, axis, 1]) / 2.0
    return _shift_turns(boxes, np.round((centre - reference_rad) / (2.0 * np.pi)), axis)


@numba.njit(cache=True)
def _wrap_into(boxes, axis):
    """:func:`wrap_headings` of ``boxes (N, d, 2)``: ``(N + K, d, 2)``, the ``K`` boxes split at
    ``pi`` last, in the order of their rows (the float operations of :func:`_shift_turns` and
    of the clamps, one box at a time)."""
    n = boxes.shape[0]
    turn = 2.0 * np.pi
    pi_up, pi_down = _nudged(np.pi, 1, 2), _nudged(-np.pi, -1, 2)
    out = boxes.copy()
    upper = np.empty(n)  # each box's upper heading once moved, before the clamp
    crossing = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        lo, hi = boxes[i, axis, 0], boxes[i, axis, 1]
        full = hi - lo >= turn
        turns = np.floor((lo + np.pi) / turn)
        if turns != 0:
            lo, hi = _nudged(lo - turns * turn, -1, 2), _nudged(hi - turns * turn, 1, 2)
        upper[i] = hi
        out[i, axis, 0] = pi_down if full else _larger(lo, pi_down)
        out[i, axis, 1] = pi_up if full else _smaller(hi, pi_up)
        crossing[i] = not full and hi > pi_up
    extra = np.flatnonzero(crossing)
    result = np.empty((n + extra.size, boxes.shape[1], 2))
    result[:n] = out
    for k in range(extra.size):
        copy_box(out, extra[k], result, n + k)
        result[n + k, axis, 0] = pi_down
        result[n + k, axis, 1] = _nudged(upper[extra[k]] - turn, 1, 2)
    return result


def wrap_headings(boxes: np.ndarray, axis: int = 2) -> np.ndarray:
    """The same poses with every heading interval within ``[-pi, pi]`` (outward rounded).

    Each box is moved by whole turns so that its lower heading lies in ``[-pi, pi)``; a box
    then reaching above ``pi`` is split at ``pi`` into two boxes (``[lo, pi]`` in its row, and
    ``[-pi, hi - 2 pi]`` after every row); a box at least ``2 pi`` wide becomes ``[-pi, pi]``.
    One compiled pass over the boxes (:func:`_wrap_into`).
    """
    return _wrap_into(np.ascontiguousarray(boxes, dtype=np.float64), int(axis))


def hull(boxes: np.ndarray) -> np.ndarray:
    """The smallest box ``(d, 2)`` holding every box of ``(N, d, 2)`` (N >= 1)."""
    return np.stack([boxes[..., 0].min(axis=0), boxes[..., 1].max(axis=0)], axis=-1)


def contains_points(boxes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(N, P)`` bool: point ``p`` of ``points (P, d)`` lies in the closed box ``n``."""
    pts = np.asarray(points, dtype=np.float64)[None]
    return np.all((boxes[:, None, :, 0] <= pts) & (pts <= boxes[:, None, :, 1]), axis=-1)


def contains_boxes(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """``(...)`` bool: box ``inner`` lies in box ``outer`` (broadcast over leading axes)."""
    return np.all((outer[..., 0] <= inner[..., 0]) & (inner[..., 1] <= outer[..., 1]), axis=-1)


def volume(boxes: np.ndarray) -> float:
    """Sum of the volumes of the boxes ``(N, d, 2)`` (units: product of the axes' units)."""
    return float(np.sum(np.prod(widths(boxes), axis=-1)))


def area_xy(boxes: np.ndarray) -> float:
    """Area in m^2 of the union of the (x, y) projections of the boxes ``(N, d >= 2, 2)``.

    Exact union (not the sum), by a sweep over x with a segment tree over y
    (:func:`intervals.union_area.union_area`): ``O(N log N)`` time, ``O(N)`` memory.
    """
    x, y = np.ascontiguousarray(boxes[:, 0, :].T), np.ascontiguousarray(boxes[:, 1, :].T)
    return float(union_area(x[0], x[1], y[0], y[1]))


def _sweep_axes(boxes: np.ndarray, periodic_axis: int | None) -> tuple[int, int, int]:
    """``(axis, slab_axis, slabs)`` for :func:`_sweep_components`.

    ``axis``: of the non-periodic axes, the one where boxes overlap least, by the estimate
    ``mean width / extent`` (two boxes of widths ``w_i, w_j`` spread over an extent ``L``
    overlap on that axis with probability about ``(w_i + w_j) / L``); the periodic axis only
    when it is the only one (``d = 1``). ``slab_axis``: the next such non-periodic axis (-1:
    none), cut into ``slabs = extent / mean width`` slabs (at most ``N``): each box lies in at
    most ``width / slab + 2`` of them, so the slabs hold at most ``3 N`` entries in all."""
    n, d = boxes.shape[0], boxes.shape[1]
    candidates = [a for a in range(d) if a != periodic_axis]
    if not candidates:
        return 0, -1, 1
    lo, hi = boxes[:, candidates, 0], boxes[:, candidates, 1]
    extent = hi.max(axis=0) - lo.min(axis=0)
    mean_width = (hi - lo).mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        overlap = np.where(extent > 0.0, mean_width / extent, np.inf)
    ranked = np.argsort(overlap, kind="stable")
    if len(candidates) == 1 or not np.isfinite(overlap[ranked[1]]):
        return candidates[int(ranked[0])], -1, 1
    slabs = int(min(n, np.floor(1.0 / max(overlap[ranked[1]], 1.0 / n))))
    return candidates[int(ranked[0])], candidates[int(ranked[1])], max(slabs, 1)


@numba.njit(cache=True)
def _find(parent, i):
    """The root of ``i`` in the union-find forest ``parent (N,)`` (path halving)."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@numba.njit(cache=True)
def _touch(lo, hi, a, b, periodic_axis, period):
    """Boxes ``a < b`` (rows of ``lo, hi (N, d)``) touch: their closed intervals meet on every
    axis, the ``periodic_axis`` (-1: none) also with ``a``'s shifted by ``-period`` or
    ``+period`` (the float operations of the all-pairs definition, ``lo_a + shift <= hi_b``
    and ``lo_b <= hi_a + shift``)."""
    for axis in range(lo.shape[1]):
        lo_a, hi_a, lo_b, hi_b = lo[a, axis], hi[a, axis], lo[b, axis], hi[b, axis]
        if lo_a <= hi_b and lo_b <= hi_a:
            continue
        if axis != periodic_axis:
            return False
        if not (
            (lo_a - period <= hi_b and lo_b <= hi_a - period)
            or (lo_a + period <= hi_b and lo_b <= hi_a + period)
        ):
            return False
    return True


@numba.njit(cache=True)
def _slab_entries(lo, hi, axis, slab_axis, slabs, periodic_axis, period):
    """``(entry_lo, entry_hi, owner, slab_start)``: the sweep entries of
    :func:`_sweep_components` grouped by slab (slab ``k``: entries ``slab_start[k]`` to
    ``slab_start[k + 1] - 1``), each slab's sorted by lower bound on ``axis``."""
    n = lo.shape[0]
    copies = 3 if axis == periodic_axis else 1
    base_lo = np.empty(copies * n)
    base_hi = np.empty(copies * n)
    base_owner = np.empty(copies * n, dtype=np.int64)
    for c in range(copies):
        shift = (0.0, -period, period)[c]
        for i in range(n):
            base_lo[c * n + i] = lo[i, axis] + shift
            base_hi[c * n + i] = hi[i, axis] + shift
            base_owner[c * n + i] = i
    order = np.argsort(base_lo)
    first = np.zeros(order.size, dtype=np.int64)
    last = np.zeros(order.size, dtype=np.int64)
    if slab_axis >= 0:
        bottom, top = lo[:, slab_axis].min(), hi[:, slab_axis].max()
        height = (top - bottom) / slabs
        for e in range(order.size if height > 0.0 else 0):  # else every box in slab 0
            i = base_owner[e]
            first[e] = min(max(int(np.floor((lo[i, slab_axis] - bottom) / height)), 0), slabs - 1)
            last[e] = min(max(int(np.floor((hi[i, slab_axis] - bottom) / height)), 0), slabs - 1)
    slab_start = np.zeros(slabs + 1, dtype=np.int64)  # a counting sort by slab, stable
    for e in range(order.size):
        for k in range(first[e], last[e] + 1):
            slab_start[k + 1] += 1
    for k in range(slabs):
        slab_start[k + 1] += slab_start[k]
    fill = slab_start[:-1].copy()
    size = slab_start[slabs]
    entry_lo, entry_hi = np.empty(size), np.empty(size)
    owner = np.empty(size, dtype=np.int64)
    for e in order:  # by lower bound
        for k in range(first[e], last[e] + 1):
            entry_lo[fill[k]], entry_hi[fill[k]], owner[fill[k]] = (
                base_lo[e],
                base_hi[e],
                base_owner[e],
            )
            fill[k] += 1
    return entry_lo, entry_hi, owner, slab_start


@numba.njit(cache=True)
def _sweep_components(lo, hi, axis, slab_axis, slabs, periodic_axis, period):
    """``labels (N,)`` of the components of the boxes ``lo, hi (N, d)`` (module doc of
    :func:`connected_components`): union-find over sweeps along ``axis``, one a slab.

    The boxes' intervals on ``axis`` are the sweep entries (when ``axis`` is the periodic one,
    also each box's copies shifted by ``-+period``: ``3 N`` entries). With a ``slab_axis``
    (-1: none), that axis is cut into ``slabs`` equal slabs and each entry goes into every slab
    its box meets there: two touching boxes share a point ``y = max(lo_i, lo_j)`` on that axis,
    and the slab index ``floor((y - bottom) / height)`` is non-decreasing in ``y`` in floating
    point too, so both lie in the slab of ``y``. In each slab, entries sorted by lower bound,
    an entry meets on ``axis`` exactly the entries after it whose lower bound is at most its
    upper bound; those pairs get the exact test :func:`_touch` (the smaller index first) and,
    when they touch, their trees are joined (pairs already in one tree are skipped). Time
    ``O(N log N + C)`` for ``C`` pairs of entries meeting on ``axis`` in a slab; memory
    ``O(N)`` (:func:`_sweep_axes` bounds the entries by ``3 N``).
    """
    n = lo.shape[0]
    entry_lo, entry_hi, owner, slab_start = _slab_entries(
        lo, hi, axis, slab_axis, slabs, periodic_axis, period
    )
    parent = np.arange(n)
    for k in range(slab_start.size - 1):
        end = slab_start[k + 1]
        for e in range(slab_start[k], end):
            top, p = entry_hi[e], owner[e]
            for f in range(e + 1, end):
                if entry_lo[f] > top:
                    break
                q = owner[f]
                if p == q or not _touch(lo, hi, min(p, q), max(p, q), periodic_axis, period):
                    continue
                root_p, root_q = _find(parent, p), _find(parent, q)
                parent[max(root_p, root_q)] = min(root_p, root_q)
    labels = np.full(n, -1, dtype=np.int64)
    count = 0
    for i in range(n):  # numbered in the order of each component's first box
        root = _find(parent, i)
        if labels[root] < 0:
            labels[root] = count
            count += 1
        labels[i] = labels[root]
    return labels


def connected_components(
    boxes: np.ndarray, periodic_axis: int | None = None, period: float = 2.0 * np.pi
) -> tuple[int, np.ndarray]:
    """Connected components of the union of closed boxes ``(N, d, 2)``.

    Two boxes are connected when they overlap or touch on every axis (closed intervals: a
    shared corner connects). ``periodic_axis`` (the heading, axis 2 of pose boxes) is compared
    modulo ``period`` as well (intervals also shifted by ``-+period``), so boxes at
    ``theta = -pi`` and ``theta = pi`` join. Returns ``(count, labels (N,))``, labels
    ``0..count-1`` numbered in the order of each component's first box.

    A compiled union-find over sweeps (:func:`_sweep_components`) along the axis where the
    boxes overlap least, one sweep a slab of the next such axis (:func:`_sweep_axes`):
    ``O(N log N)`` time for pavings (each box meeting, on that axis and in its slabs, a bounded
    number of others; ``O(N log N + C)`` for ``C`` such pairs in general) and ``O(N)`` memory,
    never an ``N x N`` array.
    """
    n = boxes.shape[0]
    if n == 0:
        return 0, np.zeros(0, dtype=np.int64)
    lo, hi = _bounds(boxes)
    periodic = -1 if periodic_axis is None else int(periodic_axis)
    axis, slab_axis, slabs = _sweep_axes(boxes, periodic_axis)
    labels = _sweep_components(lo, hi, axis, slab_axis, slabs, periodic, float(period))
    return int(labels.max()) + 1, labels


@numba.njit(cache=True)
def _meets(lo, hi, region_lo, region_hi, i, r):
    """Box ``i`` of ``lo, hi (N, d)`` meets region ``r`` of ``region_lo, region_hi (M, d)``
    (closed intervals, every axis)."""
    for a in range(lo.shape[1]):  # noqa: SIM110 (numba compiles no all() of a generator)
        if max(lo[i, a], region_lo[r, a]) > min(hi[i, a], region_hi[r, a]):
            return False
    return True


@numba.njit(cache=True)
def _larger(a, b):
    """``np.maximum`` of two floats: ``b`` on ties, as numpy (the same signed zeros)."""
    return a if a > b else b


@numba.njit(cache=True)
def _smaller(a, b):
    """``np.minimum`` of two floats: ``b`` on ties, as numpy."""
    return a if a < b else b


@numba.njit(cache=True)
def _clip_into(lo, hi, region_lo, region_hi, clipped_lo, clipped_hi, held):
    """:func:`clip_to_boxes` on ``lo, hi (N, d)`` and ``region_lo, region_hi (M, d)``, into
    ``clipped_lo, clipped_hi (N, d)`` (initialised ``+inf``, ``-inf``) and ``held (N,)``."""
    for i in range(lo.shape[0]):
        for r in range(region_lo.shape[0]):
            if not _meets(lo, hi, region_lo, region_hi, i, r):
                continue
            inside = True
            for a in range(lo.shape[1]):
                inside &= region_lo[r, a] <= lo[i, a] and hi[i, a] <= region_hi[r, a]
                lower = _larger(lo[i, a], region_lo[r, a])
                upper = _smaller(hi[i, a], region_hi[r, a])
                clipped_lo[i, a] = _smaller(clipped_lo[i, a], lower)
                clipped_hi[i, a] = _larger(clipped_hi[i, a], upper)
            held[i] |= inside


@numba.njit(cache=True)
def _meets_any(lo, hi, region_lo, region_hi):
    """:func:`meets_any_box` on ``lo, hi (N, d)`` and ``region_lo, region_hi (M, d)``."""
    out = np.zeros(lo.shape[0], dtype=np.bool_)
    for i in range(lo.shape[0]):
        for r in range(region_lo.shape[0]):
            if _meets(lo, hi, region_lo, region_hi, i, r):
                out[i] = True
                break
    return out


def _bounds(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(lo (N, d), hi (N, d))``: the bounds of ``boxes (N, d, 2)``, contiguous float64 (for
    the compiled loops)."""
    return (
        np.ascontiguousarray(boxes[..., 0], dtype=np.float64),
        np.ascontiguousarray(boxes[..., 1], dtype=np.float64),
    )


def meets_any_box(boxes: np.ndarray, regions: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: the box of ``boxes (N, d, 2)`` meets (closed intervals) at least one of
    ``regions (M, d, 2)``. A compiled loop over the ``N M`` pairs, ``O(N)`` memory."""
    return _meets_any(*_bounds(boxes), *_bounds(regions))


def clip_to_boxes(boxes: np.ndarray, regions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(clipped (N, d, 2), held (N,) bool)``: each box of ``boxes (N, d, 2)`` cut down to the
    hull of its intersections with ``regions (M, d, 2)`` (closed intervals; a box meeting none
    becomes an empty row, lower bounds ``+inf`` above upper bounds ``-inf``), and whether it
    lies within one region. Every point of a box that lies in some region stays in its clipped
    box (the bounds are maxima and minima of the given bounds: no rounding). A compiled loop
    over the ``N M`` pairs, ``O(N)`` memory."""
    lo, hi = _bounds(boxes)
    clipped_lo, clipped_hi = np.full_like(lo, np.inf), np.full_like(hi, -np.inf)
    held = np.zeros(lo.shape[0], dtype=np.bool_)
    _clip_into(lo, hi, *_bounds(regions), clipped_lo, clipped_hi, held)
    return np.stack([clipped_lo, clipped_hi], axis=-1), held


@numba.njit(cache=True)
def _before(boxes, i, j, axis):
    """Row ``i`` of ``boxes (N, d, 2)`` sorts strictly before row ``j`` in
    :func:`merge_adjacent`'s order: by the bounds of the other axes, the last axis first (its
    upper bound, then its lower), then by the lower bound on ``axis`` (the order of
    ``np.lexsort([lo_axis, lo_0, hi_0, lo_1, hi_1, ...])`` over the other axes)."""
    for a in range(boxes.shape[1] - 1, -1, -1):
        if a == axis:
            continue
        for k in (1, 0):
            if boxes[i, a, k] != boxes[j, a, k]:
                return boxes[i, a, k] < boxes[j, a, k]
    return boxes[i, axis, 0] < boxes[j, axis, 0]


@numba.njit(cache=True)
def sorted_rows(boxes, axis):
    """``(N,)`` the rows of ``boxes (N, d, 2)`` in :func:`_before`'s order, ties in row order
    (a stable bottom-up merge sort, as ``np.lexsort`` is stable: the same permutation)."""
    n = boxes.shape[0]
    order, spare = np.arange(n), np.empty(n, dtype=np.int64)
    run = 1
    while run < n:
        for start in range(0, n, 2 * run):
            middle, end = min(start + run, n), min(start + 2 * run, n)
            i, j = start, middle
            for k in range(start, end):
                if j < end and (i >= middle or _before(boxes, order[j], order[i], axis)):
                    spare[k] = order[j]
                    j += 1
                else:
                    spare[k] = order[i]
                    i += 1
        order, spare = spare, order
        run *= 2
    return order


@numba.njit(cache=True)
def continues_along(boxes, row, out, last, axis):
    """Whether row ``row`` of ``boxes (N, d, 2)`` continues row ``last`` of ``out (M, d, 2)``
    along ``axis``: equal bounds on the other axes, and it starts where that one ends
    (``hi == lo``, in floating point), so that the two join into one box exactly."""
    for a in range(boxes.shape[1]):
        if a != axis and (
            boxes[row, a, 0] != out[last, a, 0] or boxes[row, a, 1] != out[last, a, 1]
        ):
            return False
    return boxes[row, axis, 0] == out[last, axis, 1]


@numba.njit(cache=True)
def _merge_along(boxes, axis):
    """One pass of :func:`merge_adjacent` along ``axis``: ``boxes (N, d, 2)`` sorted
    (:func:`sorted_rows`), each run of rows with equal bounds on the other axes, each
    starting where the one before ends on ``axis``, joined into its first row."""
    n = boxes.shape[0]
    order = sorted_rows(boxes, axis)
    out = np.empty_like(boxes)
    count = 0
    for k in range(n):
        row = order[k]
        joined = k > 0 and continues_along(boxes, row, out, count - 1, axis)
        if joined:
            out[count - 1, axis, 1] = boxes[row, axis, 1]
        else:
            copy_box(boxes, row, out, count)
            count += 1
    return out[:count].copy()


def merge_adjacent(boxes: np.ndarray, rounds: int = 2) -> np.ndarray:
    """The same union in fewer boxes, exactly: along each axis in turn, every run of boxes
    with identical bounds on the other axes, each starting where the one before it ends on
    this axis (``hi == lo``, in floating point), becomes one box from the run's first lower
    bound to its last upper bound; ``rounds`` passes over the axes (fewer when a pass merges
    nothing). ``O(N log N)`` a pass (a compiled stable sort by the other axes' bounds, then
    by lower bound: :func:`_merge_along`); the boxes come out in that order. Siblings SIVIA
    kept both of merge back into their parent, so a strip where the set is ambiguous (a
    corridor, along its axis) is held by a few long boxes instead of a row of ``eps``
    cells."""
    d = boxes.shape[1]
    for _ in range(rounds):
        before = boxes.shape[0]
        for axis in range(d):
            if boxes.shape[0] < 2:
                return boxes
            boxes = _merge_along(np.ascontiguousarray(boxes, dtype=np.float64), axis)
        if boxes.shape[0] == before:
            break
    return boxes


def component_hulls(boxes: np.ndarray, periodic_axis: int | None = 2) -> np.ndarray:
    """The hull of each connected component of the boxes ``(N, d, 2)`` (N >= 1): ``(C, d, 2)``
    in the order of :func:`connected_components`, whose union holds the boxes. With a
    ``periodic_axis`` (the heading) each component's boxes are first moved by whole turns
    next to its first box (:func:`unwrap_headings`), so a component across the +-pi cut keeps a
    narrow interval there (possibly beyond ``pi``; a component round the whole circle gets a
    hull at least ``2 pi`` wide)."""
    count, labels = connected_components(boxes, periodic_axis)
    if periodic_axis is not None:
        first = np.empty(count, dtype=np.int64)
        first[labels[::-1]] = np.arange(labels.size)[::-1]  # each component's first box
        own = boxes[first[labels], periodic_axis]
        boxes = unwrap_headings(boxes, (own[:, 0] + own[:, 1]) / 2.0, periodic_axis)
    return group_hulls(boxes, labels, count)


def group_hulls(boxes: np.ndarray, labels: np.ndarray, count: int) -> np.ndarray:
    """``(count, d, 2)``: the hull of the boxes ``(N, d, 2)`` of each label ``0..count-1``
    (``labels (N,)``, every label present); ``O(N log N)`` (the boxes sorted by label)."""
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(count))
    lo = np.minimum.reduceat(boxes[order, :, 0], starts, axis=0)
    hi = np.maximum.reduceat(boxes[order, :, 1], starts, axis=0)
    return np.stack([lo, hi], axis=-1)


@dataclass(frozen=True)
class Subpaving:
    """Result of a set inverter: non-overlapping boxes that approximate a set ``X``.

    ``inner (Ni, d, 2)``: boxes proved inside ``X``. ``boundary (Nb, d, 2)``: undecided boxes of
    width at most ``eps`` (or exact unions of such boxes, :func:`merge_adjacent`, as the
    tracker reports them). The outer approximation ``inner ∪ boundary`` contains ``X``.
    ``coarse``: a budget cut the paving short (:func:`intervals.sivia.sivia`'s ``max_tested``,
    :func:`coarsen`): some boundary boxes are wider than ``eps``, or merged; still a cover.
    """

    inner: np.ndarray
    boundary: np.ndarray
    coarse: bool = False

    @property
    def outer(self) -> np.ndarray:
        """``(Ni + Nb, d, 2)``: every box of the outer approximation."""
        return np.concatenate([self.inner, self.boundary], axis=0)

    @property
    def is_empty(self) -> bool:
        """True when the outer approximation holds no box (the set is proved empty)."""
        return self.inner.shape[0] + self.boundary.shape[0] == 0

    def hull(self) -> np.ndarray:
        """``(d, 2)`` hull of the outer approximation; :class:`IntervalError` when empty."""
        if self.is_empty:
            raise IntervalError("hull of an empty subpaving")
        return hull(self.outer)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """``(P,)`` bool: the point ``(P, d)`` lies in some box of the outer approximation."""
        pts = np.atleast_2d(points)
        return np.any(contains_points(self.outer, pts), axis=0)

    def volume(self) -> float:
        """Volume of the outer approximation."""
        return volume(self.outer)

    def area_xy(self) -> float:
        """Projected (x, y) area of the outer approximation, m^2."""
        return area_xy(self.outer)

    def components(self, periodic_axis: int | None = 2) -> tuple[int, np.ndarray]:
        """Connected components of the outer boxes (heading axis periodic by default):
        ``(count, labels (N,))``, labels read-only. The default's are computed once per
        subpaving (the fusion, the epoch log and the recording all ask for them)."""
        if periodic_axis == 2:
            return self._heading_components
        return self._components(periodic_axis)

    @cached_property
    def _heading_components(self) -> tuple[int, np.ndarray]:
        return self._components(2)

    def _components(self, periodic_axis: int | None) -> tuple[int, np.ndarray]:
        outer = self.outer
        use = periodic_axis is not None and outer.shape[1] > periodic_axis
        count, labels = connected_components(outer, periodic_axis if use else None)
        labels.flags.writeable = False
        return count, labels
