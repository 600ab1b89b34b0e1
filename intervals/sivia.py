"""SIVIA, breadth-first (Set Inversion Via Interval Analysis; paper 002 section 3.1, eq. 6-7).

Characterise ``X = {x in [x0] : t(x) holds}`` by two subpavings ``inner ⊂ X ⊂ inner ∪ boundary``.
A *test* decides boxes: :data:`INSIDE` (every point satisfies the constraints), :data:`OUTSIDE`
(none does) or :data:`UNDECIDED`. Instead of recursing box by box, each level evaluates the test
once on the array of all undecided boxes, keeps the inner ones, drops the outside ones, stores
the undecided ones no wider than ``eps`` as boundary and bisects the rest (heading axis scaled).
"""

from __future__ import annotations

from collections.abc import Callable
from enum import IntEnum

import numba
import numpy as np

from intervals.bisection import split_rounds
from intervals.boxes import (
    Subpaving,
    as_boxes,
    continues_along,
    copy_box,
    max_width,
    sorted_rows,
)
from intervals.errors import IntervalError


class Verdict(IntEnum):
    """Values a box test returns (as an ``int8`` array)."""

    OUTSIDE = 0
    INSIDE = 1
    UNDECIDED = 2


OUTSIDE, INSIDE, UNDECIDED = int(Verdict.OUTSIDE), int(Verdict.INSIDE), int(Verdict.UNDECIDED)
"""The :class:`Verdict` values as plain ints, for the array operations: numpy compares an
array with an ``IntEnum`` member several times slower (about 25 us against 3 us for 300
verdicts), and a tracking epoch's SIVIA levels make a few dozen such operations each."""

BoxTest = Callable[
    [np.ndarray],
    np.ndarray | tuple[np.ndarray, np.ndarray] | tuple[np.ndarray, np.ndarray, np.ndarray],
]
"""``test(boxes (N, d, 2)) -> (N,) int8`` of :class:`Verdict` values, or ``(verdicts, scores
(N,))``: a score per box, lower for the boxes to refine first under a budget (e.g. the number
of sensors rejecting the box; see :func:`sivia`'s ``max_tested``), or ``(verdicts, scores,
idle (N, d) bool)``: also the *idle axes* of each box, along which cutting it cannot separate
points of ``X`` from points outside it (e.g. :func:`intervals.sonar.idle.idle_axes`), found
by the test as it decides the box (see :func:`sivia`)."""

Contractor = Callable[[np.ndarray], np.ndarray]
"""``contract(boxes (N, d, 2)) -> (N, d, 2)``: each row a box inside the input row holding
every point of it that satisfies the constraints; a row with no such point is marked empty
(NaN, or a lower bound above the upper)."""

DEFAULT_MAX_BOXES = 200_000
"""Most boxes SIVIA hands to the test at once (a larger frontier is tested in chunks)."""


