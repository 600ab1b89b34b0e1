r"""The cone test of the pieces of boxes, against the pairs their parent box left (tightening).

Why. :mod:`intervals.tighten` bisects each kept box into up to eight pieces a call and tests
every piece. The test (:func:`intervals.sonar.cone.sensor_verdicts`) looks up, for every
piece, the segments within reach and evaluates every (segment, sensor) pair; on the built-in
plans that pair loop is most of the tightening's cost (``hall`` 1.7 us a piece, 0.5 us of it
without any pair; ``apartment`` 4.2 against 0.6). Most pairs can be ruled out once for the
parent instead of once per piece.

What. For each parent box the segments within reach are looked up once, and for each sensor
a piece asks about the parent's own bounds say which of them can matter to any pose of the
parent (:func:`_parent_pairs`, listed once a parent): the segment meets the parent's union of
wedges (the half-planes of the hit test, :mod:`intervals.sonar.cone`) and its distance lower
bound to the parent's sensor box is at most ``hi`` (an echo) or ``lo`` (a no-echo reading,
``lo = d_max``). A piece is then tested as by
:func:`intervals.sonar.cone_kernel.sensor_verdicts_into` (``inner`` false: rejections only),
with its own sensor boxes and wedges, but on those pairs only, and sensor by sensor: a
sensor's flags depend on its own pairs only and never on their order (:func:`_pair_flags`),
so this gives the full loop's verdicts while a sensor's verdict is final at the end of its
list (or earlier, :func:`intervals.sonar.cone_kernel._decided`). That lets a piece stop once
``enough`` sensors reject it (a caller that only asks whether more than ``q`` do passes ``q +
1``: the verdict is the same, the row then holds only the rejections found). The sensor that
rejected the last piece is tried first (siblings and neighbours are often rejected by the
same sensor), and a sensor's box and wedges (:func:`intervals.sonar.cone_kernel.sensor_row`)
and its pair list are built only when a piece reaches it.

Cost (``benchmarks/piece_replay.py``: the tightening's calls, ``enough = q + 1 = 2`` as the
tracker has it): at 9 levels 0.79 us a piece on ``hall`` (1.35 before the sensor-by-sensor
test), 0.92 on ``office``, 1.09 on ``apartment``, 1.22 on ``corridor`` (BENCHMARKS.md, "The
piece test sensor by sensor"); at 12 levels with the distances estimated first, the heading
parts of the rows kept and the bounding-box cut of the parent's pairs, 0.55 to 0.73 us
against 0.76 to 1.05 (1.39 to 1.51 times cheaper; BENCHMARKS.md, "The tightening pass per
piece").

Soundness. A sensor rejects a piece when no remaining pair passes the piece's hit test, or
when the free-space test fires on one. (1) A pair the parent ruled out cannot hold the
nearest cone point of any pose of the parent (the hit test's argument, module doc of
:mod:`intervals.sonar.cone`: if ``d_i(p)`` is in ``[lo, hi]`` at the point ``P`` of segment
``j``, then ``j`` meets the wedge half-planes and its distance bound to the sensor box is at
most ``|P - s| <= hi``), so of any pose of the piece either, which lies in the parent: the
hit test of the piece loses no hit that could be the reading. (2) The free-space test fires on
a pair only by proving the reading wrong for every pose of the piece, whatever other pairs are
left out. So every rejection is sound, though the verdicts may differ from the full test's (a
piece may be rejected where the full test's looser bounds kept it, or kept where a free-space
firing on a pair ruled out by the parent would have rejected it). The parent's bounds being
those of the full test's own floating-point evaluation, the argument holds for the computed
values as it does for the full test (:mod:`intervals.sonar.geometry`).

Distances estimated first (:mod:`intervals.sonar.cone_kernel`, the same section): every
distance comparison here (a segment's gap with ``hi``, ``lo`` or the reach, the farthest box
point with ``lo``, the free-space bound with ``lo``) is decided on ``sqrt`` estimates where
they clear it, else on ``hypot``; the rows are those of the exact evaluation, bit for bit,
and the argument above applies unchanged. ``hypot`` was most of a pair's cost.

Shapes: ``pieces (N, 3, 2)`` and ``parents (P, 3, 2)``, piece ``n`` a part of parent
``n % P`` (the order in which :mod:`intervals.tighten` makes them). Float arrays float64 and
C-contiguous.
"""

