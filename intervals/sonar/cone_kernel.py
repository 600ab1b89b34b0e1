r"""The compiled sonar box test (numba): every box, sensor and segment of one test call at once.

:func:`intervals.sonar.cone.sensor_verdicts` calls :func:`sensor_verdicts_into` once per test call
(one SIVIA level). For each pose box the kernel builds the sensor-position boxes and the wedge
half-planes of every sensor, keeps the segments within reach of their hull (looked up in the
scene's :mod:`intervals.sonar.segment_grid`, not the whole map), and runs the hit
test, the free-space test and (optionally) the inner acceptance of the module doc of
:mod:`intervals.sonar.cone` on every (segment, used sensor) pair, with scalar loops instead of
numpy's gathered arrays; :func:`room_verdicts_into` runs the in-room test on the boxes the
sensors leave. Work whose result cannot change a verdict is skipped (:func:`_segment_verdicts`,
:func:`_decided`: distance bounds for flags already set or unused, sensors already decided);
the verdicts are those of the full evaluation. It is the same computation as the numpy
implementation of
:mod:`intervals.sonar.reference.cone` (the reference it is tested against,
``tests/intervals/test_sonar_kernel.py``; not on the production path): the same formulas,
evaluated in the same order of floating-point operations (numba does not contract ``a * b + c``
into fused multiply-adds without ``fastmath``), with the same ``GUARD_M`` biases, sensor-box
margin, ``arc_reaches`` slack and ``1e-9`` rad angle margins (passed in by the caller), the same
outward-rounded reading intervals (computed once per scan by numpy) and the same ``cos`` and
``sin`` of the heading bounds (computed by numpy per call, so that no libm-versus-numpy ulp
difference can arise; it would be covered anyway: the error budget of :mod:`intervals.sonar.geometry`
allows a few ulps, ``1e-15``, per direction component against a sensor-box widening of ``1e-9 (1
+ |m_i|)`` m and ``GUARD_M = 1e-5`` m on every comparison). ``hypot`` is the C library's in
both, ``abs``, ``min`` and ``max`` are exact. So every verdict equals the reference's bit for bit
and every guarantee of :mod:`intervals.sonar.cone` holds unchanged; the tests check equality over
random cases.

Distances estimated first. Every distance the kernels compute is only compared with a
threshold (a gap with ``hi``, ``lo`` or the reach, a farthest distance with ``lo``, the
free-space bound with ``lo`` and ``hi``), and the C library's ``hypot`` costs about 16 ns a
call against under 2 for ``sqrt(x x + y y)`` (:func:`_root`: within 4 units in the last place
of ``hypot``'s value, itself within one). So each comparison is first made on the same
operations with :func:`_root` for ``hypot`` (:func:`_gap_estimate`, :func:`_gap_within`,
:func:`_far_reaches`, :func:`_far_bound`), and decided there only when the estimate clears the
threshold by :data:`DECISION_SLACK` times ``1 + M`` (``M`` the magnitudes involved, m): about
9 000 times the largest difference the roots can make after the few roundings that follow
them. Otherwise (and where the two could take different branches of the gap at
``near_switch_m``) the exact functions decide. Every verdict is therefore the exact
evaluation's, bit for bit (the reference tests below; ``benchmarks/cone_kernel_replay.py``:
identical outputs, 17 to 20 % less CPU on recorded ``corridor`` and ``apartment`` calls). The
sensor box's half-diagonal ``hypot(hx, hy)`` is estimated the same way, so the rows no longer
hold it.

Shapes and units: ``N`` boxes ``(N, 3, 2)`` (x m, y m, theta rad; lower, upper), ``m`` segments
``(m, 2, 2)`` world frame m, ``k`` sensors. Every float array is float64 and C-contiguous, the
kinds int8 and the outputs bool: one compiled signature. The machine code is cached beside the
module (``cache=True``), so only the first use on a machine compiles it (about 3 s).
"""

from __future__ import annotations

import math

import numba
import numpy as np

IGNORED, ECHO, FREE = 0, 1, 2
"""Kinds of sensor constraint: no information, an echo ``[lo, hi]``, free space to ``d_max``
(re-exported by :mod:`intervals.sonar.scan`)."""

