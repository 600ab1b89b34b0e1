"""The vehicle reference drives and their sensors (paper 001's experiment in simulation)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from robotsim.errors import RobotsimError
from robotsim.vehicle.drives import (
    DRIVES,
    LANE_WIDTH_M,
    ManoeuvreProfile,
    highway_drive,
    urban_drive,
)
from robotsim.vehicle.sensors import VehicleSensorParams, measure
from robotsim.vehicle.single_track import VehicleParams, integrate_single_track

SEEDS = range(4)


@pytest.fixture(scope="module")
def drives():
    """Four seeds of each drive, 300 s at 100 Hz."""
    return {
        name: [make(np.random.default_rng(seed), 300.0) for seed in SEEDS]
        for name, make in DRIVES.items()
    }


def test_drives_are_reproducible_by_seed():
    for make in DRIVES.values():
        a, b = make(np.random.default_rng(11), 120.0), make(np.random.default_rng(11), 120.0)
        c = make(np.random.default_rng(12), 120.0)
        for field in ("pose", "speed_m_s", "accel_m_s2", "yaw_rate_rad_s", "steer_rad"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
        assert not np.array_equal(a.pose, c.pose)


def test_drive_length_and_sampling(drives):
    for name, runs in drives.items():
        for drive in runs:
            assert drive.name == name
            assert drive.t_s.size == 30001 and drive.duration_s == pytest.approx(300.0)
            np.testing.assert_allclose(np.diff(drive.t_s), 0.01)
            assert np.all((drive.pose[:, 2] >= -math.pi) & (drive.pose[:, 2] < math.pi))


def test_drives_stay_within_the_declared_vehicle_limits(drives):
    p = VehicleParams()
    for runs in drives.values():
        for d in runs:
            assert d.speed_m_s.min() >= 0.0 and d.speed_m_s.max() <= p.v_max_m_s
            assert p.a_min_m_s2 <= d.accel_m_s2.min() and d.accel_m_s2.max() <= p.a_max_m_s2
            assert np.abs(d.steer_rad).max() <= p.max_steer_rad
            assert np.max(d.speed_m_s * np.abs(d.yaw_rate_rad_s)) <= p.lateral_accel_max_m_s2
            # jerk-limited: acceleration changes by at most JERK * dt per sample (plus rounding)
            assert np.abs(np.diff(d.accel_m_s2)).max() <= 2.5 * 0.01 * 1.5 + 1e-9


def test_trajectory_obeys_the_single_track_kinematics(drives):
    """Independent check: finite differences of the positions give speed and heading."""
    for runs in drives.values():
        d = runs[0]
        dt = 0.01
        velocity = np.diff(d.pose[:, :2], axis=0) / dt
        v_mid = 0.5 * (d.speed_m_s[1:] + d.speed_m_s[:-1])
        np.testing.assert_allclose(np.hypot(*velocity.T), v_mid, atol=2e-3)
        turn = (np.diff(d.pose[:, 2]) + math.pi) % (2 * math.pi) - math.pi
        np.testing.assert_allclose(
            turn / dt, 0.5 * (d.yaw_rate_rad_s[1:] + d.yaw_rate_rad_s[:-1]), atol=1e-9
        )
        np.testing.assert_allclose(d.yaw_rate_rad_s, d.speed_m_s * d.curvature_1_m)
        np.testing.assert_allclose(np.diff(d.speed_m_s) / dt, d.accel_m_s2[:-1], atol=1e-6)


def test_urban_drive_has_stop_and_go_turns_and_strong_accelerations(drives):
    for d in drives["urban"]:
        stopped = d.speed_m_s == 0.0
        assert stopped[0] and stopped[200:].any()  # starts from rest and stops again later
        assert np.mean(np.abs(d.yaw_rate_rad_s) > math.radians(2.0)) > 0.05
        assert np.abs(d.yaw_rate_rad_s).max() > math.radians(20.0)  # right-angle turns
        assert d.accel_m_s2.max() > 2.0 and d.accel_m_s2.min() < -2.5
        assert d.speed_m_s.max() < 15.0


def test_highway_drive_is_fast_with_gentle_curves(drives):
    for d in drives["highway"]:
        assert d.speed_m_s.min() > 20.0 and d.speed_m_s.max() > 28.0
        assert np.abs(d.yaw_rate_rad_s).max() < math.radians(10.0)
        assert np.mean(np.abs(d.yaw_rate_rad_s) > math.radians(2.0)) > 0.02
        assert np.mean(np.abs(d.accel_m_s2) > 0.5) > 0.02
        assert np.abs(d.accel_m_s2).max() <= 1.5 + 1e-9


def test_lane_change_moves_one_lane_and_restores_the_heading():
    p = ManoeuvreProfile(100.0, 30.0, VehicleParams())
    p.hold(1.0)
    p.lane_change(LANE_WIDTH_M, 5.0)
    p.hold(1.0)
    d = p.build("lane", 7.0, 30.0, 100.0)
    assert d.pose[-1, 1] == pytest.approx(LANE_WIDTH_M, rel=2e-3)
    assert abs(d.pose[-1, 2]) < 1e-12
    assert 209.0 < d.pose[-1, 0] < 30.0 * 7.0  # the arc is 210 m long, partly sideways


def test_sensor_noise_statistics_and_biases():
    drive = highway_drive(np.random.default_rng(0), 120.0)
    params = VehicleSensorParams()
    meas = measure(drive, params, np.random.default_rng(1), runs=200)
    k = meas.t_s.size
    assert k == 1201 and meas.speed_m_s.shape == (200, k) and meas.yaw_rate_rad_s.shape == (200, k)
    np.testing.assert_allclose(np.diff(meas.t_s), 0.1)
    np.testing.assert_allclose(np.diff(meas.t_s[meas.gps_epoch]), 1.0)  # 1 Hz GPS
    gps_err = meas.gps_xy_m - drive.pose[meas.drive_index[meas.gps_epoch], :2]  # (R, G, 2)
    flat = gps_err.reshape(-1, 2)  # 24200 samples per axis
    np.testing.assert_allclose(flat.mean(axis=0), 0.0, atol=4 * 1.5 / math.sqrt(flat.shape[0]))
    np.testing.assert_allclose(flat.std(axis=0), params.gps_noise_std_m, rtol=0.03)
    assert abs(np.corrcoef(flat.T)[0, 1]) < 0.03
    assert (
        abs(np.corrcoef(gps_err[:, 1:, 0].ravel(), gps_err[:, :-1, 0].ravel())[0, 1]) < 0.03
    )  # white
    true_v = drive.speed_m_s[meas.drive_index]
    scale = np.sum(meas.speed_m_s * true_v) / (meas.speed_m_s.shape[0] * np.sum(true_v**2))
    assert scale == pytest.approx(1.0 + params.speed_scale_error, abs=2e-4)
    speed_resid = meas.speed_m_s - (1 + params.speed_scale_error) * true_v
    assert speed_resid.std() == pytest.approx(params.speed_noise_std_m_s, rel=0.02)
    yaw_err = meas.yaw_rate_rad_s - drive.yaw_rate_rad_s[meas.drive_index]
    assert yaw_err.mean() == pytest.approx(params.yaw_rate_bias_rad_s, abs=1e-4)
    assert yaw_err.std() == pytest.approx(params.yaw_rate_noise_std_rad_s, rel=0.02)


def test_sensor_draws_are_reproducible_by_seed():
    drive = urban_drive(np.random.default_rng(0), 30.0)
    a = measure(drive, VehicleSensorParams(), np.random.default_rng(5), runs=3)
    b = measure(drive, VehicleSensorParams(), np.random.default_rng(5), runs=3)
    np.testing.assert_array_equal(a.gps_xy_m, b.gps_xy_m)
    np.testing.assert_array_equal(a.speed_m_s, b.speed_m_s)


def test_bad_settings_are_refused_with_a_clear_message():
    drive = urban_drive(np.random.default_rng(0), 30.0)
    with pytest.raises(RobotsimError, match="whole multiple of gps_rate_hz"):
        VehicleSensorParams(gps_rate_hz=3.0, odometry_rate_hz=10.0)
    with pytest.raises(RobotsimError, match="gps_noise_std_m must be finite"):
        VehicleSensorParams(gps_noise_std_m=float("nan"))
    with pytest.raises(RobotsimError, match="not a whole multiple of odometry_rate_hz"):
        measure(
            drive,
            VehicleSensorParams(odometry_rate_hz=30.0, gps_rate_hz=1.0),
            np.random.default_rng(0),
        )
    with pytest.raises(RobotsimError, match="runs must be an integer >= 1"):
        measure(drive, VehicleSensorParams(), np.random.default_rng(0), runs=0)
    with pytest.raises(RobotsimError, match="duration_s must be finite and >= 10 s"):
        urban_drive(np.random.default_rng(0), 5.0)
    with pytest.raises(RobotsimError, match="a_min_m_s2 must be finite and < 0"):
        VehicleParams(a_min_m_s2=1.0)
    with pytest.raises(RobotsimError, match="make the car reverse"):
        integrate_single_track(
            "x", np.full(100, -1.0), np.zeros(100), (0, 0, 0), 0.5, 100.0, VehicleParams()
        )


@pytest.mark.slow
def test_robotsim_vehicle_does_not_import_localization():
    code = (
        "import sys, robotsim.vehicle.drives, robotsim.vehicle.sensors; "
        "bad = [m for m in sys.modules if m.split('.')[0] in ('localization', 'intervals', 'scenarios')]; "
        "sys.exit(1 if bad else 0)"
    )
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0