def _verdicts(test: BoxTest, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The test's ``(verdicts (N,), scores (N,), idle (N, d) or None)`` (scores 0 when the
    test gives none)."""
    out = test(boxes)
    v, scores, idle = (*out, None, None)[:3] if isinstance(out, tuple) else (out, None, None)
    v = np.asarray(v)
    n = boxes.shape[0]
    if v.shape != (n,):
        raise IntervalError(f"SIVIA test returned shape {v.shape}, expected ({n},)")
    if np.any((v < OUTSIDE) | (v > UNDECIDED)):
        raise IntervalError("SIVIA test returned a value other than OUTSIDE, INSIDE, UNDECIDED")
    scores = np.zeros(n) if scores is None else np.asarray(scores, dtype=np.float64)
    if scores.shape != (n,) or not np.all(np.isfinite(scores)):
        raise IntervalError(
            f"SIVIA test scores must be {n} finite numbers, got shape {scores.shape}"
        )
    if idle is not None:
        idle = np.asarray(idle)
        if idle.shape != boxes.shape[:2] or idle.dtype != bool:
            raise IntervalError(f"SIVIA test idle axes must be {boxes.shape[:2]} bool")
    return v, scores, idle


@numba.njit(cache=True)
def _kept_within(contracted, boxes):
    """The rows of ``contracted (N, d, 2)`` clamped into the rows of ``boxes (N, d, 2)``
    (``np.maximum`` of the lower bounds, ``np.minimum`` of the upper), the rows then empty on
    some axis (a lower bound above the upper, or NaN: it compares false) left out."""
    n, d = boxes.shape[0], boxes.shape[1]
    out = np.empty_like(boxes)
    count = 0
    for i in range(n):
        live = True
        for a in range(d):
            lo, hi = contracted[i, a, 0], contracted[i, a, 1]
            lo = lo if lo > boxes[i, a, 0] or np.isnan(lo) else boxes[i, a, 0]
            hi = hi if hi < boxes[i, a, 1] or np.isnan(hi) else boxes[i, a, 1]
            out[count, a, 0], out[count, a, 1] = lo, hi
            live = live and lo <= hi
        count += live
    return out[:count].copy()


def _contracted(contract: Contractor, boxes: np.ndarray) -> np.ndarray:
    """``boxes`` contracted, the empty rows dropped, every row kept within its input row."""
    c = np.asarray(contract(boxes), dtype=np.float64)
    if c.shape != boxes.shape:
        raise IntervalError(f"SIVIA contractor returned shape {c.shape}, expected {boxes.shape}")
    return _kept_within(np.ascontiguousarray(c), np.ascontiguousarray(boxes, dtype=np.float64))


@numba.njit(cache=True)
def _cut_width_of(boxes, i, scale, idle):
    """:func:`cut_width` of row ``i`` of ``boxes (N, d, 2)`` (``idle (N, d)``)."""
    best = 0.0
    for a in range(boxes.shape[1]):
        w = (boxes[i, a, 1] - boxes[i, a, 0]) * scale[a]
        if not idle[i, a] and w > best:
            best = w
    return best


@numba.njit(cache=True)
def _cut_widths(boxes, scale, idle):
    """:func:`cut_width` of every row of ``boxes (N, d, 2)``."""
    out = np.empty(boxes.shape[0])
    for i in range(boxes.shape[0]):
        out[i] = _cut_width_of(boxes, i, scale, idle)
    return out


def _unit_scale(d: int, scale) -> np.ndarray:
    """``scale`` as contiguous float64 ``(d,)``, ones when None (a width times 1.0 is the
    width)."""
    return np.ones(d) if scale is None else np.ascontiguousarray(scale, dtype=np.float64)


def _no_idle(boxes: np.ndarray, idle: np.ndarray | None) -> np.ndarray:
    """``idle (N, d)`` as contiguous bool, all False when None."""
    if idle is None:
        return np.zeros(boxes.shape[:2], dtype=np.bool_)
    return np.ascontiguousarray(idle, dtype=np.bool_)


def cut_width(boxes: np.ndarray, scale=None, idle: np.ndarray | None = None) -> np.ndarray:
    """``(N,)`` the largest scaled width of each box ``(N, d, 2)`` over its axes not ``idle
    (N, d)`` (all axes when None; 0 for a box idle along every axis). Compiled
    (:func:`_cut_widths`): widths are non-negative, so the maximum is that of the numpy
    formula ``max(where(idle, 0, (hi - lo) * scale))``."""
    b = np.ascontiguousarray(boxes, dtype=np.float64)
    return _cut_widths(b, _unit_scale(b.shape[1], scale), _no_idle(b, idle))


@numba.njit(cache=True)
def _sorted_level(boxes, verdicts, scale, idle, eps):
    """One SIVIA level's sort of ``boxes (N, d, 2)`` by ``verdicts (N,)``: ``(inner, small,
    wide, wide_idle, wide_rows)``, in row order: the INSIDE boxes; the UNDECIDED ones no wider
    than ``eps`` (:func:`cut_width`, ``idle (N, d)``); the UNDECIDED wider ones, their idle
    axes and their rows in ``boxes``."""
    n, d = boxes.shape[0], boxes.shape[1]
    inner, small, wide = np.empty_like(boxes), np.empty_like(boxes), np.empty_like(boxes)
    wide_idle = np.empty((n, d), dtype=np.bool_)
    wide_rows = np.empty(n, dtype=np.int64)
    n_inner = n_small = n_wide = 0
    for i in range(n):
        if verdicts[i] == INSIDE:
            copy_box(boxes, i, inner, n_inner)
            n_inner += 1
        elif verdicts[i] == UNDECIDED:
            if _cut_width_of(boxes, i, scale, idle) <= eps:
                copy_box(boxes, i, small, n_small)
                n_small += 1
            else:
                copy_box(boxes, i, wide, n_wide)
                wide_idle[n_wide, :] = idle[i, :]
                wide_rows[n_wide] = i
                n_wide += 1
    return (
        inner[:n_inner].copy(),
        small[:n_small].copy(),
        wide[:n_wide].copy(),
        wide_idle[:n_wide].copy(),
        wide_rows[:n_wide].copy(),
    )


@numba.njit(cache=True)
def _joined_along(boxes, idle, scores, axis):
    """One pass of :func:`_joined_idle` along ``axis``: ``(boxes, idle, scores)`` with every
    run of rows of ``boxes (N, d, 2)`` idle along ``axis`` (``idle (N, d)``), with equal bounds
    on the other axes, each starting where the one before ends on ``axis`` (``hi == lo``),
    joined into one row (:func:`intervals.boxes.merge_adjacent`'s order and test, restricted
    to idle rows): its idle axes those idle in every row of the run, its score the lowest
    of ``scores (N,)``."""
    n, d = boxes.shape[0], boxes.shape[1]
    order = sorted_rows(boxes, axis)
    out = np.empty_like(boxes)
    out_idle = np.empty_like(idle)
    out_scores = np.empty_like(scores)
    count = 0
    for k in range(n):
        row = order[k]
        last = count - 1
        joined = count > 0 and idle[row, axis] and out_idle[last, axis]
        joined = joined and continues_along(boxes, row, out, last, axis)
        if joined:
            out[last, axis, 1] = boxes[row, axis, 1]
            out_scores[last] = min(out_scores[last], scores[row])
            for a in range(d):
                out_idle[last, a] = out_idle[last, a] and idle[row, a]
        else:
            copy_box(boxes, row, out, count)
            out_idle[count, :] = idle[row, :]
            out_scores[count] = scores[row]
            count += 1
    return out[:count].copy(), out_idle[:count].copy(), out_scores[:count].copy()


def _joined_idle(
    boxes: np.ndarray, idle: np.ndarray, scores: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undecided boxes ``(N, d, 2)`` to bisect, rows that only a cut across an idle axis
    separates joined back (:func:`_joined_along`, each axis in turn): the same union, with
    their idle axes ``(N, d)`` and scores ``(N,)``. A row of boxes idle along an axis is cut
    there by the bisections made before the test could tell (SIVIA's first levels, or
    ``min_level_boxes``: big_hall's strips along its walls, cut into 16 slabs from the whole
    hall, each then paved across the strip alike); joined, the row is paved once. The input
    as it is, order kept, when nothing joins."""
    joined = (boxes, idle, scores)
    for axis in range(boxes.shape[1]):
        if joined[0].shape[0] > 1 and joined[1][:, axis].any():
            joined = _joined_along(*joined, axis)
    return joined if joined[0].shape[0] < boxes.shape[0] else (boxes, idle, scores)


