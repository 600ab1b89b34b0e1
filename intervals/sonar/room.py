"""The in-room test of pose boxes against the map's boundary polygon.

With a boundary polygon, a box whose (x, y) rectangle meets no boundary edge (no edge within
:data:`~intervals.sonar.geometry.GUARD_M` of it, by the sound lower bound
:func:`~intervals.sonar.geometry.segment_box_gap`) and whose centre is outside the polygon lies
entirely outside the free space: rejected. When no edge meets it and the centre is inside, it
lies entirely inside. The ray cast from the centre is reliable because the centre is more than
``GUARD_M`` from every edge. The compiled kernel (``room_verdicts_into`` of
:mod:`intervals.sonar.cone_kernel`) performs the operations of the numpy reference
(:mod:`intervals.sonar.reference.room`) in the same order (same verdicts, tested).
"""

from __future__ import annotations

import numpy as np

from intervals.sonar import cone_kernel
from intervals.sonar.geometry import GUARD_M, NEAR_SWITCH_M


def room_verdicts(boxes: np.ndarray, boundary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(outside (N,), inside (N,))``: the (x, y) rectangle lies entirely outside / inside the
    boundary polygon ``(p, 2)`` m: no edge comes within ``GUARD_M`` of it (sound lower bound of
    the distance) and the ray cast from its centre says outside / inside."""
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
