"""Reference drives for the motion-model comparison of paper 001: urban and highway.

A drive is a random sequence of manoeuvres (stop and go, turns at intersections, bends,
speed changes, lane changes) drawn from a ``numpy.random.Generator``: the same seed gives
the same drive. Each manoeuvre is a short vectorised profile of the inputs
(acceleration, curvature) at the sample rate; the loop runs over manoeuvres (tens per
drive), never over samples. :func:`~robotsim.vehicle.single_track.integrate_single_track`
turns the concatenated inputs into the reference trajectory.

Profiles respect the :class:`VehicleParams` limits: speed changes have a trapezoidal
acceleration with a jerk limit (``JERK_M_S3``) and a peak below the acceleration/braking
limits; turns and bends have clothoid entries and exits (the curvature ramps linearly) and a
radius large enough for the lateral-acceleration and steering limits; a lane change
follows a raised-cosine lateral offset.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from robotsim.errors import RobotsimError
from robotsim.vehicle.single_track import ReferenceDrive, VehicleParams, integrate_single_track

#: Jerk limit of every speed change (m/s^3).
JERK_M_S3 = 2.5
#: Duration of the clothoid entry (and exit) of intersection turns (s).
TURN_TRANSITION_S = 1.2
#: Duration of the clothoid entry (and exit) of highway bends (s).
BEND_TRANSITION_S = 5.0
#: Lane width of the highway (m).
LANE_WIDTH_M = 3.5
#: Margin kept below the vehicle limits (fraction of the limit used at most).
LIMIT_MARGIN = 0.9


def _trapezoid_shape(n_ramp: int, n_flat: int) -> np.ndarray:
    """Samples (at mid-sample times) of a unit trapezoid: linear ramp, flat top, ramp down."""
    ramp = (np.arange(n_ramp) + 0.5) / n_ramp
    return np.concatenate([ramp, np.ones(n_flat), ramp[::-1]])


class ManoeuvreProfile:
    """A drive under construction: manoeuvres appended as input arrays (acceleration,
    curvature) at ``rate_hz``, from the speed ``speed_m_s``.

    :func:`urban_drive` and :func:`highway_drive` are sequences of its manoeuvres
    (:meth:`hold`, :meth:`speed_change`, :meth:`turn`, :meth:`lane_change`); a hand-made
    sequence gives a drive of one's own. :meth:`build` integrates the inputs into a
    :class:`~robotsim.vehicle.single_track.ReferenceDrive`.
    """

    def __init__(self, rate_hz: float, speed_m_s: float, params: VehicleParams):
        self.dt = 1.0 / rate_hz
        self.speed = speed_m_s
        self.params = params
        self.accel: list[np.ndarray] = []
        self.curvature: list[np.ndarray] = []
        self.samples = 0

    @property
    def duration_s(self) -> float:
        return self.samples * self.dt

    def _append(self, accel: np.ndarray, curvature: np.ndarray) -> None:
        self.accel.append(accel)
        self.curvature.append(curvature)
        self.samples += accel.size

    def hold(self, duration_s: float) -> None:
        """Keep the speed and drive straight for ``duration_s``."""
        n = max(1, round(duration_s / self.dt))
        self._append(np.zeros(n), np.zeros(n))

    def speed_change(self, target_m_s: float, accel_abs_m_s2: float) -> None:
        """Reach ``target_m_s`` with a jerk-limited trapezoidal acceleration peaking at ``accel_abs_m_s2``."""
        dv = target_m_s - self.speed
        if abs(dv) < 1e-9:
            return
        peak = accel_abs_m_s2
        ramp_s = peak / JERK_M_S3
        if abs(dv) < peak * ramp_s:  # too small for a flat top: a triangle
            peak = math.sqrt(abs(dv) * JERK_M_S3)
            ramp_s = peak / JERK_M_S3
        flat_s = abs(dv) / peak - ramp_s
        shape = _trapezoid_shape(max(1, round(ramp_s / self.dt)), max(0, round(flat_s / self.dt)))
        self._append(shape * (dv / (shape.sum() * self.dt)), np.zeros(shape.size))
        self.speed = target_m_s

    def turn(self, angle_rad: float, radius_m: float, transition_s: float) -> None:
        """Turn by ``angle_rad`` (left positive) at constant speed, down to ``radius_m``.

        The curvature ramps up over ``transition_s``, holds at ``1/radius``, ramps down; the
        radius is enlarged where the lateral-acceleration or steering limit asks for it.
        """
        if self.speed <= 0.0:
            raise RobotsimError("drive profile: a turn needs a positive speed")
        radius = max(
            radius_m,
            self.speed**2 / (LIMIT_MARGIN * self.params.lateral_accel_max_m_s2),
            1.0 / (LIMIT_MARGIN * self.params.max_curvature_1_m),
        )
        turn_rate = self.speed / radius
        flat_s = abs(angle_rad) / turn_rate - transition_s
        if flat_s < 0.0:  # a short turn: ramps only, peak curvature below 1/radius
            transition_s, flat_s = abs(angle_rad) / turn_rate, 0.0
        shape = _trapezoid_shape(max(1, round(transition_s / self.dt)), round(flat_s / self.dt))
        curvature = shape * (angle_rad / (self.speed * shape.sum() * self.dt))
        self._append(np.zeros(shape.size), curvature)

    def lane_change(self, offset_m: float, duration_s: float) -> None:
        """Move ``offset_m`` sideways (left positive) along a raised cosine over ``duration_s``.

        Lateral offset ``d (1 - cos(pi t / T)) / 2``: curvature ``d pi^2 cos(pi t/T) / (2 T^2 v^2)``
        (small-angle), whose integral over the manoeuvre is zero: the heading comes back.
        """
        n = max(2, round(duration_s / self.dt))
        t = (np.arange(n) + 0.5) * self.dt
        period = n * self.dt
        curvature = (
            offset_m * math.pi**2 * np.cos(math.pi * t / period) / (2.0 * period**2 * self.speed**2)
        )
        self._append(np.zeros(n), curvature)

    def build(
        self, name: str, duration_s: float, initial_speed_m_s: float, rate_hz: float
    ) -> ReferenceDrive:
        """The reference drive ``name``: the first ``duration_s`` of the manoeuvres, starting at
        the origin heading along +x at ``initial_speed_m_s`` (the speed the profile began at)."""
        n = round(duration_s * rate_hz) + 1
        accel = np.concatenate(self.accel)[:n]
        steer = np.arctan(np.concatenate(self.curvature)[:n] * self.params.wheelbase_m)
        return integrate_single_track(
            name, accel, steer, (0.0, 0.0, 0.0), initial_speed_m_s, rate_hz, self.params
        )


def _check(duration_s: float, rate_hz: float) -> None:
    if not (math.isfinite(duration_s) and duration_s >= 10.0):
        raise RobotsimError(f"drive: duration_s must be finite and >= 10 s, got {duration_s!r}")
    if not (math.isfinite(rate_hz) and rate_hz >= 10.0):
        raise RobotsimError(f"drive: rate_hz must be finite and >= 10 Hz, got {rate_hz!r}")


def urban_drive(
    rng: np.random.Generator,
    duration_s: float = 300.0,
    rate_hz: float = 100.0,
    params: VehicleParams | None = None,
) -> ReferenceDrive:
    """City traffic from standstill: 8-14 m/s between intersections, stops at lights
    (2-10 s), right-angle turns at 4.5-7 m/s, bends; accelerations up to 0.9 of the limits.
    """
    _check(duration_s, rate_hz)
    params = params or VehicleParams()
    accel_hi = LIMIT_MARGIN * params.a_max_m_s2
    brake_hi = LIMIT_MARGIN * -params.a_min_m_s2
    p = ManoeuvreProfile(rate_hz, 0.0, params)
    while p.duration_s < duration_s:
        p.speed_change(rng.uniform(8.0, 14.0), rng.uniform(1.5, accel_hi))
        p.hold(rng.uniform(3.0, 12.0))
        kind = rng.uniform()
        side = rng.choice([-1.0, 1.0])
        if kind < 0.4:  # red light: stop, wait, sometimes turn off afterwards
            p.speed_change(0.0, rng.uniform(2.0, brake_hi))
            p.hold(rng.uniform(2.0, 10.0))
            if rng.uniform() < 0.5:
                p.speed_change(rng.uniform(4.5, 6.0), rng.uniform(1.5, accel_hi))
                p.turn(side * math.pi / 2, rng.uniform(8.0, 15.0), TURN_TRANSITION_S)
        elif kind < 0.8:  # turn at an intersection
            p.speed_change(rng.uniform(4.5, 7.0), rng.uniform(2.0, brake_hi))
            p.turn(side * math.pi / 2, rng.uniform(10.0, 20.0), TURN_TRANSITION_S)
        else:  # a bend in the street
            p.turn(side * rng.uniform(0.3, 0.8), rng.uniform(40.0, 100.0), 2.0 * TURN_TRANSITION_S)
    return p.build("urban", duration_s, 0.0, rate_hz)


def highway_drive(
    rng: np.random.Generator,
    duration_s: float = 300.0,
    rate_hz: float = 100.0,
    params: VehicleParams | None = None,
) -> ReferenceDrive:
    """Motorway at 22-34 m/s: long straights, bends of 300-1000 m radius, speed changes of
    0.6-1.5 m/s^2 and lane changes of one lane width in 4-7 s.
    """
    _check(duration_s, rate_hz)
    params = params or VehicleParams()
    initial_speed = rng.uniform(24.0, 30.0)
    p = ManoeuvreProfile(rate_hz, initial_speed, params)
    while p.duration_s < duration_s:  # every block holds one of each manoeuvre, in random order
        for kind in rng.permutation(3):
            p.hold(rng.uniform(5.0, 15.0))
            side = rng.choice([-1.0, 1.0])
            if kind == 0:
                p.turn(side * rng.uniform(0.3, 0.9), rng.uniform(300.0, 1000.0), BEND_TRANSITION_S)
            elif kind == 1:
                p.lane_change(side * LANE_WIDTH_M, rng.uniform(4.0, 7.0))
            else:
                p.speed_change(
                    rng.uniform(22.0, min(34.0, params.v_max_m_s)), rng.uniform(0.6, 1.5)
                )
    return p.build("highway", duration_s, initial_speed, rate_hz)


#: The reference drives by name: ``drive(rng, duration_s, rate_hz, params) -> ReferenceDrive``.
DRIVES: dict[str, Callable[..., ReferenceDrive]] = {"urban": urban_drive, "highway": highway_drive}
