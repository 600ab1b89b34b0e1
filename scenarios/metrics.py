"""The summary of one run: a JSON-ready dict of figures computed from its log.

Deterministic: the same scenario and seed give the same dict. Wall-clock figures are not
here; ``scenarios.runner`` adds them under a separate ``timing`` key so tests can compare
everything else exactly.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from scipy import special

from robotsim.control import Route
from robotsim.maps import nearest_segment_distance
from robotsim.robot import wrap_angle
from robotsim.sensors.imu import specific_force
from scenarios.epochs import STATUS

if TYPE_CHECKING:
    from robotsim.simulation import SimulationLog
    from scenarios.epochs import EpochLog
    from scenarios.spec import ScenarioSpec


def summarize(
    spec: ScenarioSpec, log: SimulationLog, wall_distance: np.ndarray | None = None
) -> dict[str, Any]:
    """The summary of a run of ``spec`` that produced ``log`` (no timing); ``wall_distance``:
    :func:`wall_distance_m` of the run if already computed."""
    summary: dict[str, Any] = {
        "scenario": spec.name,
        "seed": spec.run.seed,
        "duration_s": spec.run.duration_s,
        "map": spec.map.name,
        "samples": len(log.t_s),
        "scans": len(log.sonar_t_s),
        "distance_m": path_length_m(log.pose),
        "final_pose": [float(v) for v in log.pose[-1]],
    }
    summary["walls"] = wall_stats(
        log.pose,
        spec.map.segments,
        spec.robot.radius_m + log.world.wall_radius_m,
        wall_distance,
    )
    summary["walls"]["pymunk_contact_steps"] = int(np.count_nonzero(log.wall_contact))
    summary["walls"]["obstacle_contact_steps"] = int(np.count_nonzero(log.obstacle_contact))
    summary["sensors"] = {
        "encoders": encoder_stats(log.wheel_ticks),
        "gyro": gyro_stats(log.gyro_rad_s, log.velocity[:, 1]),
        "accelerometer": accelerometer_stats(log.accel_m_s2, log.velocity, spec.run.rate_hz),
        "sonar": sonar_stats(spec, log),
    }
    return summary


def path_length_m(pose: np.ndarray) -> float:
    """Length of the true path ``pose (N, 3)``, metres."""
    return float(np.hypot(*np.diff(pose[:, :2], axis=0).T).sum())


#: A footprint closer to a wall than this (metres) counts as touching it.
CONTACT_GAP_M = 0.005


def wall_distance_m(spec: ScenarioSpec, log: SimulationLog) -> np.ndarray:
    """``(N,)`` the distance from the true position at each sample to the nearest wall of the
    map, m (the summary's wall and safety figures share it)."""
    return nearest_segment_distance(log.pose[:, :2], spec.map.segments)


def wall_stats(
    pose: np.ndarray, segments: np.ndarray, reach_m: float, distance_m: np.ndarray | None = None
) -> dict[str, Any]:
    """Smallest gap between the footprint and a wall, and the samples in contact.

    ``reach_m`` is the robot radius plus the walls' collision radius; a gap below
    ``CONTACT_GAP_M`` is a contact (pymunk lets shapes overlap by its collision slop).
    ``distance_m``: the distance from each position to the nearest wall, if computed.
    """
    if distance_m is None:
        distance_m = nearest_segment_distance(pose[:, :2], segments)
    gap = distance_m - reach_m
    return {
        "min_gap_m": float(gap.min()),
        "contact_samples": int(np.count_nonzero(gap < CONTACT_GAP_M)),
    }


def encoder_stats(wheel_ticks: np.ndarray) -> dict[str, Any]:
    """Total ticks per wheel ``(N, 2)`` and the largest increment of one sample."""
    return {
        "ticks_total": [int(v) for v in wheel_ticks.sum(axis=0)],
        "ticks_per_sample_max": int(np.abs(wheel_ticks).max()) if len(wheel_ticks) else 0,
    }


def gyro_stats(gyro_rad_s: np.ndarray, true_omega_rad_s: np.ndarray) -> dict[str, float]:
    """Mean (bias plus noise mean) and standard deviation of the gyro error, rad/s."""
    error = gyro_rad_s - true_omega_rad_s
    return {"error_mean_rad_s": float(error.mean()), "error_std_rad_s": float(error.std())}


def accelerometer_stats(
    accel_m_s2: np.ndarray, velocity: np.ndarray, rate_hz: float
) -> dict[str, list[float]]:
    """Mean and standard deviation of the error ``(2,)`` of the body-frame specific force,
    against the specific force of the true motion (``robotsim.sensors.imu.specific_force``)."""
    error = accel_m_s2 - specific_force(velocity, rate_hz)
    return {
        "error_mean_m_s2": [float(e) for e in error.mean(axis=0)],
        "error_std_m_s2": [float(e) for e in error.std(axis=0)],
    }


def sonar_stats(spec: ScenarioSpec, log: SimulationLog) -> dict[str, Any]:
    """Echo and fault counts, and the worst reading error as a share of its declared bound.

    The true distances are the exact cone distances at the true scan poses; an error
    share above 1 on a reading that is not a fault would mean the simulator broke its bound.
    """
    sonar = spec.sensors.sonar
    ranges = log.sonar_range_m
    echo = np.isfinite(ranges)
    stats: dict[str, Any] = {
        "readings": int(ranges.size),
        "echoes": int(echo.sum()),
        "faults": int(np.asarray(log.sonar_fault).sum()),
    }
    true_m = log.sonar_true_range_m
    good = echo & ~np.asarray(log.sonar_fault, dtype=bool) & np.isfinite(true_m)
    if good.any():
        error = np.abs(ranges[good] - true_m[good])
        bound = sonar.error_abs_bound_m + sonar.error_rel_bound * true_m[good]
        stats["range_min_m"] = float(ranges[good].min())
        stats["range_max_m"] = float(ranges[good].max())
        stats["error_abs_max_m"] = float(error.max())
        if (bound > 0).all():
            stats["error_bound_share_max"] = float((error / bound).max())
    return stats


def rmse_position_m(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Root mean square of the position error of ``estimate (N, 3)`` against ``truth (N, 3)``."""
    return float(np.sqrt(np.mean(np.sum((estimate[:, :2] - truth[:, :2]) ** 2, axis=1))))


def rmse_heading_rad(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Root mean square of the heading error, wrapped to ``[-pi, pi)``, radians."""
    error = wrap_angle(estimate[:, 2] - truth[:, 2])
    return float(np.sqrt(np.mean(error**2)))


def interval_stats(epochs: EpochLog) -> dict[str, Any]:
    """Figures of the interval epochs (no timing): containment of the truth, box sizes, ``q``.

    ``containment`` is over the epochs that produced a set (an ``inconsistent`` or ``lost``
    epoch has none; they are counted in ``empty_epochs``); the box figures are means over those epochs of the hull
    of the outer set (``mean_width_m``: its larger position width; ``mean_heading_width_rad``:
    its heading width) and of the (x, y) area of the union of the outer boxes
    (``mean_area_m2``).
    """
    has_set = epochs.has_set
    with_set = int(has_set.sum())
    hull_w = epochs.hull[has_set, :2, 1] - epochs.hull[has_set, :2, 0]
    heading_w = epochs.hull[has_set, 2, 1] - epochs.hull[has_set, 2, 0]
    counts = {
        str(status): int(np.count_nonzero(epochs.status == code))
        for code, status in enumerate(STATUS)
    }
    return {
        "epochs": len(epochs.t_s),
        "containment": float(epochs.contains_truth[has_set].mean()) if with_set else None,
        "box": {
            "mean_width_m": float(hull_w.max(axis=1).mean()) if with_set else None,
            "mean_hull_area_m2": float(np.prod(hull_w, axis=1).mean()) if with_set else None,
            "mean_area_m2": float(epochs.area_m2[has_set].mean()) if with_set else None,
            "mean_heading_width_rad": float(heading_w.mean()) if with_set else None,
            "mean_boxes": float(epochs.box_counts[has_set].mean()) if with_set else None,
            "max_components": int(epochs.components.max()) if len(epochs.t_s) else 0,
        },
        "q_used_max": int(epochs.q_used.max()) if len(epochs.t_s) else 0,
        "q_used_epochs": int(np.count_nonzero(epochs.q_used > 0)),
        "empty_epochs": counts["inconsistent"] + counts["lost"],
        "inconsistent_epochs": counts["inconsistent"],
        "coarse_epochs": int(np.count_nonzero(epochs.coarse)),
        "lost_epochs": counts["lost"],
        "epoch_status": counts,
    }


#: Probability mass of the NEES band: a consistent filter's NEES falls inside it this often.
NEES_CONFIDENCE = 0.95


def nees(estimate: np.ndarray, cov: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``(N,)`` of ``estimate (N, n)`` with covariance
    ``cov (N, n, n)`` against ``truth (N, n)``: ``e^T P^-1 e`` with ``e = estimate - truth``
    (Bar-Shalom, Li and Kirubarajan 2001, *Estimation with Applications to Tracking and
    Navigation*, section 5.4). For ``n = 3`` poses the
    heading error is wrapped to ``[-pi, pi)``.
    """
    error = np.asarray(estimate, dtype=np.float64) - truth
    if error.shape[-1] == 3:
        error[:, 2] = wrap_angle(error[:, 2])
    solved = np.linalg.solve(cov, error[..., None])[..., 0]
    return np.einsum("ni,ni->n", error, solved)


def nees_band(dof: int, confidence: float = NEES_CONFIDENCE) -> tuple[float, float]:
    """The two-sided ``confidence`` interval of one NEES sample of a consistent estimator of
    ``dof`` states: the chi-square quantiles at ``(1 - c) / 2`` and ``(1 + c) / 2``.

    ``chdtri(k, p)`` is the ``x`` with ``P(chi2_k > x) = p`` (the upper-tail inverse), so the
    quantile at ``q`` is ``chdtri(k, 1 - q)`` (``scipy.special``: without ``scipy.stats``, which
    takes a second to import)."""
    tail = (1.0 - confidence) / 2.0
    return float(special.chdtri(dof, 1.0 - tail)), float(special.chdtri(dof, tail))


def nees_stats(values: np.ndarray, dof: int) -> dict[str, Any]:
    """Mean and median of the NEES ``values (N,)`` of a ``dof``-state estimate, the band a
    consistent estimator's samples fall in with :data:`NEES_CONFIDENCE` and the share that
    does (about 0.95 when consistent; far less: over-confident below or pessimistic above,
    ``share_above`` tells which). Per-sample band: successive samples are correlated, so a
    band on the time average would claim far more confidence than the data holds."""
    low, high = nees_band(dof)
    finite = values[np.isfinite(values)]
    if not finite.size:
        return {
            "dof": dof,
            "mean": None,
            "median": None,
            "band": [low, high],
            "share_in_band": None,
            "share_above": None,
        }
    return {
        "dof": dof,
        "mean": float(finite.mean()),
        "median": float(np.median(finite)),
        "band": [low, high],
        "share_in_band": float(np.mean((finite >= low) & (finite <= high))),
        "share_above": float(np.mean(finite > high)),
    }


def consistency_stats(
    pose: np.ndarray, pose_cov: np.ndarray, truth: np.ndarray, branches: tuple[str, ...]
) -> dict[str, Any]:
    """NEES figures of every branch: ``pose (B, N, 3)``, ``pose_cov (B, N, 3, 3)`` against
    ``truth (N, 3)``, for the full pose (3 states) and the position alone (2 states)."""
    result: dict[str, Any] = {}
    for b, name in enumerate(branches):
        result[name] = {
            "pose": nees_stats(nees(pose[b], pose_cov[b], truth), 3),
            "position": nees_stats(nees(pose[b, :, :2], pose_cov[b, :, :2, :2], truth[:, :2]), 2),
        }
    return result


#: Recovered: the estimate within this distance of the truth (m) for
#: :data:`RECOVERY_HOLD_S` seconds (the Fox-Burgard-Thrun protocol).
RECOVERY_DISTANCE_M = 0.45
RECOVERY_HOLD_S = 10.0


def recovery_time_s(
    t_s: np.ndarray, rate_hz: float, position: np.ndarray, truth: np.ndarray, kidnap_t_s: float
) -> float | None:
    """Seconds from ``kidnap_t_s`` to the first sample from which the estimated
    ``position (N, 2)`` stays within :data:`RECOVERY_DISTANCE_M` of ``truth (N, >= 2)`` for
    :data:`RECOVERY_HOLD_S` (None: not within the run); ``t_s (N,)`` the sample times."""
    start = int(np.searchsorted(t_s, kidnap_t_s - 0.5 / rate_hz))
    hold = round(RECOVERY_HOLD_S * rate_hz)
    error = np.linalg.norm(position[:, :2] - truth[:, :2], axis=1)
    misses = np.concatenate([[0], np.cumsum(error > RECOVERY_DISTANCE_M)])  # misses before k
    first = np.arange(start, len(error) - hold + 1)
    clean = misses[first + hold] == misses[first]  # no miss in [k, k + hold)
    if not clean.any():
        return None
    return float((first[np.argmax(clean)] - start) / rate_hz)


#: A waypoint is reached when the true position comes this close to it, m (the accuracy
#: threshold of the Fox-Burgard-Thrun recovery protocol: the robot is where it means to be
#: up to its localisation).
WAYPOINT_REACHED_M = 0.45


def route_stats(spec: ScenarioSpec, log: SimulationLog) -> dict[str, Any]:
    """How the true robot followed its route: the pose it steered on (``follow``), the
    distance from its true position to the route's polyline (start, waypoints, back to the
    first waypoint when looping; mean and max, m), the waypoints reached in order (within
    :data:`WAYPOINT_REACHED_M`), the laps done (looping routes) and, for a route that ends,
    whether its last waypoint was reached. Without a route: ``follow`` only."""
    stats: dict[str, Any] = {"follow": str(spec.follow)}
    if not isinstance(spec.plan, Route):
        return stats
    waypoints, loop = spec.plan.waypoints_m, spec.plan.loop
    path = np.vstack(
        [np.array(spec.start_pose[:2])[None], waypoints, *([waypoints[:1]] if loop else [])]
    )
    legs = np.array([(a, b) for a, b in itertools.pairwise(path) if np.any(a != b)])
    points = log.pose[:, :2]
    to_path = (
        nearest_segment_distance(points, legs)
        if len(legs)
        else np.linalg.norm(points - path[0], axis=1)
    )
    # (N, W) the distance to each waypoint, sqrt(dx^2 + dy^2) as np.linalg.norm sums it, on
    # the two coordinate planes (no (N, W, 2) array)
    dx = points[:, 0, None] - waypoints[None, :, 0]
    dy = points[:, 1, None] - waypoints[None, :, 1]
    near = np.sqrt(dx * dx + dy * dy) <= WAYPOINT_REACHED_M
    reached, sample = 0, 0
    while True:  # one pass per waypoint reached: the next in order, after the previous
        target = reached % len(waypoints) if loop else reached
        if target >= len(waypoints):
            break
        later = np.flatnonzero(near[sample:, target])
        if later.size == 0:
            break
        sample += int(later[0]) + 1  # the next waypoint is reached after this one
        reached += 1
    stats.update(
        {
            "path_error_m": {"mean": float(to_path.mean()), "max": float(to_path.max())},
            "waypoints_reached": reached,
            "laps": reached // len(waypoints) if loop else None,
            "goal_reached": None if loop else reached == len(waypoints),
        }
    )
    return stats


SET_WALL_BLOCK_BOXES = 20_000
"""Boxes :func:`set_wall_distance_m` turns into shapely polygons at a time: a polygon costs
about 0.35 KiB, so a run's 660 000 stored boxes at once (big_hall with lost echoes, 600 s)
made a 230 MiB transient, the run's peak; a block costs about 7 MiB."""


def set_wall_distance_m(
    epochs: EpochLog, segments: np.ndarray, block_boxes: int = SET_WALL_BLOCK_BOXES
) -> np.ndarray:
    """``(E,)`` the distance from each epoch's set (the union of its outer boxes in x, y) to
    the nearest wall segment ``(m, 2, 2)``, m: the least distance of its boxes (0 where a
    box touches a wall; NaN without a set). Vectorised shapely calls over ``block_boxes``
    boxes at a time (the result does not depend on it)."""
    walls = shapely.multilinestrings(shapely.linestrings(segments))
    boxes = epochs.boxes
    each = np.empty(len(boxes))
    for start in range(0, len(boxes), block_boxes):
        b = boxes[start : start + block_boxes]
        polygons = shapely.box(b[:, 0, 0], b[:, 1, 0], b[:, 0, 1], b[:, 1, 1])
        each[start : start + block_boxes] = shapely.distance(polygons, walls)
    distance = np.full(len(epochs.t_s), np.nan)
    with_boxes = epochs.box_counts > 0
    starts = (np.cumsum(epochs.box_counts) - epochs.box_counts)[with_boxes]
    if starts.size:
        distance[with_boxes] = np.minimum.reduceat(each, starts)
    distance[~epochs.has_set] = np.nan
    return distance


def safety_stats(
    spec: ScenarioSpec,
    log: SimulationLog,
    epochs: EpochLog,
    epoch_index: np.ndarray,
    wall_distance: np.ndarray | None = None,
) -> dict[str, Any]:
    """How often the true robot came within ``[route] safety_margin_m`` of the map's walls
    while its latest interval set said it was clear of them (every pose of the set farther
    than the margin: :func:`set_wall_distance_m`), as shares of the samples.

    The gap is the footprint's (the robot's radius and the walls' collision radius, as in
    :func:`wall_stats`). A set holds from its epoch's sample to the next epoch; before the
    first and after an epoch without a set, the set says nothing (not clear). With sets
    that always hold the truth the last share is 0 at the epoch samples; between epochs the
    robot moves on. ``wall_distance``: :func:`wall_distance_m` of the run if computed.
    """
    margin = spec.safety_margin_m
    reach = spec.robot.radius_m + log.world.wall_radius_m
    segments = spec.map.segments
    if wall_distance is None:
        wall_distance = wall_distance_m(spec, log)
    inside = wall_distance - reach < margin
    clear_at_epoch = set_wall_distance_m(epochs, segments) - reach > margin  # NaN: False
    latest = np.searchsorted(epoch_index, np.arange(len(log.t_s)), side="right") - 1
    said_clear = np.where(latest >= 0, clear_at_epoch[np.maximum(latest, 0)], False)
    return {
        "margin_m": margin,
        "inside_margin_share": float(inside.mean()),
        "set_clear_share": float(said_clear.mean()),
        "inside_margin_while_set_clear_share": float((inside & said_clear).mean()),
    }
