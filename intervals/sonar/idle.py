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

SIVIA never cuts a box across an idle axis (:func:`intervals.sivia.sivia`'s ``idle``), and
joins back the undecided boxes that a cut made before the test could tell separates only
across one: a strip along a wall, where the set is ambiguous by nature, is held by boxes as
long as the prediction, and a box out of every wall's reach is kept whole. The choice of cuts is a
heuristic: any choice keeps the set sound (SIVIA only drops boxes the test rejects).
"""

from __future__ import annotations

import numba
import numpy as np

from intervals.sonar.geometry import GUARD_M
from intervals.sonar.scan import SonarScan

MAX_SEGMENTS = 64
"""With more segments (and boundary edges) in a scan, no axis is reported idle (the check
costs ``O(N m)`` a call; a scan restricted to a tracking set holds few)."""


def scan_walls(scan: SonarScan) -> np.ndarray:
    """The segments ``(m, 2, 2)`` that can decide the scan's tests: its (restricted) segments
    and the edges of the room boundary."""
    walls = [np.asarray(scan.segments, dtype=np.float64).reshape(-1, 2, 2)]
    if scan.boundary is not None:
        b = np.asarray(scan.boundary, dtype=np.float64)
        walls.append(np.stack([b, np.roll(b, -1, axis=0)], axis=1))
    return np.concatenate(walls)


@numba.njit(cache=True)
def _idle_into(boxes, lo, hi, reach, idle):
    """Fill ``idle (N, 3)`` (False on entry) for the pose boxes ``(N, 3, 2)`` and the walls'
    bounding boxes ``lo, hi (m, 2)``, ``reach`` m (module doc). One pass over the walls a box,
    left at the first wall in reach that keeps neither ``x`` nor ``y`` idle (an oblique wall,
    or one not spanning ``W``), which decides most boxes near walls after a few walls."""
    for i in range(boxes.shape[0]):
        w_lo_x, w_hi_x = boxes[i, 0, 0] - reach, boxes[i, 0, 1] + reach
        w_lo_y, w_hi_y = boxes[i, 1, 0] - reach, boxes[i, 1, 1] + reach
        along_x, along_y, seen = True, True, False
        for j in range(lo.shape[0]):
            if lo[j, 0] > w_hi_x or w_lo_x > hi[j, 0] or lo[j, 1] > w_hi_y or w_lo_y > hi[j, 1]:
                continue  # the wall does not meet W
            seen = True
            # x stays idle if the wall is horizontal and spans W's x range; y likewise
            along_x = along_x and lo[j, 1] == hi[j, 1] and lo[j, 0] <= w_lo_x and w_hi_x <= hi[j, 0]
            along_y = along_y and lo[j, 0] == hi[j, 0] and lo[j, 1] <= w_lo_y and w_hi_y <= hi[j, 1]
            if not (along_x or along_y):
                break
        idle[i, 0], idle[i, 1], idle[i, 2] = along_x, along_y, not seen


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
    lo = np.ascontiguousarray(walls.min(axis=1))  # (m, 2) bounding boxes of the walls
    hi = np.ascontiguousarray(walls.max(axis=1))
    _idle_into(np.ascontiguousarray(boxes, dtype=np.float64), lo, hi, float(reach), idle)
    return idle


@numba.njit(cache=True)
def _collapsed(boxes, idle):
    """:func:`probes` of ``boxes (N, d, 2)`` and ``idle (N, d)``: each idle interval
    ``[lo, hi]`` becomes ``[m, m]``, ``m = lo + (hi - lo) / 2``."""
    out = boxes.copy()
    for i in range(boxes.shape[0]):
        for a in range(boxes.shape[1]):
            if idle[i, a]:
                mid = boxes[i, a, 0] + (boxes[i, a, 1] - boxes[i, a, 0]) / 2.0
                out[i, a, 0], out[i, a, 1] = mid, mid
    return out


def probes(boxes: np.ndarray, idle: np.ndarray) -> np.ndarray:
    """The boxes ``(N, 3, 2)`` with their ``idle (N, 3)`` intervals collapsed to the midpoint
    (the slices whose sensor verdicts hold for the whole box, module doc); compiled
    (:func:`_collapsed`)."""
    return _collapsed(
        np.ascontiguousarray(boxes, dtype=np.float64), np.ascontiguousarray(idle, dtype=np.bool_)
    )
