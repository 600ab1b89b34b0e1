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

import numpy as np

from intervals.bisection import split_rounds
from intervals.boxes import Subpaving, as_boxes, max_width, widths
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


def _contracted(contract: Contractor, boxes: np.ndarray) -> np.ndarray:
    """``boxes`` contracted, the empty rows dropped, every row kept within its input row."""
    c = np.asarray(contract(boxes), dtype=np.float64)
    if c.shape != boxes.shape:
        raise IntervalError(f"SIVIA contractor returned shape {c.shape}, expected {boxes.shape}")
    c = np.stack([np.maximum(c[..., 0], boxes[..., 0]), np.minimum(c[..., 1], boxes[..., 1])], -1)
    return c[np.all(c[..., 0] <= c[..., 1], axis=1)]  # NaN compares false: dropped too


def cut_width(boxes: np.ndarray, scale=None, idle: np.ndarray | None = None) -> np.ndarray:
    """``(N,)`` the largest scaled width of each box ``(N, d, 2)`` over its axes not ``idle
    (N, d)`` (all axes when None; 0 for a box idle along every axis)."""
    w = widths(boxes, scale)
    return np.max(np.where(idle, 0.0, w), axis=-1) if idle is not None else np.max(w, axis=-1)


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
    the children in the order of their parents; ``idle (N, d)``: the axes of each box never
    cut, inherited by its children, None: none)."""
    unit = np.ones(boxes.shape[1]) if scale is None else scale
    still = np.zeros(boxes.shape[:2], dtype=bool) if idle is None else np.asarray(idle, bool)
    out, parents = split_rounds(
        np.ascontiguousarray(boxes), float(eps), unit, int(times), np.ascontiguousarray(still)
    )
    if grouped:
        out = out[np.argsort(parents, kind="stable")]
    return out


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
    cuts are a choice, any choice keeps the set sound.
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
        inner.append(boxes[v == INSIDE])
        is_undecided = v == UNDECIDED
        undecided = boxes[is_undecided]
        still = None if idle is None else idle[is_undecided]
        small = cut_width(undecided, scale, still) <= eps
        boundary.append(undecided[small])
        wide = undecided[~small]
        if wide.shape[0]:
            wide_idle = None if still is None else still[~small]
            budget = max_tested is not None
            if budget:  # under a budget, the lowest scores' children first
                order = np.argsort(scores[is_undecided][~small], kind="stable")
                wide = wide[order]
                wide_idle = None if wide_idle is None else wide_idle[order]
            splits = max(splits_per_level, _extra_splits(wide, min_level_boxes))
            pending.append(_split(wide, eps, scale, splits, grouped=budget, idle=wide_idle))
    empty = np.zeros((0, d, 2))
    return Subpaving(
        inner=np.concatenate(inner, axis=0) if inner else empty,
        boundary=np.concatenate(boundary, axis=0) if boundary else empty,
        coarse=coarse,
    )
