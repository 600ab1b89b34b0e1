"""The kinematic single-track ("bicycle") model of a road vehicle and its reference drive record.

State ``(x_m, y_m, heading_rad, v_m_s)`` of the rear-axle centre, inputs the longitudinal
acceleration ``a`` and the front steering angle ``delta``::

    x' = v cos(heading),   y' = v sin(heading),   heading' = v tan(delta) / wheelbase,   v' = a

No slip: the curvature of the path is ``tan(delta) / wheelbase`` and the yaw rate is
``v`` times it. The inputs are held constant over each sample; the speed is integrated
exactly and heading and position with the trapezoid rule (error ``O(dt^2)``: below a
millimetre over a drive at 100 Hz). The result is the exact reference of the experiment:
its sensors are derived from the same arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robotsim.errors import RobotsimError


@dataclass(frozen=True)
class VehicleParams:
    """A passenger car and the limits its drives respect.

    Attributes:
        wheelbase_m: distance between the axles.
        max_steer_rad: largest front-wheel steering angle (either side).
        v_max_m_s: largest speed; drives never reverse (speed >= 0).
        a_max_m_s2: largest longitudinal acceleration.
        a_min_m_s2: strongest braking (negative).
        lateral_accel_max_m_s2: largest ``v^2 * curvature``.
    """

    wheelbase_m: float = 2.7
    max_steer_rad: float = 0.55
    v_max_m_s: float = 36.0
    a_max_m_s2: float = 3.5
    a_min_m_s2: float = -5.0
    lateral_accel_max_m_s2: float = 4.0

    def __post_init__(self) -> None:
        positive = (
            "wheelbase_m",
            "max_steer_rad",
            "v_max_m_s",
            "a_max_m_s2",
            "lateral_accel_max_m_s2",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise RobotsimError(f"VehicleParams: {name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.a_min_m_s2) and self.a_min_m_s2 < 0.0):
            raise RobotsimError(
                f"VehicleParams: a_min_m_s2 must be finite and < 0, got {self.a_min_m_s2!r}"
            )
        if self.max_steer_rad >= math.pi / 2:
            raise RobotsimError(
                f"VehicleParams: max_steer_rad must be < pi/2, got {self.max_steer_rad!r}"
            )

    @property
    def max_curvature_1_m(self) -> float:
        """Curvature at full steering lock."""
        return math.tan(self.max_steer_rad) / self.wheelbase_m


@dataclass(frozen=True)
class ReferenceDrive:
    """An exact reference trajectory sampled at ``rate_hz`` (``N`` samples).

    Attributes:
        name: ``"urban"``, ``"highway"``...
        rate_hz: sampling rate of every array.
        t_s: ``(N,)`` times from 0.
        pose: ``(N, 3)`` ``(x_m, y_m, heading_rad)``, world frame, heading wrapped to ``[-pi, pi)``.
        speed_m_s: ``(N,)`` speed (>= 0).
        accel_m_s2: ``(N,)`` longitudinal acceleration held over ``[t_i, t_i+1)``.
        yaw_rate_rad_s: ``(N,)`` yaw rate (counter-clockwise positive).
        steer_rad: ``(N,)`` front steering angle.
        params: the vehicle.
    """

    name: str
    rate_hz: float
    t_s: np.ndarray
    pose: np.ndarray
    speed_m_s: np.ndarray
    accel_m_s2: np.ndarray
    yaw_rate_rad_s: np.ndarray
    steer_rad: np.ndarray
    params: VehicleParams

    @property
    def duration_s(self) -> float:
        """Time of the last sample."""
        return float(self.t_s[-1])

    @property
    def curvature_1_m(self) -> np.ndarray:
        """``(N,)`` path curvature ``tan(steer) / wheelbase`` (left positive)."""
        return np.tan(self.steer_rad) / self.params.wheelbase_m


def integrate_single_track(
    name: str,
    accel_m_s2: np.ndarray,
    steer_rad: np.ndarray,
    initial_pose: tuple[float, float, float],
    initial_speed_m_s: float,
    rate_hz: float,
    params: VehicleParams,
) -> ReferenceDrive:
    """Integrate the single-track model over ``N`` samples of the inputs ``(N,)``.

    Speeds within ``1e-9`` m/s of 0 (rounding at a stop) are set to exactly 0; a larger
    negative speed means the inputs ask the car to reverse and is refused.

    Raises:
        RobotsimError: inputs of different lengths, non-finite, or a reversing car.
    """
    accel = np.asarray(accel_m_s2, dtype=float)
    steer = np.asarray(steer_rad, dtype=float)
    if accel.shape != steer.shape or accel.ndim != 1 or accel.size < 2:
        raise RobotsimError(
            f"single-track model: inputs must be two (N,) arrays, N >= 2, got {accel.shape}, {steer.shape}"
        )
    if not (np.isfinite(accel).all() and np.isfinite(steer).all()):
        raise RobotsimError("single-track model: the inputs are not finite")
    dt = 1.0 / rate_hz
    speed = initial_speed_m_s + np.concatenate([[0.0], np.cumsum(accel[:-1]) * dt])
    if speed.min() < -1e-9:
        raise RobotsimError(
            f"single-track model: the inputs make the car reverse (speed {speed.min():.3g} m/s)"
        )
    speed = np.where(speed < 1e-9, 0.0, speed)
    yaw_rate = speed * np.tan(steer) / params.wheelbase_m
    heading = initial_pose[2] + _cumulative_trapezoid(yaw_rate, dt)
    x = initial_pose[0] + _cumulative_trapezoid(speed * np.cos(heading), dt)
    y = initial_pose[1] + _cumulative_trapezoid(speed * np.sin(heading), dt)
    wrapped = (heading + math.pi) % (2.0 * math.pi) - math.pi
    return ReferenceDrive(
        name=name,
        rate_hz=float(rate_hz),
        t_s=np.arange(accel.size) * dt,
        pose=np.stack([x, y, wrapped], axis=-1),
        speed_m_s=speed,
        accel_m_s2=accel,
        yaw_rate_rad_s=yaw_rate,
        steer_rad=steer,
        params=params,
    )


def _cumulative_trapezoid(rate: np.ndarray, dt: float) -> np.ndarray:
    """``(N,)`` integral of ``rate (N,)`` from sample 0, trapezoid rule, starting at 0."""
    return np.concatenate([[0.0], np.cumsum(0.5 * dt * (rate[:-1] + rate[1:]))])