from __future__ import annotations

import numba
import numpy as np

from intervals import interval as ia
from intervals.sonar import cone_kernel
from intervals.sonar.cone import heading_trig
from intervals.sonar.cone_kernel import (
    CX,
    CY,
    ECHO,
    FREE,
    HX,
    HY,
    INTER,
    SENSOR_COLUMNS,
    UNION,
)
from intervals.sonar.contractor import _same_key
from intervals.sonar.geometry import ANGLE_MARGIN_RAD, ARC_SLACK, GUARD_M, NEAR_SWITCH_M
from intervals.sonar.scan import SonarScan

PARAMS = (
    "half_aperture_rad",
    "margin_m",
    "guard_m",
    "near_switch_m",
    "arc_slack",
    "angle_margin_rad",
    "trig_limit_rad",
    "decision_slack",
)
"""The tolerances of :func:`piece_rejections_into`, in the order of its ``params`` array (those
of :func:`intervals.sonar.cone_kernel.sensor_verdicts_into`, then the slack of the comparisons
decided on estimates, :data:`~intervals.sonar.cone_kernel.DECISION_SLACK` in production)."""
GUARD, NEAR_SWITCH = PARAMS.index("guard_m"), PARAMS.index("near_switch_m")
APERTURE, MARGIN, ARC = (
    PARAMS.index(name) for name in ("half_aperture_rad", "margin_m", "arc_slack")
)
ANGLE_MARGIN, TRIG_LIMIT = PARAMS.index("angle_margin_rad"), PARAMS.index("trig_limit_rad")
SLACK = PARAMS.index("decision_slack")

HEADING_SLOTS = 4
"""Heading intervals whose part of the sensor rows (:func:`intervals.sonar.cone_kernel.turned_row`)
:func:`piece_rejections_into` keeps, sensor by sensor as pieces reach them: the eight pieces
of a parent hold two or three headings (about 70 % of the pieces share one with a sibling
tested before them on ``corridor``, ``office_floor`` and ``apartment``). A slot is reused only
for the same heading bounds and the same cosines and sines of them, bit for bit (all that
part reads of a piece): the values a piece would compute alone."""


@numba.njit(cache=True)
def _parent_rows(box, cos_theta, sin_theta, belt, params, rows):
    """:func:`intervals.sonar.cone_kernel.sensor_rows` with the tolerances of ``params``."""
    return cone_kernel.sensor_rows(
        box,
        cos_theta,
        sin_theta,
        belt,
        params[APERTURE],
        params[MARGIN],
        params[GUARD],
        params[ARC],
        params[ANGLE_MARGIN],
        params[TRIG_LIMIT],
        rows,
    )


@numba.njit(cache=True, inline="always")
def _kept_turned(turned, s, i):
    """Slot ``s``'s heading part of sensor ``i``'s row (``turned (HEADING_SLOTS, k, 12)``), as
    the tuple :func:`intervals.sonar.cone_kernel.turned_row` returns."""
    t = turned[s, i]
    return (t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8], t[9], t[10], t[11])


@numba.njit(cache=True)
def _pair_flags(
    ax, ay, ex, ey, rows, i, lo, hi, echo, sure, hit, fires, guard_m, near_switch_m, slack
):
    """``(hit, fires)`` of sensor ``i`` (an echo ``[lo, hi]`` when ``echo``, else a free-space
    reading) after the segment ``a + t e``: the part of
    :func:`intervals.sonar.cone_kernel._segment_verdicts` that rejections read (``inner``
    false: no ``close``, no ``sure_hit``), with its helpers in its order of operations, each
    distance comparison decided on estimates where they clear it (the ``_gap_within``,
    ``_far_reaches`` and ``_far_bound`` of :mod:`intervals.sonar.cone_kernel`), so the flags
    are its flags
    (``test_sonar_pieces.py``: the rows of a parent tested as its own piece are the full
    test's; the rows at a slack that leaves every comparison to the exact functions are the
    rows at :data:`~intervals.sonar.cone_kernel.DECISION_SLACK`)."""
    t0, t1 = cone_kernel._clip(ax, ay, ex, ey, rows[i], UNION)
    if not t0 <= t1:
        return hit, fires
    cx, cy, hx, hy = rows[i, CX], rows[i, CY], rows[i, HX], rows[i, HY]
    if echo and not hit:
        p0x, p0y = ax + t0 * ex, ay + t0 * ey
        dx, dy = (t1 - t0) * ex, (t1 - t0) * ey
        if cone_kernel._gap_within(
            p0x, p0y, dx, dy, cx, cy, hx, hy, near_switch_m, guard_m, hi, slack
        ):
            hit = cone_kernel._far_reaches(
                p0x, p0y, p0x + dx, p0y + dy, cx, cy, hx, hy, guard_m, lo, slack
            )
    if sure:
        u0, u1 = cone_kernel._clip(ax, ay, ex, ey, rows[i], INTER)
        if u0 <= u1:
            bound = cone_kernel._far_bound(
                cx,
                cy,
                ax + u0 * ex,
                ay + u0 * ey,
                (u1 - u0) * ex,
                (u1 - u0) * ey,
                hx,
                hy,
                guard_m,
                lo,
                lo,
                slack,
            )
            fires = fires or bound < lo
    return hit, fires


