"""Path following: pure pursuit over a route of waypoints, a scripted (v, omega) profile,
and the limits every command passes through.

A plan (:class:`Route`, :class:`ScriptedProfile`) is a frozen setting; its
:meth:`controller` gives a fresh stateful controller for one run, whose
``command(t_s, x_m, y_m, theta_rad) -> (v_m_s, omega_rad_s)`` is called once per step.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from robotsim.errors import RobotsimError
from robotsim.robot import RobotParams
from validated_records import bounded, validate_fields


class Controller(Protocol):
    """One run's controller: the wanted body velocity at time ``t_s`` and true pose."""

    def command(self, t_s: float, x_m: float, y_m: float, theta_rad: float) -> tuple[float, float]:
        """Wanted ``(v_m_s, omega_rad_s)``."""
        ...


def speed_limited(v_m_s: float, omega_rad_s: float, robot: RobotParams) -> tuple[float, float]:
    """A wanted body velocity clamped to ``|v| <= v_max``, ``|omega| <= omega_max`` (what
    :func:`limit_command` returns once the accelerations have reached it)."""
    v = min(max(v_m_s, -robot.v_max_m_s), robot.v_max_m_s)
    w = min(max(omega_rad_s, -robot.omega_max_rad_s), robot.omega_max_rad_s)
    return v, w


def limit_command(
    v_m_s: float, omega_rad_s: float, previous: tuple[float, float], dt_s: float, robot: RobotParams
) -> tuple[float, float]:
    """Clamp a wanted body velocity to ``|v| <= v_max``, ``|omega| <= omega_max`` and to the
    accelerations ``|dv/dt| <= a_max``, ``|domega/dt| <= alpha_max`` from ``previous``
    (``previous`` itself when it is the clamped velocity: the ramp has reached it)."""
    dv, dw = robot.a_max_m_s2 * dt_s, robot.alpha_max_rad_s2 * dt_s
    v, w = speed_limited(v_m_s, omega_rad_s, robot)
    v = min(max(v, previous[0] - dv), previous[0] + dv)
    w = min(max(w, previous[1] - dw), previous[1] + dw)
    return v, w


@dataclass(frozen=True, eq=False)
class Route:
    """Waypoints followed by pure pursuit.

    Attributes:
        waypoints_m: ``(p, 2)`` world-frame points, p >= 1, visited in order (the path
            starts at the robot's first position).
        cruise_speed_m_s: forward speed on straight stretches.
        lookahead_m: distance along the path to the pursued point.
        goal_tolerance_m: the run's controller stops within this distance of the last
            waypoint (unless ``loop``).
        loop: after the last waypoint, go back to the first one, forever.
    """

    waypoints_m: np.ndarray
    cruise_speed_m_s: float = bounded(0.4, above=0.0, maximum=10.0)
    lookahead_m: float = bounded(0.5, above=0.0, maximum=10_000.0)
    goal_tolerance_m: float = bounded(0.05, above=0.0, maximum=10_000.0)
    loop: bool = False

    def __post_init__(self) -> None:
        waypoints = np.array(self.waypoints_m, dtype=np.float64)
        if waypoints.ndim != 2 or waypoints.shape[1] != 2 or len(waypoints) == 0:
            raise RobotsimError(
                f"route waypoints must have shape (p, 2), p >= 1, got {waypoints.shape}"
            )
        if not np.isfinite(waypoints).all():
            raise RobotsimError("route waypoints must be finite")
        if self.loop and len(waypoints) < 2:
            raise RobotsimError("a looping route needs at least 2 waypoints")
        validate_fields(self, RobotsimError)
        waypoints.setflags(write=False)
        object.__setattr__(self, "waypoints_m", waypoints)

    def controller(self, robot: RobotParams) -> PurePursuit:
        """A fresh pure-pursuit controller for one run."""
        return PurePursuit(self, robot)


