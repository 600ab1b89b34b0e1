"""The sonar belt: the exact cone distance model and simulated readings with bounded errors.

Model (docs/models.md section 3; paper 002 fig. 3 after Kieffer et al. 2000). Sensor i sits at
``s~_i`` in the robot frame and points along ``theta~_i``; in the world
``s_i = (x, y) + R(theta) s~_i`` and its cone holds the directions
``[theta + theta~_i - gamma, theta + theta~_i + gamma]``. The modelled distance is

    d_i(p) = min_j r(s_i, cone_i, [a_j, b_j])        (+inf if no segment meets the cone)

where ``r`` is the distance from ``s_i`` to the nearest point of segment j inside the cone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from robotsim.errors import RobotsimError
from validated_records import bounded, validate_fields

#: Relative slack of the inside-the-cone and on-the-segment tests: a point on a cone edge
#: is kept by both the point test and the edge-ray test, so rounding cannot lose it.
_SLACK = 1e-12

#: Upper bound on the elements of one broadcast block (poses x sensors x segments).
_BLOCK_ELEMENTS = 1 << 20


def _det(u_x, u_y, w_x, w_y):
    """2-D determinant ``det(u, w) = u_x w_y - u_y w_x`` (broadcast)."""
    return u_x * w_y - u_y * w_x


def _inside_cone(w_x, w_y, c_x, c_y, cos_gamma):
    """Whether offset ``w`` from the apex lies in the cone of axis ``c`` (unit), half-angle
    gamma < pi/2: ``w . c >= |w| cos(gamma)`` (the apex itself counts as inside)."""
    return w_x * c_x + w_y * c_y >= np.hypot(w_x, w_y) * (cos_gamma - _SLACK)


def _cone_distances_block(
    s_x: np.ndarray,
    s_y: np.ndarray,
    axis: tuple[np.ndarray, np.ndarray],
    edges: tuple[tuple[np.ndarray, np.ndarray], ...],
    a: np.ndarray,
    e: np.ndarray,
    cos_gamma: float,
) -> np.ndarray:
    """Cone distances ``(...)`` for sensor positions ``s_x, s_y (..., 1)``, the unit cone
    axes ``axis = (c_x, c_y)`` and the unit edge rays ``edges = ((u_x, u_y), (u_x, u_y))``
    (``phi -/+ gamma``; each like ``s_x``), and segments ``a`` (start) and ``e = b - a``
    (each ``(m, 2)``, or ``(..., m, 2)``: per pose): the minimum over the last axis."""
    a_x, a_y, e_x, e_y = a[..., 0], a[..., 1], e[..., 0], e[..., 1]
    c_x, c_y = axis
    # offsets from the sensor to the segment start, (..., m)
    w_x, w_y = a_x - s_x, a_y - s_y
    best = np.full(np.broadcast_shapes(w_x.shape), np.inf)

    # candidates 1 and 2: the segment's end points a and b inside the cone
    for off_x, off_y in ((w_x, w_y), (w_x + e_x, w_y + e_y)):
        inside = _inside_cone(off_x, off_y, c_x, c_y, cos_gamma)
        best = np.where(inside, np.minimum(best, np.hypot(off_x, off_y)), best)

    # candidate 3: the foot of the perpendicular a + t (b - a), t = (s - a).e / |e|^2
    t = -(w_x * e_x + w_y * e_y) / (e_x * e_x + e_y * e_y)
    foot_x, foot_y = w_x + t * e_x, w_y + t * e_y
    keep = (t >= 0.0) & (t <= 1.0) & _inside_cone(foot_x, foot_y, c_x, c_y, cos_gamma)
    best = np.where(keep, np.minimum(best, np.hypot(foot_x, foot_y)), best)

    # candidates 4 and 5: each edge ray u meets the segment at
    # rho = det(a - s, e) / det(u, e) (along the ray), tau = det(a - s, u) / det(u, e)
    det_w_e = _det(w_x, w_y, e_x, e_y)
    for u_x, u_y in edges:
        denominator = _det(u_x, u_y, e_x, e_y)
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = det_w_e / denominator
            tau = _det(w_x, w_y, u_x, u_y) / denominator
        hit = (denominator != 0.0) & (rho >= 0.0) & (tau >= -_SLACK) & (tau <= 1.0 + _SLACK)
        best = np.where(hit, np.minimum(best, rho), best)
    return best.min(axis=-1)


#: Segments each pose looks at first on a large map (:func:`_near_cone_distances`).
NEAR_SEGMENTS = 32

#: Maps of more segments than this are computed nearest first; smaller ones whole (one
#: scan of 16 sonars on 60 segments: 0.2 ms whole, 0.7 ms nearest first; on 495: 2.6 ms
#: whole, 0.26 ms nearest first).
LARGE_MAP_SEGMENTS = 4 * NEAR_SEGMENTS


def cone_distances(
    poses: Any,
    segments: Any,
    mount_xy: Any,
    mount_angle_rad: Any,
    half_aperture_rad: float,
) -> np.ndarray:
    """Exact distance from each sonar to the nearest map point inside its cone.

    Args:
        poses: ``(..., 3)`` robot poses ``(x_m, y_m, theta_rad)``, world frame.
        segments: ``(m, 2, 2)`` map segments, metres, world frame; or ``(n, m, 2, 2)``, the
            segments seen from each of ``n`` poses (``poses (n, 3)``: a world that moves).
        mount_xy: ``(k, 2)`` sensor positions, robot frame, metres.
        mount_angle_rad: ``(k,)`` sensor axis angles, robot frame.
        half_aperture_rad: cone half-angle gamma, ``0 < gamma < pi/2``.

    Returns:
        ``(..., k)`` distances in metres, ``np.inf`` where no segment meets the cone. No
        range limit is applied here.

    Vectorised over poses, sensors and segments (broadcast arrays); large batches are cut
    into blocks of at most about a million pose-sensor-segment elements to bound memory.
    On a map of more than :data:`LARGE_MAP_SEGMENTS` segments each pose looks at its
    nearest ones first (:func:`_near_cone_distances`); the result is the same, bit for bit.
    """
    poses = np.asarray(poses, dtype=np.float64)
    segments = np.asarray(segments, dtype=np.float64)
    mount_xy = np.asarray(mount_xy, dtype=np.float64)
    mount_angle_rad = np.asarray(mount_angle_rad, dtype=np.float64)
    if poses.shape[-1:] != (3,):
        raise RobotsimError(f"poses must have shape (..., 3), got {poses.shape}")
    per_pose = segments.ndim == 4
    if segments.shape[-2:] != (2, 2) or segments.ndim not in (3, 4):
        raise RobotsimError(f"segments must have shape (m, 2, 2), got {segments.shape}")
    if per_pose and (poses.ndim != 2 or len(segments) != len(poses)):
        raise RobotsimError(
            f"per-pose segments (n, m, 2, 2) need poses (n, 3), got {segments.shape} and {poses.shape}"
        )
    if (
        mount_xy.ndim != 2
        or mount_xy.shape[1] != 2
        or mount_angle_rad.shape != mount_xy[:, 0].shape
    ):
        raise RobotsimError(
            f"mount_xy must be (k, 2) and mount_angle_rad (k,), got {mount_xy.shape} and "
            f"{mount_angle_rad.shape}"
        )
    if not 0.0 < half_aperture_rad < np.pi / 2:
        raise RobotsimError(f"half_aperture_rad must be in (0, pi/2), got {half_aperture_rad}")

    batch_shape = poses.shape[:-1]
    flat = poses.reshape(-1, 3)
    k, m = len(mount_angle_rad), segments.shape[-3]
    out = np.full((len(flat), k), np.inf)
    if m == 0:
        return out.reshape(*batch_shape, k)
    x, y, theta = (flat[:, i, None] for i in range(3))  # (n, 1)
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    # s_i = (x, y) + R(theta) s~_i, axis phi_i = theta + theta~_i; shapes (n, k, 1)
    s_x = (x + cos_t * mount_xy[:, 0] - sin_t * mount_xy[:, 1])[..., None]
    s_y = (y + sin_t * mount_xy[:, 0] + cos_t * mount_xy[:, 1])[..., None]
    phi = (theta + mount_angle_rad)[..., None]
    # the cone's axis and edge rays, computed once per (pose, sensor): every segment and
    # every subset of them sees the same directions
    axis = (np.cos(phi), np.sin(phi))
    edges = tuple(
        (np.cos(edge), np.sin(edge)) for edge in (phi - half_aperture_rad, phi + half_aperture_rad)
    )
    cone = _Cones(s_x, s_y, axis, edges, float(np.cos(half_aperture_rad)))
    a, e = segments[..., 0, :], segments[..., 1, :] - segments[..., 0, :]

    if not per_pose and m > LARGE_MAP_SEGMENTS:
        reach_m = float(np.hypot(mount_xy[:, 0], mount_xy[:, 1]).max())
        block = max(1, _BLOCK_ELEMENTS // max(1, m * (k + 1)))
        for start in range(0, len(flat), block):
            rows = slice(start, start + block)
            out[rows] = _near_cone_distances(cone, rows, flat[rows, :2], a, e, reach_m)
        return out.reshape(*batch_shape, k)
    block = max(1, _BLOCK_ELEMENTS // max(1, k * m))
    for start in range(0, len(flat), block):
        rows = slice(start, start + block)
        a_rows, e_rows = (a[rows, None], e[rows, None]) if per_pose else (a, e)
        out[rows] = cone.distances(rows, a_rows, e_rows)
    return out.reshape(*batch_shape, k)


@dataclass(frozen=True, eq=False)
class _Cones:
    """The cones of ``n`` poses x ``k`` sensors: apexes ``s_x, s_y``, unit axes and unit edge
    rays, each ``(n, k, 1)``, and ``cos(gamma)``."""

    s_x: np.ndarray
    s_y: np.ndarray
    axis: tuple[np.ndarray, np.ndarray]
    edges: tuple[tuple[np.ndarray, np.ndarray], ...]
    cos_gamma: float

    def distances(self, index, a: np.ndarray, e: np.ndarray) -> np.ndarray:
        """The cone distances of the cones ``[index]`` (any numpy index of the first axes)
        to the segments ``a``, ``e`` (broadcast against them, segments last)."""
        return _cone_distances_block(
            self.s_x[index],
            self.s_y[index],
            (self.axis[0][index], self.axis[1][index]),
            tuple((u_x[index], u_y[index]) for u_x, u_y in self.edges),
            a,
            e,
            self.cos_gamma,
        )


def _near_cone_distances(
    cone: _Cones, rows: slice, centre: np.ndarray, a: np.ndarray, e: np.ndarray, reach_m: float
) -> np.ndarray:
    """The cone distances ``(n, k)`` of the poses ``rows`` (robot centres ``centre (n, 2)``)
    to the segments ``a``, ``e (m, 2)``, looking at each pose's :data:`NEAR_SEGMENTS` nearest
    segments first.

    Sensor i sits within ``reach_m`` of the centre, so a segment at distance ``D`` from the
    centre is at least ``D - reach_m`` from the sensor. With ``R`` the distance of the
    nearest segment left out, a cone distance ``d <= R - reach_m`` found among the nearest
    ones is the minimum over the whole map (every other segment is at least as far); the
    cones without such a distance (a far or no echo) are computed over the whole map. Both
    go through the same arithmetic as a whole-map pass, so the minimum is its own bit for
    bit (a slack of 1e-9 relative on the test keeps rounding on the safe side).
    """
    edge_sq = np.einsum("mi,mi->m", e, e)
    offset = centre[:, None, :] - a  # (n, m, 2), from each segment's start to the centre
    t = np.clip(np.einsum("nmi,mi->nm", offset, e) / edge_sq, 0.0, 1.0)
    gap = np.hypot(offset[..., 0] - t * e[:, 0], offset[..., 1] - t * e[:, 1])  # (n, m)
    near = np.argpartition(gap, NEAR_SEGMENTS, axis=1)  # the NEAR_SEGMENTS nearest first
    left_out = np.take_along_axis(gap, near[:, NEAR_SEGMENTS, None], axis=1)  # (n, 1)
    picked = near[:, None, :NEAR_SEGMENTS]  # (n, 1, K)
    found = cone.distances(rows, a[picked], e[picked])  # (n, k)
    scale = 1.0 + np.abs(centre).max(axis=1, keepdims=True) + left_out
    settled = found <= left_out - reach_m - 1e-9 * scale
    if not settled.all():
        far_pose, far_sensor = np.nonzero(~settled)
        index = (far_pose + rows.start, far_sensor)
        found[far_pose, far_sensor] = cone.distances(index, a, e)
    return found


def _read_only(values: Any, shape_name: str) -> np.ndarray:
    array = np.array(values, dtype=np.float64)
    if not np.isfinite(array).all():
        raise RobotsimError(f"sonar {shape_name} must be finite")
    array.setflags(write=False)
    return array


#: The most sensors of a default belt: real belts have 8 to 32; every interval epoch tests
#: each box against each sensor, so the count multiplies its memory and time.
MAX_BELT_COUNT = 64


@dataclass(frozen=True, eq=False)
class SonarBeltParams:
    """A belt of k sonars firing together at ``rate_hz``.

    Attributes:
        mount_xy: ``(k, 2)`` sensor positions, robot frame, metres.
        mount_angle_rad: ``(k,)`` sensor axes, robot frame, radians CCW from forward.
        half_aperture_rad: cone half-angle gamma, ``0 < gamma < pi/2``.
        d_max_m: range limit; a true cone distance beyond it gives no echo (``inf``).
        error_abs_bound_m, error_rel_bound: the reading error obeys
            ``|e| <= error_abs_bound_m + error_rel_bound * d`` (``0 <= error_rel_bound < 1``).
        rate_hz: scans per second.
        outlier_prob: probability that a reading is replaced by a uniform value in
            ``[0, d_max_m]`` (a fault; 0 disables).
        lost_echo_prob: probability that an echo is lost (reading ``inf``; 0 disables).
    """

    mount_xy: np.ndarray
    mount_angle_rad: np.ndarray
    half_aperture_rad: float = bounded(above=0.0, below=np.pi / 2)
    d_max_m: float = bounded(3.0, above=0.0, maximum=100.0)
    error_abs_bound_m: float = bounded(0.02, minimum=0.0, maximum=10.0)
    error_rel_bound: float = bounded(0.01, minimum=0.0, below=1.0)
    rate_hz: float = bounded(1.0, above=0.0, maximum=10_000.0)
    outlier_prob: float = bounded(0.0, minimum=0.0, maximum=1.0)
    lost_echo_prob: float = bounded(0.0, minimum=0.0, maximum=1.0)

    def __post_init__(self) -> None:
        mount_xy = _read_only(self.mount_xy, "mount_xy")
        mount_angle = _read_only(self.mount_angle_rad, "mount_angle_rad")
        if mount_xy.ndim != 2 or mount_xy.shape[1] != 2 or len(mount_xy) == 0:
            raise RobotsimError(
                f"sonar mount_xy must have shape (k, 2), k >= 1, got {mount_xy.shape}"
            )
        if mount_angle.shape != (len(mount_xy),):
            raise RobotsimError(
                f"sonar mount_angle_rad must have shape ({len(mount_xy)},), got {mount_angle.shape}"
            )
        object.__setattr__(self, "mount_xy", mount_xy)
        object.__setattr__(self, "mount_angle_rad", mount_angle)
        validate_fields(self, RobotsimError)

    @property
    def count(self) -> int:
        """Number of sensors k."""
        return len(self.mount_angle_rad)

    @classmethod
    def default_belt(
        cls,
        robot_radius_m: float = 0.2,
        count: int = 16,
        half_aperture_rad: float = np.deg2rad(12.5),
        **settings: Any,
    ) -> SonarBeltParams:
        """``count`` sensors evenly around the rim of a disk robot, the first one facing
        forward, each pointing radially outwards. ``settings`` are the other fields
        (``d_max_m``, error bounds, rate, fault probabilities)."""
        if not (1 <= count <= MAX_BELT_COUNT) or not robot_radius_m > 0:
            raise RobotsimError(
                f"sonar belt needs 1 <= count <= {MAX_BELT_COUNT} and robot_radius_m > 0, "
                f"got {count}, {robot_radius_m}"
            )
        angle = 2.0 * np.pi * np.arange(count) / count
        angle = np.where(angle >= np.pi, angle - 2.0 * np.pi, angle)  # wrap to [-pi, pi)
        mount_xy = robot_radius_m * np.stack([np.cos(angle), np.sin(angle)], axis=1)
        return cls(
            mount_xy=mount_xy,
            mount_angle_rad=angle,
            half_aperture_rad=half_aperture_rad,
            **settings,
        )


def simulate_readings(
    true_distance_m: Any, params: SonarBeltParams, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Readings and fault mask from true cone distances ``(M, k)`` (any shape works).

    Error model (the team contract):
    - no echo (``inf``) iff the true distance ``d > d_max_m``;
    - otherwise ``d + e``, ``e`` uniform in ``[-bound, bound]``,
      ``bound = error_abs_bound_m + error_rel_bound * d``, then clipped at 0 (the clip moves
      a reading towards ``d`` so the bound still holds);
    - faults: a lost echo (probability ``lost_echo_prob``) turns an echo into ``inf``; an
      outlier (probability ``outlier_prob``, drawn for every reading, echo or not, unless
      that echo was lost) replaces the reading by a uniform value in ``[0, d_max_m]``.

    Every random array is drawn in bulk, whatever the probabilities, so turning a fault on
    does not change the other draws of the same generator.

    Returns:
        ``(readings_m, fault)``: readings like ``true_distance_m`` (``inf`` = no echo) and a
        bool mask of faulty readings (outliers and lost echoes; truth, for tests only).
    """
    d = np.asarray(true_distance_m, dtype=np.float64)
    return readings_from_draws(d, params, sonar_draws(d.shape, params, rng))