# columns of the belt table (k, 8) built by intervals.sonar.scan.SonarBelt.kernel_table
COS_BETA, SIN_BETA, R_LO, R_HI, COS_RIGHT, SIN_RIGHT, COS_LEFT, SIN_LEFT = range(8)

# columns of the per-sensor scratch rows of one box: sensor box, union and intersection
# half-planes (nx, ny, c) x 2 each
CX, CY, HX, HY = range(4)
UNION = 4
INTER = 10
SENSOR_COLUMNS = 16

DECISION_SLACK = 1e-12
"""Relative margin of the distance comparisons decided on ``sqrt`` estimates (module doc,
"Distances estimated first"): a comparison is taken from the estimates only when they clear
its threshold by ``DECISION_SLACK (1 + M)``, ``M`` the sum of the magnitudes involved (m);
about 9 000 times the error bound of the estimates (20 units in the last place of ``M``)."""


@numba.njit(cache=True)
def _max(a: float, b: float) -> float:
    """``np.maximum`` on scalars (a NaN operand gives NaN)."""
    if a > b or a != a:
        return a
    return b


@numba.njit(cache=True)
def _min(a: float, b: float) -> float:
    """``np.minimum`` on scalars (a NaN operand gives NaN)."""
    if a < b or a != a:
        return a
    return b


@numba.njit(cache=True, inline="always")
def _nearest_point(px, py, ax, ay, ex, ey):
    """``(qx, qy)``: nearest point of the segment ``a + t e`` (t in [0, 1]) to ``p`` (as
    ``intervals.sonar.geometry.nearest_on_segment``)."""
    ee = ex * ex + ey * ey
    t = ((px - ax) * ex + (py - ay) * ey) / (ee if ee > 0 else 1.0)
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    return ax + t * ex, ay + t * ey


@numba.njit(cache=True)
def _nearest_distance(px, py, ax, ay, ex, ey):
    """``(qx, qy, dist)``: :func:`_nearest_point` and its distance to ``p``."""
    qx, qy = _nearest_point(px, py, ax, ay, ex, ey)
    return qx, qy, math.hypot(qx - px, qy - py)


@numba.njit(cache=True, inline="always")
def _nearest_estimate(px, py, ax, ay, ex, ey):
    """``(qx, qy, dist)`` of :func:`_nearest_distance` with :func:`_root` for ``hypot``."""
    qx, qy = _nearest_point(px, py, ax, ay, ex, ey)
    return qx, qy, _root(qx - px, qy - py)


@numba.njit(cache=True)
def _segment_box_gap(ax, ay, ex, ey, cx, cy, hx, hy, near_switch_m):
    """Lower bound of the distance between the segment ``a + t e`` and the box ``(c, h)`` (as
    ``intervals.sonar.geometry.segment_box_gap``, which states why it is a bound)."""
    qx, qy, dist = _nearest_distance(cx, cy, ax, ay, ex, ey)
    if dist >= near_switch_m:
        return dist - (abs(qx - cx) / dist * hx + abs(qy - cy) / dist * hy)
    return dist - math.hypot(hx, hy)


@numba.njit(cache=True)
def _point_box_farthest(px, py, cx, cy, hx, hy):
    """Largest distance from the point ``p`` to the points of the box ``(c, h)``."""
    return math.hypot(abs(px - cx) + hx, abs(py - cy) + hy)


@numba.njit(cache=True, inline="always")
def _root(x, y):
    """``sqrt(x x + y y)``: ``hypot(x, y)`` within 4 units in its last place (one rounding of
    each square, of the sum and of the root; ``hypot`` itself is within one), about ten times
    cheaper than the C library's ``hypot``."""
    return math.sqrt(x * x + y * y)


@numba.njit(cache=True, inline="always")
def _gap_estimate(ax, ay, ex, ey, cx, cy, hx, hy, near_switch_m, slack):
    """``(gap, err)``: :func:`_segment_box_gap` in its order of
    operations with :func:`_root` for ``hypot``, and a bound of its distance to the exact
    function's value (``inf`` where the two may take different branches at
    ``near_switch_m``)."""
    ee = ex * ex + ey * ey
    t = ((cx - ax) * ex + (cy - ay) * ey) / (ee if ee > 0 else 1.0)
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    qx, qy = ax + t * ex, ay + t * ey
    dist = _root(qx - cx, qy - cy)
    err = slack * (1.0 + dist + hx + hy)
    if abs(dist - near_switch_m) <= err:
        return dist, np.inf
    if dist >= near_switch_m:
        return dist - (abs(qx - cx) / dist * hx + abs(qy - cy) / dist * hy), err
    return dist - _root(hx, hy), err