class PurePursuit:
    """Pure pursuit (Coulter 1992): steer along the arc through the point ``lookahead_m``
    ahead on the path, curvature ``kappa = 2 y_l / l^2`` (``y_l`` the point's lateral offset
    in the robot frame, ``l`` its distance); ``omega = kappa v``. The speed drops where the
    arc is tight (``|omega| <= omega_max``) and near the goal (stopping within ``a_max``);
    a point behind the robot makes it turn in place."""

    def __init__(self, route: Route, robot: RobotParams) -> None:
        self.route = route
        self.robot = robot
        self._waypoints = [tuple(point) for point in route.waypoints_m.tolist()]
        self._start: tuple[float, float] | None = None
        self._segment = 0
        self.finished = False

    def _point(self, index: int) -> tuple[float, float]:
        """Path point ``index``: 0 is the start, then the waypoints (cycling if looping)."""
        if index == 0:
            if self._start is None:  # set by the first command
                raise RobotsimError("pure pursuit: the path has no start before the first command")
            return self._start
        count = len(self._waypoints)
        return self._waypoints[
            (index - 1) % count if self.route.loop else min(index - 1, count - 1)
        ]

    def _is_last(self, segment: int) -> bool:
        return not self.route.loop and segment >= len(self._waypoints) - 1

    def command(self, t_s: float, x_m: float, y_m: float, theta_rad: float) -> tuple[float, float]:
        """Wanted ``(v_m_s, omega_rad_s)`` at the true pose."""
        if self._start is None:
            self._start = (x_m, y_m)
        if self.finished:
            return 0.0, 0.0
        lookahead = self.route.lookahead_m
        # move on to the next segment once past this one's end or near its end point (a loop
        # at most one lap a command: every waypoint of a loop can lie within the lookahead)
        for _ in range(len(self._waypoints) + 1):
            if self._is_last(self._segment):
                break
            t, _ = _project(self._point(self._segment), self._point(self._segment + 1), x_m, y_m)
            end_x, end_y = self._point(self._segment + 1)
            if t < 1.0 and math.hypot(end_x - x_m, end_y - y_m) > lookahead:
                break
            self._segment += 1
        goal_x, goal_y = self._point(self._segment + 1)
        goal_distance = math.hypot(goal_x - x_m, goal_y - y_m)
        if self._is_last(self._segment) and goal_distance <= self.route.goal_tolerance_m:
            self.finished = True
            return 0.0, 0.0

        target_x, target_y = self._target(x_m, y_m, lookahead)
        cos_t, sin_t = math.cos(theta_rad), math.sin(theta_rad)
        dx, dy = target_x - x_m, target_y - y_m
        ahead, lateral = cos_t * dx + sin_t * dy, -sin_t * dx + cos_t * dy
        if ahead <= 0.0:  # the pursued point is behind: turn in place towards it
            return 0.0, math.copysign(self.robot.omega_max_rad_s, lateral)
        curvature = 2.0 * lateral / (dx * dx + dy * dy)
        v = self.route.cruise_speed_m_s
        if curvature != 0.0:
            v = min(v, self.robot.omega_max_rad_s / abs(curvature))
        if self._is_last(self._segment):
            v = min(v, math.sqrt(self.robot.a_max_m_s2 * goal_distance))
        return v, curvature * v

    def _target(self, x_m: float, y_m: float, lookahead: float) -> tuple[float, float]:
        """The point ``lookahead`` metres along the path beyond the robot's projection."""
        segment = self._segment
        start, end = self._point(segment), self._point(segment + 1)
        t, length = _project(start, end, x_m, y_m)
        remaining = lookahead + min(max(t, 0.0), 1.0) * length
        for _ in range(len(self._waypoints) + 1):  # at most one lap (a loop of zero length)
            if remaining <= length or self._is_last(segment):
                break
            remaining -= length
            segment += 1
            start, end = self._point(segment), self._point(segment + 1)
            length = math.hypot(end[0] - start[0], end[1] - start[1])
        if remaining >= length:
            return end
        fraction = remaining / length
        return start[0] + fraction * (end[0] - start[0]), start[1] + fraction * (end[1] - start[1])


def _project(start, end, x_m: float, y_m: float) -> tuple[float, float]:
    """Parameter ``t`` of the projection of (x, y) on the line start-end, and its length."""
    ex, ey = end[0] - start[0], end[1] - start[1]
    length_sq = ex * ex + ey * ey
    if length_sq == 0.0:
        return 1.0, 0.0
    return ((x_m - start[0]) * ex + (y_m - start[1]) * ey) / length_sq, math.sqrt(length_sq)


@dataclass(frozen=True, eq=False)
class ScriptedProfile:
    """A piecewise-constant command: ``(v_m_s[i], omega_rad_s[i])`` from ``t_s[i]`` until
    ``t_s[i + 1]`` (the last one held); zero before ``t_s[0]``. Arrays ``(n,)``, ``t_s``
    strictly increasing."""

    t_s: np.ndarray
    v_m_s: np.ndarray
    omega_rad_s: np.ndarray

    def __post_init__(self) -> None:
        names = ("t_s", "v_m_s", "omega_rad_s")
        arrays = {name: np.array(getattr(self, name), dtype=np.float64) for name in names}
        shapes = {array.shape for array in arrays.values()}
        if len(shapes) != 1 or arrays["t_s"].ndim != 1 or arrays["t_s"].size == 0:
            raise RobotsimError(
                f"scripted profile arrays must share one shape (n,), n >= 1, got {sorted(shapes)}"
            )
        if not all(np.isfinite(array).all() for array in arrays.values()):
            raise RobotsimError("scripted profile values must be finite")
        if (np.diff(arrays["t_s"]) <= 0).any():
            raise RobotsimError("scripted profile t_s must be strictly increasing")
        for name, array in arrays.items():
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def controller(self, robot: RobotParams) -> ScriptedController:
        """The controller replaying this profile."""
        return ScriptedController(self)


class ScriptedController:
    """Replays a :class:`ScriptedProfile`, whatever the pose."""

    def __init__(self, profile: ScriptedProfile) -> None:
        self._t = profile.t_s.tolist()
        self._commands = list(
            zip(profile.v_m_s.tolist(), profile.omega_rad_s.tolist(), strict=True)
        )

    def command(self, t_s: float, x_m: float, y_m: float, theta_rad: float) -> tuple[float, float]:
        """The profile's ``(v_m_s, omega_rad_s)`` at ``t_s``."""
        index = bisect.bisect_right(self._t, t_s) - 1
        return self._commands[index] if index >= 0 else (0.0, 0.0)


#: What the robot is told to do: a route to follow or a scripted profile.
Plan = Route | ScriptedProfile
