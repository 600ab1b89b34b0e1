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


def unwrap_headings(boxes: np.ndarray, reference_rad: float, axis: int = 2) -> np.ndarray:
    """The same poses, each box moved by whole turns in heading so that its centre lies within
    ``pi`` of ``reference_rad`` (lets the hull of a set span the +-pi cut tightly)."""
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


def connected_components(
    boxes: np.ndarray, periodic_axis: int | None = None, period: float = 2.0 * np.pi
) -> tuple[int, np.ndarray]:
    """Connected components of the union of closed boxes ``(N, d, 2)``.

    Two boxes are connected when they overlap or touch on every axis. ``periodic_axis`` (the
    heading, axis 2 of pose boxes) is compared modulo ``period``, so boxes at ``theta = -pi``
    and ``theta = pi`` join. Returns ``(count, labels (N,))`` (labels 0..count-1).
    The overlap test is one vectorised ``(N, N, d)`` comparison; the graph search is
    ``scipy.sparse.csgraph.connected_components``.
    """
    n = boxes.shape[0]
    if n == 0:
        return 0, np.zeros(0, dtype=np.int64)
    lo, hi = boxes[:, None, :, 0], boxes[:, None, :, 1]
    lo_t, hi_t = boxes[None, :, :, 0], boxes[None, :, :, 1]
    touch = (lo <= hi_t) & (lo_t <= hi)
    if periodic_axis is not None:
        a = periodic_axis
        for shift in (-period, period):
            shifted_lo, shifted_hi = lo[..., a] + shift, hi[..., a] + shift
            touch[..., a] |= (shifted_lo <= hi_t[..., a]) & (lo_t[..., a] <= shifted_hi)
    rows, cols = np.nonzero(np.all(touch, axis=-1))
    graph = coo_matrix((np.ones(rows.size, dtype=np.int8), (rows, cols)), shape=(n, n))
    count, labels = _csgraph_components(graph, directed=False)
    return int(count), labels


@dataclass(frozen=True)
class Subpaving:
    """Result of a set inverter: non-overlapping boxes that approximate a set ``X``.

    ``inner (Ni, d, 2)``: boxes proved inside ``X``. ``boundary (Nb, d, 2)``: undecided boxes of
    width at most ``eps``. The outer approximation ``inner ∪ boundary`` contains ``X``.
    """

    inner: np.ndarray
    boundary: np.ndarray

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
