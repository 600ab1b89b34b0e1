"""The in-room test of pose boxes against the map's boundary polygon.

With a boundary polygon, a box whose (x, y) rectangle meets no boundary edge (no edge within
:data:`~intervals.sonar.geometry.GUARD_M` of it, by the sound lower bound
:func:`~intervals.sonar.geometry.segment_box_gap`) and whose centre is outside the polygon lies
entirely outside the free space: rejected. When no edge meets it and the centre is inside, it
lies entirely inside. The ray cast from the centre is reliable because the centre is more than
``GUARD_M`` from every edge. The compiled kernel (``room_verdicts_into`` of
:mod:`intervals.sonar.cone_kernel`) performs the numpy reference's operations in the same
order (same verdicts, tested).
"""

from __future__ import annotations

import numpy as np

from intervals.sonar import cone_kernel
from intervals.sonar.engines import Engine
from intervals.sonar.geometry import GUARD_M, NEAR_SWITCH_M, segment_box_gap


def room_verdicts(
    boxes: np.ndarray, boundary: np.ndarray, engine: str
) -> tuple[np.ndarray, np.ndarray]:
    """``(outside (N,), inside (N,))``: the (x, y) rectangle lies entirely outside / inside the
    boundary polygon: no edge comes within ``GUARD_M`` of it (sound lower bound of the
    distance) and the ray cast from its centre says outside / inside. ``engine`` as in
    :func:`intervals.sonar.cone.sensor_verdicts` (the numpy code below is the reference)."""
    if engine == Engine.COMPILED:
        n = boxes.shape[0]
        outside, inside = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        cone_kernel.room_verdicts_into(
            np.ascontiguousarray(boxes, dtype=np.float64),
            boundary,
            GUARD_M,
            NEAR_SWITCH_M,
            outside,
            inside,
        )
        return outside, inside
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
