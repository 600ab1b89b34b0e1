"""Gyro and accelerometer statistics against their declared parameters."""

import numpy as np
import pytest

from robotsim.errors import RobotsimError
from robotsim.sensors.imu import (
    AccelerometerParams,
    GyroParams,
    simulate_accelerometer,
    simulate_gyro,
    specific_force,
)

RATE_HZ = 100.0


def gyro(noise=0.0, turn_on=0.0, walk=0.0):
    return GyroParams(
        noise_density_rad_s_sqrt_hz=noise,
        turn_on_bias_std_rad_s=turn_on,
        bias_random_walk_rad_s_sqrt_s=walk,
    )


def accelerometer(noise=0.0, turn_on=0.0, walk=0.0):
    return AccelerometerParams(
        noise_density_m_s2_sqrt_hz=noise,
        turn_on_bias_std_m_s2=turn_on,
        bias_random_walk_m_s2_sqrt_s=walk,
    )


def simulate(kind, truth, seed, **settings):
    rng = np.random.default_rng(seed)
    if kind == "gyro":
        return simulate_gyro(truth, gyro(**settings), RATE_HZ, rng)
    return simulate_accelerometer(truth, accelerometer(**settings), RATE_HZ, rng)


@pytest.mark.parametrize(("kind", "density"), [("gyro", 1e-4), ("accel", 4e-3)])
def test_white_noise_std_is_density_times_root_rate(kind, density):
    truth = np.zeros((200_000, 2)) if kind == "accel" else np.zeros(200_000)
    measured, bias = simulate(kind, truth, 1, noise=density)
    assert np.all(bias == 0.0)
    expected = density * np.sqrt(RATE_HZ)
    std = measured.std(axis=0)
    # the sample std of 200000 normals is within 1 % (6 standard errors)
    np.testing.assert_allclose(std, expected, rtol=0.01)
    # white: neighbouring samples are uncorrelated
    lag_1 = np.corrcoef(measured[1:].ravel(), measured[:-1].ravel())[0, 1]
    assert abs(lag_1) < 0.01


@pytest.mark.parametrize(("kind", "std"), [("gyro", 2e-3), ("accel", 0.2)])
def test_turn_on_bias_is_constant_in_a_run_and_spread_as_declared(kind, std):
    runs = 8000
    truth = np.zeros((50, runs, 2)) if kind == "accel" else np.zeros((50, runs))
    measured, bias = simulate(kind, truth, 2, turn_on=std)
    np.testing.assert_array_equal(measured, bias)
    assert np.all(measured == measured[0])  # no noise, no walk: the bias never moves
    spread = measured[0].ravel()
    assert abs(spread.std() / std - 1.0) < 0.05  # 4 standard errors of a std estimate
    assert abs(spread.mean()) < 4 * std / np.sqrt(spread.size)


@pytest.mark.slow
@pytest.mark.parametrize(("kind", "walk"), [("gyro", 3e-5), ("accel", 5e-4)])
def test_bias_random_walk_variance_grows_linearly(kind, walk):
    runs = 4000
    samples = 1001  # 10 s
    truth = np.zeros((samples, runs, 2)) if kind == "accel" else np.zeros((samples, runs))
    _, bias = simulate(kind, truth, 3, walk=walk)
    assert np.all(bias[0] == 0.0)
    for t_s in (2.5, 10.0):
        spread = bias[int(t_s * RATE_HZ)].ravel()
        # Var w(t) = walk^2 t; the sample variance of n normals has relative s.e. sqrt(2/n)
        ratio = spread.var() / (walk**2 * t_s)
        assert abs(ratio - 1.0) < 4 * np.sqrt(2 / spread.size)
    # increments are independent: the walk does not mean-revert or drift
    assert abs(bias[-1].mean()) < 4 * walk * np.sqrt(10.0 / bias[-1].size)


def test_specific_force_of_a_known_motion():
    t = np.arange(0, 5, 1 / RATE_HZ)
    v = 0.2 * t  # constant acceleration 0.2 m/s^2
    omega = np.full_like(t, 0.4)
    force = specific_force(np.column_stack([v, omega]), RATE_HZ)
    np.testing.assert_allclose(force[:, 0], 0.2, atol=1e-9)
    np.testing.assert_allclose(force[:, 1], v * omega)


def test_negative_parameters_are_refused():
    with pytest.raises(RobotsimError, match="noise_density_rad_s_sqrt_hz"):
        gyro(noise=-1.0)
    with pytest.raises(RobotsimError, match="turn_on_bias_std_m_s2"):
        accelerometer(turn_on=float("nan"))


def test_specific_force_is_numpys_gradient_bit_for_bit_on_any_length():
    """The written-out differences equal ``np.gradient`` (central inside, one-sided at the
    ends) and ``v omega``, on the short windows the closed loop passes and on a whole run."""
    rng = np.random.default_rng(5)
    for count in [*range(1, 25), 6001]:
        velocity = rng.normal(0.0, 0.5, (count, 2))
        force = specific_force(velocity, 100.0)
        a_x = np.gradient(velocity[:, 0], 0.01) if count > 1 else np.zeros(count)
        np.testing.assert_array_equal(force[:, 0], a_x)
        np.testing.assert_array_equal(force[:, 1], velocity[:, 0] * velocity[:, 1])
