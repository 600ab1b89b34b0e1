"""What the particle filter (:mod:`localization.mcl`) needs to know of the map and the belt.

- :func:`cone_range_function`: the expected sonar ranges of particle poses, the simulator's
  exact cone model (:func:`robotsim.sensors.sonar.cone_distances`, docs/models.md section 3)
  compiled with numba: the same candidates (the segment's end points and the foot of the
  perpendicular inside the cone, the cone's edge rays meeting the segment), the same slack
  and the same arithmetic, so without noise it gives what the simulator's sonar reads
  (``tests/localization/test_mcl.py`` checks it on random poses);
- :func:`free_space_sampler`: positions uniform over the space the robot's centre can
  occupy (the uniform prior of global localisation).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import shapely
from shapely.geometry import LineString, MultiLineString, Polygon, box

from localization.mcl import ExpectedRanges, FreeSpaceSampler
from robotsim.errors import MapError
from robotsim.maps import SegmentMap
from robotsim.sensors.sonar import SonarBeltParams

#: The simulator's slack of the inside-the-cone and on-the-segment tests (robotsim's _SLACK).
_SLACK = 1e-12


@numba.njit(cache=True)
def _cone_point(w_x: float, w_y: float, c_x: float, c_y: float, cos_gamma: float) -> float:
    """``|w|`` if offset ``w`` from the apex lies inside the cone of unit axis ``c``
    (``w . c >= |w| cos(gamma)``, with the simulator's slack), else ``inf``."""
    length = math.hypot(w_x, w_y)
    return length if w_x * c_x + w_y * c_y >= length * (cos_gamma - _SLACK) else np.inf


@numba.njit(cache=True)
def _edge_hit(w_x: float, w_y: float, e_x: float, e_y: float, u_x: float, u_y: float) -> float:
    """Distance ``rho`` along the ray ``u`` (unit) from the apex to segment ``a + tau e``
    (``w = a - s``), or ``inf`` when the ray misses it: ``rho = det(w, e) / det(u, e) >= 0``,
    ``tau = det(w, u) / det(u, e)`` in ``[0, 1]`` (with the simulator's slack)."""
    denominator = u_x * e_y - u_y * e_x
    if denominator == 0.0:
        return np.inf
    rho = (w_x * e_y - w_y * e_x) / denominator
    tau = (w_x * u_y - w_y * u_x) / denominator
    if rho >= 0.0 and tau >= -_SLACK and tau <= 1.0 + _SLACK:
        return rho
    return np.inf


@numba.njit(cache=True)
def cone_ranges(
    poses: np.ndarray,
    segments: np.ndarray,
    mount_xy: np.ndarray,
    mount_angle_rad: np.ndarray,
    half_aperture_rad: float,
) -> np.ndarray:
    """Exact cone distances ``(N, k)`` (``inf``: no segment in the cone; no range limit) for
    poses ``(N, 3)``, segments ``(m, 2, 2)``, mounts ``(k, 2)`` and ``(k,)`` (robot frame).

    Sensor ``i`` at ``s_i = (x, y) + R(theta) s~_i`` with axis ``phi_i = theta + theta~_i``;
    for each segment ``a + t e``, ``e = b - a``, the nearest point inside the cone is among
    ``a``, ``b``, the foot ``t = -(a - s).e / |e|^2`` (when inside), and the edge rays
    ``u = (cos, sin)(phi -+ gamma)`` at ``rho = det(a - s, e) / det(u, e)``,
    ``tau = det(a - s, u) / det(u, e)`` in ``[0, 1]``.
    """
    n, k, m = poses.shape[0], mount_xy.shape[0], segments.shape[0]
    cos_gamma = math.cos(half_aperture_rad)
    out = np.full((n, k), np.inf)
    for p in range(n):
        x, y, theta = poses[p, 0], poses[p, 1], poses[p, 2]
        cos_t, sin_t = math.cos(theta), math.sin(theta)
        for i in range(k):
            s_x = x + cos_t * mount_xy[i, 0] - sin_t * mount_xy[i, 1]
            s_y = y + sin_t * mount_xy[i, 0] + cos_t * mount_xy[i, 1]
            phi = theta + mount_angle_rad[i]
            c_x, c_y = math.cos(phi), math.sin(phi)
            lo, hi = phi - half_aperture_rad, phi + half_aperture_rad
            u1_x, u1_y, u2_x, u2_y = math.cos(lo), math.sin(lo), math.cos(hi), math.sin(hi)
            best = np.inf
            for j in range(m):
                a_x, a_y = segments[j, 0, 0], segments[j, 0, 1]
                e_x, e_y = segments[j, 1, 0] - a_x, segments[j, 1, 1] - a_y
                w_x, w_y = a_x - s_x, a_y - s_y
                best = min(best, _cone_point(w_x, w_y, c_x, c_y, cos_gamma))
                best = min(best, _cone_point(w_x + e_x, w_y + e_y, c_x, c_y, cos_gamma))
                t = -(w_x * e_x + w_y * e_y) / (e_x * e_x + e_y * e_y)
                if t >= 0.0 and t <= 1.0:
                    foot = _cone_point(w_x + t * e_x, w_y + t * e_y, c_x, c_y, cos_gamma)
                    best = min(best, foot)
                best = min(best, _edge_hit(w_x, w_y, e_x, e_y, u1_x, u1_y))
                best = min(best, _edge_hit(w_x, w_y, e_x, e_y, u2_x, u2_y))
            out[p, i] = best
    return out


def cone_range_function(segments, belt: SonarBeltParams) -> ExpectedRanges:
    """``particles (N, 3) -> (N, k)``: the belt's exact cone distances in the map
    ``segments (m, 2, 2)``, the function :class:`localization.mcl.MonteCarloLocalization`
    takes (``inf`` where no segment meets a cone; the filter applies the range limit)."""
    segments = np.ascontiguousarray(segments, dtype=np.float64)
    mount_xy = np.ascontiguousarray(belt.mount_xy, dtype=np.float64)
    mount_angle = np.ascontiguousarray(belt.mount_angle_rad, dtype=np.float64)
    gamma = float(belt.half_aperture_rad)

    def expected_ranges(particles: np.ndarray) -> np.ndarray:
        poses = np.ascontiguousarray(particles, dtype=np.float64)
        return cone_ranges(poses, segments, mount_xy, mount_angle, gamma)

    return expected_ranges


def free_space(segment_map: SegmentMap, robot_radius_m: float) -> Polygon:
    """Where the robot's centre can be: the interior of the map's outer wall (its bounding box
    when it has none) shrunk by ``robot_radius_m``, less every wall grown by it; of what is
    left the largest connected piece (the insides of closed landmarks, too small or cut off,
    drop out)."""
    outline = (
        Polygon(segment_map.boundary)
        if segment_map.boundary is not None
        else box(*segment_map.bounds[:, 0], *segment_map.bounds[:, 1])
    )
    walls = MultiLineString([LineString(s) for s in segment_map.segments])
    space = outline.buffer(-robot_radius_m).difference(walls.buffer(robot_radius_m))
    pieces = list(getattr(space, "geoms", [space]))
    largest = max(pieces, key=lambda piece: piece.area)
    if largest.is_empty:
        raise MapError(
            f"map {segment_map.name!r}: no free space for a robot of radius {robot_radius_m} m"
        )
    shapely.prepare(largest)
    return largest


def free_space_sampler(segment_map: SegmentMap, robot_radius_m: float) -> FreeSpaceSampler:
    """``(rng, n) -> (n, 2)``: positions uniform over :func:`free_space` (rejection sampling
    from its bounding box, in batches)."""
    space = free_space(segment_map, robot_radius_m)
    x_min, y_min, x_max, y_max = space.bounds
    acceptance = space.area / ((x_max - x_min) * (y_max - y_min))

    def sample(rng: np.random.Generator, n: int) -> np.ndarray:
        kept: list[np.ndarray] = []
        found = 0
        while found < n:
            batch = int(1.2 * (n - found) / acceptance) + 16
            xy = np.column_stack(
                [rng.uniform(x_min, x_max, batch), rng.uniform(y_min, y_max, batch)]
            )
            xy = xy[shapely.contains_xy(space, xy[:, 0], xy[:, 1])]
            kept.append(xy)
            found += len(xy)
        return np.concatenate(kept)[:n]

    return sample