@numba.njit(cache=True)
def _gap_within(ax, ay, ex, ey, cx, cy, hx, hy, near_switch_m, guard_m, limit, slack):
    """``_segment_box_gap(...) - guard_m <= limit``, decided on :func:`_gap_estimate` when it
    clears ``limit`` by its error bound and the slack, else on the exact function."""
    gap, err = _gap_estimate(ax, ay, ex, ey, cx, cy, hx, hy, near_switch_m, slack)
    err += slack * (1.0 + abs(limit))
    if gap - guard_m <= limit - err:
        return True
    if gap - guard_m > limit + err:
        return False
    gap = _segment_box_gap(ax, ay, ex, ey, cx, cy, hx, hy, near_switch_m)
    return gap - guard_m <= limit


@numba.njit(cache=True)
def _far_reaches(p0x, p0y, p1x, p1y, cx, cy, hx, hy, guard_m, lo, slack):
    """``max(far(p0), far(p1)) + guard_m >= lo``, ``far`` the farthest distance from the point
    to the box ``(c, h)`` (:func:`_point_box_farthest`), decided on
    :func:`_root` where it clears ``lo`` by the slack (the maximum of two sums is the sum of
    the maximum, rounding being monotone), else on the exact functions."""
    ux0, uy0 = abs(p0x - cx) + hx, abs(p0y - cy) + hy
    f0 = _root(ux0, uy0)
    err0 = slack * (1.0 + f0 + lo)
    if f0 + guard_m >= lo + err0:
        return True
    ux1, uy1 = abs(p1x - cx) + hx, abs(p1y - cy) + hy
    f1 = _root(ux1, uy1)
    err1 = slack * (1.0 + f1 + lo)
    if f1 + guard_m >= lo + err1:
        return True
    if f0 + guard_m < lo - err0 and f1 + guard_m < lo - err1:
        return False
    far = _max(math.hypot(ux0, uy0), math.hypot(ux1, uy1))
    return far + guard_m >= lo


@numba.njit(cache=True)
def _far_bound(px, py, ax, ay, ex, ey, hx, hy, guard_m, lo, hi, slack):
    """The free-space test's bound ``near + hypot(hx, hy) + guard_m`` (``near`` the distance from
    ``p`` to the segment ``a + t e``, :func:`_nearest_distance`, ``h`` the sensor box's
    half-widths), or an estimate (:func:`_root` for ``hypot``) on the same side of ``lo`` and of
    ``hi`` (strictly or not) where it clears both by the slack (module doc, "Distances
    estimated first")."""
    qx, qy, near = _nearest_estimate(px, py, ax, ay, ex, ey)
    diag = _root(hx, hy)
    bound = near + diag + guard_m
    err = slack * (1.0 + near + diag)
    if abs(bound - lo) <= err or abs(bound - hi) <= err:
        bound = math.hypot(qx - px, qy - py) + math.hypot(hx, hy) + guard_m
    return bound


@numba.njit(cache=True)
def _clip(ax, ay, ex, ey, planes, first):
    """Parameter range ``(t_lo, t_hi)`` of ``a + t e``, t in [0, 1], in the two half-planes
    ``nx qx + ny qy >= c`` stored as ``planes[first:first + 6] = (nx, ny, c, nx, ny, c)``;
    empty where ``t_lo > t_hi`` (as ``intervals.sonar.reference.geometry.clip_segment``)."""
    t_lo, t_hi = 0.0, 1.0
    for h in range(first, first + 6, 3):
        nx, ny, c = planes[h], planes[h + 1], planes[h + 2]
        g0 = nx * ax + ny * ay - c
        ge = nx * ex + ny * ey
        if ge > 0:
            t_lo = _max(t_lo, -g0 / ge)
        elif ge < 0:
            t_hi = _min(t_hi, -g0 / ge)
        elif ge == 0 and not g0 >= 0:
            t_hi = -np.inf
    return t_lo, t_hi


