"""The closed loop's compiled sample block against the numpy formulas of the whole-run pass:
bit for bit on random states cut into random blocks, and in a closed-loop run with a kidnap
and wheel slip."""

import numpy as np

from robotsim.control import Route
from robotsim.maps import builtin_map
from robotsim.robot import RobotParams, wrap_angle
from robotsim.sensors.encoders import EncoderParams
from robotsim.sensors.stream_kernel import sample_block
from robotsim.simulation import KidnapEvent, SensorSuite, simulate

RATE_HZ = 100.0
ROBOT = RobotParams()


def numpy_readings(states, kidnapped, slip_factor, ticks_per_rad, noise):
    """Ticks, gyro and accel ``(N, ...)`` of the whole run, written here from the models'
    equations: the rotation over each sample from the pose change (the kidnap samples from
    the previous velocity), the floor of the cumulative turn times ticks per radian,
    differenced; the specific force by ``np.gradient`` (central differences)."""
    x, y, theta, v, omega = states.T
    turn = wrap_angle(np.diff(theta))
    heading = theta[:-1] + 0.5 * turn
    ds = np.diff(x) * np.cos(heading) + np.diff(y) * np.sin(heading)
    half = 0.5 * ROBOT.wheel_base_m * turn
    rotation = np.zeros((len(x), 2))
    rotation[1:, 0] = (ds - half) / ROBOT.true_wheel_radius_left_m
    rotation[1:, 1] = (ds + half) / ROBOT.true_wheel_radius_right_m
    jumps = np.flatnonzero(kidnapped)
    half_turn = 0.5 * ROBOT.wheel_base_m * omega[jumps - 1]
    rotation[jumps, 0] = (v[jumps - 1] - half_turn) / ROBOT.true_wheel_radius_left_m / RATE_HZ
    rotation[jumps, 1] = (v[jumps - 1] + half_turn) / ROBOT.true_wheel_radius_right_m / RATE_HZ
    counted = np.floor(np.cumsum(rotation * slip_factor, axis=0) * ticks_per_rad)
    ticks = np.diff(counted, axis=0, prepend=0.0).astype(np.int64)
    gyro = omega + noise["gyro_bias"] + noise["gyro_white"]
    force = np.column_stack([np.gradient(v, 1.0 / RATE_HZ), v * omega])
    accel = force + noise["accel_bias"] + noise["accel_white"]
    return ticks, gyro, accel


def random_run(rng, count):
    states = np.column_stack(
        [
            np.cumsum(rng.normal(0.0, 0.01, count)),
            np.cumsum(rng.normal(0.0, 0.01, count)),
            np.cumsum(rng.normal(0.0, 0.4, count)),  # unwrapped, steps past +-pi
            rng.normal(0.3, 0.2, count),
            rng.normal(0.0, 1.0, count),
        ]
    )
    kidnapped = np.zeros(count, dtype=bool)
    kidnapped[rng.choice(np.arange(1, count), size=3, replace=False)] = True
    slip_factor = 1.0 + 0.05 * rng.standard_normal((count, 2))
    noise = {
        "gyro_bias": rng.normal(0.0, 1e-3, count),
        "gyro_white": rng.normal(0.0, 1e-3, count),
        "accel_bias": rng.normal(0.0, 0.2, (count, 2)),
        "accel_white": rng.normal(0.0, 0.04, (count, 2)),
    }
    return states, kidnapped, slip_factor, noise


