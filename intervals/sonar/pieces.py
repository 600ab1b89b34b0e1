r"""The cone test of the pieces of boxes, against the pairs their parent box left (tightening).

Why. :mod:`intervals.tighten` bisects each kept box into up to eight pieces a call and tests
every piece. The test (:func:`intervals.sonar.cone.sensor_verdicts`) looks up, for every
piece, the segments within reach and evaluates every (segment, sensor) pair; on the built-in
plans that pair loop is most of the tightening's cost (``hall`` 1.7 us a piece, 0.5 us of it
without any pair; ``apartment`` 4.2 against 0.6). Most pairs can be ruled out once for the
parent instead of once per piece.

What. For each parent box the segments within reach are looked up once, and for each of them
and each sensor the parent's own bounds say whether the pair can matter to any pose of the
parent: the segment meets the parent's union of wedges (the half-planes of the hit test,
:mod:`intervals.sonar.cone`) and its distance lower bound to the parent's sensor box is at
most ``hi`` (an echo) or ``lo`` (a no-echo reading, ``lo = d_max``). A piece is then tested
as by :func:`intervals.sonar.cone_kernel.sensor_verdicts_into` (``inner`` false: rejections
only), with its own sensor boxes and wedges, but on those pairs only.

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
from intervals.sonar.cone_kernel import CX, CY, ECHO, FREE, HX, HY, IGNORED, SENSOR_COLUMNS, UNION
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
)
"""The tolerances of :func:`piece_rejections_into`, in the order of its ``params`` array (those
of :func:`intervals.sonar.cone_kernel.sensor_verdicts_into`)."""
GUARD, NEAR_SWITCH = PARAMS.index("guard_m"), PARAMS.index("near_switch_m")


@numba.njit(cache=True)
def _rows(box, cos_theta, sin_theta, belt, params, rows):
    """:func:`intervals.sonar.cone_kernel.sensor_rows` with the tolerances of ``params``."""
    return cone_kernel.sensor_rows(
        box,
        cos_theta,
        sin_theta,
        belt,
        params[0],
        params[1],
        params[2],
        params[4],
        params[5],
        params[6],
        rows,
    )


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
    reject,
):
    """``reject (N, k)`` in place: sensor ``i`` rejects piece ``n`` (module doc). The arguments
    as :func:`intervals.sonar.cone_kernel.sensor_verdicts_into`'s, with the ``parents (P, 3, 2)``
    and the ``cos``/``sin`` of their heading bounds beside the pieces', and the tolerances in
    ``params`` (:data:`PARAMS`)."""
    guard_m, near_switch_m = params[GUARD], params[NEAR_SWITCH]
    k, n_parents = belt.shape[0], parents.shape[0]
    rows = np.empty((k, SENSOR_COLUMNS))
    hit = np.empty(k, dtype=np.bool_)
    fires = np.empty(k, dtype=np.bool_)
    close = np.empty(k, dtype=np.bool_)
    sure_hit = np.empty(k, dtype=np.bool_)
    done = np.empty(k, dtype=np.bool_)
    skip = np.empty(k, dtype=np.bool_)  # per pair: done, or ruled out by the parent
    impossible = np.empty(k, dtype=np.bool_)
    for i in range(k):
        impossible[i] = kind[i] == ECHO and ranges[i, 0] > ranges[i, 1]
    visible = reach_m + guard_m
    nx, ny = grid_shape[0], grid_shape[1]
    seen = np.zeros(segments.shape[0], dtype=np.int64)  # parent number + 1 of the last visit
    ids = np.empty(segments.shape[0], dtype=np.int64)
    pairs = np.empty((segments.shape[0], k), dtype=np.bool_)
    for p in range(n_parents):
        # the parent's sensor boxes and wedges, the segments within reach of their hull
        _rows(parents[p], parent_cos[p], parent_sin[p], belt, params, rows)
        hull_cx, hull_cy, hull_hx, hull_hy = cone_kernel.sensor_hull(rows)
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
                    gap = cone_kernel._segment_box_gap(
                        ax, ay, ex, ey, hull_cx, hull_cy, hull_hx, hull_hy, near_switch_m
                    )
                    if not gap <= visible:
                        continue
                    # the pairs that can matter: in the parent's wedge half-planes, and
                    # within hi (an echo) or lo (a no-echo reading) of its sensor box
                    matters = False
                    for i in range(k):
                        pairs[count, i] = False
                        if kind[i] == IGNORED:
                            continue
                        t0, t1 = cone_kernel._clip(ax, ay, ex, ey, rows[i], UNION)
                        if not t0 <= t1:
                            continue
                        dist_lb = (
                            cone_kernel._segment_box_gap(
                                ax + t0 * ex,
                                ay + t0 * ey,
                                (t1 - t0) * ex,
                                (t1 - t0) * ey,
                                rows[i, CX],
                                rows[i, CY],
                                rows[i, HX],
                                rows[i, HY],
                                near_switch_m,
                            )
                            - guard_m
                        )
                        limit = ranges[i, 1] if kind[i] == ECHO else ranges[i, 0]
                        if dist_lb <= limit:
                            pairs[count, i] = True
                            matters = True
                    if matters:
                        ids[count] = j
                        count += 1
        # each piece of this parent on those pairs only
        for n in range(p, pieces.shape[0], n_parents):
            sure = _rows(pieces[n], piece_cos[n], piece_sin[n], belt, params, rows)
            hit[:] = False
            fires[:] = False
            close[:] = False
            sure_hit[:] = False
            remaining = 0
            for i in range(k):
                done[i] = kind[i] == IGNORED or impossible[i] or (kind[i] == FREE and not sure)
                remaining += 0 if done[i] else 1
            for t in range(count):
                if remaining == 0:
                    break
                live = False
                for i in range(k):
                    skip[i] = done[i] or not pairs[t, i]
                    live = live or not skip[i]
                if not live:
                    continue
                j = ids[t]
                ax, ay = segments[j, 0, 0], segments[j, 0, 1]
                ex, ey = segments[j, 1, 0] - ax, segments[j, 1, 1] - ay
                remaining -= cone_kernel._segment_verdicts(
                    ax,
                    ay,
                    ex,
                    ey,
                    rows,
                    ranges,
                    kind,
                    sure,
                    False,
                    guard_m,
                    near_switch_m,
                    hit,
                    fires,
                    close,
                    sure_hit,
                    skip,
                )
                for i in range(k):  # the sensors this pair decided
                    done[i] = done[i] or (pairs[t, i] and skip[i])
            for i in range(k):
                echo, free = kind[i] == ECHO, kind[i] == FREE
                reject[n, i] = (echo and (not hit[i] or impossible[i])) or (
                    (echo or free) and fires[i]
                )


def piece_rejections(pieces: np.ndarray, parents: np.ndarray, scan: SonarScan) -> np.ndarray:
    """``reject (N, k)`` bool: sensor ``i`` rejects every pose of piece ``n`` (module doc), each
    piece ``pieces[n]`` a part of ``parents[n % P]`` (checked float64 boxes, e.g. the
    tightening's)."""
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
            ]
        ),
        reject,
    )
    return reject
