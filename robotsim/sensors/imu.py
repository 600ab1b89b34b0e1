"""Gyro (yaw rate) and two-axis accelerometer (body x, y) with bias and white noise.

Each axis measures ``truth + b(t) + n`` (docs/models.md section 2):
- ``n`` white, per-sample standard deviation ``noise_density * sqrt(rate_hz)``;
- ``b(t) = b0 + w(t)``: a turn-on bias ``b0 ~ N(0, turn_on_bias_std^2)`` drawn once per run
  and a random walk ``w``, ``w(0) = 0``, increments ``N(0, bias_random_walk^2 / rate_hz)``,
  so ``Var w(t) = bias_random_walk^2 t``.
The accelerometer's truth is the specific force in the plane: ``a_x = dv/dt``,
``a_y = v omega``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robotsim.errors import RobotsimError
from validated_records import bounded, validate_fields

_G_M_S2 = 9.80665


@dataclass(frozen=True)
class GyroParams:
    """Attributes (defaults: a low-cost MEMS gyro):
    noise_density_rad_s_sqrt_hz: white noise density, rad/s/sqrt(Hz) (0.005 deg/s/sqrt(Hz)).
    turn_on_bias_std_rad_s: standard deviation of the turn-on bias, rad/s (0.1 deg/s).
    bias_random_walk_rad_s_sqrt_s: bias random walk, rad/s/sqrt(s) (0.002 deg/s/sqrt(s)).
    """

    noise_density_rad_s_sqrt_hz: float = bounded(math.radians(0.005), minimum=0.0, maximum=1.0)
    turn_on_bias_std_rad_s: float = bounded(math.radians(0.1), minimum=0.0, maximum=1.0)
    bias_random_walk_rad_s_sqrt_s: float = bounded(math.radians(0.002), minimum=0.0, maximum=1.0)

    def __post_init__(self) -> None:
        validate_fields(self, RobotsimError)


@dataclass(frozen=True)
class AccelerometerParams:
    """Attributes (defaults: a low-cost MEMS accelerometer), per axis:
    noise_density_m_s2_sqrt_hz: white noise density, m/s^2/sqrt(Hz) (400 micro-g/sqrt(Hz)).
    turn_on_bias_std_m_s2: standard deviation of the turn-on bias, m/s^2 (20 milli-g).
    bias_random_walk_m_s2_sqrt_s: bias random walk, m/s^2/sqrt(s) (0.05 milli-g/sqrt(s)).
    """

    noise_density_m_s2_sqrt_hz: float = bounded(400e-6 * _G_M_S2, minimum=0.0, maximum=10.0)
    turn_on_bias_std_m_s2: float = bounded(20e-3 * _G_M_S2, minimum=0.0, maximum=10.0)
    bias_random_walk_m_s2_sqrt_s: float = bounded(0.05e-3 * _G_M_S2, minimum=0.0, maximum=1.0)

    def __post_init__(self) -> None:
        validate_fields(self, RobotsimError)


def axis_noise(
    shape: tuple[int, ...],
    noise_density: float,
    turn_on_bias_std: float,
    bias_random_walk: float,
    rate_hz: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """The bias and the white noise ``shape = (N, ...)`` of axes sampled at ``rate_hz`` (time
    first; every other element an independent axis with its own bias): a turn-on value plus a
    random walk, and the white noise of density ``noise_density``. They do not depend on the
    motion, so they can be drawn before it (the closed loop reads them sample by sample)."""
    axes = shape[1:]
    turn_on = rng.standard_normal(axes) * turn_on_bias_std
    steps = rng.standard_normal(shape) * (bias_random_walk / math.sqrt(rate_hz))
    steps[0] = 0.0
    bias = turn_on + np.cumsum(steps, axis=0)
    white = rng.standard_normal(shape) * (noise_density * math.sqrt(rate_hz))
    return bias, white


def simulate_axes(
    truth,
    noise_density: float,
    turn_on_bias_std: float,
    bias_random_walk: float,
    rate_hz: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Measurements ``truth + bias + white`` and bias, both shaped like ``truth (N, ...)``
    (:func:`axis_noise`). Units are those of ``truth``."""
    truth = np.asarray(truth, dtype=np.float64)
    bias, white = axis_noise(
        truth.shape, noise_density, turn_on_bias_std, bias_random_walk, rate_hz, rng
    )
    return truth + bias + white, bias


def gyro_noise(count: int, params: GyroParams, rate_hz: float, rng: np.random.Generator):
    """Bias and white noise ``(N,)`` rad/s of the gyro (as :func:`simulate_gyro` draws them)."""
    return axis_noise(
        (count,),
        params.noise_density_rad_s_sqrt_hz,
        params.turn_on_bias_std_rad_s,
        params.bias_random_walk_rad_s_sqrt_s,
        rate_hz,
        rng,
    )


def accelerometer_noise(
    count: int, params: AccelerometerParams, rate_hz: float, rng: np.random.Generator
):
    """Bias and white noise ``(N, 2)`` m/s^2 of the accelerometer (as
    :func:`simulate_accelerometer` draws them)."""
    return axis_noise(
        (count, 2),
        params.noise_density_m_s2_sqrt_hz,
        params.turn_on_bias_std_m_s2,
        params.bias_random_walk_m_s2_sqrt_s,
        rate_hz,
        rng,
    )


def simulate_gyro(omega_rad_s, params: GyroParams, rate_hz: float, rng: np.random.Generator):
    """Gyro readings and bias ``(N,)`` rad/s from the true yaw rate ``(N,)``."""
    return simulate_axes(
        omega_rad_s,
        params.noise_density_rad_s_sqrt_hz,
        params.turn_on_bias_std_rad_s,
        params.bias_random_walk_rad_s_sqrt_s,
        rate_hz,
        rng,
    )


def specific_force(velocity, rate_hz: float) -> np.ndarray:
    """True planar specific force ``(N, 2)`` m/s^2, body frame, from body velocities
    ``(N, 2)`` = (v, omega) sampled at ``rate_hz``: ``a_x = dv/dt`` (central differences),
    ``a_y = v omega``."""
    velocity = np.asarray(velocity, dtype=np.float64)
    v, omega = velocity[:, 0], velocity[:, 1]
    force = np.zeros((len(v), 2))
    if len(v) > 1:  # np.gradient's arithmetic, written out
        dt_s = 1.0 / rate_hz
        force[1:-1, 0] = (v[2:] - v[:-2]) / (2.0 * dt_s)  # central differences inside
        force[0, 0] = (v[1] - v[0]) / dt_s  # one-sided at the ends
        force[-1, 0] = (v[-1] - v[-2]) / dt_s
    force[:, 1] = v * omega
    return force


def simulate_accelerometer(
    specific_force_m_s2, params: AccelerometerParams, rate_hz: float, rng: np.random.Generator
):
    """Accelerometer readings and bias ``(N, 2)`` m/s^2 from the true specific force."""
    return simulate_axes(
        specific_force_m_s2,
        params.noise_density_m_s2_sqrt_hz,
        params.turn_on_bias_std_m_s2,
        params.bias_random_walk_m_s2_sqrt_s,
        rate_hz,
        rng,
    )
