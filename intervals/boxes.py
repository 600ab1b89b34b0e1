"""Box arrays ``(N, d, 2)`` and subpavings.

A box is an array ``(d, 2)`` of intervals (``[:, 0]`` lower, ``[:, 1]`` upper bounds); many
boxes are an array ``(N, d, 2)``. Pose boxes are ``(N, 3, 2)`` for ``(x_m, y_m, theta_rad)``.

To compare a heading width with position widths, widths are multiplied by a per-axis
``scale`` (metres per unit of the axis: 1 for x and y, ``heading_scale_m_per_rad`` for theta).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components as _csgraph_components
from scipy.spatial import cKDTree

from intervals.errors import IntervalError

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


def bisect(boxes: np.ndarray, scale: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Bisect every box ``(N, d, 2)`` at the middle of its widest scaled dimension.

    Returns ``(left, right)``, each ``(N, d, 2)``; they share the cut value, so their union is
    exactly the parent box.
    """
    n = boxes.shape[0]
    axis = np.argmax(widths(boxes, scale), axis=-1)
    rows = np.arange(n)
    cut = centres(boxes)[rows, axis]
    left, right = boxes.copy(), boxes.copy()
    left[rows, axis, 1] = cut
    right[rows, axis, 0] = cut
    return left, right


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


def _nudge(x, direction: int, ulps: int = 2):
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
    out[:, axis, 0] = np.where(moved, _nudge(boxes[:, axis, 0] - shift, -1), boxes[:, axis, 0])
    out[:, axis, 1] = np.where(moved, _nudge(boxes[:, axis, 1] - shift, 1), boxes[:, axis, 1])
    return out


def unwrap_headings(
    boxes: np.ndarray, reference_rad: float | np.ndarray, axis: int = 2
) -> np.ndarray:
    """The same poses, each box moved by whole turns in heading so that its centre lies within
    ``pi`` of ``reference_rad`` (one for all, or one per box ``(N,)``; lets the hull of a set
    span the +-pi cut tightly)."""
    centre = (boxes[:, axis, 0] + boxes[:, axis, 1]) / 2.0
    return _shift_turns(boxes, np.round((centre - reference_rad) / (2.0 * np.pi)), axis)


