r"""Idle axes: the pose axes along which a box's sonar constraints cannot change.

For a pose box ``[x] x [y] x [theta]`` let ``R`` be the reach of the scan (the largest distance
at which a wall can matter, plus the mount radius and ``GUARD_M``, as in
:meth:`intervals.sonar.scan.SonarScan.restricted_to`) and ``W = [x - R, x + R] x [y - R, y + R]``
the region every sensor of every pose of the box sees within. Only the map's segments (and the
room boundary's edges) meeting ``W`` can decide a reading or the in-room test.

* ``x`` is idle when every such segment is horizontal (``y`` constant) and spans ``W``'s whole
  ``x`` range: moving the pose along ``x`` within the box moves no visible wall, so every
  reading's model, and the in-room test, is the same for ``(x, y, theta)`` and
  ``(x', y, theta)``. The consistent set within the box is a cylinder along ``x``, and cutting
  the box across ``x`` cannot separate consistent from inconsistent poses.
* ``y`` likewise with vertical segments spanning ``W``'s ``y`` range.
* ``theta`` (and then ``x`` and ``y``) is idle when no segment meets ``W``: no sensor of any pose
  of the box can see a wall, so every pose of the box has the same readings' model.

So the sensor verdicts of the box's slice through its centre across its idle axes (the
idle intervals collapsed to their midpoints, :func:`probes`) hold for the whole box: a
sensor rejects every pose of the slice only if it rejects every pose of the box (each has
the same readings' model as a pose of the slice), and likewise for "certainly satisfied".
The slice is tested instead of the box: a box as long as a wall is then as well decided as
a short one (the cone test of a long box is loose across it). The in-room test still sees
the box.

SIVIA never cuts a box across an idle axis (:func:`intervals.sivia.sivia`'s ``idle``): a
strip along a wall, where the set is ambiguous by nature, is held by boxes as long as the
prediction, and a box out of every wall's reach is kept whole. The choice of cuts is a
heuristic: any choice keeps the set sound (SIVIA only drops boxes the test rejects).
"""

from __future__ import annotations

import numpy as np

from intervals.sonar.geometry import GUARD_M
from intervals.sonar.scan import SonarScan

MAX_SEGMENTS = 64
"""With more segments (and boundary edges) in a scan, no axis is reported idle (the check
costs ``O(N m)`` a call; a scan restricted to a tracking set holds few)."""

BLOCK_PAIRS = 1 << 20
"""Largest number of (box, segment) pairs compared at once."""


def scan_walls(scan: SonarScan) -> np.ndarray:
    """The segments ``(m, 2, 2)`` that can decide the scan's tests: its (restricted) segments
    and the edges of the room boundary."""
    walls = [np.asarray(scan.segments, dtype=np.float64).reshape(-1, 2, 2)]
    if scan.boundary is not None:
        b = np.asarray(scan.boundary, dtype=np.float64)
        walls.append(np.stack([b, np.roll(b, -1, axis=0)], axis=1))
    return np.concatenate(walls)


def idle_axes(boxes: np.ndarray, scan: SonarScan, walls: np.ndarray | None = None) -> np.ndarray:
    """``(N, 3)`` bool: the axes ``(x, y, theta)`` of each pose box ``(N, 3, 2)`` along which the
    scan's constraints cannot change (module doc). ``walls``: :func:`scan_walls` (computed when
    None). All False when there are more than :data:`MAX_SEGMENTS` walls."""
    n = boxes.shape[0]
    idle = np.zeros((n, 3), dtype=bool)
    if walls is None:
        walls = scan_walls(scan)
    if walls.shape[0] > MAX_SEGMENTS or n == 0:
        return idle
    assert scan.scene is not None
    reach = scan.reach_m + scan.scene.mount_radius_m + GUARD_M
    lo = walls.min(axis=1)  # (m, 2) bounding boxes of the walls
    hi = walls.max(axis=1)
    flat = lo == hi  # (m, 2): [:, 1] horizontal (y constant), [:, 0] vertical
    step = max(1, BLOCK_PAIRS // max(walls.shape[0], 1))
    for start in range(0, n, step):
        b = boxes[start : start + step, :2]  # (n', 2, 2)
        w_lo, w_hi = b[:, None, :, 0] - reach, b[:, None, :, 1] + reach  # (n', 1, 2)
        meets = np.all((lo[None] <= w_hi) & (w_lo <= hi[None]), axis=2)  # (n', m)
        spans = (lo[None] <= w_lo) & (w_hi <= hi[None])  # (n', m, 2)
        for axis, other in ((0, 1), (1, 0)):
            along = flat[None, :, other] & spans[..., axis]  # the wall runs along ``axis``
            idle[start : start + step, axis] = np.all(~meets | along, axis=1)
        idle[start : start + step, 2] = ~meets.any(axis=1)
    return idle


def probes(boxes: np.ndarray, idle: np.ndarray) -> np.ndarray:
    """The boxes ``(N, 3, 2)`` with their ``idle (N, 3)`` intervals collapsed to the midpoint
    (the slices whose sensor verdicts hold for the whole box, module doc)."""
    mid = boxes[..., 0] + (boxes[..., 1] - boxes[..., 0]) / 2.0
    return np.where(idle[..., None], mid[..., None], boxes)