@numba.njit(cache=True)
def _arc_reaches(ux_a, uy_a, ux_b, uy_b, ex, ey, half_turn, slack):
    """Whether the arc from ``u_a`` counter-clockwise to ``u_b`` holds the axis direction
    ``e`` (as ``intervals.sonar.reference.geometry.arc_reaches``, slack towards "reached")."""
    det_a = ux_a * ey - uy_a * ex
    det_b = ex * uy_b - ey * ux_b
    if half_turn:
        return not (det_a < -slack and det_b < -slack)
    return det_a >= -slack and det_b >= -slack


@numba.njit(cache=True)
def _wedge_planes(ux, uy, flip, cx, cy, hx, hy, sign, guard_m, out, at):
    """One wedge-edge half-plane ``(nx, ny, c)`` into ``out[at:at + 3]`` (as one turn of
    ``intervals.sonar.reference.geometry.wedge_constraints``)."""
    nx, ny = -flip * uy, flip * ux
    spread = abs(nx) * hx + abs(ny) * hy
    out[at] = nx
    out[at + 1] = ny
    out[at + 2] = nx * cx + ny * cy + sign * (spread + guard_m)


@numba.njit(cache=True)
def heading_flags(box, half_aperture_rad, angle_margin_rad, trig_limit_rad):
    """``(full, half_turn, narrow, sure)`` of the heading interval of a pose box ``(3, 2)``
    (:func:`sensor_rows`): the mount arcs are whole circles, at least half turns, the wedges'
    union is narrow enough for its half-planes, the direction set ``Psi`` is not empty."""
    theta_lo, theta_hi = box[2, 0], box[2, 1]
    width = theta_hi - theta_lo
    trusted = abs(theta_lo) < trig_limit_rad and abs(theta_hi) < trig_limit_rad
    full = not trusted or width >= 2.0 * np.pi - angle_margin_rad
    half_turn = width >= np.pi
    narrow = trusted and width + 2.0 * half_aperture_rad < np.pi - angle_margin_rad
    sure = trusted and width < 2.0 * half_aperture_rad - angle_margin_rad
    return full, half_turn, narrow, sure


@numba.njit(cache=True, inline="always")
def turned_row(cos_theta, sin_theta, belt, i, full, half_turn, arc_slack):
    """The part of row ``i`` of :func:`sensor_rows` that depends on the heading alone: the
    mount's offset range ``(x_lo, x_hi, y_lo, y_hi)`` (m, the mount turned by every heading of
    the box), then the unit vectors of the right wedge edge at ``theta_lo``, the left at
    ``theta_hi``, the right at ``theta_hi`` and the left at ``theta_lo`` (``x, y`` each): a
    12-tuple for :func:`placed_row`."""
    cos_lo, sin_lo, cos_hi, sin_hi = cos_theta[0], sin_theta[0], cos_theta[1], sin_theta[1]
    cb, sb = belt[i, COS_BETA], belt[i, SIN_BETA]
    ax, ay = cos_lo * cb - sin_lo * sb, sin_lo * cb + cos_lo * sb  # theta_lo + beta
    bx, by = cos_hi * cb - sin_hi * sb, sin_hi * cb + cos_hi * sb  # theta_hi + beta
    reach_px = full or _arc_reaches(ax, ay, bx, by, 1.0, 0.0, half_turn, arc_slack)
    reach_py = full or _arc_reaches(ax, ay, bx, by, 0.0, 1.0, half_turn, arc_slack)
    reach_nx = full or _arc_reaches(ax, ay, bx, by, -1.0, 0.0, half_turn, arc_slack)
    reach_ny = full or _arc_reaches(ax, ay, bx, by, 0.0, -1.0, half_turn, arc_slack)
    cos_min = -1.0 if reach_nx else _min(ax, bx)
    cos_max = 1.0 if reach_px else _max(ax, bx)
    sin_min = -1.0 if reach_ny else _min(ay, by)
    sin_max = 1.0 if reach_py else _max(ay, by)
    r_lo, r_hi = belt[i, R_LO], belt[i, R_HI]
    # right edge alpha - gamma, left edge alpha + gamma, at theta_lo and theta_hi
    cr, sr = belt[i, COS_RIGHT], belt[i, SIN_RIGHT]
    cl, sl = belt[i, COS_LEFT], belt[i, SIN_LEFT]
    return (
        _min(r_lo * cos_min, r_hi * cos_min),
        _max(r_lo * cos_max, r_hi * cos_max),
        _min(r_lo * sin_min, r_hi * sin_min),
        _max(r_lo * sin_max, r_hi * sin_max),
        cos_lo * cr - sin_lo * sr,
        sin_lo * cr + cos_lo * sr,
        cos_hi * cl - sin_hi * sl,
        sin_hi * cl + cos_hi * sl,
        cos_hi * cr - sin_hi * sr,
        sin_hi * cr + cos_hi * sr,
        cos_lo * cl - sin_lo * sl,
        sin_lo * cl + cos_lo * sl,
    )