def wrap_headings(boxes: np.ndarray, axis: int = 2) -> np.ndarray:
    """The same poses with every heading interval within ``[-pi, pi]`` (outward rounded).

    Each box is moved by whole turns so that its lower heading lies in ``[-pi, pi)``; a box
    then reaching above ``pi`` is split at ``pi`` into two boxes (``[lo, pi]`` and
    ``[-pi, hi - 2 pi]``); a box at least ``2 pi`` wide becomes ``[-pi, pi]``.
    """
    full = boxes[:, axis, 1] - boxes[:, axis, 0] >= 2.0 * np.pi
    out = _shift_turns(boxes, np.floor((boxes[:, axis, 0] + np.pi) / (2.0 * np.pi)), axis)
    pi_up, pi_down = _nudge(np.pi, 1), _nudge(-np.pi, -1)
    hi = out[:, axis, 1].copy()
    out[:, axis, 0] = np.where(full, pi_down, np.maximum(out[:, axis, 0], pi_down))
    out[:, axis, 1] = np.where(full, pi_up, np.minimum(hi, pi_up))
    crossing = ~full & (hi > pi_up)
    extra = out[crossing].copy()
    extra[:, axis, 0] = pi_down
    extra[:, axis, 1] = _nudge(hi[crossing] - 2.0 * np.pi, 1)
    return np.concatenate([out, extra], axis=0)


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

    Exact union (not the sum): the projections are rasterised on the grid of their own edge
    coordinates with a 2-D difference array, so overlapping projections count once.
    """
    if boxes.shape[0] == 0:
        return 0.0
    xs = np.unique(boxes[:, 0, :])
    ys = np.unique(boxes[:, 1, :])
    i0, i1 = np.searchsorted(xs, boxes[:, 0, 0]), np.searchsorted(xs, boxes[:, 0, 1])
    j0, j1 = np.searchsorted(ys, boxes[:, 1, 0]), np.searchsorted(ys, boxes[:, 1, 1])
    cover = np.zeros((xs.size + 1, ys.size + 1), dtype=np.int64)
    np.add.at(cover, (i0, j0), 1)
    np.add.at(cover, (i1, j0), -1)
    np.add.at(cover, (i0, j1), -1)
    np.add.at(cover, (i1, j1), 1)
    covered = np.cumsum(np.cumsum(cover, axis=0), axis=1)[:-2, :-2] > 0
    cell_area = np.outer(np.diff(xs), np.diff(ys))
    return float(np.sum(cell_area[covered]))


COMPONENT_BRUTE_FORCE_BOXES = 64
"""Box sets up to this size are compared all pairs with all pairs by
:func:`touching_pairs` (a tree costs more than it saves)."""

_CANDIDATE_MARGIN = 1e-3
"""Relative slack of the candidate search of :func:`touching_pairs`, far above its float
error (see there)."""


def _touch_on_axis(lo_a, hi_a, lo_b, hi_b, periodic: bool, period: float) -> np.ndarray:
    """Closed intervals ``[lo_a, hi_a]`` and ``[lo_b, hi_b]`` meet (``periodic``: also with the
    first shifted by ``-period`` or ``+period``)."""
    touch = (lo_a <= hi_b) & (lo_b <= hi_a)
    if periodic:
        for shift in (-period, period):
            touch |= (lo_a + shift <= hi_b) & (lo_b <= hi_a + shift)
    return touch


def _touching(boxes, i, j, periodic_axis, period) -> np.ndarray:
    """``(P,)`` bool: boxes ``i[p]`` and ``j[p]`` touch on every axis (the exact test)."""
    touch = np.ones(i.shape, dtype=bool)
    for axis in range(boxes.shape[1]):
        touch &= _touch_on_axis(
            boxes[i, axis, 0],
            boxes[i, axis, 1],
            boxes[j, axis, 0],
            boxes[j, axis, 1],
            axis == periodic_axis,
            period,
        )
    return touch


def touching_pairs(
    boxes: np.ndarray, periodic_axis: int | None = None, period: float = 2.0 * np.pi
) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of touching boxes of ``(N, d, 2)``: ``(i (P,), j (P,))`` int64 with ``i < j``
    (closed intervals meeting on every axis, the ``periodic_axis`` also shifted by
    ``-+period``; each pair once, in no particular order).

    Candidates come from a k-d tree (``scipy.spatial.cKDTree``) and are then decided by the
    exact test. Two boxes with centres ``c`` and half-widths ``h`` touch only if ``|c_i - c_j|
    <= h_i + h_j`` on every axis. The "small" boxes, no wider than twice the median half-width
    on any axis, have ``h <= H`` (their largest half-widths, per axis); scaled by ``1 / (2 H)``
    per axis, two touching small boxes are within Chebyshev distance 1, which
    ``query_pairs`` finds (the periodic axis as a torus, ``boxsize``). A wider box ``b`` can only
    touch small boxes within ``max_a (h_b + H) / (2 H)`` of it (``query_ball_point``); the wider
    boxes among themselves are paired by the same method, recursively, or by a sweep along
    the first non-periodic axis when they are more than half of the boxes. Float errors: the
    computed centres and half-widths are off by a few ulps of the largest coordinate ``M``,
    and ``H`` is taken at least ``1e-9 (1 + M)``, so the scaled distances of touching boxes
    exceed their bound by far less than the search radius' slack :data:`_CANDIDATE_MARGIN`:
    no touching pair is missed. For pavings (boxes of similar sizes, each touching a few
    neighbours) the time is ``O(N log N)`` and the memory ``O(N)``.
    """
    n = boxes.shape[0]
    if n <= COMPONENT_BRUTE_FORCE_BOXES:
        i, j = np.triu_indices(n, 1)
        keep = _touching(boxes, i, j, periodic_axis, period)
        return i[keep].astype(np.int64), j[keep].astype(np.int64)
    centre = (boxes[..., 0] + boxes[..., 1]) / 2.0
    half = (boxes[..., 1] - boxes[..., 0]) / 2.0
    small = np.all(half <= 2.0 * np.median(half, axis=0), axis=1)
    wide = np.flatnonzero(~small)
    if 2 * wide.size > n:
        return sweep_pairs(boxes, periodic_axis, period)
    narrow = np.flatnonzero(small)
    extent = 1.0 + float(np.max(np.abs(boxes)))
    reach = np.maximum(half[narrow].max(axis=0), 1e-9 * extent)  # H, per axis
    scale = 1.0 / (2.0 * reach)
    points = centre * scale
    size = np.zeros(boxes.shape[1])  # 0: not periodic
    if periodic_axis is not None:
        torus = period * scale[periodic_axis]
        wrapped = np.mod(points[:, periodic_axis], torus)
        points[:, periodic_axis] = np.where(wrapped < torus, wrapped, 0.0)
        size[periodic_axis] = torus
    tree = cKDTree(points[narrow], boxsize=size)
    radius = 1.0 + _CANDIDATE_MARGIN
    found = tree.query_pairs(radius, p=np.inf, output_type="ndarray")
    firsts, seconds = [narrow[found[:, 0]]], [narrow[found[:, 1]]]
    if wide.size:
        ball = np.max((half[wide] + reach) * scale, axis=1) * radius
        near = tree.query_ball_point(points[wide], ball, p=np.inf, return_sorted=False)
        counts = np.array([len(found) for found in near], dtype=np.int64)
        firsts.append(np.repeat(wide, counts))
        seconds.append(narrow[np.concatenate([np.asarray(f, dtype=np.int64) for f in near])])
        among_i, among_j = touching_pairs(boxes[wide], periodic_axis, period)
        firsts.append(wide[among_i])
        seconds.append(wide[among_j])
    i, j = np.concatenate(firsts), np.concatenate(seconds)
    i, j = np.minimum(i, j), np.maximum(i, j)
    keep = _touching(boxes, i, j, periodic_axis, period)
    return i[keep].astype(np.int64), j[keep].astype(np.int64)