def blockwise(states, kidnapped, slip_factor, ticks_per_rad, noise, stops):
    """The kernel called as the closed loop calls it: each block with the window of its
    rows, the row before and the row after (when they exist)."""
    count = len(states)
    ticks, gyro, accel = np.zeros((count, 2), np.int64), np.zeros(count), np.zeros((count, 2))
    turned = np.zeros(2)
    start = 0
    for stop in stops:
        low, high = max(start - 1, 0), min(stop + 1, count)
        sample_block(
            states[low:high].copy(),
            low,
            start,
            stop,
            kidnapped,
            0.5 * ROBOT.wheel_base_m,
            ROBOT.true_wheel_radius_left_m,
            ROBOT.true_wheel_radius_right_m,
            RATE_HZ,
            slip_factor,
            ticks_per_rad,
            turned,
            noise["gyro_bias"],
            noise["gyro_white"],
            noise["accel_bias"],
            noise["accel_white"],
            ticks,
            gyro,
            accel,
        )
        start = stop
    return ticks, gyro, accel


def test_blocks_of_any_size_give_the_numpy_readings_bit_for_bit():
    rng = np.random.default_rng(7)
    for trial in range(20):
        count = int(rng.integers(2, 400))
        run = random_run(rng, count)
        ticks_per_rad = float(rng.choice([2048, 100, 7])) / (2.0 * np.pi)
        cuts = np.sort(rng.choice(np.arange(1, count), size=min(count - 1, 12), replace=False))
        stops = [*cuts.tolist(), count] if trial % 2 else [count]  # blocks, or one block
        expected = numpy_readings(*run[:3], ticks_per_rad, run[3])
        got = blockwise(*run[:3], ticks_per_rad, run[3], stops)
        for name, e, g in zip(("ticks", "gyro", "accel"), expected, got, strict=True):
            np.testing.assert_array_equal(g, e, err_msg=f"{name}, trial {trial}")
        assert np.abs(expected[0]).max() > 0  # the wheels turned by whole ticks


def test_a_single_sample_run_has_no_motion():
    states = np.array([[1.0, 2.0, 3.0, 0.5, 0.2]])
    noise = {"gyro_bias": [0.1], "gyro_white": [0.2], "accel_bias": [[0.3, 0.4]]}
    noise = {key: np.array(value, dtype=np.float64) for key, value in noise.items()}
    noise["accel_white"] = np.zeros((1, 2))
    ticks, gyro, accel = blockwise(states, np.zeros(1, bool), np.ones((1, 2)), 100.0, noise, [1])
    np.testing.assert_array_equal(ticks, [[0, 0]])
    np.testing.assert_array_equal(gyro, [0.2 + 0.1 + 0.2])
    np.testing.assert_array_equal(accel, [[0.0 + 0.3, 0.5 * 0.2 + 0.4]])


class Kept:
    """An observer steering on a fixed pose that keeps the samples it was handed."""

    def __init__(self):
        self.blocks = []

    def odometry_block(self, t_s, ticks, gyro_rad_s, accel_m_s2):
        self.blocks.append(tuple(np.array(a) for a in (t_s, ticks, gyro_rad_s, accel_m_s2)))

    def scan(self, t_s, readings_m):
        pass

    def pose(self):
        return (1.0, 1.0, 0.0)


def test_the_closed_loop_hands_over_the_logged_readings_with_a_kidnap_and_slip():
    observer = Kept()
    log = simulate(
        builtin_map("hall"),
        Route([[8.5, 1.0], [8.8, 4.0], [5.0, 4.3]], loop=True),
        start_pose=(1.0, 1.0, 0.0),
        duration_s=6.0,
        rng=np.random.default_rng(3),
        sensors=SensorSuite(encoders=EncoderParams(slip_std=0.05)),
        kidnaps=(KidnapEvent(2.345, (5.0, 4.0, 1.0)),),
        observer=observer,
        control_stride=7,
    )
    assert log.kidnap_t_s.size == 1
    handed = [np.concatenate([block[i] for block in observer.blocks]) for i in range(4)]
    logged = (log.t_s, log.wheel_ticks, log.gyro_rad_s, log.accel_m_s2)
    for got, expected in zip(handed, logged, strict=True):
        np.testing.assert_array_equal(got, expected)
    assert len(observer.blocks) > len(log.t_s) // 7  # many blocks: the window edges matter
