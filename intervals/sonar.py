r"""Sound tests of the sonar cone model on pose boxes (MODELS.md sections 3-4, paper 002 s. 3).

Model. Sensor ``i`` sits at ``m_i`` in the robot frame and points along ``alpha_i``; for the pose
``p = (x, y, theta)`` it is at ``s_i(p) = (x, y) + R(theta) m_i`` and its cone holds the
directions ``[theta + alpha_i - gamma, theta + alpha_i + gamma]``. The modelled reading
``d_i(p)`` is the distance from ``s_i`` to the nearest map point inside the cone (``+inf`` if
none). A reading ``m`` with ``|e| <= e_abs + e_rel d`` gives the distance interval
``[d_i] = [(m - e_abs)/(1 + e_rel), (m + e_abs)/(1 - e_rel)]`` (outward rounded); a finite
reading also means ``d <= d_max`` (the simulator returns no echo beyond), so ``hi`` is capped at
``d_max``. A no-echo reading means ``d > d_max`` and is used (as ``[d_max, inf]``, free space)
only when the caller states that echoes are never lost; otherwise it is ignored.

Tests on a pose box ``[p] = [x] x [y] x [theta]`` for sensor ``i`` with ``[d_i] = [lo, hi]``.
Write ``S`` for a box enclosing ``{s_i(p) : p in [p]}``: ``[x] + |m_i| [c]`` etc., where
``[c]`` bounds ``cos`` over the arc ``[theta] + beta_i`` (its end values, or +-1 where the arc
passes an axis direction), then widened by ``SENSOR_BOX_MARGIN (1 + |m_i|)`` m (see below);
``Phi`` for the cone-direction interval ``[theta] + alpha_i + [-gamma, gamma]`` and ``Psi`` for
the directions in the cone for *every* ``theta`` of the box: ``[theta_hi + alpha_i - gamma,
theta_lo + alpha_i + gamma]`` (empty, i.e. not used, unless the box is narrower than
``2 gamma - 1e-9`` rad; ``width(Phi) < pi`` likewise only claimed with a ``1e-9`` rad margin).

* **Hit (data) test** (reject when it fails). If ``d_i(p) in [lo, hi]`` with ``hi`` finite,
  the nearest cone point ``P`` of some segment ``j`` satisfies ``P - s in W(Phi)`` (the wedge of
  directions ``Phi``, apex included) and ``|P - s| in [lo, hi]``. Relaxation (each step gives a
  superset, so rejection stays sound): let ``s`` range over ``S`` independently of the cone
  direction; then ``P`` lies in ``U = S + W(Phi)``, which, when ``width(Phi) < pi``, is contained
  in the two half-planes ``n_k . q >= min_{s in S} n_k . s`` (``n_k`` the inward normals of
  the wedge edges; for ``width(Phi) >= pi`` we use the whole plane). Clipping segment ``j`` to
  them gives a sub-segment ``seg'`` holding ``P``; hence ``dist(seg', S) <= |P - s| <= hi`` and
  ``max_{q in seg', s in S} |q - s| >= lo``. The box is rejected by sensor ``i`` when no segment
  passes both, evaluated with a lower bound of ``dist(seg', S)`` (``_segment_box_gap``) and an
  upper bound of the maximum (attained at an end of ``seg'`` and a corner of ``S``).
* **Free-space test** (reject when it fires). If ``P`` on a segment lies in
  ``W(s, Psi)`` for every ``s in S`` (the half-planes ``n_k . P >= max_{s in S} n_k . s``, an
  intersection of wedges, exact) and ``|P - c| + r < lo`` with ``c, r`` the centre and
  half-diagonal of ``S`` (so ``|P - s| < lo`` for every ``s in S``), then for every pose of the
  box ``P`` is in the cone closer than ``lo``, so ``d_i(p) < lo``: the box is infeasible.
* **Inner acceptance** (optional). Every pose of the box satisfies sensor ``i`` when
  ``dist(seg'_j, S) >= lo`` for every segment (so ``d_i >= lo``) and some segment has a point
  as in the free-space test with ``|P - c| + r <= hi`` (so ``d_i <= hi``); for a no-echo reading
  the first condition with ``> d_max`` suffices.
* **In-room test**: with a boundary polygon, a box whose (x, y) rectangle meets no boundary
  edge and whose centre is outside the polygon lies entirely outside the free space: rejected.
  (Inner when no edge meets it and the centre is inside.)
* Only segments within ``reach`` of the hull of the sensor boxes take part (``reach`` = the
  largest ``hi`` of an echo, or ``d_max`` when no-echo readings are used): farther segments can
  neither be hit within ``hi`` nor be closer than any ``lo``.
* **q-relaxation**: a box is OUTSIDE when the in-room test rejects it or more than ``q`` sensors
  reject it; INSIDE (if inner tests are on) when it is inside the room and at most ``q``
  sensors are not certainly satisfied; else UNDECIDED. GOMNE raises ``q`` from 0.

Floating point. The reading intervals are outward rounded with :mod:`intervals.interval`.
Directions ``theta + c`` (``c`` = ``beta_i``, ``alpha_i -+ gamma``) are unit vectors computed by
angle addition from ``cos``/``sin`` of the box's heading bounds and of the constants: each
component is off by a few ulps (below ``1e-15``). Hence the ends of the arcs in ``S`` are off by
less than ``1e-15 |m_i|`` m, and after adding ``[x]`` (``|x| <= 1e3``) by less than ``3e-13`` m,
far below the widening ``1e-9 (1 + |m_i|)`` m, so ``S`` holds every sensor position. Whether an
arc passes an axis direction ``e`` is decided from ``det(u_a, e)`` and ``det(e, u_b)`` with a
slack of ``1e-12`` towards "passes" (``_arc_reaches``), a thousand times their float error: a
passed direction is never missed, only a near-miss counted (a larger, still sound ``S``). A
wedge edge normal tilted by ``1e-15`` rad moves its half-plane by less than ``1e-15 * 3e3`` m
over the map, absorbed by ``GUARD_M`` below like every other predicate error.
The geometric predicates (half-plane clips,
distances) are evaluated in float64 on coordinates bounded by ``MAX_COORDINATE_M = 1e3`` m
(checked); each is a handful of operations, so a computed point or distance is off by
``delta <= 1e-12`` m (a few ulps of 1e3). The one amplified error is the direction used by
``_segment_box_gap``: tilted by at most ``2 delta / NEAR_SWITCH_M = 2e-10`` rad, which moves
its bound by at most ``2e-10 * 3e3 m = 6e-7`` m. Every comparison is biased in favour of keeping
the box by ``GUARD_M = 1e-5`` m, more than ten times these errors, so a float error never turns
a feasible box into a rejected one. A half-plane clip shifted by ``GUARD_M`` moves its boundary
by ``GUARD_M`` in space, whatever the angle between the segment and the boundary, and its
rounding error scales with the same angle.

Two implementations (:class:`intervals.engine.Engine`). The box tests (sensor tests and in-room test) run by
default in the compiled kernels of :mod:`intervals.sonar_kernel` (numba; one call per SIVIA
level, scalar loops over boxes, segments and sensors). The vectorised numpy code in this module
is their reference. The kernels evaluate the same formulas in the same order of float64
operations (compiled without ``fastmath``: no fused multiply-adds, no reassociation), with the
same constants and biases, on the same outward-rounded reading intervals, mount constants and
``cos``/``sin`` of the heading bounds (computed here by numpy and passed in), so their verdicts
are the reference's bit for bit and everything above holds for both (the tests compare 36,000
random boxes, about 1.7 million per-sensor verdicts and 108,000 box verdicts: none differs).
Had the kernel taken ``cos``/``sin`` from libm instead, the ulp or two by which they may differ
from numpy's would still lie inside the ``1e-15`` per component allowed above.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from intervals import interval as ia
from intervals import rays, sonar_kernel
from intervals.boxes import (
    DEFAULT_HEADING_SCALE_M_PER_RAD,
    Subpaving,
    as_boxes,
    hull,
    max_width,
    pose_scale,
)
from intervals.engine import Engine
from intervals.errors import IntervalError
from intervals.sivia import INSIDE, OUTSIDE, UNDECIDED, sivia
from intervals.sonar_kernel import ECHO, FREE, IGNORED  # kinds of sensor constraint

GUARD_M = 1e-5
"""Bias (metres) of every geometric comparison in favour of keeping a box (see module doc)."""

MAX_COORDINATE_M = 1e3
"""Largest map coordinate accepted: keeps float errors far below :data:`GUARD_M`."""

NEAR_SWITCH_M = 1e-2
"""Below this centre-to-segment distance the segment-box gap uses the triangle-inequality
bound, whose rounding error does not grow as the distance shrinks (see ``_segment_box_gap``)."""

MIN_LEVEL_BOXES = 128
"""SIVIA levels of fewer boxes are bisected more (see :func:`intervals.sivia.sivia`)."""

RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD = 0.1
"""With ``ray_test=None`` (auto), :mod:`intervals.rays` joins the box test when the belt's
half-aperture is at most this. Measured (``benchmarks/intervals_vs_codac.py``, tracking epochs
in ``hall``): the outer volume with the ray test over the volume without is 0.37-0.74 for
half-apertures of 0.003-0.1 rad but 0.90 for the default belt's 12.5 deg (0.22 rad), where it
costs about 5 ms an epoch (more than the rest of the epoch): worth it on thin cones, a choice
(``ray_test=True``) on wide ones."""

SENSOR_BOX_MARGIN = 1e-9
"""Relative widening of the sensor-position boxes (see :meth:`SonarBelt.sensor_box_margin_m`)."""

_ARC_SLACK = 1e-12
"""Slack of the arc-extremum decisions in :func:`_arc_reaches`, towards "reached"."""

_ANGLE_MARGIN_RAD = 1e-9
"""Margin of the heading-width decisions (``Psi`` not empty, ``width(Phi) < pi``, a full turn),
towards the larger, sound choice."""


@dataclass(frozen=True, eq=False)
class SonarBelt:
    """Geometry and error bounds of a sonar belt (same fields as ``robotsim``'s parameters).

    ``mount_xy (k, 2)`` robot frame, m; ``mount_angle_rad (k,)`` robot frame;
    ``half_aperture_rad`` in ``(0, pi/2)``; ``d_max_m`` range limit;
    ``|error| <= error_abs_bound_m + error_rel_bound * d``; ``echoes_never_lost``: a no-echo
    reading then proves free space up to ``d_max_m`` (only true when the sensor cannot lose an
    echo: see the team contract).
    """

    mount_xy: np.ndarray
    mount_angle_rad: np.ndarray
    half_aperture_rad: float
    d_max_m: float = 3.0
    error_abs_bound_m: float = 0.02
    error_rel_bound: float = 0.01
    echoes_never_lost: bool = False

    def __post_init__(self) -> None:
        xy = np.array(self.mount_xy, dtype=np.float64)
        ang = np.array(self.mount_angle_rad, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] == 0 or ang.shape != (xy.shape[0],):
            raise IntervalError(
                f"sonar belt: mount_xy must be (k, 2) and mount_angle_rad (k,), got "
                f"{xy.shape} and {ang.shape}"
            )
        if not (np.all(np.isfinite(xy)) and np.all(np.isfinite(ang))):
            raise IntervalError("sonar belt: mount positions and angles must be finite")
        checks = (
            (0.0 < self.half_aperture_rad < np.pi / 2, "half_aperture_rad must be in (0, pi/2)"),
            (0.0 < self.d_max_m < np.inf, "d_max_m must be positive and finite"),
            (0.0 <= self.error_abs_bound_m < np.inf, "error_abs_bound_m must be >= 0"),
            (0.0 <= self.error_rel_bound < 1.0, "error_rel_bound must be in [0, 1)"),
        )
        for ok, message in checks:
            if not ok:
                raise IntervalError(f"sonar belt: {message}")
        xy.setflags(write=False)
        ang.setflags(write=False)
        object.__setattr__(self, "mount_xy", xy)
        object.__setattr__(self, "mount_angle_rad", ang)

    @classmethod
    def from_params(cls, params, echoes_never_lost: bool | None = None) -> SonarBelt:
        """From any object with the fields of ``robotsim.sensors.sonar.SonarBeltParams``.

        ``echoes_never_lost`` defaults to ``params.lost_echo_prob == 0``.
        """
        if echoes_never_lost is None:
            echoes_never_lost = getattr(params, "lost_echo_prob", 1.0) == 0.0
        return cls(
            mount_xy=params.mount_xy,
            mount_angle_rad=params.mount_angle_rad,
            half_aperture_rad=float(params.half_aperture_rad),
            d_max_m=float(params.d_max_m),
            error_abs_bound_m=float(params.error_abs_bound_m),
            error_rel_bound=float(params.error_rel_bound),
            echoes_never_lost=bool(echoes_never_lost),
        )

    @property
    def count(self) -> int:
        """Number of sensors k."""
        return self.mount_angle_rad.shape[0]

    @cached_property
    def mount_polar(self) -> tuple[np.ndarray, np.ndarray]:
        """``(radius (k, 2), angle (k, 2))`` intervals of the mounts in polar form, robot frame:
        ``m_i = r_i (cos beta_i, sin beta_i)``; ``hypot`` and ``arctan2`` are within 1 ulp, the
        intervals are widened by 1 and 2 ulps."""
        radius = np.hypot(self.mount_xy[:, 0], self.mount_xy[:, 1])
        beta = np.arctan2(self.mount_xy[:, 1], self.mount_xy[:, 0])
        return (
            np.stack([np.maximum(_down(radius), 0.0), _up(radius)], axis=-1),
            np.stack([_down(_down(beta)), _up(_up(beta))], axis=-1),
        )

    @cached_property
    def mount_trig(self) -> tuple[np.ndarray, np.ndarray]:
        """``(cos beta_i, sin beta_i)`` ``(k,)`` of the mount directions (see
        :meth:`mount_polar`)."""
        beta = np.arctan2(self.mount_xy[:, 1], self.mount_xy[:, 0])
        return np.cos(beta), np.sin(beta)

    @cached_property
    def mount_radius_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(r_lo, r_hi)`` ``(k,)`` of the mount radii (see :meth:`mount_polar`)."""
        r = self.mount_polar[0]
        return r[:, 0], r[:, 1]

    @cached_property
    def cone_trig(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """``((cos, sin) of alpha_i - gamma, (cos, sin) of alpha_i + gamma)``, each ``(k,)``:
        the right and left cone edges in the robot frame."""
        right = self.mount_angle_rad - self.half_aperture_rad
        left = self.mount_angle_rad + self.half_aperture_rad
        return (np.cos(right), np.sin(right)), (np.cos(left), np.sin(left))

    @property
    def sensor_box_margin_m(self) -> float:
        """Widening of the computed sensor-position boxes: ``SENSOR_BOX_MARGIN`` times (1 m +
        the largest mount radius), far above their float error (see the module doc)."""
        return SENSOR_BOX_MARGIN * (1.0 + float(np.max(self.mount_polar[0][:, 1])))

    @cached_property
    def kernel_table(self) -> np.ndarray:
        """``(k, 8)`` float64, the constants the compiled kernel reads per sensor (columns
        named in :mod:`intervals.sonar_kernel`): ``cos beta_i, sin beta_i`` (:meth:`mount_trig`),
        ``r_lo, r_hi`` (:meth:`mount_radius_bounds`), and ``(cos, sin)`` of the right and left
        cone edges (:meth:`cone_trig`): the very values the numpy reference uses."""
        (c_right, s_right), (c_left, s_left) = self.cone_trig
        table = np.ascontiguousarray(
            np.column_stack(
                [*self.mount_trig, *self.mount_radius_bounds, c_right, s_right, c_left, s_left]
            )
        )
        table.setflags(write=False)
        return table


def _down(x):
    return np.nextafter(x, -np.inf)


def _up(x):
    return np.nextafter(x, np.inf)


def reading_intervals(readings_m, belt: SonarBelt) -> tuple[np.ndarray, np.ndarray]:
    """Distance intervals and constraint kinds from readings ``(k,)`` (``inf`` = no echo).

    Returns ``(ranges (k, 2), kind (k,) int8)``: for an echo
    ``[(m - e_abs)/(1 + e_rel), min((m + e_abs)/(1 - e_rel), d_max)]`` rounded outward (lower
    bound at least 0; an echo whose interval is empty cannot come from a fault-free sensor, it is
    marked by ``lo > hi`` and rejects every box); a no-echo reading gives ``[d_max, inf]`` of
    kind :data:`FREE` when ``belt.echoes_never_lost``, else kind :data:`IGNORED`.
    Raises :class:`IntervalError` for a wrong shape, NaN or negative readings.
    """
    m = np.asarray(readings_m, dtype=np.float64)
    if m.shape != (belt.count,):
        raise IntervalError(f"sonar readings: expected shape ({belt.count},), got {m.shape}")
    if np.any(np.isnan(m)) or np.any(m < 0) or np.any(m == -np.inf):
        raise IntervalError("sonar readings: NaN or negative reading (use inf for no echo)")
    echo = np.isfinite(m)
    mf = np.where(echo, m, 0.0)
    lo = _down(_down(mf - belt.error_abs_bound_m) / _up(1.0 + belt.error_rel_bound))
    hi = _up(_up(mf + belt.error_abs_bound_m) / _down(1.0 - belt.error_rel_bound))
    lo = np.maximum(lo, 0.0)
    hi = np.minimum(hi, belt.d_max_m)
    free = ~echo & belt.echoes_never_lost
    kind = np.where(echo, ECHO, np.where(free, FREE, IGNORED)).astype(np.int8)
    lo = np.where(echo, lo, np.where(free, belt.d_max_m, 0.0))
    hi = np.where(echo, hi, np.inf)
    return np.stack([lo, hi], axis=-1), kind


@dataclass(frozen=True, eq=False)
class SonarScan:
    """One scan's constraints against a map: everything the box tests need.

    ``segments (m, 2, 2)`` world frame, m; ``belt``; ``readings_m (k,)``; ``boundary (p, 2)``
    outer wall polygon whose interior is the free space, or None. Derived fields: ``ranges
    (k, 2)`` and ``kind (k,)`` from :func:`reading_intervals`; ``reach_m``: the largest distance
    at which a segment can matter to some sensor (0 if no sensor is used).
    """

    segments: np.ndarray
    belt: SonarBelt
    readings_m: np.ndarray
    boundary: np.ndarray | None = None
    ranges: np.ndarray = field(init=False)
    kind: np.ndarray = field(init=False)
    reach_m: float = field(init=False)

    def __post_init__(self) -> None:
        seg = np.array(self.segments, dtype=np.float64)
        if seg.ndim != 3 or seg.shape[1:] != (2, 2):
            raise IntervalError(f"sonar scan: segments must be (m, 2, 2), got {seg.shape}")
        if not np.all(np.abs(seg) <= MAX_COORDINATE_M):
            raise IntervalError(
                f"sonar scan: segment coordinates must be finite, |.| <= {MAX_COORDINATE_M} m"
            )
        boundary = None
        if self.boundary is not None:
            boundary = np.array(self.boundary, dtype=np.float64)
            if boundary.ndim != 2 or boundary.shape[1] != 2 or boundary.shape[0] < 3:
                raise IntervalError(
                    f"sonar scan: boundary must be (p >= 3, 2), got {boundary.shape}"
                )
            if not np.all(np.abs(boundary) <= MAX_COORDINATE_M):
                raise IntervalError("sonar scan: boundary coordinates must be finite and bounded")
        ranges, kind = reading_intervals(self.readings_m, self.belt)
        object.__setattr__(self, "segments", seg)
        object.__setattr__(self, "boundary", boundary)
        object.__setattr__(self, "readings_m", np.asarray(self.readings_m, dtype=np.float64))
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "kind", kind)
        used = kind != IGNORED
        reach = np.where(kind == ECHO, ranges[:, 1], self.belt.d_max_m)
        object.__setattr__(self, "reach_m", float(np.max(reach[used])) if used.any() else 0.0)

    def restricted_to(self, boxes: np.ndarray) -> SonarScan:
        """The same scan with only the segments that can matter to poses in ``boxes``."""
        hull_xy = hull(as_boxes(boxes))[:2]
        radius = float(np.max(np.hypot(*self.belt.mount_xy.T)))
        a, e = self.segments[:, 0], self.segments[:, 1] - self.segments[:, 0]
        centre, half = (hull_xy[:, 0] + hull_xy[:, 1]) / 2, (hull_xy[:, 1] - hull_xy[:, 0]) / 2
        gap = _segment_box_gap(a[:, 0], a[:, 1], e[:, 0], e[:, 1], *centre, *half)
        near = gap <= self.reach_m + radius + GUARD_M
        return SonarScan(self.segments[near], self.belt, self.readings_m, self.boundary)


# ---------------------------------------------------------------------------------------------
# Vectorised geometric primitives on component arrays (x and y separately, broadcast shapes).
# Boxes are given by centre (cx, cy) and half-widths (hx, hy): a box [lo, hi] is enclosed by
# [c - h, c + h] up to one rounding of (lo + hi)/2 and (hi - lo)/2, far below GUARD_M.


def _nearest_on_segment(px, py, ax, ay, ex, ey):
    """Nearest point of segments ``a + t e, t in [0, 1]`` to points ``p``: ``(qx, qy, dist)``."""
    ee = ex * ex + ey * ey
    t = ((px - ax) * ex + (py - ay) * ey) / np.where(ee > 0, ee, 1.0)
    t = np.clip(t, 0.0, 1.0)
    qx, qy = ax + t * ex, ay + t * ey
    return qx, qy, np.hypot(qx - px, qy - py)


def _segment_box_gap(ax, ay, ex, ey, cx, cy, hx, hy):
    """Lower bound of the distance between segments ``a + t e`` and boxes ``(c, h)``.

    For any unit vector ``u``, ``dist(seg, box) >= min_seg u.q - max_box u.s``; we take ``u``
    from the box centre towards the nearest segment point ``q*``, for which
    ``min_seg u.q = u.q*`` (projection property of the nearest point of a convex set), so the
    bound is ``|q* - c| - (|u_x| h_x + |u_y| h_y)``: exact in most configurations. A rounding
    error ``delta`` in ``q*`` tilts ``u`` by ``delta / |q* - c|`` and moves that identity by at
    most the tilt times the segment's extent; below ``NEAR_SWITCH_M`` we therefore use the
    always-valid ``|q* - c| - |h|`` (triangle inequality) instead (see the module doc).
    """
    qx, qy, dist = _nearest_on_segment(cx, cy, ax, ay, ex, ey)
    far = dist >= NEAR_SWITCH_M
    safe = np.where(far, dist, 1.0)
    spread = np.abs(qx - cx) / safe * hx + np.abs(qy - cy) / safe * hy
    return dist - np.where(far, spread, np.hypot(hx, hy))


def _point_box_farthest(px, py, cx, cy, hx, hy):
    """Largest distance from points to the points of boxes ``(c, h)``."""
    return np.hypot(np.abs(px - cx) + hx, np.abs(py - cy) + hy)


def _clip_segment(ax, ay, ex, ey, constraints, t_lo, t_hi):
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


def _wedge_constraints(u_lo, u_hi, cx, cy, hx, hy, sign):
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


# ---------------------------------------------------------------------------------------------


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


def _arc_reaches(ux_a, uy_a, ux_b, uy_b, ex, ey, half_turn):
    """Whether the arc of directions swept counter-clockwise from ``u_a`` to ``u_b`` (unit
    vectors) holds the direction ``e`` (a unit axis vector ``(ex, ey)``). ``half_turn``: the arc
    is at least pi wide (then it misses ``e`` only when ``e`` is strictly inside the
    complementary arc from ``u_b`` to ``u_a``). Decided with a slack of ``_ARC_SLACK`` towards
    "reached": a wrong "not reached" can only happen within ``1e-12`` rad of an end of the arc,
    where the extreme value differs from the end's by less than ``1e-24``."""
    det_a = ux_a * ey - uy_a * ex  # det(u_a, e)
    det_b = ex * uy_b - ey * ux_b  # det(e, u_b)
    narrow = (det_a >= -_ARC_SLACK) & (det_b >= -_ARC_SLACK)
    return np.where(half_turn, ~((det_a < -_ARC_SLACK) & (det_b < -_ARC_SLACK)), narrow)


def _heading_trig(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cos, sin)`` ``(N, 2)`` of the heading bounds of boxes ``(N, 3, 2)``: the one source of
    these values for both engines (so they see the same directions)."""
    theta = boxes[:, 2]
    return np.cos(theta), np.sin(theta)


def _sensor_boxes(boxes: np.ndarray, belt: SonarBelt) -> _SensorBoxes:
    theta_lo, theta_hi = boxes[:, 2, 0], boxes[:, 2, 1]  # (N,)
    width = theta_hi - theta_lo
    limit = ia.TRIG_EXACT_LIMIT_RAD
    trusted = (np.abs(theta_lo) < limit) & (np.abs(theta_hi) < limit)
    full = ~trusted | (width >= 2.0 * np.pi - _ANGLE_MARGIN_RAD)
    # angle addition: direction of theta + c for every box bound and sensor constant c
    cos_theta, sin_theta = _heading_trig(boxes)
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
        axis: whole | _arc_reaches(ax, ay, bx, by, *axis, half_turn)
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
    narrow = trusted & (width + 2.0 * belt.half_aperture_rad < np.pi - _ANGLE_MARGIN_RAD)
    narrow = narrow[:, None]
    union = _wedge_constraints(
        (right_lo_x, right_lo_y), (left_hi_x, left_hi_y), cx, cy, hx, hy, -1.0
    )
    union = tuple((nx, ny, np.where(narrow, c, -np.inf)) for nx, ny, c in union)
    inter = _wedge_constraints(
        (right_hi_x, right_hi_y), (left_lo_x, left_lo_y), cx, cy, hx, hy, 1.0
    )
    sure = trusted & (width < 2.0 * belt.half_aperture_rad - _ANGLE_MARGIN_RAD)
    sure = np.broadcast_to(sure[:, None], cx.shape)
    return _SensorBoxes(cx, cy, hx, hy, union, tuple(inter), sure)


def _room_verdict(
    boxes: np.ndarray, boundary: np.ndarray, engine: str
) -> tuple[np.ndarray, np.ndarray]:
    """``(outside (N,), inside (N,))``: the (x, y) rectangle lies entirely outside / inside the
    boundary polygon: no edge comes within ``GUARD_M`` of it (sound lower bound of the
    distance) and the ray cast from its centre says outside / inside. ``engine`` as in
    :func:`sensor_verdicts` (the numpy code below is the reference)."""
    if engine == Engine.COMPILED:
        n = boxes.shape[0]
        outside, inside = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        sonar_kernel.room_verdicts_into(
            np.ascontiguousarray(boxes, dtype=np.float64),
            boundary,
            GUARD_M,
            NEAR_SWITCH_M,
            outside,
            inside,
        )
        return outside, inside
    a = boundary
    e = np.roll(boundary, -1, axis=0) - a
    cx = ((boxes[:, 0, 0] + boxes[:, 0, 1]) / 2.0)[:, None]
    cy = ((boxes[:, 1, 0] + boxes[:, 1, 1]) / 2.0)[:, None]
    hx = ((boxes[:, 0, 1] - boxes[:, 0, 0]) / 2.0)[:, None]
    hy = ((boxes[:, 1, 1] - boxes[:, 1, 0]) / 2.0)[:, None]
    gap = _segment_box_gap(a[:, 0], a[:, 1], e[:, 0], e[:, 1], cx, cy, hx, hy)
    clear = np.all(gap > GUARD_M, axis=1)
    # ray casting to +x; reliable because the centre is more than GUARD_M from every edge
    ay, by = a[:, 1], a[:, 1] + e[:, 1]
    crosses = (ay > cy) != (by > cy)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = a[:, 0] + (cy - ay) * e[:, 0] / e[:, 1]
    inside = (np.count_nonzero(crosses & (x_cross > cx), axis=1) % 2) == 1
    return clear & ~inside, clear & inside


def sensor_verdicts(
    boxes, scan: SonarScan, inner: bool = True, engine: str = "compiled"
) -> tuple[np.ndarray, np.ndarray]:
    """Per box and sensor: ``(reject (N, k), certain (N, k))`` bool arrays.

    ``reject``: the sensor's reading is inconsistent with every pose of the box (hit test fails
    or free-space test fires). ``certain``: the reading is consistent with every pose of the box
    (only computed when ``inner``; else all False). Ignored sensors never reject and are always
    certain (when ``inner``). See the module doc for the tests and their soundness.
    ``engine``: an :class:`~intervals.engine.Engine`; ``"compiled"`` runs :mod:`intervals.sonar_kernel` (one
    call for all boxes), ``"numpy"`` the vectorised reference below (same results).
    """
    boxes = as_boxes(boxes)
    if boxes.shape[1] != 3:
        raise IntervalError(f"sonar test: pose boxes must be (N, 3, 2), got {boxes.shape}")
    if engine not in tuple(Engine):
        raise IntervalError(
            f"sonar test: engine must be one of {', '.join(Engine)}, got {engine!r}"
        )
    if engine == Engine.NUMPY:
        return _numpy_sensor_verdicts(boxes, scan, inner)
    n, k = boxes.shape[0], scan.belt.count
    reject, certain = np.empty((n, k), dtype=bool), np.empty((n, k), dtype=bool)
    belt, boxes = scan.belt, np.ascontiguousarray(boxes)  # one compiled signature: C order
    sonar_kernel.sensor_verdicts_into(
        boxes,
        *_heading_trig(boxes),
        scan.segments,
        scan.ranges,
        scan.kind,
        scan.reach_m,
        belt.kernel_table,
        belt.half_aperture_rad,
        belt.sensor_box_margin_m,
        GUARD_M,
        NEAR_SWITCH_M,
        _ARC_SLACK,
        _ANGLE_MARGIN_RAD,
        ia.TRIG_EXACT_LIMIT_RAD,
        bool(inner),
        reject,
        certain,
    )
    return reject, certain


def _numpy_sensor_verdicts(boxes: np.ndarray, scan: SonarScan, inner: bool):
    """The numpy reference of :func:`sensor_verdicts`: every (box, visible segment, sensor)
    triple as gathered arrays."""
    n, k = boxes.shape[0], scan.belt.count
    lo_d, hi_d = scan.ranges[:, 0], scan.ranges[:, 1]
    echo, free = scan.kind == ECHO, scan.kind == FREE
    sb = _sensor_boxes(boxes, scan.belt)

    # visible segments: pairs (box, segment) within reach of the hull of the sensor boxes
    seg = scan.segments
    sx_lo, sx_hi = (sb.cx - sb.hx).min(axis=1), (sb.cx + sb.hx).max(axis=1)
    sy_lo, sy_hi = (sb.cy - sb.hy).min(axis=1), (sb.cy + sb.hy).max(axis=1)
    gap = _segment_box_gap(
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
    t0, t1 = _clip_segment(ax, ay, ex, ey, union, 0.0, 1.0)
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
    dist_lb = _segment_box_gap(p0x, p0y, dx, dy, cx, cy, hx, hy) - GUARD_M
    dist_ub = (
        np.maximum(
            _point_box_farthest(p0x, p0y, cx, cy, hx, hy),
            _point_box_farthest(p0x + dx, p0y + dy, cx, cy, hx, hy),
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
        u0, u1 = _clip_segment(fax, fay, fex, fey, inter, 0.0, 1.0)
        part = u0 <= u1
        sure[fs] = part
        u0, u1 = np.where(part, u0, 0.0), np.where(part, u1, 0.0)
        far_bound[fs] = (
            _nearest_on_segment(
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


def _test_and_counts(boxes, scan: SonarScan, q: int, inner: bool, engine: str):
    """``(verdicts (N,) int8, rejects (N,), reject (N, k) bool)``: :func:`box_test`, the number
    of sensors rejecting each box, and which."""
    reject, certain = sensor_verdicts(boxes, scan, inner, engine)
    rejects = np.count_nonzero(reject, axis=1)
    out = rejects > q
    inside = np.count_nonzero(~certain, axis=1) <= q if inner else np.zeros(out.shape, bool)
    if scan.boundary is not None:
        # the in-room test only matters for the boxes the sensors do not reject
        live = np.flatnonzero(~out)
        room_out, room_in = _room_verdict(boxes[live], scan.boundary, engine)
        out[live] |= room_out
        inside[live] &= room_in
    verdicts = np.where(out, OUTSIDE, np.where(inside, INSIDE, UNDECIDED)).astype(np.int8)
    return verdicts, rejects, reject


def box_test(
    boxes, scan: SonarScan, q: int = 0, inner: bool = True, engine: str = "compiled"
) -> np.ndarray:
    """SIVIA test ``(N,) int8``: OUTSIDE when the in-room test or more than ``q`` sensors reject
    the box, INSIDE when (``inner``) it is inside the room and at most ``q`` sensors are not
    certainly satisfied, else UNDECIDED. ``engine``: see :func:`sensor_verdicts`."""
    return _test_and_counts(as_boxes(boxes), scan, q, inner, engine)[0]


def _checked_q(q) -> None:
    if not (isinstance(q, (int, np.integer)) and q >= 0):
        raise IntervalError(f"q must be a non-negative integer, got {q!r}")


def _initial_poses(initial) -> np.ndarray:
    boxes = as_boxes(initial, "initial pose boxes")
    if boxes.shape[1] != 3:
        raise IntervalError(f"initial pose boxes must be (N, 3, 2), got {boxes.shape}")
    return boxes


def _uses_ray_test(ray_test: bool | None, belt: SonarBelt) -> bool:
    """Whether the ray test joins the box test (``None``: by the belt's aperture, see
    :data:`RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD`)."""
    if ray_test is None:
        return belt.half_aperture_rad <= RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD
    if not isinstance(ray_test, bool):
        raise IntervalError(f"ray_test must be True, False or None (auto), got {ray_test!r}")
    return ray_test


def _pave(local: SonarScan, boxes, eps, q, scale, inner, splits_per_level, engine, ray_test):
    """SIVIA on ``boxes`` at relaxation ``q``: ``(paving, rejects (Nb,))`` with the number of
    sensors rejecting each boundary box, kept from the SIVIA level that stored the box (the
    boundary boxes are the undecided boxes no wider than ``eps``, in the order SIVIA met
    them; checked, and recomputed if SIVIA ever stored them otherwise).

    With ``ray_test`` the boxes SIVIA would store are also tested by
    :func:`intervals.rays.joint_rejection_counts` (pieces of the box, each rejected by the
    ray test or the cone test of its sensors): a box whose every piece is rejected by more
    than ``q`` sensors holds no pose with at most ``q`` bad readings, so it is OUTSIDE. Its
    count is never below the cone test's, so GOMNE's ``count <= q`` sets stay sound. Only the
    stored boxes are tested: rejecting those is all that changes the outer set (testing every
    level gave the same volumes at twice the time).
    """
    stored, counts = [], []

    def recount(b, reject):
        return rays.joint_rejection_counts(
            b, local, rays.DEFAULT_PIECES, other=reject, engine=engine
        )

    def test(b):
        verdicts, rejects, reject = _test_and_counts(b, local, q, inner, engine)
        keep = (verdicts == UNDECIDED) & (max_width(b, scale) <= eps)
        if ray_test and (idx := np.flatnonzero(keep)).size:
            rejects[idx] = recount(b[idx], reject[idx])
            out = idx[rejects[idx] > q]
            verdicts[out] = OUTSIDE
            keep[out] = False
        stored.append(b[keep])
        counts.append(rejects[keep])
        return verdicts

    paving = sivia(
        test, boxes, eps, scale, splits_per_level=splits_per_level, min_level_boxes=MIN_LEVEL_BOXES
    )
    rejects = np.concatenate(counts)
    if not np.array_equal(np.concatenate(stored), paving.boundary):
        reject = sensor_verdicts(paving.boundary, local, False, engine)[0]
        rejects = recount(paving.boundary, reject) if ray_test else np.count_nonzero(reject, axis=1)
    return paving, rejects


def localize(
    scan: SonarScan,
    initial,
    eps: float,
    q: int = 0,
    heading_scale_m_per_rad: float = DEFAULT_HEADING_SCALE_M_PER_RAD,
    inner: bool = False,
    splits_per_level: int = 3,
    engine: str = "compiled",
    ray_test: bool | None = None,
) -> Subpaving:
    """Pose set ``{p in initial : at most q sensors inconsistent}`` paved by SIVIA.

    ``initial``: a pose box ``(3, 2)`` or a subpaving ``(N, 3, 2)``. Only the segments within
    reach of the initial boxes take part. Levels of fewer than :data:`MIN_LEVEL_BOXES` boxes
    are bisected further before the test (see :func:`intervals.sivia.sivia`).
    ``inner=False`` (default) skips the inner acceptance
    test: the outer approximation is what the fusion uses, and it is cheaper.
    ``engine``: the implementation of the box test (see :func:`sensor_verdicts`).
    ``ray_test``: add :mod:`intervals.rays` to the test of the boxes kept (``None``: when the
    cones are thin, :data:`RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD`).
    """
    _checked_q(q)
    boxes = _initial_poses(initial)
    scale = pose_scale(heading_scale_m_per_rad)
    local = scan.restricted_to(boxes)
    return _pave(
        local,
        boxes,
        eps,
        q,
        scale,
        inner,
        splits_per_level,
        engine,
        _uses_ray_test(ray_test, scan.belt),
    )[0]


@dataclass(frozen=True)
class GomneResult:
    """Outcome of :func:`gomne`.

    ``q``: GOMNE's estimate, the smallest number of outliers that leaves a non-empty set (None
    when even ``q_max`` leaves it empty: the data are inconsistent); ``q_set``: the relaxation
    of the returned ``paving`` (``q_max`` when guaranteed, else ``q``).
    """

    paving: Subpaving
    q: int | None
    q_set: int | None

    @property
    def consistent(self) -> bool:
        """False when no ``q <= q_max`` explains the data (never clamp to this set)."""
        return self.q is not None


def gomne(
    scan: SonarScan,
    initial,
    eps: float,
    q_max: int,
    heading_scale_m_per_rad: float = DEFAULT_HEADING_SCALE_M_PER_RAD,
    inner: bool = False,
    guaranteed: bool = True,
    engine: str = "compiled",
    ray_test: bool | None = None,
) -> GomneResult:
    """GOMNE: the smallest ``q <= q_max`` whose q-relaxed set is not empty.

    The sets are nested (``S_0 ⊆ S_1 ⊆ ... ⊆ S_qmax``), so ``S_qmax`` is paved first (empty:
    inconsistent, stop); without inner boxes ``S_q`` is read off the number of sensors rejecting
    each of its boxes, recorded during that pass; with them ``q = 0, 1, ...`` are tried on its
    boxes (a SIVIA pass each).

    ``guaranteed=True`` returns ``S_qmax``: it holds the true pose whenever at most ``q_max``
    readings are outliers. GOMNE's own set ``S_q`` (``guaranteed=False``) is smaller but can
    miss the truth: outliers that happen to agree with some other pose make fewer than the
    actual number of outliers suffice, and ``S_q`` then holds only those other poses.
    ``engine`` and ``ray_test``: as in :func:`localize`.
    """
    if not (isinstance(q_max, (int, np.integer)) and 0 <= q_max <= scan.belt.count):
        raise IntervalError(f"q_max must be an integer in [0, {scan.belt.count}], got {q_max!r}")
    boxes = _initial_poses(initial)
    scale = pose_scale(heading_scale_m_per_rad)
    local = scan.restricted_to(boxes)
    widest, rejects = _pave(
        local, boxes, eps, q_max, scale, inner, 3, engine, _uses_ray_test(ray_test, scan.belt)
    )
    if widest.is_empty:
        return GomneResult(widest, None, None)
    if inner:
        for q in range(q_max):
            minimal = localize(
                scan,
                widest.outer,
                eps,
                q,
                heading_scale_m_per_rad,
                inner,
                engine=engine,
                ray_test=ray_test,
            )
            if not minimal.is_empty:
                break
        else:
            q, minimal = q_max, widest
    else:
        # Every box of S_qmax is then a boundary box no wider than eps that passed the
        # in-room test: SIVIA at q < q_max on them would keep exactly those rejected by at most
        # q sensors, so the reject counts of the q_max pass give every S_q without a new pass.
        q = int(min(rejects.min(), q_max))
        minimal = Subpaving(widest.inner, widest.boundary[rejects <= q])
    return GomneResult(widest if guaranteed else minimal, q, q_max if guaranteed else q)
