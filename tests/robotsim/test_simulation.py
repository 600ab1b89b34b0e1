"""A whole run: the log's layout, determinism, and its sensors against the truth."""

import dataclasses

import numpy as np
import pytest

from robotsim.control import Route
from robotsim.errors import RobotsimError
from robotsim.maps import builtin_map
from robotsim.sensors.imu import specific_force
from robotsim.sensors.sonar import SonarBeltParams, cone_distances
from robotsim.simulation import KidnapEvent, SensorSuite, SimulationLog, simulate

ROUTE = Route([[8.5, 1.0], [8.8, 4.0], [5.0, 4.3], [4.5, 7.0], [1.0, 7.0]], loop=True)
HALL = builtin_map("hall")


def run(seed, duration_s=30.0, **settings):
    return simulate(
        HALL,
        ROUTE,
        start_pose=(1.0, 1.0, 0.0),
        duration_s=duration_s,
        rng=np.random.default_rng(seed),
        **settings,
    )


def arrays(log):
    return {
        f.name: getattr(log, f.name)
        for f in dataclasses.fields(SimulationLog)
        if isinstance(getattr(log, f.name), np.ndarray)
    }


def test_log_layout_matches_the_contract():
    log = run(1, duration_s=12.0)
    n, m, k = 1201, 13, 16
    expected = {
        "t_s": (n,),
        "pose": (n, 3),
        "velocity": (n, 2),
        "command": (n, 2),
        "wheel_ticks": (n, 2),
        "gyro_rad_s": (n,),
        "accel_m_s2": (n, 2),
        "gyro_bias_rad_s": (n,),
        "accel_bias_m_s2": (n, 2),
        "sonar_t_s": (m,),
        "sonar_pose": (m, 3),
        "sonar_range_m": (m, k),
        "sonar_fault": (m, k),
        "sonar_true_range_m": (m, k),
        "kidnap_t_s": (0,),
        "wall_contact": (n,),
        "obstacle_contact": (n,),
    }
    assert {name: a.shape for name, a in arrays(log).items()} == expected
    assert log.rate_hz == 100.0
    np.testing.assert_allclose(np.diff(log.t_s), 0.01)
    np.testing.assert_allclose(log.sonar_t_s, np.arange(13.0))
    assert log.wheel_ticks.dtype == np.int64 and log.sonar_fault.dtype == bool
    assert log.wall_contact.dtype == bool and not log.wall_contact.any()  # the route is clear
    assert np.all((log.pose[:, 2] >= -np.pi) & (log.pose[:, 2] < np.pi))
    with pytest.raises(ValueError):
        log.pose[0, 0] = 1.0  # read-only


def test_same_seed_gives_the_same_log_and_another_seed_differs():
    first, again, other = run(7), run(7), run(8)
    for name, value in arrays(first).items():
        np.testing.assert_array_equal(value, arrays(again)[name], err_msg=name)
    np.testing.assert_array_equal(first.pose, other.pose)  # the physics has no noise
    for name in ("gyro_rad_s", "accel_m_s2", "sonar_range_m"):
        assert not np.array_equal(getattr(first, name), getattr(other, name)), name


def test_sonar_readings_come_from_the_exact_cone_model_at_the_scan_poses():
    belt = SonarBeltParams.default_belt(outlier_prob=0.05)
    log = run(2, duration_s=60.0, sensors=SensorSuite(sonar=belt))
    np.testing.assert_array_equal(log.sonar_pose, log.pose[::100])
    exact = cone_distances(
        log.sonar_pose, HALL.segments, belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad
    )
    np.testing.assert_array_equal(log.sonar_true_range_m, exact)
    good = ~log.sonar_fault
    echo = exact <= belt.d_max_m
    assert echo.any() and (~echo).any() and log.sonar_fault.any()
    np.testing.assert_array_equal(np.isinf(log.sonar_range_m[good]), ~echo[good])
    error = np.abs(log.sonar_range_m - exact)[good & echo]
    assert np.all(
        error <= belt.error_abs_bound_m + belt.error_rel_bound * exact[good & echo] + 1e-12
    )


def test_inertial_readings_are_truth_plus_bias_plus_declared_white_noise():
    log = run(3, duration_s=120.0)
    gyro = log.sensors.gyro
    residual = log.gyro_rad_s - log.velocity[:, 1] - log.gyro_bias_rad_s
    expected = gyro.noise_density_rad_s_sqrt_hz * np.sqrt(log.rate_hz)
    assert abs(residual.std() / expected - 1.0) < 0.03
    accel = log.sensors.accelerometer
    residual = log.accel_m_s2 - specific_force(log.velocity, log.rate_hz) - log.accel_bias_m_s2
    expected = accel.noise_density_m_s2_sqrt_hz * np.sqrt(log.rate_hz)
    np.testing.assert_allclose(residual.std(axis=0), expected, rtol=0.03)
    # the centripetal term is really there while turning
    turning = np.abs(log.velocity[:, 0] * log.velocity[:, 1]) > 0.1
    assert turning.any()


def test_wall_contacts_come_from_pymunk_and_progress_is_reported():
    # drive head-on into the east wall of the hall (x = 10): contact from when the disk
    # reaches it; the geometric clearance agrees with pymunk's flags
    from robotsim.control import ScriptedProfile
    from robotsim.maps import point_segment_distance

    fractions = []
    log = simulate(
        HALL,
        ScriptedProfile([0.0], [0.5], [0.0]),
        start_pose=(8.0, 3.5, 0.0),
        duration_s=8.0,
        rng=np.random.default_rng(0),
        progress=fractions.append,
    )
    clearance = point_segment_distance(
        log.pose[:, None, :2], HALL.segments[:, 0], HALL.segments[:, 1]
    ).min(axis=1)
    reach = log.robot.radius_m + log.world.wall_radius_m
    assert log.wall_contact.any() and not log.wall_contact[:100].any()
    first = int(np.argmax(log.wall_contact))
    assert clearance[first + 1] < reach + 0.01 and clearance[: first - 5].min() > reach + 0.005
    assert log.wall_contact[first:-1].mean() > 0.9  # pressed against the wall from then on
    assert fractions[0] == 0.0 and fractions[-1] == 1.0 and np.all(np.diff(fractions) > 0)
    assert 50 <= len(fractions) <= 102


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        ({"duration_s": 0.0}, "duration_s"),
        ({"start_pose": (0.1, 1.0, 0.0)}, "overlaps wall"),
        ({"kidnaps": (KidnapEvent(99.0, (5.0, 4.0, 0.0)),)}, "outside the run"),
        ({"kidnaps": (KidnapEvent(1.0, (2.5, 2.0, 0.0)),)}, "overlaps wall"),
    ],
)
def test_bad_run_settings_are_refused(settings, words):
    arguments = {"start_pose": (1.0, 1.0, 0.0), "duration_s": 5.0, "rng": np.random.default_rng(0)}
    arguments.update(settings)
    with pytest.raises(RobotsimError, match=words):
        simulate(HALL, ROUTE, **arguments)
