"""IMAGESP: image of a subpaving through an inclusion function (paper 002 section 3.2).

The input set, given as boxes ``(N, d, 2)``, is first cut into boxes no wider than ``eps``
(scaled widths); each small box is mapped through an inclusion function ``f`` (an enclosure of
the image of every box: ``f([x]) ⊇ {f(x) : x in [x]}``); the image boxes are then merged into a
*regular* subpaving: the cells of a grid of pitch ``eps / scale`` (per axis) anchored at
``origin`` that meet some image box. The union of those cells contains ``f(X)``.

In the tracker the inclusion function is the motion bound (previous pose box -> every pose
reachable within one epoch); the result is then contracted by SIVIA with the sonar test.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from intervals.boxes import as_boxes, bisect, hull, max_width, widths
from intervals.errors import IntervalError

InclusionFunction = Callable[[np.ndarray], np.ndarray]
"""``f(boxes (N, d, 2)) -> (N, e, 2)`` enclosing the image of each box."""

DEFAULT_MAX_CELLS = 2_000_000
"""Number of grid cells at which IMAGESP stops with an error instead of exhausting memory."""


def _down(x):
    return np.nextafter(x, -np.inf)


def _up(x):
    return np.nextafter(x, np.inf)


def refine(boxes: np.ndarray, eps: float, scale: np.ndarray | None = None) -> np.ndarray:
    """Bisect boxes ``(N, d, 2)`` until every scaled width is at most ``eps`` (same union)."""
    done, todo = [], boxes
    while todo.shape[0]:
        small = max_width(todo, scale) <= eps
        done.append(todo[small])
        left, right = bisect(todo[~small], scale)
        todo = np.concatenate([left, right], axis=0)
    return np.concatenate(done, axis=0)


def grid_cells(
    images: np.ndarray,
    pitch: np.ndarray,
    origin: np.ndarray,
    max_cells: int = DEFAULT_MAX_CELLS,
) -> np.ndarray:
    """Cells ``(M, e, 2)`` of the grid ``origin + k * pitch`` that meet the boxes ``images``.

    Cell bounds are computed in floating point and rounded outward, and each image box's index
    range is extended until the (rounded) cells cover it, so the union of cells contains the
    union of the images. Duplicates are merged (:func:`unique_rows` on integer cell indices).
    """
    lo_idx = np.floor((images[..., 0] - origin) / pitch).astype(np.int64)
    hi_idx = np.floor((images[..., 1] - origin) / pitch).astype(np.int64)
    lo_idx -= (origin + lo_idx * pitch > images[..., 0]).astype(np.int64)
    hi_idx += (origin + (hi_idx + 1) * pitch < images[..., 1]).astype(np.int64)
    counts = hi_idx - lo_idx + 1  # (N, e)
    per_box = np.prod(counts, axis=-1)
    total = int(per_box.sum())
    if total > max_cells:
        raise IntervalError(
            f"IMAGESP: the images cover {total} grid cells, more than max_cells={max_cells}; "
            "raise eps or tighten the inclusion function"
        )
    owner = np.repeat(np.arange(images.shape[0]), per_box)
    offset = np.arange(total) - np.repeat(np.cumsum(per_box) - per_box, per_box)
    # mixed-radix decomposition of the offset into per-axis cell offsets
    idx = np.empty((total, images.shape[1]), dtype=np.int64)
    rest = offset
    for axis in range(images.shape[1] - 1, -1, -1):
        c = counts[owner, axis]
        idx[:, axis] = lo_idx[owner, axis] + rest % c
        rest = rest // c
    idx = unique_rows(idx)
    return np.stack([_down(origin + idx * pitch), _up(origin + (idx + 1) * pitch)], axis=-1)


def unique_rows(idx: np.ndarray) -> np.ndarray:
    """The distinct rows of ``idx (M, e)`` int64 in lexicographic order (what
    ``np.unique(idx, axis=0)`` returns, about five times faster: a lexicographic sort of the
    columns instead of a sort of the rows as opaque records)."""
    ordered = idx[np.lexsort(idx.T[::-1])]
    fresh = np.ones(ordered.shape[0], dtype=bool)
    np.any(ordered[1:] != ordered[:-1], axis=1, out=fresh[1:])
    return ordered[fresh]


def imagesp(
    f: InclusionFunction,
    boxes: np.ndarray,
    eps: float,
    scale: np.ndarray | None = None,
    origin: np.ndarray | None = None,
    max_cells: int = DEFAULT_MAX_CELLS,
    pitch: np.ndarray | None = None,
) -> np.ndarray:
    """Regular subpaving ``(M, e, 2)`` at ``eps`` enclosing ``f(union of boxes)``.

    ``boxes``: ``(N, d, 2)`` (or one box ``(d, 2)``), cut to width ``eps`` before mapping.
    ``scale (e,)``: per-axis scale of the output (grid pitch ``eps / scale``; the same scale is
    used to cut the input, so ``d == e`` is expected when it is given). ``origin (e,)``: grid
    anchor (default 0). ``pitch (e,)``: grid pitch when coarser cells are wanted (e.g. to be
    contracted by SIVIA afterwards; default ``eps / scale``).
    Raises :class:`IntervalError` for ``eps <= 0``, a NaN or unbounded
    input box, an inclusion function that returns a bad shape or NaN, or more than
    ``max_cells`` input pieces or output cells (checked before they are made).
    """
    if not np.isfinite(eps) or eps <= 0:
        raise IntervalError(f"IMAGESP: eps must be a positive finite width, got {eps!r}")
    boxes = as_boxes(boxes, "IMAGESP boxes")
    if not np.all(np.isfinite(boxes)):
        raise IntervalError("IMAGESP: input boxes must be bounded")
    scale_d = np.ones(boxes.shape[1]) if scale is None else np.asarray(scale, dtype=np.float64)
    with np.errstate(divide="ignore"):
        halvings = np.ceil(np.log2(np.maximum(widths(boxes, scale_d) / eps, 1.0)))
    if np.sum(np.exp2(halvings.sum(axis=-1))) > max_cells:  # the pieces refine would make
        raise IntervalError(
            f"IMAGESP: cutting the input to eps makes more than max_cells={max_cells} boxes; "
            "raise eps or shrink the input"
        )
    small = refine(boxes, eps, scale)
    images = np.asarray(f(small), dtype=np.float64)
    if images.ndim != 3 or images.shape[0] != small.shape[0] or images.shape[-1] != 2:
        raise IntervalError(f"IMAGESP: inclusion function returned shape {images.shape}")
    if not np.all(np.isfinite(images)):
        raise IntervalError("IMAGESP: inclusion function returned NaN or unbounded boxes")
    e = images.shape[1]
    scale_e = np.ones(e) if scale is None else np.asarray(scale, dtype=np.float64)
    origin_e = np.zeros(e) if origin is None else np.asarray(origin, dtype=np.float64)
    pitch_e = eps / scale_e if pitch is None else np.asarray(pitch, dtype=np.float64)
    if pitch_e.shape != (e,) or np.any(~(pitch_e > 0)) or not np.all(np.isfinite(pitch_e)):
        raise IntervalError(f"IMAGESP: the grid pitch must be {e} positive numbers, got {pitch_e}")
    return grid_cells(images, pitch_e, origin_e, max_cells)


def coarsen(boxes: np.ndarray, max_count: int, scale: np.ndarray | None = None) -> np.ndarray:
    """At most ``max_count`` boxes ``(M, d, 2)`` whose union holds the union of ``boxes (N, d,
    2)``: the boxes themselves if few enough, else the cells of a regular grid that meet them
    (:func:`grid_cells`: outward rounded, no two cells overlap), the pitch starting at the
    median scaled width and doubled until few enough boxes remain (the boxes wider than the
    pitch kept as they are, beside the cells: a few large boxes, such as those a paving keeps
    whole, do not make the grid as coarse as they are wide); the hull, one box, if even a
    grid as wide as the set has too many (``max_count < 2^d``). ``scale (d,)`` as in
    :func:`imagesp` (the pitch is ``p / scale`` per axis). Each step costs ``O(N log N)`` and
    holds at most ``3^d N`` cells (at a pitch no smaller than its width a box meets two cells
    per axis, one more where the outward rounding extends its range)."""
    if boxes.shape[0] <= max_count:
        return boxes
    d = boxes.shape[1]
    scale_d = np.ones(d) if scale is None else np.asarray(scale, dtype=np.float64)
    origin = boxes[..., 0].min(axis=0)
    extent = float(np.max(widths(hull(boxes)[None], scale_d)))
    box_widths = np.max(widths(boxes, scale_d), axis=-1)
    pitch = float(np.median(box_widths))
    while pitch <= 2.0 * extent and pitch > 0.0:
        large = box_widths > pitch
        small = boxes[~large]
        cells = grid_cells(small, pitch / scale_d, origin, max_cells=(3**d) * small.shape[0])
        if cells.shape[0] + np.count_nonzero(large) <= max_count:
            return np.concatenate([cells, boxes[large]])
        pitch *= 2.0
    return hull(boxes)[None]
