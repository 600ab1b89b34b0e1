"""Wheel encoders: integer ticks, no accumulating quantisation, slip noise."""

import numpy as np

from robotsim.control import ScriptedProfile
from robotsim.maps import builtin_map
from robotsim.robot import RobotParams, wheel_rates
from robotsim.sensors.encoders import EncoderParams, simulate_ticks
from robotsim.simulation import SensorSuite, simulate


def test_ticks_are_integers_and_count_the_true_wheel_rotation():
    robot = RobotParams(ticks_per_rev=500)
    profile = ScriptedProfile([0.0, 5.0], [0.3, 0.2], [0.0, 0.5])
    log = simulate(
        builtin_map("hall"),
        profile,
        start_pose=(3.0, 4.0, 0.0),
        duration_s=10.0,
        rng=np.random.default_rng(1),
        robot=robot,
    )
    assert log.wheel_ticks.dtype == np.int64
    assert log.wheel_ticks.shape == (1001, 2)
    assert np.all(log.wheel_ticks[0] == 0)
    # the total rotation over the steady part matches the commanded wheel speeds
    # (wheel rate = commanded body velocity through the nominal radius), within 1 tick
    window = slice(101, 501)  # 1 s to 5 s: steady 0.3 m/s straight
    wheel = wheel_rates([0.3, 0.0], robot.nominal_radii_m, robot.wheel_base_m)
    expected_ticks = wheel * 4.0 * robot.ticks_per_rev / (2 * np.pi)
    assert np.all(np.abs(log.wheel_ticks[window].sum(axis=0) - expected_ticks) <= 1.0)


def test_quantisation_does_not_accumulate():
    rng = np.random.default_rng(2)
    rotation = np.full((10_000, 2), 0.0123)  # a fraction of a tick per sample
    ticks = simulate_ticks(rotation, 1024, EncoderParams(), rng)
    assert set(np.unique(ticks)) <= {2, 3}
    exact = rotation.sum(axis=0) * 1024 / (2 * np.pi)
    assert np.all(np.abs(ticks.sum(axis=0) - exact) < 1.0)


def test_slip_noise_has_the_declared_relative_std():
    rng = np.random.default_rng(3)
    rotation = np.full((50_000, 2), 2 * np.pi)  # one revolution per sample
    ticks = simulate_ticks(rotation, 100_000, EncoderParams(slip_std=0.01), rng)
    relative = ticks / 100_000 - 1.0
    np.testing.assert_allclose(relative.std(axis=0), 0.01, rtol=0.02)
    assert np.all(np.abs(relative.mean(axis=0)) < 4 * 0.01 / np.sqrt(50_000) + 1e-5)


def test_slip_changes_the_ticks_of_a_run():
    common = {"start_pose": (3.0, 4.0, 0.0), "duration_s": 5.0, "rng": np.random.default_rng(1)}
    profile = ScriptedProfile([0.0], [0.3], [0.0])
    clean = simulate(builtin_map("hall"), profile, **common)
    common["rng"] = np.random.default_rng(1)
    slipping = simulate(
        builtin_map("hall"),
        profile,
        sensors=SensorSuite(encoders=EncoderParams(slip_std=0.05)),
        **common,
    )
    assert not np.array_equal(clean.wheel_ticks, slipping.wheel_ticks)
    np.testing.assert_array_equal(clean.pose, slipping.pose)
