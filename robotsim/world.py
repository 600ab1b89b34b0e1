"""The pymunk world: the map as static walls, the robot as a dynamic disk.

Units are metres, kilograms, seconds. The robot is driven like pymunk's "tank" example: a
kinematic control body carries the wanted velocity, and two constraints with finite
forces drag the robot body along, as the wheels' traction would:

- a ``PivotJoint`` with ``max_bias = 0`` matches the velocities of the two bodies' centres
  (no position correction) with at most ``traction_force_n``;
- a ``GearJoint`` with ``max_bias = 0`` matches their yaw rates with at most
  ``traction_torque_nm``.

Wall contacts have unbounded force, so a wall stops the robot while the traction gives
way. The true pose and velocity are whatever pymunk computes.

Unmapped obstacles (``robotsim.obstacles``) are shapes of the same thickness as the walls:
static ones on the static body, each moving one on a kinematic body of its own, put at its
path's position at the start of every step and given the velocity that reaches the next
one (pymunk pushes the robot with it, with unbounded force).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pymunk
import shapely
from pymunk._chipmunk import lib as _chipmunk

from robotsim.errors import RobotsimError
from robotsim.maps import SegmentMap, point_segment_distance
from robotsim.obstacles import NO_OBSTACLES, Obstacle, Obstacles
from robotsim.robot import RobotParams

_GRAVITY_M_S2 = 9.81

#: Steps of moving-obstacle positions computed at once (:meth:`World._mover_track`).
MOVER_BLOCK_STEPS = 1024

#: pymunk collision types: the robot's disk, the map's walls, the unmapped obstacles.
ROBOT_SHAPE, WALL_SHAPE, OBSTACLE_SHAPE = 1, 0, 2


@dataclass(frozen=True)
class WorldParams:
    """Physics settings.

    Attributes:
        step_hz: physics (and sensor sampling) rate; one :meth:`World.step` lasts 1/step_hz.
        substeps: pymunk steps per :meth:`World.step` (finer collision handling).
        wall_radius_m: thickness radius of the wall segments (collision only; the sonar
            model uses the zero-width segments).
        collision_slop_m: allowed overlap of shapes (pymunk's default assumes pixels).
        traction_coefficient: traction force = coefficient * mass * g (newtons); the
            torque is the same force at half the wheel base.
        wall_friction: Coulomb friction between robot and walls.
        solver_iterations: pymunk solver iterations per step.
    """

    step_hz: float = 100.0
    substeps: int = 1
    wall_radius_m: float = 0.02
    collision_slop_m: float = 1e-3
    traction_coefficient: float = 1.0
    wall_friction: float = 0.3
    solver_iterations: int = 10

    def __post_init__(self) -> None:
        checks = [
            (self.step_hz > 0 and math.isfinite(self.step_hz), "step_hz must be positive"),
            (
                int(self.substeps) == self.substeps and self.substeps >= 1,
                "substeps must be an integer >= 1",
            ),
            (self.wall_radius_m >= 0, "wall_radius_m must be >= 0"),
            (self.collision_slop_m >= 0, "collision_slop_m must be >= 0"),
            (self.traction_coefficient > 0, "traction_coefficient must be positive"),
            (self.wall_friction >= 0, "wall_friction must be >= 0"),
            (
                int(self.solver_iterations) == self.solver_iterations
                and self.solver_iterations >= 1,
                "solver_iterations must be an integer >= 1",
            ),
        ]
        for ok, message in checks:
            if not ok:
                raise RobotsimError(f"world: {message}")


class World:
    """A pymunk space holding the walls of ``segment_map``, the ``obstacles`` and the robot at
    ``pose`` (time 0).

    Mutable (it is the simulation state); :meth:`step` advances it by ``1 / step_hz``.
    """

    def __init__(
        self,
        segment_map: SegmentMap,
        robot: RobotParams,
        pose,
        params: WorldParams = WorldParams(),
        obstacles: Obstacles = NO_OBSTACLES,
    ) -> None:
        self.map = segment_map
        self.robot = robot
        self.params = params
        self.obstacles = obstacles
        self.t_s = 0.0
        self._steps = 0
        self.dt_s = 1.0 / params.step_hz
        self._substep_s = self.dt_s / params.substeps
        self._substeps = range(int(params.substeps))
        self._velocity_lead_s = 0.5 * self.dt_s + self._substep_s

        space = pymunk.Space()
        space.iterations = int(params.solver_iterations)
        space.collision_slop = params.collision_slop_m
        for (ax, ay), (bx, by) in segment_map.segments.tolist():
            wall = pymunk.Segment(space.static_body, (ax, ay), (bx, by), params.wall_radius_m)
            wall.friction = params.wall_friction
            space.add(wall)
        self._movers: list[tuple[Obstacle, pymunk.Body]] = []  # each moving obstacle, its body
        self._track: list = []  # per step from _track_start: each mover's position, velocity
        self._track_start = 0
        for obstacle in obstacles.items:
            body = space.static_body
            origin = np.zeros(2)
            if obstacle.moving:
                body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
                origin = obstacle.reference_m
                body.position = (float(origin[0]), float(origin[1]))
                space.add(body)
                self._movers.append((obstacle, body))
            local = (obstacle.vertices_m - origin).tolist()
            shape = (
                pymunk.Poly(body, local, radius=params.wall_radius_m)
                if obstacle.polygon
                else pymunk.Segment(body, local[0], local[1], params.wall_radius_m)
            )
            shape.friction = params.wall_friction
            shape.collision_type = OBSTACLE_SHAPE
            space.add(shape)

        moment = pymunk.moment_for_circle(robot.mass_kg, 0.0, robot.radius_m)
        body = pymunk.Body(robot.mass_kg, moment)
        disk = pymunk.Circle(body, robot.radius_m)
        disk.friction = 1.0  # combined with the wall's by multiplication
        disk.collision_type = ROBOT_SHAPE
        control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        traction_n = params.traction_coefficient * robot.mass_kg * _GRAVITY_M_S2
        pivot = pymunk.PivotJoint(control, body, (0.0, 0.0), (0.0, 0.0))
        pivot.max_bias = 0.0  # match velocities only
        pivot.max_force = traction_n
        gear = pymunk.GearJoint(control, body, 0.0, 1.0)
        gear.max_bias = 0.0
        gear.max_force = traction_n * 0.5 * robot.wheel_base_m
        space.add(body, disk, control, pivot, gear)

        self._space, self._body, self._control = space, body, control
        # the per-step path calls pymunk's C functions on the bodies and the space directly:
        # pymunk's properties and Space.step (its checks of newly added bodies, the adds and
        # removals deferred during a step) cost more than the step itself, and nothing is
        # added to or removed from the space after this constructor
        self._robot_ref, self._control_ref, self._space_ref = (
            body._body,
            control._body,
            space._space,
        )
        self._contact: dict[int, Callable[[], None]] = {}

        def post_solve(arbiter: pymunk.Arbiter, space: pymunk.Space, data: dict) -> None:
            # the robot's disk is the only dynamic shape: every solved contact is the robot
            # against a wall or an obstacle (kinematic and static shapes do not collide)
            kinds = {shape.collision_type for shape in arbiter.shapes}
            callback = self._contact.get(OBSTACLE_SHAPE if OBSTACLE_SHAPE in kinds else WALL_SHAPE)
            if callback is not None:
                callback()

        space.on_collision(None, None, post_solve=post_solve)
        self._place_movers()
        self.teleport(pose)

    def on_wall_contact(self, callback: Callable[[], None]) -> None:
        """Call ``callback()`` each time pymunk's solver resolves a contact of the robot with a
        wall of the map (a ``post_solve`` handler); called during :meth:`step`, possibly
        several times a step.

        The callback only observes: it gets no handle on the space and must not change the
        world from inside the solver. A later call replaces the earlier callback.
        """
        self._contact[WALL_SHAPE] = callback

    def on_obstacle_contact(self, callback: Callable[[], None]) -> None:
        """As :meth:`on_wall_contact`, for the contacts of the robot with an obstacle."""
        self._contact[OBSTACLE_SHAPE] = callback

    def _place_movers(self) -> None:
        """Put each moving obstacle where its path has it at :attr:`t_s`, with the velocity
        that takes it to where it is one step later (from :meth:`_mover_track`)."""
        if not self._movers:
            return
        row = self._steps - self._track_start
        if not 0 <= row < len(self._track):
            self._mover_track()
            row = 0
        for (_, body), (position, velocity) in zip(self._movers, self._track[row], strict=True):
            body.position, body.velocity = position, velocity
            self._space.reindex_shapes_for_body(body)

    def _mover_track(self) -> None:
        """The moving obstacles' positions and velocities at the next :data:`MOVER_BLOCK_STEPS`
        steps from this one, computed at once (each step's values are those of the step's own
        time ``t = steps * dt``: the path lookups are element-wise)."""
        t_s = np.arange(self._steps, self._steps + MOVER_BLOCK_STEPS) * self.dt_s
        columns = []
        for obstacle, _ in self._movers:
            now, then = obstacle.offset_m(t_s), obstacle.offset_m(t_s + self.dt_s)
            columns.append(
                zip(
                    map(tuple, (obstacle.reference_m + now).tolist()),
                    map(tuple, ((then - now) / self.dt_s).tolist()),
                    strict=True,
                )
            )
        self._track = list(zip(*columns, strict=True))
        self._track_start = self._steps

    def check_free(self, pose, t_s: float | None = None) -> np.ndarray:
        """The pose as a float array ``(3,)`` if the robot's disk fits there (clear of all
        walls and of the obstacles as they are at ``t_s``, by default now, inside the
        boundary); otherwise a :class:`RobotsimError` naming the reason."""
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            raise RobotsimError(
                f"a pose must be 3 finite numbers (x_m, y_m, theta_rad), got {pose.tolist()}"
            )
        segments = self.map.segments
        clearance = point_segment_distance(pose[:2], segments[:, 0], segments[:, 1])
        needed = self.robot.radius_m + self.params.wall_radius_m
        if clearance.min() < needed:
            index = int(np.argmin(clearance))
            raise RobotsimError(
                f"the robot at ({pose[0]:g}, {pose[1]:g}) overlaps wall segment {index} of map "
                f"{self.map.name!r} (clearance {clearance.min():.3f} m < {needed:.3f} m)"
            )
        if self.map.boundary is not None and not shapely.contains_xy(
            shapely.Polygon(self.map.boundary), pose[0], pose[1]
        ):
            raise RobotsimError(
                f"the robot at ({pose[0]:g}, {pose[1]:g}) is outside the walls of map {self.map.name!r}"
            )
        when = self.t_s if t_s is None else t_s
        gap = self.obstacles.clearance_m(pose[:2], when)
        if gap < needed:
            raise RobotsimError(
                f"the robot at ({pose[0]:g}, {pose[1]:g}) overlaps an obstacle at t = {when:g} s "
                f"(clearance {gap:.3f} m < {needed:.3f} m)"
            )
        return pose

    def teleport(self, pose) -> None:
        """Put the robot at ``pose`` (x_m, y_m, theta_rad), keeping its velocity (a kidnap)."""
        x, y, theta = self.check_free(pose).tolist()
        for body in (self._body, self._control):
            body.position = (x, y)
            body.angle = theta
        self._space.reindex_shapes_for_body(self._body)

    def step(self, v_m_s: float, omega_rad_s: float) -> None:
        """Advance ``1 / step_hz`` seconds while the wheels try to move the robot at the
        true body velocity ``(v_m_s, omega_rad_s)`` (robot frame)."""
        control, space, substep_s = self._control_ref, self._space_ref, self._substep_s
        # pymunk moves a body with the velocity solved one substep earlier, so the velocity
        # set now acts from ``substep_s`` after the step's start to as long after its end:
        # point it along the heading at the middle of that interval
        heading = _chipmunk.cpBodyGetAngle(self._robot_ref) + omega_rad_s * self._velocity_lead_s
        _chipmunk.cpBodySetVelocity(control, (v_m_s * math.cos(heading), v_m_s * math.sin(heading)))
        _chipmunk.cpBodySetAngularVelocity(control, omega_rad_s)
        for _ in self._substeps:
            _chipmunk.cpSpaceStep(space, substep_s)
        self._steps += 1
        self.t_s = self._steps * self.dt_s
        if self._movers:
            self._place_movers()

    @property
    def steps(self) -> int:
        """The steps taken so far (during :meth:`step`, the index of the step under way)."""
        return self._steps

    def state(self) -> tuple[float, float, float, float, float]:
        """True ``(x_m, y_m, theta_rad, v_m_s, omega_rad_s)``: theta unwrapped, ``v`` the
        velocity component along the heading."""
        body = self._robot_ref
        position = _chipmunk.cpBodyGetPosition(body)
        velocity = _chipmunk.cpBodyGetVelocity(body)
        theta = _chipmunk.cpBodyGetAngle(body)
        return (
            position.x,
            position.y,
            theta,
            velocity.x * math.cos(theta) + velocity.y * math.sin(theta),
            _chipmunk.cpBodyGetAngularVelocity(body),
        )