def sweep_pairs(boxes, periodic_axis, period) -> tuple[np.ndarray, np.ndarray]:
    """:func:`touching_pairs` by sweep and prune along the first non-periodic axis (boxes
    sorted by lower bound: each meets, on that axis, the boxes after it whose lower bound is at
    most its upper bound; with one periodic axis alone, also their copies shifted by
    ``-+period``). ``O(N log N + C)`` for ``C`` candidate pairs on that axis."""
    n, d = boxes.shape[0], boxes.shape[1]
    axis = next((a for a in range(d) if a != periodic_axis), 0)
    lo, hi = boxes[:, axis, 0], boxes[:, axis, 1]
    owner = np.arange(n)
    if axis == periodic_axis:
        owner = np.tile(owner, 3)
        shift = np.repeat([0.0, -period, period], n)
        lo, hi = np.tile(lo, 3) + shift, np.tile(hi, 3) + shift
    order = np.argsort(lo, kind="stable")
    ends = np.searchsorted(lo[order], hi[order], side="right")
    counts = ends - np.arange(order.size) - 1
    first = np.repeat(np.arange(order.size), counts)
    second = first + 1 + np.arange(first.size) - np.repeat(np.cumsum(counts) - counts, counts)
    i, j = owner[order[first]], owner[order[second]]
    i, j = np.minimum(i, j), np.maximum(i, j)
    keep = (i != j) & _touching(boxes, i, j, periodic_axis, period)
    return i[keep], j[keep]


def connected_components(
    boxes: np.ndarray, periodic_axis: int | None = None, period: float = 2.0 * np.pi
) -> tuple[int, np.ndarray]:
    """Connected components of the union of closed boxes ``(N, d, 2)``.

    Two boxes are connected when they overlap or touch on every axis (closed intervals: a
    shared corner connects). ``periodic_axis`` (the heading, axis 2 of pose boxes) is compared
    modulo ``period`` as well (intervals also shifted by ``-+period``), so boxes at
    ``theta = -pi`` and ``theta = pi`` join. Returns ``(count, labels (N,))``, labels
    ``0..count-1`` numbered in the order of each component's first box. The touching pairs
    come from :func:`touching_pairs` (``O(N log N)`` for pavings, never an ``N x N`` array),
    the components from ``scipy.sparse.csgraph.connected_components``.
    """
    n = boxes.shape[0]
    if n == 0:
        return 0, np.zeros(0, dtype=np.int64)
    i, j = touching_pairs(boxes, periodic_axis, period)
    graph = coo_matrix((np.ones(i.size, dtype=np.int8), (i, j)), shape=(n, n))
    count, labels = _csgraph_components(graph, directed=False)
    _, first_box, inverse = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(first_box.size, dtype=np.int64)
    rank[np.argsort(first_box, kind="stable")] = np.arange(first_box.size)
    return int(count), rank[inverse]


def merge_adjacent(boxes: np.ndarray, rounds: int = 2) -> np.ndarray:
    """The same union in fewer boxes, exactly: along each axis in turn, every run of boxes
    with identical bounds on the other axes, each starting where the one before it ends on
    this axis (``hi == lo``, in floating point), becomes one box from the run's first lower
    bound to its last upper bound; ``rounds`` passes over the axes (fewer when a pass merges
    nothing). ``O(N log N)`` a pass (a lexicographic sort). Siblings SIVIA kept both of merge
    back into their parent, so a strip where the set is ambiguous (a corridor, along its
    axis) is held by a few long boxes instead of a row of ``eps`` cells."""
    d = boxes.shape[1]
    for _ in range(rounds):
        before = boxes.shape[0]
        for axis in range(d):
            if boxes.shape[0] < 2:
                return boxes
            others = [a for a in range(d) if a != axis]
            keys = [boxes[:, axis, 0]] + [boxes[:, a, k] for a in others for k in (0, 1)]
            b = boxes[np.lexsort(keys)]  # by the other axes' bounds, then by lower bound
            joined = np.all(b[1:, others] == b[:-1, others], axis=(1, 2))
            joined &= b[1:, axis, 0] == b[:-1, axis, 1]
            first = np.flatnonzero(np.concatenate([[True], ~joined]))
            last = np.append(first[1:] - 1, b.shape[0] - 1)
            boxes = b[first].copy()
            boxes[:, axis, 1] = b[last, axis, 1]
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
        """Connected components of the outer boxes (heading axis periodic by default)."""
        outer = self.outer
        use = periodic_axis is not None and outer.shape[1] > periodic_axis
        axis = periodic_axis if use else None
        return connected_components(outer, periodic_axis=axis)
