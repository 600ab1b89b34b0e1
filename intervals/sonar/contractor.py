r"""A sound contractor of pose boxes by the sonar echoes (forward-backward, before bisection).

Why. SIVIA (:mod:`intervals.sivia`) only decides and bisects: a box that holds a thin strip of
consistent poses is cut until the pieces off the strip are rejected one by one. A contractor
shrinks the box to (a box around) the strip first, as codac's ``CtcSegment``/``CtcPolar``
chained by HC4 do, so the paving needs fewer levels and keeps smaller boxes.

Constraint (the cone model of :mod:`intervals.sonar.scan`, docs/models.md section 3). If sensor
``i`` has an echo with distance interval ``[lo, hi]`` and its reading is right, the nearest map
point ``P`` inside its cone is at distance ``d = d_i(p)`` in ``[lo, hi]`` along a direction
``phi`` of the cone, on some segment ``j``:

    P = s_i(p) + d u(phi),   s_i(p) = (x, y) + R(theta) m_i,
    P in [a_j, b_j],   d in [lo, hi],   phi in theta + alpha_i + [-gamma, gamma].

So ``(x, y) = P - d u(phi) - R(theta) m_i`` for some such ``P, d, phi``. Over a pose box
``[x] x [y] x [theta]`` (HC4 on this chain, one sensor and one segment at a time):

* forward: ``O_i``, a box holding ``R(theta) m_i`` for every heading of the box (the mount arc,
  computed as the sensor boxes of :mod:`intervals.sonar.cone_kernel`, same margin); ``V_i``, a
  box holding ``d u(phi)`` for every ``d`` and ``phi`` (the extremes of ``cos`` and ``sin`` on the
  direction arc, :func:`intervals.sonar.cone_kernel._arc_reaches`, times ``lo`` or ``hi``);
  ``Q_i = [x] x [y] + O_i + V_i`` holds every possible ``P``;
* ``CtcSegment``: the part of segment ``j`` inside ``Q_i`` (a parametric clip), whose bounding
  box ``H_ij`` holds ``P``;
* backward: ``(x, y) in (H_ij - V_i - O_i) ∩ ([x] x [y])``.

The union over the segments of these boxes holds every ``(x, y)`` of the box at which sensor
``i``'s reading can be right: its hull ``A_i`` (empty when no segment meets ``Q_i``). Sensors
without an echo constrain nothing here (``A_i`` is the box); an empty reading interval
(``lo > hi``) allows nothing.

q-relaxation. A pose with at most ``q`` wrong readings lies in at least ``k - q`` of the
``A_i``, so on each axis it is at least the ``(q + 1)``-th largest lower bound of the ``A_i``
(below that, ``q + 1`` lower bounds exceed it) and at most the ``(q + 1)``-th smallest upper
bound. The contracted box is those bounds (the heading unchanged), or empty (marked NaN) when
they cross: no pose of the box has at most ``q`` wrong readings. Repeated ``passes`` times
on the narrower box (HC4's fixed-point loop, stopped early), or until nothing moves. The
segment loop of a box stops once at most ``q`` echo sensors can still contract it (each other
one allows the whole box already, so no ``(q + 1)``-th bound can move: the box is returned as
it is, which is always sound).

Known wrong readings. A caller that has proved sensor ``i``'s reading wrong at every pose
of a box (a sound box test rejecting the box by that sensor, :mod:`intervals.sonar.pieces`)
may say so (``wrong``): ``A_i`` is then empty, which it is (no pose of the box is right for
``i``), so a pose with at most ``q`` wrong readings is wrong at most ``q - c`` times among
the other sensors (``c`` known wrong): the bounds become the ``(q - c + 1)``-th of the other
sensors' (for ``c = q`` their intersection, ``q = 0``, not the ``q = 1`` bound that lets one
sensor be ignored), and a box with ``c > q`` is empty. The tightening's pieces, tested before
they are contracted, hand their rejection rows here (:mod:`intervals.tighten`).

Cost. Each segment is checked against the hull of the ``Q_i`` by its bounding box (the scan's
segments are those within reach of the paved boxes), then against each ``Q_i``; the
offset and polar boxes, which depend on the heading only, are kept for the last
:data:`HEADING_SLOTS` heading intervals. Measured on a ``corridor`` tracking frontier of
3 516 boxes: 1.7 ms CPU, about 0.5 us a box (BENCHMARKS.md, "The corridor's tracking tail").

Shaving (:func:`shave`): the heading, which this chain does not narrow, and the faces the
free-space part of the cone test can cut, are narrowed after SIVIA by testing thin slices at
each face of the boxes kept with the sound box test (3B consistency).

Floating point (as in :mod:`intervals.sonar.geometry`): every box is widened by
:data:`~intervals.sonar.geometry.GUARD_M` at each of the three steps (far above the few ulps
of 1e3 m each addition or product may cost); the clip is made against ``Q_i`` widened by
``GUARD_M``, so a clip parameter computed with a large relative error (a segment nearly
parallel to a face) still keeps every point of the segment within the unwidened face (the
error moves the computed crossing along the segment by less than ``GUARD_M`` across the
face, and the coordinate is monotone along the segment). The unit vectors at the arc ends are
those of the cone test (numpy's ``cos``/``sin`` of the heading bounds by angle addition, a few
ulps), and a direction arc that may pass an axis is taken to pass it (``arc_slack``). Heading
bounds beyond :data:`intervals.interval.TRIG_EXACT_LIMIT_RAD` or arcs of a full turn use the
whole circle.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np

from intervals import interval as ia
from intervals.boxes import as_boxes
from intervals.errors import IntervalError
from intervals.sonar import cone_kernel
from intervals.sonar.cone import heading_trig
from intervals.sonar.cone_kernel import (
    COS_BETA,
    COS_LEFT,
    COS_RIGHT,
    ECHO,
    R_HI,
    R_LO,
    SIN_BETA,
    SIN_LEFT,
    SIN_RIGHT,
)
from intervals.sonar.geometry import ANGLE_MARGIN_RAD, ARC_SLACK, GUARD_M
from intervals.sonar.scan import SonarScan

DEFAULT_PASSES = 2
"""Forward-backward passes per call: a second pass starts from the box the first narrowed (its
``Q_i`` are narrower); a box the first pass leaves unchanged stops there."""

SHAVE_ROUNDS = 2
"""Rounds of :func:`shave` when its caller does not say (each: the six faces, then
:func:`contract`; the pipeline's are ``[estimation] shave_rounds``, default 0). Measured on one of
``hall``'s tracking epochs at eps 0.05 (21 boxes): the outer volume becomes 0.58 of the
unshaved after one round, 0.47 after two, 0.43 after four, the consistent volume unchanged;
on the codac ray problem 4 rounds take another sixth off (``benchmarks/intervals_vs_codac.py``).
Two rounds cost about 7 ms a ``hall`` epoch."""

SHAVE_FRACTION = 0.25
"""Width of the slice :func:`shave` tests at a face, as a fraction of the box's width there."""

HEADING_SLOTS = 4
"""Heading intervals whose offset and polar boxes (:func:`_turned_rows`) :func:`contract_into`
keeps, so that the boxes of a frontier sharing a heading (the pieces of a strip cut along
its length; four slots hold all but a few of a corridor epoch's frontiers) compute them once.
A slot is reused only for the same heading bounds and the same cosines and sines of them,
bit for bit (all that :func:`_turned_rows` reads of a box): the values a box would compute
alone."""

# columns of the per-sensor scratch rows: offset box O, polar box V, hit box Q, allowed A
O_XL, O_XH, O_YL, O_YH, V_XL, V_XH, V_YL, V_YH = range(8)
Q_XL, Q_XH, Q_YL, Q_YH, A_XL, A_XH, A_YL, A_YH = range(8, 16)
ROW_COLUMNS = 16


@numba.njit(cache=True)
def _arc_extremes(ax, ay, bx, by, whole, half_turn, arc_slack):
    """``(cos_min, cos_max, sin_min, sin_max)`` over the arc of directions counter-clockwise
    from ``a`` to ``b`` (unit vectors): an end's value, or -+1 where the arc may pass the axis
    direction (``whole``: the full circle)."""
    reach = cone_kernel._arc_reaches
    cos_max = 1.0 if whole or reach(ax, ay, bx, by, 1.0, 0.0, half_turn, arc_slack) else max(ax, bx)
    sin_max = 1.0 if whole or reach(ax, ay, bx, by, 0.0, 1.0, half_turn, arc_slack) else max(ay, by)
    cos_min = (
        -1.0 if whole or reach(ax, ay, bx, by, -1.0, 0.0, half_turn, arc_slack) else min(ax, bx)
    )
    sin_min = (
        -1.0 if whole or reach(ax, ay, bx, by, 0.0, -1.0, half_turn, arc_slack) else min(ay, by)
    )
    return cos_min, cos_max, sin_min, sin_max


@numba.njit(cache=True)
def _scaled(lo, hi, c_min, c_max):
    """``[min, max]`` of ``r c`` over ``r in [lo, hi]`` (``lo >= 0``) and ``c in [c_min, c_max]``."""
    return min(lo * c_min, hi * c_min), max(lo * c_max, hi * c_max)


@numba.njit(cache=True)
def _turned_rows(theta_lo, theta_hi, cos_theta, sin_theta, belt, ranges, kind, params, rows):
    """Offset boxes ``O_i`` and polar boxes ``V_i`` of every echo sensor into ``rows (k,
    ROW_COLUMNS)``, for the heading interval ``[theta_lo, theta_hi]`` (``cos_theta, sin_theta
    (2,)``: of its bounds): they depend on the heading alone, not on the box's ``(x, y)``.
    ``params = (half_aperture_rad, margin_m, guard_m, arc_slack, angle_margin_rad,
    trig_limit_rad)``. The rows of the other sensors (no echo, or an empty reading interval)
    are left as they were: no step reads them."""
    gamma, margin_m, guard_m, arc_slack, angle_margin, trig_limit = (
        params[0],
        params[1],
        params[2],
        params[3],
        params[4],
        params[5],
    )
    width = theta_hi - theta_lo
    trusted = abs(theta_lo) < trig_limit and abs(theta_hi) < trig_limit
    mount_whole = not trusted or width >= 2.0 * np.pi - angle_margin
    mount_half = width >= np.pi - angle_margin
    cone_width = width + 2.0 * gamma
    cone_whole = not trusted or cone_width >= 2.0 * np.pi - angle_margin
    cone_half = cone_width >= np.pi - angle_margin
    cos_lo, sin_lo, cos_hi, sin_hi = cos_theta[0], sin_theta[0], cos_theta[1], sin_theta[1]
    for i in range(belt.shape[0]):
        if kind[i] != ECHO or not ranges[i, 0] <= ranges[i, 1]:
            continue
        # O_i: the mount m_i turned by every heading of the box
        cb, sb = belt[i, COS_BETA], belt[i, SIN_BETA]
        ax, ay = cos_lo * cb - sin_lo * sb, sin_lo * cb + cos_lo * sb
        bx, by = cos_hi * cb - sin_hi * sb, sin_hi * cb + cos_hi * sb
        c_min, c_max, s_min, s_max = _arc_extremes(
            ax, ay, bx, by, mount_whole, mount_half, arc_slack
        )
        r_lo, r_hi = belt[i, R_LO], belt[i, R_HI]
        ox_lo, ox_hi = _scaled(r_lo, r_hi, c_min, c_max)
        oy_lo, oy_hi = _scaled(r_lo, r_hi, s_min, s_max)
        rows[i, O_XL], rows[i, O_XH] = ox_lo - margin_m, ox_hi + margin_m
        rows[i, O_YL], rows[i, O_YH] = oy_lo - margin_m, oy_hi + margin_m
        # V_i: d u(phi), d in [lo, hi], phi from theta_lo + alpha - gamma to theta_hi + alpha + gamma
        cr, sr = belt[i, COS_RIGHT], belt[i, SIN_RIGHT]
        cl, sl = belt[i, COS_LEFT], belt[i, SIN_LEFT]
        ax, ay = cos_lo * cr - sin_lo * sr, sin_lo * cr + cos_lo * sr
        bx, by = cos_hi * cl - sin_hi * sl, sin_hi * cl + cos_hi * sl
        c_min, c_max, s_min, s_max = _arc_extremes(ax, ay, bx, by, cone_whole, cone_half, arc_slack)
        lo, hi = ranges[i, 0], ranges[i, 1]
        vx_lo, vx_hi = _scaled(lo, hi, c_min, c_max)
        vy_lo, vy_hi = _scaled(lo, hi, s_min, s_max)
        rows[i, V_XL], rows[i, V_XH] = vx_lo - guard_m, vx_hi + guard_m
        rows[i, V_YL], rows[i, V_YH] = vy_lo - guard_m, vy_hi + guard_m


@numba.njit(cache=True)
def _same_key(keys, s, key):
    """Row ``s`` of ``keys (slots, m)`` holds the floats of ``key (m,)``, bit for bit (equal
    and with the same sign: ``-0.0`` and ``0.0`` differ; a NaN matches nothing)."""
    for c in range(key.shape[0]):
        a, b = keys[s, c], key[c]
        if not (a == b and math.copysign(1.0, a) == math.copysign(1.0, b)):
            return False
    return True


@numba.njit(cache=True)
def _hit_rows(box, ranges, kind, guard_m, wrong, rows):
    """Hit boxes ``Q_i = box + O_i + V_i`` (widened) of every echo sensor of ``rows (k,
    ROW_COLUMNS)`` not ``wrong (k,)`` (``O_i, V_i`` filled by :func:`_turned_rows` for the
    heading of ``box``), and every ``A_i`` set empty (filled by the segments). Returns the hull
    ``(x_lo, x_hi, y_lo, y_hi)`` of the ``Q_i``."""
    hx_lo, hx_hi, hy_lo, hy_hi = np.inf, -np.inf, np.inf, -np.inf
    for i in range(rows.shape[0]):
        rows[i, A_XL], rows[i, A_XH], rows[i, A_YL], rows[i, A_YH] = (
            np.inf,
            -np.inf,
            np.inf,
            -np.inf,
        )
        if kind[i] != ECHO or not ranges[i, 0] <= ranges[i, 1] or wrong[i]:
            continue
        q_xl = box[0, 0] + rows[i, O_XL] + rows[i, V_XL] - guard_m
        q_xh = box[0, 1] + rows[i, O_XH] + rows[i, V_XH] + guard_m
        q_yl = box[1, 0] + rows[i, O_YL] + rows[i, V_YL] - guard_m
        q_yh = box[1, 1] + rows[i, O_YH] + rows[i, V_YH] + guard_m
        rows[i, Q_XL], rows[i, Q_XH], rows[i, Q_YL], rows[i, Q_YH] = q_xl, q_xh, q_yl, q_yh
        hx_lo, hx_hi = min(hx_lo, q_xl), max(hx_hi, q_xh)
        hy_lo, hy_hi = min(hy_lo, q_yl), max(hy_hi, q_yh)
    return hx_lo, hx_hi, hy_lo, hy_hi


@numba.njit(cache=True)
def _clip_axis(a, e, lo, hi, t0, t1):
    """Narrow ``[t0, t1]`` to the ``t`` with ``a + t e`` in ``[lo, hi]`` (one coordinate)."""
    if e > 0.0:
        t0 = max(t0, (lo - a) / e)
        t1 = min(t1, (hi - a) / e)
    elif e < 0.0:
        t0 = max(t0, (hi - a) / e)
        t1 = min(t1, (lo - a) / e)
    elif not (lo <= a <= hi):
        t1 = -np.inf
    return t0, t1


@numba.njit(cache=True)
def _segment_backward(ax, ay, ex, ey, box, rows, done, guard_m):
    """Segment ``a + t e`` against every echo sensor not ``done``: widen ``A_i`` by the robot
    positions of the box from which ``i`` may hit it (``CtcSegment`` then the backward step);
    mark ``done`` the sensors whose ``A_i`` has become the whole box (no segment can change it
    then). Returns how many were marked."""
    sx_lo, sx_hi = min(ax, ax + ex), max(ax, ax + ex)
    sy_lo, sy_hi = min(ay, ay + ey), max(ay, ay + ey)
    marked = 0
    for i in range(rows.shape[0]):
        if done[i]:
            continue
        if (
            sx_hi < rows[i, Q_XL]
            or sx_lo > rows[i, Q_XH]
            or sy_hi < rows[i, Q_YL]
            or sy_lo > rows[i, Q_YH]
        ):
            continue
        t0, t1 = _clip_axis(ax, ex, rows[i, Q_XL], rows[i, Q_XH], 0.0, 1.0)
        t0, t1 = _clip_axis(ay, ey, rows[i, Q_YL], rows[i, Q_YH], t0, t1)
        if not t0 <= t1:
            continue
        p0x, p0y, p1x, p1y = ax + t0 * ex, ay + t0 * ey, ax + t1 * ex, ay + t1 * ey
        h_xl = max(min(p0x, p1x) - guard_m, rows[i, Q_XL])
        h_xh = min(max(p0x, p1x) + guard_m, rows[i, Q_XH])
        h_yl = max(min(p0y, p1y) - guard_m, rows[i, Q_YL])
        h_yh = min(max(p0y, p1y) + guard_m, rows[i, Q_YH])
        # backward: (x, y) in H - V - O, within the box
        x_lo = max(h_xl - rows[i, V_XH] - rows[i, O_XH] - guard_m, box[0, 0])
        x_hi = min(h_xh - rows[i, V_XL] - rows[i, O_XL] + guard_m, box[0, 1])
        y_lo = max(h_yl - rows[i, V_YH] - rows[i, O_YH] - guard_m, box[1, 0])
        y_hi = min(h_yh - rows[i, V_YL] - rows[i, O_YL] + guard_m, box[1, 1])
        if x_lo <= x_hi and y_lo <= y_hi:
            rows[i, A_XL], rows[i, A_XH] = min(rows[i, A_XL], x_lo), max(rows[i, A_XH], x_hi)
            rows[i, A_YL], rows[i, A_YH] = min(rows[i, A_YL], y_lo), max(rows[i, A_YH], y_hi)
            if (
                rows[i, A_XL] <= box[0, 0]
                and rows[i, A_XH] >= box[0, 1]
                and rows[i, A_YL] <= box[1, 0]
                and rows[i, A_YH] >= box[1, 1]
            ):
                done[i] = True
                marked += 1
    return marked


@numba.njit(cache=True)
def _largest(values, q, top):
    """The ``(q + 1)``-th largest of ``values (k,)`` (``q < k``), ``np.sort(values)[k - 1 - q]``,
    in one pass keeping the ``q + 1`` largest in ``top (q + 1,)`` (descending)."""
    count = 0
    for v in values:
        if count <= q:
            pos = count
            count += 1
        elif v > top[q]:
            pos = q
        else:
            continue
        while pos > 0 and top[pos - 1] < v:
            top[pos] = top[pos - 1]
            pos -= 1
        top[pos] = v
    return top[q]


@numba.njit(cache=True)
def _relaxed_bounds(rows, kind, wrong, box, q, lows, highs, top, out):
    """The q-relaxed ``(x_lo, x_hi, y_lo, y_hi)`` into ``out (4,)``: per axis the ``(q + 1)``-th
    largest lower bound and the ``(q + 1)``-th smallest upper bound of the sensors' allowed
    boxes (a sensor without an echo allows the whole box, one ``wrong (k,)`` nothing); ``lows,
    highs (k,)``, ``top (q + 1,)``: scratch (the upper bounds negated, so that the smallest is
    the largest of their negatives, exactly). Returns ``out``."""
    k = rows.shape[0]
    for axis in range(2):
        if q >= k:
            out[2 * axis], out[2 * axis + 1] = box[axis, 0], box[axis, 1]
            continue
        for i in range(k):
            if wrong[i]:  # allows no pose of the box: an empty A_i
                lows[i], highs[i] = np.inf, np.inf
            elif kind[i] == ECHO:
                lows[i] = rows[i, A_XL + 2 * axis]
                highs[i] = -rows[i, A_XH + 2 * axis]
            else:
                lows[i], highs[i] = box[axis, 0], -box[axis, 1]
        out[2 * axis] = max(_largest(lows, q, top), box[axis, 0])
        out[2 * axis + 1] = min(-_largest(highs, q, top), box[axis, 1])
    return out


@numba.njit(cache=True)
def contract_into(
    boxes,
    cos_theta,
    sin_theta,
    segments,
    allowed,
    grid_origin,
    grid_cell_m,
    grid_shape,
    grid_starts,
    grid_members,
    ranges,
    kind,
    belt,
    params,
    q,
    passes,
    wrong,
    has_wrong,
    out,
):
    """Contract every box of ``boxes (N, 3, 2)`` into ``out (N, 3, 2)`` (module doc).

    ``cos_theta, sin_theta (N, 2)``: of the heading bounds (:func:`intervals.sonar.cone.heading_trig`);
    ``segments (M, 2, 2)``: the scene's, of which only those with ``allowed (M,)`` take part
    (the scan's, within reach of the boxes, :meth:`intervals.sonar.scan.SonarScan.restricted_to`),
    looked up in the scene's grid (``grid_origin (2,)``, ``grid_cell_m``, ``grid_shape (2,)``
    int64, ``grid_starts``, ``grid_members``, :class:`intervals.sonar.segment_grid.SegmentGrid`)
    in the cells the hull of the hit boxes meets, each skipped unless its bounding box meets
    that hull;
    ``ranges (k, 2)``, ``kind (k,)``: the scan's reading intervals; ``belt (k, 8)``: the belt's
    kernel table; ``params``: see :func:`_turned_rows`; ``q``: the relaxation; ``passes``:
    forward-backward passes; ``wrong (N, k)`` bool (with ``has_wrong``, else ``(0, k)``): the
    sensors known to be wrong at every pose of each box (module doc, "Known wrong readings").
    An empty result row is all NaN.
    """
    k = belt.shape[0]
    # the rows of the last HEADING_SLOTS heading intervals met (their O_i and V_i computed once;
    # a frontier's boxes share a few headings); a NaN bound matches no heading
    tables = np.empty((HEADING_SLOTS, k, ROW_COLUMNS))
    keys = np.full((HEADING_SLOTS, 6), np.nan)  # each slot's heading bounds and their trig
    key = np.empty(6)
    oldest = 0
    lows, highs, top, bounds = np.empty(k), np.empty(k), np.empty(q + 1), np.empty(4)
    done = np.empty(k, dtype=np.bool_)  # the sensor's A_i can change no more
    guard_m = params[2]
    echoes = 0
    for i in range(k):
        echoes += 1 if kind[i] == ECHO else 0
    if echoes <= q and not has_wrong:  # no (q + 1)-th bound can move (module doc): as they are
        out[:, :, :] = boxes
        return
    right = np.zeros(k, dtype=np.bool_)  # the wrong row of a box without known wrong readings
    work = np.empty((3, 2))
    nx, ny = grid_shape[0], grid_shape[1]
    seen = np.zeros(segments.shape[0], dtype=np.int64)  # stamp of the last pass that met it
    stamp = 0
    for n in range(boxes.shape[0]):
        work[:, :] = boxes[n]
        known = wrong[n] if has_wrong else right
        # the other sensors may be wrong at q - known_count of a pose's readings at most
        q_left = q
        for i in range(k):
            q_left -= 1 if known[i] else 0
        if q_left < 0:  # more than q readings wrong at every pose of the box
            out[n, :, :] = np.nan
            continue
        empty = False
        # everything _turned_rows reads of the box (the passes leave the heading as it is)
        key[0], key[1] = work[2, 0], work[2, 1]
        key[2], key[3] = cos_theta[n, 0], cos_theta[n, 1]
        key[4], key[5] = sin_theta[n, 0], sin_theta[n, 1]
        slot = -1
        for s in range(HEADING_SLOTS):
            if _same_key(keys, s, key):
                slot = s
                break
        if slot < 0:  # a new heading: into the oldest slot
            slot, oldest = oldest, (oldest + 1) % HEADING_SLOTS
            _turned_rows(
                key[0],
                key[1],
                cos_theta[n],
                sin_theta[n],
                belt,
                ranges,
                kind,
                params,
                tables[slot],
            )
            keys[slot, :] = key
        rows = tables[slot]
        for _ in range(passes):
            stamp += 1
            hx_lo, hx_hi, hy_lo, hy_hi = _hit_rows(work, ranges, kind, guard_m, known, rows)
            # sensors that can still contract: the echoes not known wrong (A_i starts empty);
            # once at most q_left remain, no face can move (the (q + 1)-th bound is the box's,
            # the known wrong taking q - q_left of the q + 1 places), so stop early (an empty
            # reading interval counts as remaining: it never allows the whole box)
            remaining = 0
            for i in range(k):
                done[i] = known[i] or not (kind[i] == ECHO and ranges[i, 0] <= ranges[i, 1])
                remaining += 1 if kind[i] == ECHO and not known[i] else 0
            if hx_lo <= hx_hi:  # some echo: the segments whose bounding box meets a hit box
                # only a segment with a point in some Q_i (so in their hull) can widen an A_i;
                # the grid registers it in that point's cell, inside the hull's cell range
                # widened by one (intervals.sonar.segment_grid): each visited once a pass
                ix0 = max(math.floor((hx_lo - grid_origin[0]) / grid_cell_m) - 1, 0)
                ix1 = min(math.floor((hx_hi - grid_origin[0]) / grid_cell_m) + 1, nx - 1)
                iy0 = max(math.floor((hy_lo - grid_origin[1]) / grid_cell_m) - 1, 0)
                iy1 = min(math.floor((hy_hi - grid_origin[1]) / grid_cell_m) + 1, ny - 1)
                # a hull beyond the grid's last row or column meets no cell (and its row
                # range would index past ``grid_starts``)
                for ix in range(ix0, ix1 + 1 if iy0 <= iy1 else ix0):
                    if remaining <= q_left:
                        break
                    for member in range(grid_starts[ix * ny + iy0], grid_starts[ix * ny + iy1 + 1]):
                        if remaining <= q_left:
                            break
                        j = grid_members[member]
                        if seen[j] == stamp or not allowed[j]:
                            continue
                        seen[j] = stamp
                        ax, ay = segments[j, 0, 0], segments[j, 0, 1]
                        bx, by = segments[j, 1, 0], segments[j, 1, 1]
                        if max(ax, bx) < hx_lo or min(ax, bx) > hx_hi:
                            continue
                        if max(ay, by) < hy_lo or min(ay, by) > hy_hi:
                            continue
                        remaining -= _segment_backward(
                            ax, ay, bx - ax, by - ay, work, rows, done, guard_m
                        )
            b = _relaxed_bounds(rows, kind, known, work, q, lows, highs, top, bounds)
            if not (b[0] <= b[1] and b[2] <= b[3]):
                empty = True
                break
            unchanged = (
                b[0] == work[0, 0]
                and b[1] == work[0, 1]
                and b[2] == work[1, 0]
                and b[3] == work[1, 1]
            )
            work[0, 0], work[0, 1], work[1, 0], work[1, 1] = b[0], b[1], b[2], b[3]
            if unchanged:
                break
        if empty:
            out[n, :, :] = np.nan
        else:
            out[n] = work


def contract(
    boxes,
    scan: SonarScan,
    q: int = 0,
    passes: int = DEFAULT_PASSES,
    validated: bool = False,
    wrong: np.ndarray | None = None,
) -> np.ndarray:
    """Pose boxes ``(N, 3, 2)`` contracted by the scan's echoes at relaxation ``q`` (module
    doc): each row lies in the input row and holds every pose of it at which at most ``q``
    readings are wrong; a row with no such pose is NaN. The heading is left as it is.
    ``validated``: ``boxes`` is already a checked float64 ``(N, 3, 2)`` array
    (:func:`intervals.boxes.as_boxes`, e.g. a SIVIA frontier), not checked again.
    ``wrong (N, k)`` bool: sensors whose reading is wrong at every pose of the box (e.g. the
    rows of a sound box test's rejections; module doc, "Known wrong readings"); None: none
    known."""
    if not validated:
        boxes = as_boxes(boxes)
        if boxes.shape[1] != 3:
            raise IntervalError(f"contractor: pose boxes must be (N, 3, 2), got {boxes.shape}")
    boxes = np.ascontiguousarray(boxes)
    if not (isinstance(q, (int, np.integer)) and q >= 0):
        raise IntervalError(f"contractor: q must be a non-negative integer, got {q!r}")
    if not (isinstance(passes, (int, np.integer)) and passes >= 1):
        raise IntervalError(f"contractor: passes must be an integer >= 1, got {passes!r}")
    out = np.empty_like(boxes)
    if boxes.shape[0] == 0:
        return out
    belt = scan.belt
    if wrong is not None:
        wrong = np.ascontiguousarray(wrong, dtype=bool)
        if wrong.shape != (boxes.shape[0], belt.count):
            raise IntervalError(
                f"contractor: wrong must be ({boxes.shape[0]}, {belt.count}), got {wrong.shape}"
            )
    params = np.array(
        [
            belt.half_aperture_rad,
            belt.sensor_box_margin_m,
            GUARD_M,
            ARC_SLACK,
            ANGLE_MARGIN_RAD,
            ia.TRIG_EXACT_LIMIT_RAD,
        ]
    )
    cos_theta, sin_theta = heading_trig(boxes)
    assert scan.scene is not None
    grid = scan.scene.grid
    contract_into(
        boxes,
        np.ascontiguousarray(cos_theta),
        np.ascontiguousarray(sin_theta),
        scan.scene.segments,
        scan.allowed,
        grid.origin,
        grid.cell_m,
        np.array(grid.shape, dtype=np.int64),
        grid.starts,
        grid.members,
        scan.ranges,
        scan.kind,
        belt.kernel_table,
        params,
        int(q),
        int(passes),
        np.zeros((0, belt.count), dtype=bool) if wrong is None else wrong,
        wrong is not None,
        out,
    )
    return out


def shave(
    boxes: np.ndarray,
    rejected: Callable[[np.ndarray], np.ndarray],
    scan: SonarScan,
    q: int,
    rounds: int = SHAVE_ROUNDS,
    fraction: float = SHAVE_FRACTION,
    max_per_call: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(shaved (K, 3, 2), rows (K,))``: the boxes ``(N, 3, 2)`` narrowed by shaving (3B
    consistency, one slice per face), those emptied by :func:`contract` dropped; ``rows`` are the
    input rows of the boxes kept.

    ``rejected(slices (M, 3, 2)) -> (M,) bool``: a sound box test (True only when no pose of the
    slice is in the set). Each round, for the heading then x then y, the slices of width
    ``fraction`` of the box's width at its two faces are tested in one call, and a rejected slice
    is cut off (the slice ``[lo, fl(lo + w f)]`` and the rest ``[fl(lo + w f), hi]`` share that
    float bound, so they cover the box: no pose outside the rejected slice is lost; with
    ``fraction < 1/2`` the two slices never overlap, so the box never empties); then the round
    ends with :func:`contract` at relaxation ``q``. Every pose the test and the contractor keep
    stays in its box. ``max_per_call``: the most slices handed to ``rejected`` at once (None: all
    ``2 N`` of an axis in one call). The test sees ``6 N rounds`` slices in all.
    """
    boxes = np.array(boxes, dtype=np.float64)
    rows = np.arange(boxes.shape[0])
    for _ in range(rounds):
        n = boxes.shape[0]
        if n == 0:
            break
        for axis in (2, 0, 1):
            lo, hi = boxes[:, axis, 0], boxes[:, axis, 1]
            cut = fraction * (hi - lo)
            left, right = boxes.copy(), boxes.copy()
            left[:, axis, 1] = lo + cut
            right[:, axis, 0] = hi - cut
            slices = np.concatenate([left, right])
            step = slices.shape[0] if max_per_call is None else max(1, max_per_call)
            out = np.concatenate(
                [
                    np.asarray(rejected(slices[start : start + step]), dtype=bool)
                    for start in range(0, slices.shape[0], step)
                ]
            )
            boxes[out[:n], axis, 0] = left[out[:n], axis, 1]
            boxes[out[n:], axis, 1] = right[out[n:], axis, 0]
        boxes = contract(boxes, scan, q)
        full = ~np.isnan(boxes).any(axis=(1, 2))
        boxes, rows = boxes[full], rows[full]
    return boxes, rows
