"""The numpy reference of the cone test (:mod:`intervals.sonar.cone`): tests and benchmarks only.

The same tests as :func:`intervals.sonar.cone.sensor_verdicts`, vectorised over gathered
(box, segment, sensor) arrays instead of the kernel's scalar loops (module doc of
:mod:`intervals.sonar.cone` for the maths, and why the two agree bit for bit). The production
path never imports this module.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from intervals import interval as ia
from intervals.boxes import as_boxes
from intervals.errors import IntervalError
from intervals.sonar.cone import heading_trig
from intervals.sonar.geometry import ANGLE_MARGIN_RAD, GUARD_M, nearest_on_segment, segment_box_gap
from intervals.sonar.reference.geometry import (
    arc_reaches,
    clip_segment,
    point_box_farthest,
    wedge_constraints,
)
from intervals.sonar.scan import ECHO, FREE, IGNORED, SonarBelt, SonarScan

BLOCK_ELEMENTS = 1 << 18
"""Largest number of (box, segment, sensor) triples the reference evaluates at once."""


@dataclass(frozen=True)
class _SensorBoxes:
    """Per box and sensor ``(N, k)``: the sensor-position box (centre ``cx, cy``, half-widths
    ``hx, hy``), the two half-planes ``(nx, ny, c)`` holding ``S + W(Phi)`` (``union``; ``c =
    -inf`` where ``width(Phi) >= pi``) and the two holding the intersection of the wedges
    ``s + W(Psi)`` over ``s in S`` (``inter``), and ``sure``: ``Psi`` is not empty."""

    cx: np.ndarray
    cy: np.ndarray
    hx: np.ndarray
    hy: np.ndarray
    union: tuple
    inter: tuple
    sure: np.ndarray


def sensor_boxes(boxes: np.ndarray, belt: SonarBelt) -> _SensorBoxes:
    """The sensor-position boxes and wedge half-planes of every box and sensor (the kernel's
    ``sensor_rows``, :func:`intervals.sonar.cone_kernel.sensor_rows`)."""
    theta_lo, theta_hi = boxes[:, 2, 0], boxes[:, 2, 1]  # (N,)
    width = theta_hi - theta_lo
    limit = ia.TRIG_EXACT_LIMIT_RAD
    trusted = (np.abs(theta_lo) < limit) & (np.abs(theta_hi) < limit)
    full = ~trusted | (width >= 2.0 * np.pi - ANGLE_MARGIN_RAD)
    # angle addition: direction of theta + c for every box bound and sensor constant c
    cos_theta, sin_theta = heading_trig(boxes)
    cos_lo, sin_lo = cos_theta[:, 0:1], sin_theta[:, 0:1]  # (N, 1)
    cos_hi, sin_hi = cos_theta[:, 1:2], sin_theta[:, 1:2]
    cb, sb = belt.mount_trig

    def turned(c, s):  # ((N, k) x4): unit vectors at theta_lo + c and theta_hi + c
        return (
            cos_lo * c - sin_lo * s,
            sin_lo * c + cos_lo * s,
            cos_hi * c - sin_hi * s,
            sin_hi * c + cos_hi * s,
        )

    # sensor positions: x + r cos(theta + beta) over the arc [theta_lo, theta_hi] + beta
    ax, ay, bx, by = turned(cb, sb)
    half_turn = (width >= np.pi)[:, None]
    whole = full[:, None]
    reach = {
        axis: whole | arc_reaches(ax, ay, bx, by, *axis, half_turn)
        for axis in ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))
    }
    cos_min = np.where(reach[(-1.0, 0.0)], -1.0, np.minimum(ax, bx))
    cos_max = np.where(reach[(1.0, 0.0)], 1.0, np.maximum(ax, bx))
    sin_min = np.where(reach[(0.0, -1.0)], -1.0, np.minimum(ay, by))
    sin_max = np.where(reach[(0.0, 1.0)], 1.0, np.maximum(ay, by))
    r_lo, r_hi = belt.mount_radius_bounds
    margin = belt.sensor_box_margin_m
    x_lo = boxes[:, None, 0, 0] + np.minimum(r_lo * cos_min, r_hi * cos_min) - margin
    x_hi = boxes[:, None, 0, 1] + np.maximum(r_lo * cos_max, r_hi * cos_max) + margin
    y_lo = boxes[:, None, 1, 0] + np.minimum(r_lo * sin_min, r_hi * sin_min) - margin
    y_hi = boxes[:, None, 1, 1] + np.maximum(r_lo * sin_max, r_hi * sin_max) + margin
    cx, cy = (x_lo + x_hi) / 2.0, (y_lo + y_hi) / 2.0
    hx, hy = (x_hi - x_lo) / 2.0, (y_hi - y_lo) / 2.0
    # wedge edges: union over the box at theta_lo + alpha - gamma and theta_hi + alpha + gamma,
    # intersection at theta_hi + alpha - gamma and theta_lo + alpha + gamma
    (c_right, s_right), (c_left, s_left) = belt.cone_trig
    right_lo_x, right_lo_y, right_hi_x, right_hi_y = turned(c_right, s_right)
    left_lo_x, left_lo_y, left_hi_x, left_hi_y = turned(c_left, s_left)
    narrow = trusted & (width + 2.0 * belt.half_aperture_rad < np.pi - ANGLE_MARGIN_RAD)
    narrow = narrow[:, None]
    union = wedge_constraints(
        (right_lo_x, right_lo_y), (left_hi_x, left_hi_y), cx, cy, hx, hy, -1.0
    )
    union = tuple((nx, ny, np.where(narrow, c, -np.inf)) for nx, ny, c in union)
    inter = wedge_constraints((right_hi_x, right_hi_y), (left_lo_x, left_lo_y), cx, cy, hx, hy, 1.0)
    sure = trusted & (width < 2.0 * belt.half_aperture_rad - ANGLE_MARGIN_RAD)
    sure = np.broadcast_to(sure[:, None], cx.shape)
    return _SensorBoxes(cx, cy, hx, hy, union, tuple(inter), sure)


def sensor_verdicts(
    boxes, scan: SonarScan, inner: bool = True, validated: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`intervals.sonar.cone.sensor_verdicts` evaluated with numpy: ``(reject (N, k),
    certain (N, k))``, in blocks of boxes (its arrays grow with boxes x segments x sensors);
    ``validated`` as there."""
    if not validated:
        boxes = as_boxes(boxes)
        if boxes.shape[1] != 3:
            raise IntervalError(f"sonar test: pose boxes must be (N, 3, 2), got {boxes.shape}")
    block = max(1, BLOCK_ELEMENTS // max(1, scan.segments.shape[0] * scan.belt.count))
    parts = [
        _block_verdicts(boxes[start : start + block], scan, inner)
        for start in range(0, max(boxes.shape[0], 1), block)
    ]
    reject = np.concatenate([part[0] for part in parts])
    return reject, np.concatenate([part[1] for part in parts])


def _block_verdicts(boxes: np.ndarray, scan: SonarScan, inner: bool):
    """:func:`sensor_verdicts` of one block of boxes: every (box, visible segment, sensor)
    triple as gathered arrays."""
    n, k = boxes.shape[0], scan.belt.count
    lo_d, hi_d = scan.ranges[:, 0], scan.ranges[:, 1]
    echo, free = scan.kind == ECHO, scan.kind == FREE
    sb = sensor_boxes(boxes, scan.belt)

    # visible segments: pairs (box, segment) within reach of the hull of the sensor boxes
    seg = scan.segments
    sx_lo, sx_hi = (sb.cx - sb.hx).min(axis=1), (sb.cx + sb.hx).max(axis=1)
    sy_lo, sy_hi = (sb.cy - sb.hy).min(axis=1), (sb.cy + sb.hy).max(axis=1)
    gap = segment_box_gap(
        seg[:, 0, 0],
        seg[:, 0, 1],
        seg[:, 1, 0] - seg[:, 0, 0],
        seg[:, 1, 1] - seg[:, 0, 1],
        ((sx_lo + sx_hi) / 2)[:, None],
        ((sy_lo + sy_hi) / 2)[:, None],
        ((sx_hi - sx_lo) / 2)[:, None],
        ((sy_hi - sy_lo) / 2)[:, None],
    )
    box_idx, seg_idx = np.nonzero(gap <= scan.reach_m + GUARD_M)  # (P,) visible pairs
    ax, ay = seg[seg_idx, 0, 0][:, None], seg[seg_idx, 0, 1][:, None]  # (P, 1)
    ex, ey = seg[seg_idx, 1, 0][:, None] - ax, seg[seg_idx, 1, 1][:, None] - ay

    # stage 1, every (pair, sensor): the part [t0, t1] of the segment in S + W(Phi)
    union = tuple(tuple(v[box_idx] for v in h) for h in sb.union)
    t0, t1 = clip_segment(ax, ay, ex, ey, union, 0.0, 1.0)
    # stage 2, only the (pair, sensor) triples whose segment part is not empty and whose
    # sensor is used: nothing else can satisfy the hit test or fire the free-space test
    pair, sensor = np.nonzero((t0 <= t1) & (scan.kind != IGNORED))  # (T,)
    t0, t1 = t0[pair, sensor], t1[pair, sensor]
    box, j = box_idx[pair], seg_idx[pair]
    ax, ay = seg[j, 0, 0], seg[j, 0, 1]
    ex, ey = seg[j, 1, 0] - ax, seg[j, 1, 1] - ay
    cx, cy, hx, hy = sb.cx[box, sensor], sb.cy[box, sensor], sb.hx[box, sensor], sb.hy[box, sensor]
    lo_t, hi_t = lo_d[sensor], hi_d[sensor]

    # hit test: distance bounds between that part and the sensor box
    p0x, p0y = ax + t0 * ex, ay + t0 * ey
    dx, dy = (t1 - t0) * ex, (t1 - t0) * ey
    dist_lb = segment_box_gap(p0x, p0y, dx, dy, cx, cy, hx, hy) - GUARD_M
    dist_ub = (
        np.maximum(
            point_box_farthest(p0x, p0y, cx, cy, hx, hy),
            point_box_farthest(p0x + dx, p0y + dy, cx, cy, hx, hy),
        )
        + GUARD_M
    )
    hit_ok = (dist_lb <= hi_t) & (dist_ub >= lo_t)

    # free-space test: segment points inside the cone for every pose of the box (the
    # intersection of the wedges lies in their union, so these triples suffice); only where
    # Psi is not empty, elsewhere it cannot fire
    sure = sb.sure[box, sensor]
    far_bound = np.zeros(t0.shape)
    fs = np.flatnonzero(sure)
    if fs.size:
        b_fs, s_fs = box[fs], sensor[fs]
        inter = tuple(tuple(v[b_fs, s_fs] for v in h) for h in sb.inter)
        fax, fay, fex, fey = ax[fs], ay[fs], ex[fs], ey[fs]
        u0, u1 = clip_segment(fax, fay, fex, fey, inter, 0.0, 1.0)
        part = u0 <= u1
        sure[fs] = part
        u0, u1 = np.where(part, u0, 0.0), np.where(part, u1, 0.0)
        far_bound[fs] = (
            nearest_on_segment(
                cx[fs], cy[fs], fax + u0 * fex, fay + u0 * fey, (u1 - u0) * fex, (u1 - u0) * fey
            )[2]
            + np.hypot(hx[fs], hy[fs])
            + GUARD_M
        )  # >= |P - s| for every s of the sensor box
    free_fires = sure & (far_bound < lo_t)

    idx = box * k + sensor

    def any_pair(flags):
        return np.bincount(idx, weights=flags, minlength=n * k).reshape(n, k) > 0

    impossible = echo & (lo_d > hi_d)
    reject = (echo & (~any_pair(hit_ok) | impossible)) | ((echo | free) & any_pair(free_fires))
    certain = np.zeros((n, k), dtype=bool)
    if inner:
        too_close = np.where(free[sensor], dist_lb <= lo_t, dist_lb < lo_t)
        all_far = ~any_pair(too_close)
        sure_hit = any_pair(sure & (far_bound <= hi_t))
        certain = (echo & all_far & sure_hit & ~impossible) | (free & all_far)
        certain |= scan.kind == IGNORED
    return reject, certain
