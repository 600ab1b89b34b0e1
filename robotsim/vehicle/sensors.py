"""GPS and odometry of the simulated vehicle, batched over Monte Carlo runs.

Declared error model (:class:`VehicleSensorParams`):

- GPS: the true position (the reference point of the drive) at ``gps_rate_hz`` plus white
  Gaussian noise of ``gps_noise_std_m`` on each axis, independent between fixes;
- odometry speed: ``(1 + speed_scale_error) v + n_v``, ``n_v ~ N(0, speed_noise_std_m_s^2)``
  (a wheel-radius scale bias plus white noise);
- odometry yaw rate: ``omega + yaw_rate_bias_rad_s + n_w``, ``n_w ~ N(0, yaw_rate_noise_std_rad_s^2)``
  (a constant gyro bias plus white noise).

The biases are constants, the same in every run; only the white noise differs between runs.
Odometry epochs are every ``drive.rate_hz / odometry_rate_hz``-th reference sample; GPS fixes
fall on every ``odometry_rate_hz / gps_rate_hz``-th odometry epoch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robotsim.errors import RobotsimError
from robotsim.vehicle.single_track import ReferenceDrive


@dataclass(frozen=True)
class VehicleSensorParams:
    """Rates, noise standard deviations and biases of the vehicle's sensors.

    Attributes:
        gps_rate_hz: GPS fixes per second.
        gps_noise_std_m: standard deviation of the GPS error on each axis.
        odometry_rate_hz: odometry samples per second (speed and yaw rate together).
        speed_noise_std_m_s: white-noise standard deviation of the speed.
        speed_scale_error: relative scale bias of the speed (0.01 reads 1 % high).
        yaw_rate_noise_std_rad_s: white-noise standard deviation of the yaw rate.
        yaw_rate_bias_rad_s: constant bias of the yaw rate.
    """

    gps_rate_hz: float = 1.0
    gps_noise_std_m: float = 1.5
    odometry_rate_hz: float = 10.0
    speed_noise_std_m_s: float = 0.1
    speed_scale_error: float = 0.01
    yaw_rate_noise_std_rad_s: float = 0.005
    yaw_rate_bias_rad_s: float = math.radians(0.1)

    def __post_init__(self) -> None:
        for name in ("gps_rate_hz", "odometry_rate_hz"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise RobotsimError(
                    f"VehicleSensorParams: {name} must be finite and > 0, got {value!r}"
                )
        for name in ("gps_noise_std_m", "speed_noise_std_m_s", "yaw_rate_noise_std_rad_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise RobotsimError(
                    f"VehicleSensorParams: {name} must be finite and >= 0, got {value!r}"
                )
        for name in ("speed_scale_error", "yaw_rate_bias_rad_s"):
            if not math.isfinite(getattr(self, name)):
                raise RobotsimError(f"VehicleSensorParams: {name} must be finite")
        if not _is_multiple(self.odometry_rate_hz, self.gps_rate_hz):
            raise RobotsimError(
                "VehicleSensorParams: odometry_rate_hz must be a whole multiple of gps_rate_hz, "
                f"got {self.odometry_rate_hz} and {self.gps_rate_hz}"
            )


@dataclass(frozen=True)
class VehicleMeasurements:
    """The sensor readings of ``R`` Monte Carlo runs on one drive (``K`` odometry epochs).

    Attributes:
        t_s: ``(K,)`` odometry epochs.
        drive_index: ``(K,)`` index of each epoch in the drive's arrays (for the reference).
        speed_m_s: ``(R, K)`` measured speed.
        yaw_rate_rad_s: ``(R, K)`` measured yaw rate.
        gps_epoch: ``(K,)`` bool, the epochs with a GPS fix.
        gps_xy_m: ``(R, G, 2)`` the fixes, ``G = gps_epoch.sum()``, world frame.
        params: the sensor settings used.
    """

    t_s: np.ndarray
    drive_index: np.ndarray
    speed_m_s: np.ndarray
    yaw_rate_rad_s: np.ndarray
    gps_epoch: np.ndarray
    gps_xy_m: np.ndarray
    params: VehicleSensorParams


def _is_multiple(rate_hz: float, base_hz: float) -> bool:
    ratio = rate_hz / base_hz
    return abs(ratio - round(ratio)) < 1e-9 and round(ratio) >= 1


def measure(
    drive: ReferenceDrive, params: VehicleSensorParams, rng: np.random.Generator, runs: int = 1
) -> VehicleMeasurements:
    """Sensor readings of ``runs`` independent Monte Carlo runs on ``drive`` (vectorised).

    Raises:
        RobotsimError: ``runs < 1`` or an odometry rate that does not divide the drive's rate.
    """
    if not (isinstance(runs, (int, np.integer)) and runs >= 1):
        raise RobotsimError(f"vehicle sensors: runs must be an integer >= 1, got {runs!r}")
    if not _is_multiple(drive.rate_hz, params.odometry_rate_hz):
        raise RobotsimError(
            f"vehicle sensors: the drive rate {drive.rate_hz} Hz is not a whole multiple of "
            f"odometry_rate_hz {params.odometry_rate_hz}"
        )
    stride = round(drive.rate_hz / params.odometry_rate_hz)
    index = np.arange(0, drive.t_s.size, stride)
    gps_stride = round(params.odometry_rate_hz / params.gps_rate_hz)
    gps_epoch = np.arange(index.size) % gps_stride == 0
    true_speed = drive.speed_m_s[index]
    true_yaw_rate = drive.yaw_rate_rad_s[index]
    k, g = index.size, int(gps_epoch.sum())
    speed_noise = params.speed_noise_std_m_s * rng.standard_normal((runs, k))
    speed = (1.0 + params.speed_scale_error) * true_speed + speed_noise
    yaw_rate = (
        true_yaw_rate
        + params.yaw_rate_bias_rad_s
        + params.yaw_rate_noise_std_rad_s * rng.standard_normal((runs, k))
    )
    gps = drive.pose[index[gps_epoch], :2] + params.gps_noise_std_m * rng.standard_normal(
        (runs, g, 2)
    )
    return VehicleMeasurements(
        t_s=drive.t_s[index],
        drive_index=index,
        speed_m_s=speed,
        yaw_rate_rad_s=yaw_rate,
        gps_epoch=gps_epoch,
        gps_xy_m=gps,
        params=params,
    )
