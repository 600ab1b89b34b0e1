"""The closed loop: the controller steered on the localiser's estimate, the simulator and the
localiser stepped together; the summary says how the route was followed."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from robotsim.maps import point_segment_distance
from robotsim.sensors.sonar import readings_from_draws
from robotsim.simulation import SensorNoise
from scenarios.epochs import EpochLog
from scenarios.metrics import WAYPOINT_REACHED_M, route_stats
from scenarios.pipeline import FUSED, Steering, estimate, gathered, localizer_for
from scenarios.runner import run_scenario, simulate_spec
from scenarios.spec import Follow, load_scenario


def closed(name: str, follow: Follow, seed: int = 0, duration_s: float = 60.0):
    spec = load_scenario(name).with_run(seed=seed, duration_s=duration_s)
    return dataclasses.replace(spec, follow=follow)


class Recorder(Steering):
    """The pipeline's observer, keeping what the simulator handed it."""

    def __init__(self, localizer, branch):
        super().__init__(localizer, branch)
        self.samples, self.scans, self.poses = [], [], []

    def odometry_block(self, t_s, ticks, gyro_rad_s, accel_m_s2):
        for row in zip(t_s, ticks, gyro_rad_s, accel_m_s2, strict=True):
            self.samples.append(tuple(np.array(value) for value in row))
        super().odometry_block(t_s, ticks, gyro_rad_s, accel_m_s2)

    def scan(self, t_s, readings_m):
        self.scans.append((t_s, np.array(readings_m)))
        super().scan(t_s, readings_m)

    def pose(self):
        pose = super().pose()
        self.poses.append(pose)
        return pose


def test_the_loop_hands_over_the_logged_readings_and_steers_on_the_estimate():
    spec = closed("hall", Follow.ESTIMATE, seed=2, duration_s=20.0)
    localizer = localizer_for(spec)
    observer = Recorder(localizer, FUSED)
    log = simulate_spec(spec, observer=observer)
    # what the loop handed over, sample by sample, is what the vectorised pass logged
    np.testing.assert_array_equal([s[0] for s in observer.samples], log.t_s)
    np.testing.assert_array_equal([s[1] for s in observer.samples], log.wheel_ticks)
    np.testing.assert_array_equal([s[2] for s in observer.samples], log.gyro_rad_s)
    np.testing.assert_array_equal([s[3] for s in observer.samples], log.accel_m_s2)
    np.testing.assert_array_equal([s[0] for s in observer.scans], log.sonar_t_s)
    np.testing.assert_array_equal([s[1] for s in observer.scans], log.sonar_range_m)
    # so the online estimates equal the pipeline run afterwards on the finished log
    online, _ = gathered(localizer, log)
    after, _ = estimate(spec, log)
    np.testing.assert_array_equal(online.pose, after.pose)
    # the epoch log reuses the fusion's components: the same as computing them all again
    records = localizer.epochs
    assert any(r.components is not None for r in records)
    again = EpochLog.collect(
        online.epochs.t_s,
        [r.result for r in records],
        log.sonar_pose[np.searchsorted(log.sonar_t_s, online.epochs.t_s)],
    )
    np.testing.assert_array_equal(online.epochs.labels, again.labels)
    np.testing.assert_array_equal(online.epochs.components, again.components)
    # the controller was fed the fused estimate at its ticks (every 10 samples at 10 Hz), one
    # sample late (the first: the start pose)
    stride = spec.control_stride
    assert stride == 10
    ticks = np.arange(0, len(log.t_s) - 1, stride)  # no step follows the last sample
    assert len(observer.poses) == len(ticks)
    np.testing.assert_array_equal(observer.poses[1:], online.pose[FUSED, ticks[1:] - 1])
    np.testing.assert_allclose(observer.poses[0], spec.start_pose)
    # and it matters: the true path differs from the run steered on the truth
    truth = simulate_spec(dataclasses.replace(spec, follow=Follow.TRUTH))
    assert not np.array_equal(truth.pose, log.pose)


def test_the_closed_loops_sonar_log_is_the_whole_run_pass_on_its_poses():
    """The closed loop logs the scans it computed as they came; they equal the vectorised
    pass over the whole run at the logged poses and times (the walls, the armchair and the
    walking person of apartment_lived_in, the error model from the same draws)."""
    spec = closed("apartment_lived_in", Follow.ESTIMATE, seed=4, duration_s=30.0)
    log = simulate_spec(spec, observer=Steering(localizer_for(spec), FUSED))
    belt = spec.sensors.sonar
    true_range = spec.obstacles.cone_distances(
        log.sonar_pose,
        log.sonar_t_s,
        spec.map.segments,
        belt.mount_xy,
        belt.mount_angle_rad,
        belt.half_aperture_rad,
    )
    np.testing.assert_array_equal(log.sonar_true_range_m, true_range)
    noise = SensorNoise.draw(
        len(log.t_s), len(log.sonar_t_s), log.sensors, log.rate_hz, np.random.default_rng(4)
    )
    readings, fault = readings_from_draws(true_range, belt, noise.sonar)
    np.testing.assert_array_equal(log.sonar_range_m, readings)
    np.testing.assert_array_equal(log.sonar_fault, fault)
    assert np.isfinite(readings).any() and fault.any() == (belt.outlier_prob > 0)