@numba.njit(cache=True, inline="always")
def placed_row(box, turned, i, narrow, margin_m, guard_m, rows):
    """Row ``i`` of :func:`sensor_rows` for the pose box ``box (3, 2)`` from its heading's part
    ``turned`` (:func:`turned_row`)."""
    x_lo = box[0, 0] + turned[0] - margin_m
    x_hi = box[0, 1] + turned[1] + margin_m
    y_lo = box[1, 0] + turned[2] - margin_m
    y_hi = box[1, 1] + turned[3] + margin_m
    cx, cy = (x_lo + x_hi) / 2.0, (y_lo + y_hi) / 2.0
    hx, hy = (x_hi - x_lo) / 2.0, (y_hi - y_lo) / 2.0
    rows[i, CX], rows[i, CY], rows[i, HX], rows[i, HY] = cx, cy, hx, hy
    row = rows[i]
    # union of the wedges over the box (a superset; unused, c = -inf, unless narrow)
    _wedge_planes(turned[4], turned[5], 1.0, cx, cy, hx, hy, -1.0, guard_m, row, UNION)
    _wedge_planes(turned[6], turned[7], -1.0, cx, cy, hx, hy, -1.0, guard_m, row, UNION + 3)
    if not narrow:
        row[UNION + 2] = -np.inf
        row[UNION + 5] = -np.inf
    # intersection of the wedges (a subset; used only when sure)
    _wedge_planes(turned[8], turned[9], 1.0, cx, cy, hx, hy, 1.0, guard_m, row, INTER)
    _wedge_planes(turned[10], turned[11], -1.0, cx, cy, hx, hy, 1.0, guard_m, row, INTER + 3)


@numba.njit(cache=True, inline="always")
def sensor_row(
    box, cos_theta, sin_theta, belt, i, full, half_turn, narrow, margin_m, guard_m, arc_slack, rows
):
    """Row ``i`` of :func:`sensor_rows` (sensor ``i``'s box and wedge half-planes), the flags
    those of :func:`heading_flags`."""
    turned = turned_row(cos_theta, sin_theta, belt, i, full, half_turn, arc_slack)
    placed_row(box, turned, i, narrow, margin_m, guard_m, rows)


@numba.njit(cache=True)
def sensor_rows(
    box,
    cos_theta,
    sin_theta,
    belt,
    half_aperture_rad,
    margin_m,
    guard_m,
    arc_slack,
    angle_margin_rad,
    trig_limit_rad,
    rows,
):
    """Sensor boxes and wedge half-planes of every sensor for one pose box ``(3, 2)`` whose
    heading bounds have the cosines ``cos_theta (2,)`` and sines ``sin_theta (2,)``, into
    ``rows (k, SENSOR_COLUMNS)`` (as ``intervals.sonar.reference.cone.sensor_boxes``); returns ``sure``
    (the direction set ``Psi`` is not empty: the intersection half-planes may be used)."""
    full, half_turn, narrow, sure = heading_flags(
        box, half_aperture_rad, angle_margin_rad, trig_limit_rad
    )
    for i in range(belt.shape[0]):
        sensor_row(
            box,
            cos_theta,
            sin_theta,
            belt,
            i,
            full,
            half_turn,
            narrow,
            margin_m,
            guard_m,
            arc_slack,
            rows,
        )
    return sure