@numba.njit(cache=True)
def _parent_pairs(near, count, parent_rows, i, ranges, kind, guard_m, near_switch_m, slack, out):
    """The segments ``near[:count]`` (``(a, e)`` and the bounding box ``(x_lo, x_hi, y_lo,
    y_hi)`` each) that can matter to sensor ``i`` for some pose of the parent (``parent_rows``,
    :func:`_parent_rows`): in its wedge half-planes, and within ``hi`` (an echo) or ``lo`` (a
    no-echo reading) of its sensor box (:func:`~intervals.sonar.cone_kernel._gap_within`); into
    ``out[i]`` in the order met. Returns how many.

    A segment whose bounding box lies farther than ``limit + guard_m + hx + hy`` from the
    sensor box's centre along x or y (by more than the slack, which covers the few ulps of 1e3
    m its clipped points and their distance may be off) is left out first, without its clip:
    the gap of any part of it is at least its distance from the centre less ``hx + hy`` (the
    most :func:`intervals.sonar.cone_kernel._segment_box_gap` takes off), so it would fail the
    distance test."""
    limit = ranges[i, 1] if kind[i] == ECHO else ranges[i, 0]
    cx, cy = parent_rows[i, CX], parent_rows[i, CY]
    hx, hy = parent_rows[i, HX], parent_rows[i, HY]
    far = limit + guard_m + hx + hy
    far += slack * (1.0 + abs(cx) + abs(cy) + abs(far)) * 8.0
    kept = 0
    for c in range(count):
        if (
            near[c, 4] - cx > far
            or cx - near[c, 5] > far
            or near[c, 6] - cy > far
            or cy - near[c, 7] > far
        ):
            continue
        ax, ay, ex, ey = near[c, 0], near[c, 1], near[c, 2], near[c, 3]
        t0, t1 = cone_kernel._clip(ax, ay, ex, ey, parent_rows[i], UNION)
        if not t0 <= t1:
            continue
        if cone_kernel._gap_within(
            ax + t0 * ex,
            ay + t0 * ey,
            (t1 - t0) * ex,
            (t1 - t0) * ey,
            cx,
            cy,
            hx,
            hy,
            near_switch_m,
            guard_m,
            limit,
            slack,
        ):
            out[i, kept, 0], out[i, kept, 1], out[i, kept, 2], out[i, kept, 3] = ax, ay, ex, ey
            kept += 1
    return kept


