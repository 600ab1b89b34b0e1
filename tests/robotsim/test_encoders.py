"""Wheel encoders: integer ticks, no accumulating quantisation, slip noise."""

import numpy as np

from robotsim.control import ScriptedProfile
from robotsim.maps import builtin_map
from robotsim.robot import RobotParams, wheel_rates
from robotsim.sensors.encoders import (
    EncoderParams,
    simulate_ticks,
    wheel_rotation_increments,
)
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


def test_wheel_rotations_follow_the_mid_step_heading_on_any_length():
    """Each row from the step before it, computed one step at a time (the module's formula
    with numpy's functions on one-element arrays), on windows of any length."""
    robot = RobotParams()  # true radii 0.0503 and 0.0498 m: the columns differ
    rng = np.random.default_rng(8)
    for count in [1, 2, 3, 11, 500]:
        pose = np.cumsum(rng.normal(0.0, [0.01, 0.01, 0.5], (count, 3)), axis=0)
        got = wheel_rotation_increments(pose, robot)
        assert got.shape == (count, 2) and not got[0].any()
        for k in range(1, count):
            dx, dy, dtheta = pose[k] - pose[k - 1]
            turn = (dtheta + np.pi) % (2 * np.pi) - np.pi
            heading = np.array([pose[k - 1, 2] + 0.5 * turn])
            ds = dx * np.cos(heading)[0] + dy * np.sin(heading)[0]
            half = 0.5 * robot.wheel_base_m * turn
            np.testing.assert_allclose(
                got[k],
                np.array([ds - half, ds + half]) / robot.true_radii_m,
                rtol=1e-12,
                atol=1e-15,
            )
