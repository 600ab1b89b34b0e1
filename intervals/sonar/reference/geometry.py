"""The numpy geometric primitives of the reference cone test (:mod:`intervals.sonar.reference.cone`).

Component arrays, broadcast shapes; boxes by centre ``(cx, cy)`` and half-widths ``(hx, hy)``
as in :mod:`intervals.sonar.geometry`, whose floating-point argument covers them (and the
distance bound ``segment_box_gap`` kept there for the scan's segment selection). The compiled
kernels of :mod:`intervals.sonar.cone_kernel` evaluate the same formulas operation for
operation (``_point_box_farthest``, ``_clip``, ``_wedge_planes``, ``_arc_reaches``).
"""

from __future__ import annotations

import numpy as np

from intervals.sonar.geometry import ARC_SLACK, GUARD_M


def point_box_farthest(px, py, cx, cy, hx, hy):
    """Largest distance from points to the points of boxes ``(c, h)``."""
    return np.hypot(np.abs(px - cx) + hx, np.abs(py - cy) + hy)


def clip_segment(ax, ay, ex, ey, constraints, t_lo, t_hi):
    """Parameter range of ``a + t e`` (t in ``[t_lo, t_hi]``) satisfying ``nx qx + ny qy >= c``
    for each ``(nx, ny, c)`` of ``constraints``; empty where the returned ``lo > hi``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        for nx, ny, c in constraints:
            g0 = nx * ax + ny * ay - c
            ge = nx * ex + ny * ey
            bound = -g0 / ge
            t_lo = np.where(ge > 0, np.maximum(t_lo, bound), t_lo)
            t_hi = np.where(ge < 0, np.minimum(t_hi, bound), t_hi)
            t_hi = np.where((ge == 0) & ~(g0 >= 0), -np.inf, t_hi)
    return t_lo, t_hi


def wedge_constraints(u_lo, u_hi, cx, cy, hx, hy, sign):
    """Half-planes bounding wedges of directions from ``u_lo`` to ``u_hi`` (unit vectors
    ``(ux, uy)``, counter-clockwise, less than pi apart) with apexes in the boxes ``(c, h)``:
    ``det(u_lo, q) >= k_1`` and ``det(q, u_hi) >= k_2`` where ``k`` is the minimum over the box
    minus ``GUARD_M`` (``sign = -1``: union of the wedges, a superset) or the maximum plus
    ``GUARD_M`` (``sign = +1``: intersection of the wedges, a subset)."""
    out = []
    for (ux, uy), flip in ((u_lo, 1.0), (u_hi, -1.0)):
        nx, ny = -flip * uy, flip * ux
        spread = np.abs(nx) * hx + np.abs(ny) * hy
        out.append((nx, ny, nx * cx + ny * cy + sign * (spread + GUARD_M)))
    return out


def arc_reaches(ux_a, uy_a, ux_b, uy_b, ex, ey, half_turn):
    """Whether the arc of directions swept counter-clockwise from ``u_a`` to ``u_b`` (unit
    vectors) holds the direction ``e`` (a unit axis vector ``(ex, ey)``). ``half_turn``: the arc
    is at least pi wide (then it misses ``e`` only when ``e`` is strictly inside the
    complementary arc from ``u_b`` to ``u_a``). Decided with a slack of ``ARC_SLACK`` towards
    "reached": a wrong "not reached" can only happen within ``1e-12`` rad of an end of the arc,
    where the extreme value differs from the end's by less than ``1e-24``."""
    det_a = ux_a * ey - uy_a * ex  # det(u_a, e)
    det_b = ex * uy_b - ey * ux_b  # det(e, u_b)
    narrow = (det_a >= -ARC_SLACK) & (det_b >= -ARC_SLACK)
    return np.where(half_turn, ~((det_a < -ARC_SLACK) & (det_b < -ARC_SLACK)), narrow)
