"""Wheel encoders: integer ticks per sample from the true wheel rotation.

The wheels roll without slipping on the ground the robot really covered (as pymunk moved
it), so the true rotation of a wheel over one sample is its travel over its TRUE radius:

    travel_l = ds - L/2 dtheta,   travel_r = ds + L/2 dtheta,   rotation = travel / r_true

with ``ds`` the displacement along the mid-step heading and ``dtheta`` the heading change.
Ticks count whole steps of ``2 pi / ticks_per_rev`` of the cumulative rotation, so the
quantisation error never accumulates. Optional slip scales each sample's rotation by
``1 + slip_std * N(0, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robotsim.errors import RobotsimError
from robotsim.robot import RobotParams, wrap_angle
from validated_records import bounded, validate_fields


@dataclass(frozen=True)
class EncoderParams:
    """Attributes:
    slip_std: relative standard deviation of a wheel's rotation per sample
        (dimensionless, 0 = no slip)."""

    slip_std: float = bounded(0.0, minimum=0.0, maximum=1.0)

    def __post_init__(self) -> None:
        validate_fields(self, RobotsimError)


def wheel_rotation_increments(pose, robot: RobotParams) -> np.ndarray:
    """True wheel rotations ``(N, 2)`` rad (left, right) from pose ``N-1`` to ``N`` along
    ``pose (N, 3)``; row 0 is zero."""
    pose = np.asarray(pose, dtype=np.float64)
    rotation = np.zeros((len(pose), 2))
    if len(pose) > 1:
        step = pose[1:] - pose[:-1]
        turn = wrap_angle(step[:, 2])
        heading = pose[:-1, 2] + 0.5 * turn
        ds = step[:, 0] * np.cos(heading) + step[:, 1] * np.sin(heading)
        half = 0.5 * robot.wheel_base_m * turn
        rotation[1:, 0] = (ds - half) / robot.true_wheel_radius_left_m
        rotation[1:, 1] = (ds + half) / robot.true_wheel_radius_right_m
    return rotation


def simulate_ticks(
    rotation_rad, ticks_per_rev: int, params: EncoderParams, rng: np.random.Generator
) -> np.ndarray:
    """Integer tick increments ``(N, 2)`` int64 from wheel rotations per sample ``(N, 2)``."""
    rotation = np.asarray(rotation_rad, dtype=np.float64)
    return ticks_from_slip(rotation, ticks_per_rev, params, rng.standard_normal(rotation.shape))


def ticks_from_slip(rotation_rad, ticks_per_rev: int, params: EncoderParams, slip) -> np.ndarray:
    """Tick increments ``(N, 2)`` int64 from wheel rotations ``(N, 2)`` and standard normal
    slip draws ``(N, 2)``: each rotation scaled by ``1 + slip_std slip``, the cumulative turn
    counted in whole ticks, differenced."""
    turned = np.asarray(rotation_rad, dtype=np.float64) * (1.0 + params.slip_std * slip)
    count = np.floor(np.cumsum(turned, axis=0) * (ticks_per_rev / (2.0 * np.pi)))
    return np.diff(count, axis=0, prepend=np.zeros((1, turned.shape[1]))).astype(np.int64)
