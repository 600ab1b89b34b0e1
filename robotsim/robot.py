"""The differential-drive robot: its parameters and kinematics (docs/models.md section 2).

Wheel rates ``w_l, w_r`` (rad/s), radii ``r_l, r_r`` (m), wheel base ``L`` (m):

    v     = (r_r w_r + r_l w_l) / 2        forward speed, m/s
    omega = (r_r w_r - r_l w_l) / L        yaw rate, rad/s

The robot's software knows only the nominal radius ``wheel_radius_m``; the world moves it
with the true radii, which differ by a calibration error (what makes odometry drift).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robotsim.errors import RobotsimError
from validated_records import bounded, validate_fields


def wrap_angle(angle_rad):
    """Angles wrapped to ``[-pi, pi)`` (array or float; a float gives a numpy float).

    ``(a + pi) % 2 pi`` can round up to exactly ``2 pi`` for ``a`` just below ``-pi``; that
    result (``+pi``) is moved to ``-pi`` so the half-open range holds at the edge too.
    """
    wrapped = np.add(
        angle_rad, np.pi
    )  # a new array (or numpy float): the steps below work in place
    wrapped %= 2.0 * np.pi
    wrapped -= np.pi
    # rare: one comparison pass in the common case (the ufunc's reduce: ndarray.max's
    # Python wrapper costs more than the pass on the few angles of a closed-loop block)
    if wrapped.size and np.maximum.reduce(wrapped, axis=None) >= np.pi:
        wrapped = np.where(wrapped >= np.pi, wrapped - 2.0 * np.pi, wrapped)[()]
    return wrapped


#: Largest relative difference between a true wheel radius and the nominal one: a calibration
#: error of real wheels is a few per mille; the dead-reckoning model is first order in it.
MAX_WHEEL_RADIUS_ERROR = 0.1

#: Largest encoder resolution, ticks per revolution (2^24, the finest absolute encoders): the
#: cumulative tick count of the longest run at the largest speed over the smallest wheel stays
#: far inside int64 (1e4 rad/s over 1e7 s is 3e17 ticks at this resolution).
MAX_TICKS_PER_REV = 2**24


@dataclass(frozen=True)
class RobotParams:
    """A disk-shaped differential-drive robot (bounds declared beside each field: a robot
    the simulator can move with every number in range).

    Attributes:
        wheel_radius_m: nominal wheel radius, the one the estimator knows.
        true_wheel_radius_left_m, true_wheel_radius_right_m: the radii the world uses
            (within :data:`MAX_WHEEL_RADIUS_ERROR` of the nominal one).
        wheel_base_m: distance between the wheel contact points.
        ticks_per_rev: encoder ticks per wheel revolution.
        radius_m: radius of the footprint disk (collision shape; the sonar belt sits on it).
        mass_kg: body mass.
        v_max_m_s, omega_max_rad_s: bounds on the true forward speed and yaw rate.
        a_max_m_s2: bound on the forward acceleration; the yaw acceleration is bounded by
            ``alpha_max_rad_s2 = 2 a_max / wheel_base`` (each wheel at most ``a_max``).
    """

    wheel_radius_m: float = bounded(0.05, minimum=1e-3, maximum=1.0)
    true_wheel_radius_left_m: float = bounded(0.0503, minimum=1e-3, maximum=1.0)
    true_wheel_radius_right_m: float = bounded(0.0498, minimum=1e-3, maximum=1.0)
    wheel_base_m: float = bounded(0.30, minimum=0.01, maximum=10.0)
    ticks_per_rev: int = bounded(2048, minimum=1, maximum=MAX_TICKS_PER_REV, integer=True)
    radius_m: float = bounded(0.20, minimum=0.01, maximum=10.0)
    mass_kg: float = bounded(8.0, minimum=0.1, maximum=10_000.0)
    v_max_m_s: float = bounded(0.6, above=0.0, maximum=10.0)
    omega_max_rad_s: float = bounded(1.5, above=0.0, maximum=20.0)
    a_max_m_s2: float = bounded(0.5, above=0.0, maximum=20.0)

    def __post_init__(self) -> None:
        validate_fields(self, RobotsimError)
        for name in ("true_wheel_radius_left_m", "true_wheel_radius_right_m"):
            error = getattr(self, name) / self.wheel_radius_m - 1.0
            if abs(error) > MAX_WHEEL_RADIUS_ERROR:
                raise RobotsimError(
                    f"RobotParams.{name} must be within {MAX_WHEEL_RADIUS_ERROR:.0%} of "
                    f"wheel_radius_m ({self.wheel_radius_m:g} m), got {getattr(self, name):g} m"
                )

    @property
    def alpha_max_rad_s2(self) -> float:
        """Bound on the yaw acceleration, ``2 a_max / wheel_base``."""
        return 2.0 * self.a_max_m_s2 / self.wheel_base_m

    @property
    def true_radii_m(self) -> np.ndarray:
        """True wheel radii ``(2,)`` = (left, right)."""
        return np.array([self.true_wheel_radius_left_m, self.true_wheel_radius_right_m])

    @property
    def nominal_radii_m(self) -> np.ndarray:
        """Nominal wheel radii ``(2,)`` = (left, right)."""
        return np.full(2, self.wheel_radius_m)


def body_velocity(wheel_rate_rad_s, radii_m, wheel_base_m: float) -> np.ndarray:
    """Body velocity ``(..., 2)`` = (v_m_s, omega_rad_s) from wheel rates ``(..., 2)``
    (left, right) and radii ``(2,)`` (left, right)."""
    travel = np.asarray(wheel_rate_rad_s) * np.asarray(radii_m)  # wheel rim speeds, m/s
    return np.stack(
        [0.5 * (travel[..., 1] + travel[..., 0]), (travel[..., 1] - travel[..., 0]) / wheel_base_m],
        axis=-1,
    )


def wheel_rates(velocity, radii_m, wheel_base_m: float) -> np.ndarray:
    """Wheel rates ``(..., 2)`` rad/s (left, right) giving body velocity ``(..., 2)``
    = (v_m_s, omega_rad_s): the inverse of :func:`body_velocity`."""
    velocity = np.asarray(velocity)
    v, omega = velocity[..., 0], velocity[..., 1]
    half_turn = 0.5 * wheel_base_m * omega
    radii = np.asarray(radii_m)
    return np.stack([(v - half_turn) / radii[0], (v + half_turn) / radii[1]], axis=-1)


def integrate_pose(pose, velocity, dt_s: float) -> np.ndarray:
    """Exact unicycle step: poses ``(..., 3)`` moved for ``dt_s`` at constant body velocity
    ``(..., 2)`` = (v, omega) along a circular arc (a straight line when omega = 0)."""
    pose, velocity = np.asarray(pose, dtype=np.float64), np.asarray(velocity, dtype=np.float64)
    theta, v, omega = pose[..., 2], velocity[..., 0], velocity[..., 1]
    turn = omega * dt_s
    # chord length / (v dt) = sinc(turn / 2); the chord points along theta + turn / 2
    chord = v * dt_s * np.sinc(turn / (2.0 * np.pi))
    heading = theta + 0.5 * turn
    return np.stack(
        [
            pose[..., 0] + chord * np.cos(heading),
            pose[..., 1] + chord * np.sin(heading),
            wrap_angle(theta + turn),
        ],
        axis=-1,
    )