@numba.njit(cache=True)
def _segment_verdicts(
    ax,
    ay,
    ex,
    ey,
    rows,
    ranges,
    kind,
    sure,
    inner,
    guard_m,
    near_switch_m,
    hit,
    fires,
    close,
    sure_hit,
    done,
):
    """The hit and free-space tests (and the inner acceptance's parts) of one pose box against
    the segment ``a + t e``, every sensor not ``done``: sets ``hit``, ``fires``, ``close`` and
    ``sure_hit`` ``(k,)`` where this segment makes them true (never resets them), so the
    verdicts do not depend on the order in which the segments come. The distance bounds of the
    hit test are computed only while a flag they set can still change a verdict (``hit`` of an
    echo not yet hit, ``close`` when ``inner`` and not yet close). Marks ``done`` the sensors
    whose verdict no further segment can change (:func:`_decided`); returns how many."""
    k = rows.shape[0]
    decided = 0
    for i in range(k):
        if done[i]:
            continue
        # the part [t0, t1] of the segment in S + W(Phi)
        t0, t1 = _clip(ax, ay, ex, ey, rows[i], UNION)
        if not t0 <= t1:
            continue
        cx, cy, hx, hy = rows[i, CX], rows[i, CY], rows[i, HX], rows[i, HY]
        lo, hi = ranges[i, 0], ranges[i, 1]
        echo = kind[i] == ECHO
        # hit test: distance bounds between that part and the sensor box, for the flags that can
        # still change a verdict: hit (echo readings only), close (``certain`` only)
        need_hit = echo and not hit[i]
        need_close = inner and not close[i]
        if need_hit or need_close:
            p0x, p0y = ax + t0 * ex, ay + t0 * ey
            dx, dy = (t1 - t0) * ex, (t1 - t0) * ey
            # dist_lb = _segment_box_gap(...) - guard_m, its comparisons decided on the estimate
            # where it clears them (module doc, "Distances estimated first")
            dist_lb, err = _gap_estimate(
                p0x, p0y, dx, dy, cx, cy, hx, hy, near_switch_m, DECISION_SLACK
            )
            dist_lb -= guard_m
            if (need_hit and abs(dist_lb - hi) <= err) or (need_close and abs(dist_lb - lo) <= err):
                dist_lb = (
                    _segment_box_gap(p0x, p0y, dx, dy, cx, cy, hx, hy, near_switch_m) - guard_m
                )
            if (
                need_hit
                and dist_lb <= hi
                and _far_reaches(
                    p0x, p0y, p0x + dx, p0y + dy, cx, cy, hx, hy, guard_m, lo, DECISION_SLACK
                )
            ):
                hit[i] = True
            if need_close and (dist_lb < lo or (kind[i] == FREE and dist_lb == lo)):
                close[i] = True  # some pose may see this segment closer than lo
        # free-space test: segment points in the cone for every pose of the box
        if sure:
            u0, u1 = _clip(ax, ay, ex, ey, rows[i], INTER)
            if u0 <= u1:
                far_bound = _far_bound(
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
                    hi,
                    DECISION_SLACK,
                )
                if far_bound < lo:
                    fires[i] = True
                if far_bound <= hi:
                    sure_hit[i] = True
        if _decided(echo, hit[i], fires[i], close[i], sure):
            done[i] = True
            decided += 1
    return decided


@numba.njit(cache=True)
def _decided(echo, hit, fires, close, sure):
    """Whether the verdicts of a sensor with an echo (``echo``) or a free-space reading are final
    for the box whatever segments come next (``hit``, ``fires``, ``close`` and the final
    formulas of :func:`sensor_verdicts_into` only ever turn towards these): the free-space test
    fired (rejected); or it cannot fire (``sure`` false, so ``sure_hit`` stays false and an echo
    is never certain) and an echo passes the hit test (not rejected) or a free-space reading
    is ``close`` (not certain)."""
    return fires or (not sure and (hit if echo else close))