@numba.njit(cache=True)
def _by_parent(children, parents, n):
    """``children (M, d, 2)`` in the order of their ``parents (M,)`` (rows ``0..n-1``), each
    parent's in their own order: a stable counting sort (``argsort(parents, "stable")``)."""
    start = np.zeros(n + 1, dtype=np.int64)
    for p in parents:
        start[p + 1] += 1
    for p in range(n):
        start[p + 1] += start[p]
    out = np.empty_like(children)
    for k in range(parents.size):
        copy_box(children, k, out, start[parents[k]])
        start[parents[k]] += 1
    return out


def _split(
    boxes: np.ndarray,
    eps: float,
    scale,
    times: int,
    grouped: bool = False,
    idle: np.ndarray | None = None,
) -> np.ndarray:
    """Bisect ``boxes`` (all wider than ``eps``), then their children still wider, ``times``
    rounds in all, in one compiled call (:func:`intervals.bisection.split_rounds`; ``grouped``:
    the children in the order of their parents, :func:`_by_parent`; ``idle (N, d)``: the axes
    of each box never cut, inherited by its children, None: none)."""
    b = np.ascontiguousarray(boxes, dtype=np.float64)
    out, parents = split_rounds(
        b, float(eps), _unit_scale(b.shape[1], scale), int(times), _no_idle(b, idle)
    )
    return _by_parent(out, parents, b.shape[0]) if grouped else out


