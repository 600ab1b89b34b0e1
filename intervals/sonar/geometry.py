r"""Tolerances of the sonar box tests and the numpy distance primitives of the scan.

The primitives work on component arrays (x and y separately, broadcast shapes); boxes are
given by centre ``(cx, cy)`` and half-widths ``(hx, hy)``: a box ``[lo, hi]`` is enclosed by
``[c - h, c + h]`` up to one rounding of ``(lo + hi)/2`` and ``(hi - lo)/2``, far below
:data:`GUARD_M`. The compiled kernels (:mod:`intervals.sonar.cone_kernel`) repeat these
formulas operation for operation; the other primitives of the numpy reference test are in
:mod:`intervals.sonar.reference.geometry`. The argument below covers both.

Floating point. The reading intervals are outward rounded with :mod:`intervals.interval`. ``S`` is
a sensor-position box of :mod:`intervals.sonar.cone`. Directions ``theta + c`` (``c`` = ``beta_i``,
``alpha_i -+ gamma``) are unit vectors computed by angle addition from ``cos``/``sin`` of the box's
heading bounds and of the constants: each component is off by a few ulps (below ``1e-15``). Hence
the ends of the arcs in ``S`` are off by less than ``1e-15 |m_i|`` m, and after adding ``[x]``
(``|x| <= 1e3``) by less than ``3e-13`` m, far below the widening ``1e-9 (1 + |m_i|)`` m, so ``S``
holds every sensor position. Whether an arc passes an axis direction ``e`` is decided from
``det(u_a, e)`` and ``det(e, u_b)`` with a slack of ``1e-12`` towards "passes" (``arc_reaches``), a
thousand times their float error: a passed direction is never missed, only a near-miss counted (a
larger, still sound ``S``). A wedge edge normal tilted by ``1e-15`` rad moves its half-plane by
less than ``1e-15 * 3e3`` m over the map, absorbed by ``GUARD_M`` below like every other predicate
error. The geometric predicates (half-plane clips, distances) are evaluated in float64 on
coordinates bounded by ``MAX_COORDINATE_M = 1e3`` m (checked); each is a handful of operations, so
a computed point or distance is off by ``delta <= 1e-12`` m (a few ulps of 1e3). The one amplified
error is the direction used by ``segment_box_gap``: tilted by at most ``2 delta / NEAR_SWITCH_M =
2e-10`` rad, which moves its bound by at most ``2e-10 * 3e3 m = 6e-7`` m. Every comparison is
biased in favour of keeping the box by ``GUARD_M = 1e-5`` m, more than ten times these errors, so a
float error never turns a feasible box into a rejected one. A half-plane clip shifted by
``GUARD_M`` moves its boundary by ``GUARD_M`` in space, whatever the angle between the segment and
the boundary, and its rounding error scales with the same angle.
"""

from __future__ import annotations

import numpy as np

GUARD_M = 1e-5
"""Bias (metres) of every geometric comparison in favour of keeping a box (see module doc)."""

MAX_COORDINATE_M = 1e3
"""Largest map coordinate accepted: keeps float errors far below :data:`GUARD_M`."""

NEAR_SWITCH_M = 1e-2
"""Below this centre-to-segment distance the segment-box gap uses the triangle-inequality
bound, whose rounding error does not grow as the distance shrinks (see ``segment_box_gap``)."""


SENSOR_BOX_MARGIN = 1e-9
"""Relative widening of the sensor-position boxes (see :meth:`intervals.sonar.scan.SonarBelt.sensor_box_margin_m`)."""

ARC_SLACK = 1e-12
"""Slack of the arc-extremum decisions (``arc_reaches``), towards "reached"."""

ANGLE_MARGIN_RAD = 1e-9
"""Margin of the heading-width decisions (``Psi`` not empty, ``width(Phi) < pi``, a full turn),
towards the larger, sound choice."""


def down(x):
    """``x`` moved one ulp towards ``-inf``."""
    return np.nextafter(x, -np.inf)


def up(x):
    """``x`` moved one ulp towards ``+inf``."""
    return np.nextafter(x, np.inf)


def nearest_on_segment(px, py, ax, ay, ex, ey):
    """Nearest point of segments ``a + t e, t in [0, 1]`` to points ``p``: ``(qx, qy, dist)``."""
    ee = ex * ex + ey * ey
    t = ((px - ax) * ex + (py - ay) * ey) / np.where(ee > 0, ee, 1.0)
    t = np.clip(t, 0.0, 1.0)
    qx, qy = ax + t * ex, ay + t * ey
    return qx, qy, np.hypot(qx - px, qy - py)


def segment_box_gap(ax, ay, ex, ey, cx, cy, hx, hy):
    """Lower bound of the distance between segments ``a + t e`` and boxes ``(c, h)``.

    For any unit vector ``u``, ``dist(seg, box) >= min_seg u.q - max_box u.s``; we take ``u``
    from the box centre towards the nearest segment point ``q*``, for which
    ``min_seg u.q = u.q*`` (projection property of the nearest point of a convex set), so the
    bound is ``|q* - c| - (|u_x| h_x + |u_y| h_y)``: exact in most configurations. A rounding
    error ``delta`` in ``q*`` tilts ``u`` by ``delta / |q* - c|`` and moves that identity by at
    most the tilt times the segment's extent; below ``NEAR_SWITCH_M`` we therefore use the
    always-valid ``|q* - c| - |h|`` (triangle inequality) instead (see the module doc).
    """
    qx, qy, dist = nearest_on_segment(cx, cy, ax, ay, ex, ey)
    far = dist >= NEAR_SWITCH_M
    safe = np.where(far, dist, 1.0)
    spread = np.abs(qx - cx) / safe * hx + np.abs(qy - cy) / safe * hy
    return dist - np.where(far, spread, np.hypot(hx, hy))
