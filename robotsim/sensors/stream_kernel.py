"""The closed loop's sensor readings of a block of samples in one compiled call (numba).

:class:`robotsim.simulation._SensorStream` hands the samples to the observer a few at a time
(one control period); :func:`sample_block` computes the readings of samples ``start..stop-1``
from a window of states and writes them into the run's preallocated arrays. It performs the
operations of the whole-run numpy pass in the same order, so every value is bit for bit the
one that pass computes (``tests/robotsim/test_stream_kernel.py``):

- true wheel rotation over sample ``j`` (:func:`robotsim.sensors.encoders.wheel_rotation_increments`):
  ``turn = wrap(theta_j - theta_{j-1})``, ``heading = theta_{j-1} + turn / 2``,
  ``ds = dx cos(heading) + dy sin(heading)``, ``rotation = (ds -/+ (L/2) turn) / r_true``;
  at a kidnap sample the wheels turn as the robot drove the sample before
  (:func:`robotsim.robot.wheel_rates` of the previous velocity, over one period);
- encoder ticks (:func:`robotsim.sensors.encoders.ticks_from_slip`): the cumulative turn
  ``T_j = T_{j-1} + rotation_j (1 + slip_std slip_j)`` counted in whole ticks,
  ``ticks_j = floor(T_j k) - floor(T_{j-1} k)`` with ``k = ticks_per_rev / (2 pi)``;
- gyro: ``omega_j + bias_j + white_j``;
- accelerometer (:func:`robotsim.sensors.imu.specific_force`): ``a_x = dv/dt`` by central
  differences inside the window (one-sided at its ends), ``a_y = v omega``, plus bias and
  white noise.

Shapes: ``N`` samples in the run; the window ``(w, 5)`` holds the states
``(x_m, y_m, theta_rad unwrapped, v_m_s, omega_rad_s)`` of samples ``low..low + w - 1``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_TWO_PI = 2.0 * np.pi


@numba.njit(cache=True)
def _wrap(angle_rad: float) -> float:
    """``angle_rad`` wrapped to ``[-pi, pi)``, the operations of :func:`robotsim.robot.wrap_angle`
    (the estimator's compiled twin, ``localization.compiled.linalg.wrap_angle``, is not
    imported: the simulator does not depend on the estimator)."""
    wrapped = (angle_rad + np.pi) % _TWO_PI - np.pi
    if wrapped >= np.pi:
        wrapped -= _TWO_PI
    return wrapped


@numba.njit(cache=True)
def sample_block(
    window,
    low,
    start,
    stop,
    kidnapped,
    half_base_m,
    radius_left_m,
    radius_right_m,
    rate_hz,
    slip_factor,
    ticks_per_rad,
    turned_rad,
    gyro_bias,
    gyro_white,
    accel_bias,
    accel_white,
    ticks_out,
    gyro_out,
    accel_out,
) -> None:
    """Write the readings of samples ``start..stop-1`` into rows ``start..stop-1`` of
    ``ticks_out (N, 2)`` int64, ``gyro_out (N,)`` rad/s and ``accel_out (N, 2)`` m/s^2.

    Args:
        window: ``(w, 5)`` states of samples ``low..low + w - 1``; it must hold samples
            ``start - 1`` (unless ``start == 0``) to ``stop - 1``, and ``stop`` when a sample
            follows (the central difference of sample ``stop - 1``).
        low, start, stop: sample indices (``low <= start < stop <= low + w``).
        kidnapped: ``(N,)`` bool, the samples at which the robot was teleported.
        half_base_m: half the wheel base, ``0.5 * wheel_base_m``.
        radius_left_m, radius_right_m: the true wheel radii.
        rate_hz: the sample rate.
        slip_factor: ``(N, 2)`` the per-sample factors ``1 + slip_std * slip``.
        ticks_per_rad: ``ticks_per_rev / (2 pi)``.
        turned_rad: ``(2,)`` the cumulative turn with slip of samples ``0..start-1`` (left,
            right), rad; updated in place to that of ``0..stop-1``.
        gyro_bias, gyro_white: ``(N,)`` rad/s; accel_bias, accel_white: ``(N, 2)`` m/s^2.
    """
    dt_s = 1.0 / rate_hz
    two_dt_s = 2.0 * dt_s
    last = window.shape[0] - 1
    for j in range(start, stop):
        r = j - low  # the sample's window row
        if kidnapped[j]:  # the jump is not odometry: the wheels turned as the robot drove
            half_turn = half_base_m * window[r - 1, 4]
            left = (window[r - 1, 3] - half_turn) / radius_left_m / rate_hz
            right = (window[r - 1, 3] + half_turn) / radius_right_m / rate_hz
        elif r == 0:  # the run's first sample: no motion before it
            left = right = 0.0
        else:
            turn = _wrap(window[r, 2] - window[r - 1, 2])
            heading = window[r - 1, 2] + 0.5 * turn
            ds = (window[r, 0] - window[r - 1, 0]) * math.cos(heading) + (
                window[r, 1] - window[r - 1, 1]
            ) * math.sin(heading)
            half = half_base_m * turn
            left = (ds - half) / radius_left_m
            right = (ds + half) / radius_right_m
        for wheel, rotation in ((0, left), (1, right)):
            before = math.floor(turned_rad[wheel] * ticks_per_rad)
            turned_rad[wheel] += rotation * slip_factor[j, wheel]
            after = math.floor(turned_rad[wheel] * ticks_per_rad)
            ticks_out[j, wheel] = np.int64(after - before)

        v, omega = window[r, 3], window[r, 4]
        gyro_out[j] = omega + gyro_bias[j] + gyro_white[j]
        if last == 0:
            forward = 0.0
        elif r == 0:
            forward = (window[1, 3] - window[0, 3]) / dt_s
        elif r == last:
            forward = (window[last, 3] - window[last - 1, 3]) / dt_s
        else:
            forward = (window[r + 1, 3] - window[r - 1, 3]) / two_dt_s
        accel_out[j, 0] = forward + accel_bias[j, 0] + accel_white[j, 0]
        accel_out[j, 1] = v * omega + accel_bias[j, 1] + accel_white[j, 1]