@numba.njit(cache=True)
def sensor_hull(rows):
    """``(cx, cy, hx, hy)``: centre and half-widths (m) of the hull of the sensor boxes of
    ``rows (k, SENSOR_COLUMNS)`` (:func:`sensor_rows`)."""
    sx_lo, sx_hi = rows[0, CX] - rows[0, HX], rows[0, CX] + rows[0, HX]
    sy_lo, sy_hi = rows[0, CY] - rows[0, HY], rows[0, CY] + rows[0, HY]
    for i in range(1, rows.shape[0]):
        sx_lo = _min(sx_lo, rows[i, CX] - rows[i, HX])
        sx_hi = _max(sx_hi, rows[i, CX] + rows[i, HX])
        sy_lo = _min(sy_lo, rows[i, CY] - rows[i, HY])
        sy_hi = _max(sy_hi, rows[i, CY] + rows[i, HY])
    return (sx_lo + sx_hi) / 2, (sy_lo + sy_hi) / 2, (sx_hi - sx_lo) / 2, (sy_hi - sy_lo) / 2


@numba.njit(cache=True)
def reach_cells(cx, cy, hx, hy, visible, grid_origin, grid_cell_m, nx, ny):
    """``(ix0, ix1, iy0, iy1)``: the cells of the segment grid (``nx`` by ``ny``) that hold
    every segment within ``visible`` m of the box ``(c, h)`` (one cell of margin,
    :mod:`intervals.sonar.segment_grid`); an empty range where the box lies off the grid."""
    radius = visible + math.hypot(hx, hy)
    ix0 = max(math.floor((cx - radius - grid_origin[0]) / grid_cell_m) - 1, 0)
    ix1 = min(math.floor((cx + radius - grid_origin[0]) / grid_cell_m) + 1, nx - 1)
    iy0 = max(math.floor((cy - radius - grid_origin[1]) / grid_cell_m) - 1, 0)
    iy1 = min(math.floor((cy + radius - grid_origin[1]) / grid_cell_m) + 1, ny - 1)
    return ix0, ix1, iy0, iy1


@numba.njit(cache=True)
def sensor_verdicts_into(
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
    reach_m,
    belt,
    half_aperture_rad,
    margin_m,
    guard_m,
    near_switch_m,
    arc_slack,
    angle_margin_rad,
    trig_limit_rad,
    inner,
    reject,
    certain,
):
    """Per box and sensor verdicts of :func:`intervals.sonar.cone.sensor_verdicts`, in place.

    ``boxes (N, 3, 2)`` and ``cos_theta, sin_theta (N, 2)`` of their heading bounds (numpy's
    ``cos`` and ``sin``, those of the reference); ``segments (M, 2, 2)`` (the scene's) of which
    only those with ``allowed (M,)`` take part, and their grid
    (:class:`intervals.sonar.segment_grid.SegmentGrid`: ``grid_origin (2,)``, ``grid_cell_m``,
    ``grid_shape (2,)`` int64, ``grid_starts``, ``grid_members``); ``ranges (k, 2)`` distance
    intervals m and ``kind (k,)`` int8 of the readings
    (:func:`intervals.sonar.scan.reading_intervals`); ``reach_m``
    (:attr:`intervals.sonar.scan.SonarScan.reach_m`); ``belt (k, 8)``
    (:attr:`intervals.sonar.scan.SonarBelt.kernel_table`); the aperture, the sensor-box margin
    m and the tolerances of :mod:`intervals.sonar.geometry`; ``inner``: compute ``certain``.
    Writes ``reject (N, k)`` and ``certain (N, k)`` (bool, every element).
    """
    k = belt.shape[0]
    rows = np.empty((k, SENSOR_COLUMNS))
    hit = np.empty(k, dtype=np.bool_)  # some segment passes the hit test
    fires = np.empty(k, dtype=np.bool_)  # the free-space test fires
    close = np.empty(k, dtype=np.bool_)  # some segment may be closer than lo
    sure_hit = np.empty(k, dtype=np.bool_)  # some segment is surely hit within hi
    done = np.empty(k, dtype=np.bool_)  # the sensor's verdicts are final for this box
    impossible = np.empty(k, dtype=np.bool_)  # an echo interval that is empty: always rejected
    for i in range(k):
        impossible[i] = kind[i] == ECHO and ranges[i, 0] > ranges[i, 1]
    visible = reach_m + guard_m
    nx, ny = grid_shape[0], grid_shape[1]
    seen = np.zeros(segments.shape[0], dtype=np.int64)  # box number + 1 of the last visit
    for n in range(boxes.shape[0]):
        sure = sensor_rows(
            boxes[n],
            cos_theta[n],
            sin_theta[n],
            belt,
            half_aperture_rad,
            margin_m,
            guard_m,
            arc_slack,
            angle_margin_rad,
            trig_limit_rad,
            rows,
        )
        # the hull of the sensor boxes: only segments within reach of it take part
        hull_cx, hull_cy, hull_hx, hull_hy = sensor_hull(rows)
        hit[:] = False
        fires[:] = False
        close[:] = False
        sure_hit[:] = False
        # sensors decided before any segment: ignored ones, impossible echoes (rejected, never
        # certain), and free-space readings when the free-space test cannot fire (their
        # verdict is "not rejected", certain unused)
        remaining = 0
        for i in range(k):
            done[i] = (
                kind[i] == IGNORED or impossible[i] or (kind[i] == FREE and not sure and not inner)
            )
            remaining += 0 if done[i] else 1
        # the segments registered near the hull (intervals.sonar.segment_grid: every segment
        # the gap test below keeps is among them), each once (stamped with the box number)
        ix0, ix1, iy0, iy1 = reach_cells(
            hull_cx, hull_cy, hull_hx, hull_hy, visible, grid_origin, grid_cell_m, nx, ny
        )
        for ix in range(ix0, ix1 + 1):
            if remaining == 0:
                break  # every verdict is final: the other segments cannot change it
            for cell in range(ix * ny + iy0, ix * ny + iy1 + 1):
                if remaining == 0:
                    break
                for member in range(grid_starts[cell], grid_starts[cell + 1]):
                    if remaining == 0:
                        break
                    j = grid_members[member]
                    if seen[j] == n + 1 or not allowed[j]:
                        continue
                    seen[j] = n + 1
                    ax, ay = segments[j, 0, 0], segments[j, 0, 1]
                    ex, ey = segments[j, 1, 0] - ax, segments[j, 1, 1] - ay
                    if _gap_within(  # gap - 0.0 is the gap, bit for bit
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
                        DECISION_SLACK,
                    ):
                        remaining -= _segment_verdicts(
                            ax,
                            ay,
                            ex,
                            ey,
                            rows,
                            ranges,
                            kind,
                            sure,
                            inner,
                            guard_m,
                            near_switch_m,
                            hit,
                            fires,
                            close,
                            sure_hit,
                            done,
                        )
        for i in range(k):
            echo, free = kind[i] == ECHO, kind[i] == FREE
            reject[n, i] = (echo and (not hit[i] or impossible[i])) or ((echo or free) and fires[i])
            certain[n, i] = inner and (
                (echo and not close[i] and sure_hit[i] and not impossible[i])
                or (free and not close[i])
                or kind[i] == IGNORED
            )