@numba.njit(cache=True)
def piece_rejections_into(
    pieces,
    piece_cos,
    piece_sin,
    parents,
    parent_cos,
    parent_sin,
    segments,
    allowed,
    grid_origin,
    grid_cell_m,
    grid_shape,
    grid_starts,
    grid_members,
    ranges,
    kind,
    reach_m,
    belt,
    params,
    enough,
    reject,
):
    """``reject (N, k)`` in place: sensor ``i`` rejects piece ``n`` (module doc); a piece's row
    is left once ``enough`` of its sensors reject it (its other entries False). The arguments
    as :func:`intervals.sonar.cone_kernel.sensor_verdicts_into`'s, with the ``parents (P, 3,
    2)`` and the ``cos``/``sin`` of their heading bounds beside the pieces', and the tolerances
    in ``params`` (:data:`PARAMS`)."""
    guard_m, near_switch_m, slack = params[GUARD], params[NEAR_SWITCH], params[SLACK]
    k, n_parents = belt.shape[0], parents.shape[0]
    rows, parent_rows = np.empty((k, SENSOR_COLUMNS)), np.empty((k, SENSOR_COLUMNS))
    impossible = np.empty(k, dtype=np.bool_)
    for i in range(k):
        impossible[i] = kind[i] == ECHO and ranges[i, 0] > ranges[i, 1]
    visible = reach_m + guard_m
    nx, ny = grid_shape[0], grid_shape[1]
    seen = np.zeros(segments.shape[0], dtype=np.int64)  # parent number + 1 of the last visit
    near = np.empty((segments.shape[0], 8))  # the parent's segments within reach: a, e, box
    # per sensor, those of its pairs the parent leaves (a, e), listed when a piece first asks
    listed = np.empty(k, dtype=np.bool_)
    pair_count = np.empty(k, dtype=np.int64)
    pair_segments = np.empty((k, segments.shape[0], 4))
    order = np.arange(k)  # the order the sensors are tried in: the last to reject a piece first
    # the heading parts of the sensor rows of the last HEADING_SLOTS headings, filled per sensor
    turned = np.empty((HEADING_SLOTS, k, 12))
    ready = np.zeros((HEADING_SLOTS, k), dtype=np.bool_)
    keys = np.full((HEADING_SLOTS, 6), np.nan)  # each slot's heading bounds and their trig
    key = np.empty(6)
    oldest = 0
    for p in range(n_parents):
        # the parent's sensor boxes and wedges, the segments within reach of their hull
        _parent_rows(parents[p], parent_cos[p], parent_sin[p], belt, params, parent_rows)
        hull_cx, hull_cy, hull_hx, hull_hy = cone_kernel.sensor_hull(parent_rows)
        ix0, ix1, iy0, iy1 = cone_kernel.reach_cells(
            hull_cx, hull_cy, hull_hx, hull_hy, visible, grid_origin, grid_cell_m, nx, ny
        )
        count = 0
        for ix in range(ix0, ix1 + 1):
            for cell in range(ix * ny + iy0, ix * ny + iy1 + 1):
                for member in range(grid_starts[cell], grid_starts[cell + 1]):
                    j = grid_members[member]
                    if seen[j] == p + 1 or not allowed[j]:
                        continue
                    seen[j] = p + 1
                    ax, ay = segments[j, 0, 0], segments[j, 0, 1]
                    ex, ey = segments[j, 1, 0] - ax, segments[j, 1, 1] - ay
                    if cone_kernel._gap_within(  # gap - 0.0 is the gap, bit for bit
                        ax,
                        ay,
                        ex,
                        ey,
                        hull_cx,
                        hull_cy,
                        hull_hx,
                        hull_hy,
                        near_switch_m,
                        0.0,
                        visible,
                        slack,
                    ):
                        near[count, 0], near[count, 1] = ax, ay
                        near[count, 2], near[count, 3] = ex, ey
                        near[count, 4] = min(ax, segments[j, 1, 0])
                        near[count, 5] = max(ax, segments[j, 1, 0])
                        near[count, 6] = min(ay, segments[j, 1, 1])
                        near[count, 7] = max(ay, segments[j, 1, 1])
                        count += 1
        listed[:] = False
        # each piece of this parent on those pairs only, sensor by sensor (the verdicts of a
        # sensor do not depend on the others', nor on the order of its segments)
        for n in range(p, pieces.shape[0], n_parents):
            box, box_cos, box_sin = pieces[n], piece_cos[n], piece_sin[n]
            full, half_turn, narrow, sure = cone_kernel.heading_flags(
                box, params[APERTURE], params[ANGLE_MARGIN], params[TRIG_LIMIT]
            )
            key[0], key[1], key[2] = box[2, 0], box[2, 1], box_cos[0]
            key[3], key[4], key[5] = box_cos[1], box_sin[0], box_sin[1]
            slot = -1
            for h in range(HEADING_SLOTS):
                if _same_key(keys, h, key):
                    slot = h
                    break
            if slot < 0:  # a new heading: into the oldest slot, no sensor's part computed yet
                slot, oldest = oldest, (oldest + 1) % HEADING_SLOTS
                keys[slot, :] = key
                ready[slot, :] = False
            reject[n, :] = False
            rejected = 0
            for s in range(k):
                if rejected >= enough:
                    break
                i = order[s]
                echo = kind[i] == ECHO
                if not (echo or (kind[i] == FREE and sure)):
                    continue  # ignored, or free space the free-space test cannot prove wrong
                if impossible[i]:  # an empty echo interval: rejected by every pose
                    reject[n, i] = True
                    rejected += 1
                    continue
                if not listed[i]:
                    pair_count[i] = _parent_pairs(
                        near,
                        count,
                        parent_rows,
                        i,
                        ranges,
                        kind,
                        guard_m,
                        near_switch_m,
                        slack,
                        pair_segments,
                    )
                    listed[i] = True
                hit, fires = False, False
                if pair_count[i]:  # the sensor's row of sensor_rows, only when a pair reads it
                    if not ready[slot, i]:
                        part = cone_kernel.turned_row(
                            box_cos, box_sin, belt, i, full, half_turn, params[ARC]
                        )
                        for c in range(12):
                            turned[slot, i, c] = part[c]
                        ready[slot, i] = True
                    cone_kernel.placed_row(
                        box,
                        _kept_turned(turned, slot, i),
                        i,
                        narrow,
                        params[MARGIN],
                        guard_m,
                        rows,
                    )
                for c in range(pair_count[i]):
                    hit, fires = _pair_flags(
                        pair_segments[i, c, 0],
                        pair_segments[i, c, 1],
                        pair_segments[i, c, 2],
                        pair_segments[i, c, 3],
                        rows,
                        i,
                        ranges[i, 0],
                        ranges[i, 1],
                        echo,
                        sure,
                        hit,
                        fires,
                        guard_m,
                        near_switch_m,
                        slack,
                    )
                    if cone_kernel._decided(echo, hit, fires, False, sure):
                        break  # no further pair can change this sensor's verdict
                if (echo and not hit) or fires:
                    reject[n, i] = True
                    rejected += 1
                    for t in range(s, 0, -1):  # first for the next piece
                        order[t] = order[t - 1]
                    order[0] = i