def sonar_draws(
    shape: tuple[int, ...], params: SonarBeltParams, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The random arrays of :func:`simulate_readings`, each ``shape``: the unit error in
    ``[-1, 1]``, the lost-echo and outlier draws in ``[0, 1)``, the outlier value in
    ``[0, d_max_m]``. They do not depend on the motion (the closed loop draws them first)."""
    return (
        rng.uniform(-1.0, 1.0, size=shape),
        rng.random(size=shape),
        rng.random(size=shape),
        rng.uniform(0.0, params.d_max_m, size=shape),
    )


def readings_from_draws(
    d: np.ndarray, params: SonarBeltParams, draws: tuple[np.ndarray, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """Readings and fault mask from true cone distances ``d`` and :func:`sonar_draws` of the
    same shape (the error model of :func:`simulate_readings`)."""
    unit_error, lost_draw, outlier_draw, outlier_value = draws
    echo = d <= params.d_max_m
    bound = params.error_abs_bound_m + params.error_rel_bound * np.where(echo, d, 0.0)
    readings = np.where(echo, np.maximum(np.where(echo, d, 0.0) + unit_error * bound, 0.0), np.inf)
    lost = echo & (lost_draw < params.lost_echo_prob)
    outlier = ~lost & (outlier_draw < params.outlier_prob)
    readings = np.where(lost, np.inf, np.where(outlier, outlier_value, readings))
    return readings, lost | outlier