@numba.njit(cache=True)
def room_verdicts_into(boxes, boundary, guard_m, near_switch_m, outside, inside):
    """The in-room test of :mod:`intervals.sonar.room` (as ``intervals.sonar.reference.room.room_verdicts``), in
    place: ``outside (N,)`` / ``inside (N,)`` bool, the (x, y) rectangle of box ``n`` lies
    entirely outside / inside the polygon ``boundary (p, 2)`` m: no edge comes within
    ``guard_m`` of it, and the ray cast from its centre towards +x crosses the boundary an even
    / odd number of times."""
    p = boundary.shape[0]
    for n in range(boxes.shape[0]):
        cx, cy = (boxes[n, 0, 0] + boxes[n, 0, 1]) / 2.0, (boxes[n, 1, 0] + boxes[n, 1, 1]) / 2.0
        hx, hy = (boxes[n, 0, 1] - boxes[n, 0, 0]) / 2.0, (boxes[n, 1, 1] - boxes[n, 1, 0]) / 2.0
        clear, crossings = True, 0
        for i in range(p):
            ax, ay = boundary[i, 0], boundary[i, 1]
            nxt = i + 1 if i + 1 < p else 0
            ex, ey = boundary[nxt, 0] - ax, boundary[nxt, 1] - ay
            if not _segment_box_gap(ax, ay, ex, ey, cx, cy, hx, hy, near_switch_m) > guard_m:
                clear = False
                break
            if (ay > cy) != (ay + ey > cy) and ax + (cy - ay) * ex / ey > cx:
                crossings += 1
        outside[n] = clear and crossings % 2 == 0
        inside[n] = clear and crossings % 2 == 1