def _extra_splits(boxes: np.ndarray, min_level_boxes: int) -> int:
    """Bisections that bring ``n`` boxes up to about ``min_level_boxes`` (0 when ``n`` is 0 or
    already at least ``min_level_boxes``)."""
    n = boxes.shape[0]
    return int(np.log2(min_level_boxes / n)) if 0 < n < min_level_boxes else 0


def sivia(
    test: BoxTest,
    initial: np.ndarray,
    eps: float,
    scale: np.ndarray | None = None,
    max_boxes: int = DEFAULT_MAX_BOXES,
    splits_per_level: int = 1,
    min_level_boxes: int = 1,
    max_tested: int | None = None,
    contract: Contractor | None = None,
) -> Subpaving:
    """Pave ``initial`` (one box ``(d, 2)`` or a subpaving ``(N, d, 2)``) with ``test``.

    ``eps``: boxes whose largest scaled width is at most ``eps`` are not bisected further.
    ``scale (d,)``: per-axis scale of the widths (e.g. :func:`intervals.boxes.pose_scale`).
    ``splits_per_level``: successive bisections applied to each undecided box per level (children
    already no wider than ``eps`` are not cut again): 3 turns a box into up to 8 children and
    divides the number of levels, hence of test calls, by about 3 (fewer, larger numpy passes).
    ``min_level_boxes``: a frontier of ``n`` boxes smaller than this (the initial boxes included)
    is bisected ``floor(log2(min_level_boxes / n))`` times instead (if more), so that no test call
    is spent on a handful of boxes (a call has a fixed cost; the boxes it would have rejected
    are rejected as children on the next call instead: same soundness, fewer calls).
    ``max_boxes``: a frontier of more boxes is cut into equal chunks of at most this many, each
    tested and refined before the next (depth first: the memory held is a few frontiers of
    ``max_boxes``, whatever the set; as sound as one call per level, and the same boxes unless
    a chunk leaves fewer than ``min_level_boxes`` to bisect).
    ``max_tested``: the most boxes the test may see in all (None: no limit). When the next
    chunk would exceed it, SIVIA stops and keeps every box not yet decided as a boundary box
    (possibly wider than ``eps``; each lies in a box the test left undecided, so the outer
    approximation still holds ``X``), and the subpaving is marked ``coarse``: a sound, coarser
    cover in bounded time, never an error. Under this budget the undecided boxes of a level
    are bisected in the order of their scores (the test's second output, lowest first: e.g.
    the fewest sensors rejecting them), so that the depth-first descent spends the budget on
    the most promising boxes first, and what it leaves whole is mostly the boxes it never
    reached, as they were: a later call on the same problem (a later epoch refining this
    cover) starts where this one stopped instead of from a cover of finer, more numerous
    boxes.
    ``contract``: a :data:`Contractor` applied to every frontier before the test (None: none);
    the boxes it empties are dropped as OUTSIDE, the others tested (and bisected) as
    contracted. Sound when the contractor is: it keeps every point that satisfies the
    constraints, and the test sees only such boxes.
    Idle axes (the test's third output, :data:`BoxTest`): the undecided boxes are never cut
    across their idle axes (nor their children, which inherit them), and a box is small when
    its other axes are no wider than ``eps`` (a box idle along every axis is kept whole): the
    cuts are a choice, any choice keeps the set sound. For the same reason the undecided boxes
    of a level that a cut across a shared idle axis alone separates (adjacent along it, equal
    bounds on the other axes) are joined before they are bisected (:func:`_joined_idle`): the
    same union, paved once instead of once a piece.
    Preconditions (checked first, :class:`IntervalError`): ``eps > 0`` and finite, at least one
    non-empty bounded box, ``scale`` positive. Returns a :class:`Subpaving`.
    """
    if not np.isfinite(eps) or eps <= 0:
        raise IntervalError(f"SIVIA: eps must be a positive finite width, got {eps!r}")
    boxes = as_boxes(initial, "SIVIA initial box")
    if boxes.shape[0] == 0:
        raise IntervalError("SIVIA: the initial subpaving holds no box")
    if not np.all(np.isfinite(boxes)):
        raise IntervalError("SIVIA: the initial box must be bounded (finite bounds)")
    if not (isinstance(min_level_boxes, (int, np.integer)) and min_level_boxes >= 1):
        raise IntervalError(
            f"SIVIA: min_level_boxes must be an integer >= 1, got {min_level_boxes!r}"
        )
    if not (isinstance(splits_per_level, (int, np.integer)) and splits_per_level >= 1):
        raise IntervalError(
            f"SIVIA: splits_per_level must be an integer >= 1, got {splits_per_level!r}"
        )
    d = boxes.shape[1]
    if scale is not None:
        scale = np.asarray(scale, dtype=np.float64)
        if scale.shape != (d,) or np.any(~(scale > 0)) or not np.all(np.isfinite(scale)):
            raise IntervalError(f"SIVIA: scale must be {d} positive finite numbers, got {scale}")
    if not (isinstance(max_boxes, (int, np.integer)) and max_boxes >= 1):
        raise IntervalError(f"SIVIA: max_boxes must be an integer >= 1, got {max_boxes!r}")
    if max_tested is not None and not (
        isinstance(max_tested, (int, np.integer)) and max_tested >= 0
    ):
        raise IntervalError(f"SIVIA: max_tested must be an integer >= 0, got {max_tested!r}")
    inner, boundary = [], []
    first = _extra_splits(boxes, min_level_boxes)
    if first:
        small = max_width(boxes, scale) <= eps
        boxes = np.concatenate([boxes[small], _split(boxes[~small], eps, scale, first)])
    pending, tested, coarse = [boxes], 0, False  # frontiers still to test, the last first
    while pending:
        boxes = pending.pop()
        if boxes.shape[0] > max_boxes:  # equal chunks, the first on top
            pending.extend(np.array_split(boxes, -(-boxes.shape[0] // max_boxes))[::-1])
            continue
        if contract is not None:
            boxes = _contracted(contract, boxes)
            if boxes.shape[0] == 0:
                continue
        if max_tested is not None and tested + boxes.shape[0] > max_tested:
            boundary.extend([boxes, *pending[::-1]])  # undecided, kept whole: a coarser cover
            coarse = True
            break
        tested += boxes.shape[0]
        v, scores, idle = _verdicts(test, boxes)
        unit, still = _unit_scale(d, scale), _no_idle(boxes, idle)
        kept, small, wide, wide_idle, rows = _sorted_level(boxes, v, unit, still, float(eps))
        inner.append(kept)
        boundary.append(small)
        if wide.shape[0]:
            wide_scores = scores[rows]
            if idle is not None:
                wide, wide_idle, wide_scores = _joined_idle(wide, wide_idle, wide_scores)
            budget = max_tested is not None
            if budget:  # under a budget, the lowest scores' children first
                order = np.argsort(wide_scores, kind="stable")
                wide, wide_idle = wide[order], wide_idle[order]
            splits = max(splits_per_level, _extra_splits(wide, min_level_boxes))
            pending.append(_split(wide, eps, unit, splits, grouped=budget, idle=wide_idle))
    empty = np.zeros((0, d, 2))
    return Subpaving(
        inner=np.concatenate(inner, axis=0) if inner else empty,
        boundary=np.concatenate(boundary, axis=0) if boundary else empty,
        coarse=coarse,
    )