def piece_rejections(
    pieces: np.ndarray,
    parents: np.ndarray,
    scan: SonarScan,
    enough: int | None = None,
    slack: float | None = None,
) -> np.ndarray:
    """``reject (N, k)`` bool: sensor ``i`` rejects every pose of piece ``n`` (module doc), each
    piece ``pieces[n]`` a part of ``parents[n % P]`` (checked float64 boxes, e.g. the
    tightening's). ``enough``: a piece is left once that many of its sensors reject it (its
    other entries False: a caller counting more than ``q`` rejections passes ``q + 1``); None:
    every row complete. ``slack``: of the comparisons decided on estimates (None:
    :data:`~intervals.sonar.cone_kernel.DECISION_SLACK`; a large one leaves every distance
    comparison to the exact functions, the same rows)."""
    pieces, parents = np.ascontiguousarray(pieces), np.ascontiguousarray(parents)
    reject = np.empty((pieces.shape[0], scan.belt.count), dtype=bool)
    if pieces.shape[0] == 0:
        return reject
    belt = scan.belt
    assert scan.scene is not None
    grid = scan.scene.grid
    piece_rejections_into(
        pieces,
        *heading_trig(pieces),
        parents,
        *heading_trig(parents),
        scan.scene.segments,
        scan.allowed,
        grid.origin,
        grid.cell_m,
        np.array(grid.shape, dtype=np.int64),
        grid.starts,
        grid.members,
        scan.ranges,
        scan.kind,
        scan.reach_m,
        belt.kernel_table,
        np.array(
            [
                belt.half_aperture_rad,
                belt.sensor_box_margin_m,
                GUARD_M,
                NEAR_SWITCH_M,
                ARC_SLACK,
                ANGLE_MARGIN_RAD,
                ia.TRIG_EXACT_LIMIT_RAD,
                cone_kernel.DECISION_SLACK if slack is None else slack,
            ]
        ),
        belt.count + 1 if enough is None else int(enough),
        reject,
    )
    return reject
