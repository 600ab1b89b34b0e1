"""The numpy reference of the in-room test (:mod:`intervals.sonar.room`): tests and benchmarks only."""

from __future__ import annotations

import numpy as np

from intervals.sonar.geometry import GUARD_M, segment_box_gap


def room_verdicts(boxes: np.ndarray, boundary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`intervals.sonar.room.room_verdicts` evaluated with numpy over (box, edge) arrays:
    ``(outside (N,), inside (N,))``."""
    a = boundary
    e = np.roll(boundary, -1, axis=0) - a
    cx = ((boxes[:, 0, 0] + boxes[:, 0, 1]) / 2.0)[:, None]
    cy = ((boxes[:, 1, 0] + boxes[:, 1, 1]) / 2.0)[:, None]
    hx = ((boxes[:, 0, 1] - boxes[:, 0, 0]) / 2.0)[:, None]
    hy = ((boxes[:, 1, 1] - boxes[:, 1, 0]) / 2.0)[:, None]
    gap = segment_box_gap(a[:, 0], a[:, 1], e[:, 0], e[:, 1], cx, cy, hx, hy)
    clear = np.all(gap > GUARD_M, axis=1)
    # ray casting to +x; reliable because the centre is more than GUARD_M from every edge
    ay, by = a[:, 1], a[:, 1] + e[:, 1]
    crosses = (ay > cy) != (by > cy)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = a[:, 0] + (cy - ay) * e[:, 0] / e[:, 1]
    inside = (np.count_nonzero(crosses & (x_cross > cx), axis=1) % 2) == 1
    return clear & ~inside, clear & inside
