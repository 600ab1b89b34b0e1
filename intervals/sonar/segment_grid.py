r"""A uniform grid over the map's segments: the segments within reach of a place, not the map.

Each segment is cut into pieces no longer than a cell, and registered in every cell that the
bounding box of a piece (widened by :data:`PIECE_MARGIN_M`) meets. :meth:`SegmentGrid.near`
(and the loop of the compiled cone test, :mod:`intervals.sonar.cone_kernel`) gathers the
segments registered in the cells that a query square meets, widened by one cell on each side.

Soundness: no segment within reach is ever left out. Write ``k(v) = floor(fl((v - o) / C))``
for the float-computed cell index of a coordinate ``v`` (origin ``o``, cell size ``C``);
``k`` is non-decreasing in ``v``, since the rounded subtraction, the rounded division by
``C > 0`` and ``floor`` all are. Let ``q`` be a point of segment ``j`` within Euclidean
distance ``r`` of a query centre ``c``. (i) The pieces are ``a + [t_p, t_{p + 1}] e`` with the
float ``t_p = p / n`` shared by neighbours, so they cover the segment and ``q`` lies in one;
its computed ends are off by a few ulps of the coordinates (below ``1e-12`` m for ``|.| <=
1e3`` m), so the piece lies in its computed bounding box widened by ``PIECE_MARGIN_M = 1e-9``
m, ``[b_lo, b_hi]``; hence ``k(b_lo) <= k(q) <= k(b_hi)`` on each axis: ``j`` is registered
in the cell ``(k(q_x), k(q_y))``, which lies inside the grid. (ii) ``|q - c| <= r`` gives ``c - r <=
q <= c + r`` on each axis; the computed bounds ``fl(c -+ r)`` are off by at most one ulp of
their magnitude (at most ``1e3`` m), which moves ``(v - o) / C`` by less than one, so
``k(fl(c - r)) - 1 <= k(q) <= k(fl(c + r)) + 1``: the widened cell range, clipped to the grid,
holds ``q``'s cell. Hence every segment with a point within ``r`` of ``c`` is gathered.

The box tests keep a segment when a lower bound of its distance to the hull of the sensor
boxes (centre ``c``, half-widths ``h``; ``segment_box_gap``) is at most the reach ``R``. That
bound is ``|q* - c| - s`` with ``q*`` the segment point nearest ``c`` and ``s <= |h|``, so a kept
segment has a point within ``R + |h|`` of ``c``: the grid queried with ``r = R + |h|`` gathers
every segment the box tests would keep (they then decide exactly as over the whole map: their
verdicts are the same, checked in ``tests/intervals/test_segment_grid.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CELL_M = 1.0
"""Cell size (metres) of the grid: a query of the sonar's reach (3 m) plus a pose box meets a
few tens of cells, each holding a few segments."""

PIECE_MARGIN_M = 1e-9
"""Widening of the pieces' bounding boxes, far above the float error of their ends."""

MAX_CELLS_PER_AXIS = 1024
"""Larger maps get larger cells (the grid never holds more than about a million cells)."""


@dataclass(frozen=True, eq=False)
class SegmentGrid:
    """Segments ``(m, 2, 2)`` registered in a uniform grid of ``shape = (nx, ny)`` cells of
    ``cell_m`` metres from ``origin (2,)``: cell ``(ix, iy)`` (flat index ``ix * ny + iy``)
    holds ``members[starts[f]:starts[f + 1]]`` (segment indices, int64)."""

    origin: np.ndarray
    cell_m: float
    shape: tuple[int, int]
    starts: np.ndarray
    members: np.ndarray

    @classmethod
    def build(cls, segments: np.ndarray, cell_m: float = CELL_M) -> SegmentGrid:
        """The grid of ``segments (m, 2, 2)`` (m >= 0; finite coordinates)."""
        m = segments.shape[0]
        if m == 0:
            empty = np.zeros(0, dtype=np.int64)
            return cls(np.zeros(2), float(cell_m), (1, 1), np.zeros(2, dtype=np.int64), empty)
        origin = segments.min(axis=(0, 1)) - 2.0 * PIECE_MARGIN_M  # below every widened piece
        extent = float(np.max(segments.max(axis=(0, 1)) - origin)) + PIECE_MARGIN_M
        cell_m = max(float(cell_m), extent / (MAX_CELLS_PER_AXIS - 1))
        # pieces of at most one cell: a long slanted wall is registered along itself only
        e = segments[:, 1] - segments[:, 0]
        count = np.maximum(np.ceil(np.hypot(e[:, 0], e[:, 1]) / cell_m), 1).astype(np.int64)
        segment = np.repeat(np.arange(m), count)
        p = np.arange(segment.size) - np.repeat(np.cumsum(count) - count, count)
        t0, t1 = p / count[segment], (p + 1) / count[segment]
        ends = np.stack(
            [segments[segment, 0] + t[:, None] * e[segment] for t in (t0, t1)], axis=1
        )  # (pieces, 2, 2)
        lo, hi = ends.min(axis=1) - PIECE_MARGIN_M, ends.max(axis=1) + PIECE_MARGIN_M
        first, last = _index(lo, origin, cell_m), _index(hi, origin, cell_m)  # (pieces, 2)
        nx, ny = (int(v) + 1 for v in last.max(axis=0))
        span = last - first + 1
        per_piece = span[:, 0] * span[:, 1]
        piece = np.repeat(np.arange(segment.size), per_piece)
        offset = np.arange(piece.size) - np.repeat(np.cumsum(per_piece) - per_piece, per_piece)
        ix = first[piece, 0] + offset // span[piece, 1]
        iy = first[piece, 1] + offset % span[piece, 1]
        # each (cell, segment) once, sorted by cell
        pairs = np.unique((ix * ny + iy) * m + segment[piece])
        flat, members = pairs // m, pairs % m
        starts = np.searchsorted(flat, np.arange(nx * ny + 1))
        return cls(origin, cell_m, (nx, ny), starts.astype(np.int64), members.astype(np.int64))

    def cell_ranges(self, centre: np.ndarray, radius) -> np.ndarray:
        """``(..., 2, 2)`` int64 inclusive cell-index ranges ``[[ix0, ix1], [iy0, iy1]]`` of the
        squares ``centre (..., 2) -+ radius (...)``, widened by one cell and clipped to the grid
        (see the module doc)."""
        r = np.asarray(radius, dtype=np.float64)[..., None]
        first = _index(centre - r, self.origin, self.cell_m) - 1
        last = _index(centre + r, self.origin, self.cell_m) + 1
        top = np.array(self.shape) - 1
        return np.stack([np.clip(first, 0, top), np.clip(last, 0, top)], axis=-1)

    def near(self, centre, radius: float) -> np.ndarray:
        """Sorted indices ``(K,)`` of the segments registered in the cells of the square
        ``centre (2,) -+ radius``: every segment with a point within ``radius`` of ``centre``
        is among them (see the module doc)."""
        (ix0, ix1), (iy0, iy1) = self.cell_ranges(np.asarray(centre, dtype=np.float64), radius)
        ny = self.shape[1]
        rows = np.arange(ix0, ix1 + 1) * ny
        begin, end = self.starts[rows + iy0], self.starts[rows + iy1 + 1]
        counts = end - begin
        picks = np.repeat(begin - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
        return np.unique(self.members[picks])


def _index(v: np.ndarray, origin: np.ndarray, cell_m: float) -> np.ndarray:
    """Cell indices ``floor((v - origin) / cell_m)`` (int64, float-computed: non-decreasing)."""
    return np.floor((v - origin) / cell_m).astype(np.int64)