@pytest.mark.slow
@pytest.mark.parametrize(("name", "seed"), [("hall", 0), ("hall", 1), ("office", 0), ("office", 1)])
def test_steering_on_the_fused_estimate_keeps_the_guarantee_and_the_route(name, seed):
    on_truth = run_scenario(closed(name, Follow.TRUTH, seed)).summary
    on_estimate = run_scenario(closed(name, Follow.ESTIMATE, seed)).summary
    assert on_estimate["containment"] == 1.0
    assert on_estimate["walls"]["contact_samples"] == 0
    assert on_estimate["walls"]["pymunk_contact_steps"] == 0
    route = on_estimate["route"]
    assert route["follow"] == "estimate"
    assert route["waypoints_reached"] >= on_truth["route"]["waypoints_reached"] - 1 >= 1
    assert route["path_error_m"]["max"] < 0.5


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_steering_on_the_ukf_only_branch_drifts_off_the_route_on_a_long_run(seed):
    # five minutes of hall: the dead reckoning alone drifts by decimetres, the fused branch
    # stays within centimetres; a robot steered on each follows its route as well as that
    fused = run_scenario(closed("hall", Follow.ESTIMATE, seed, duration_s=300.0)).summary
    alone = run_scenario(closed("hall", Follow.UKF_ONLY, seed, duration_s=300.0)).summary
    assert fused["containment"] == 1.0 and fused["walls"]["pymunk_contact_steps"] == 0
    assert fused["route"]["path_error_m"]["max"] < 0.3
    assert alone["route"]["follow"] == "ukf_only"
    assert alone["route"]["path_error_m"]["max"] > 2.0 * fused["route"]["path_error_m"]["max"]
    assert alone["route"]["path_error_m"]["mean"] > 3.0 * fused["route"]["path_error_m"]["mean"]
    assert alone["rmse_position_m"]["ukf_only"] > 5.0 * fused["rmse_position_m"]["fused"]
    # the steering branch's error is the path's: the sets still hold the truth
    assert alone["containment"] == 1.0


def test_route_stats_against_a_direct_computation():
    spec = closed("hall", Follow.TRUTH, duration_s=40.0)
    log = simulate_spec(spec)
    stats = route_stats(spec, log)
    waypoints = spec.plan.waypoints_m
    path = np.array([spec.start_pose[:2], *waypoints, waypoints[0]])
    points = log.pose[:, :2]
    distance = np.full(len(points), np.inf)
    for a, b in itertools.pairwise(path):  # the distance to each leg, by projection
        t = np.clip((points - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
        distance = np.minimum(distance, np.hypot(*(points - (a + t[:, None] * (b - a))).T))
    assert stats["path_error_m"]["max"] == pytest.approx(distance.max(), rel=1e-9)
    assert stats["path_error_m"]["mean"] == pytest.approx(distance.mean(), rel=1e-9)
    first = np.linalg.norm(log.pose[:, :2] - waypoints[0], axis=1).min()
    assert (stats["waypoints_reached"] >= 1) == (first <= WAYPOINT_REACHED_M)
    assert stats["laps"] == stats["waypoints_reached"] // len(waypoints)
    assert stats["goal_reached"] is None  # a looping route has no goal


def old_route_figures(spec, log):
    """The path error (mean, max) and waypoints reached as route_stats computed them before
    it called nearest_segment_distance: every leg over every sample, the waypoint distances
    through np.linalg.norm of an (N, W, 2) array."""
    waypoints, loop = spec.plan.waypoints_m, spec.plan.loop
    path = np.vstack(
        [np.array(spec.start_pose[:2])[None], waypoints, *([waypoints[:1]] if loop else [])]
    )
    legs = [(a, b) for a, b in itertools.pairwise(path) if np.any(a != b)]
    points = log.pose[:, :2]
    to_path = np.min([point_segment_distance(points, a, b) for a, b in legs], axis=0)
    near = np.linalg.norm(points[:, None, :] - waypoints[None], axis=2) <= WAYPOINT_REACHED_M
    reached, sample = 0, 0
    while (target := reached % len(waypoints) if loop else reached) < len(waypoints):
        later = np.flatnonzero(near[sample:, target])
        if later.size == 0:
            break
        sample += int(later[0]) + 1
        reached += 1
    return float(to_path.mean()), float(to_path.max()), reached


@pytest.mark.parametrize("name", ["apartment_lived_in", "corridor"])
@pytest.mark.parametrize("loop", [True, False])
def test_route_stats_equals_the_per_leg_formula_bit_for_bit(name, loop):
    spec = closed(name, Follow.TRUTH, seed=3, duration_s=40.0)
    log = simulate_spec(spec)
    spec = dataclasses.replace(spec, plan=dataclasses.replace(spec.plan, loop=loop))
    stats = route_stats(spec, log)
    mean, worst, reached = old_route_figures(spec, log)
    assert stats["path_error_m"] == {"mean": mean, "max": worst}
    assert stats["waypoints_reached"] == reached
