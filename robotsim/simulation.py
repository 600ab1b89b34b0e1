"""One simulated run: the pymunk world stepped at a fixed rate, then every sensor.

The per-step Python loop holds only the physics and the controller. The sensors are
computed afterwards, vectorised over time, with their noise drawn in bulk from child
generators of the run's ``Generator`` (one child per sensor, so switching one sensor's
faults on leaves the other sensors' draws unchanged).

Commands: the controller asks for a body velocity; the robot's software turns it into
wheel rates with the NOMINAL radius, and the wheels move the body with the TRUE radii
(MODELS.md section 2). The resulting true velocity target is clamped to the robot's
limits (``v_max``, ``omega_max``, ``a_max``) and handed to the world.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from robotsim.control import Plan, limit_command
from robotsim.errors import RobotsimError
from robotsim.maps import SegmentMap
from robotsim.robot import RobotParams, body_velocity, wheel_rates, wrap_angle
from robotsim.sensors.encoders import EncoderParams, simulate_ticks, wheel_rotation_increments
from robotsim.sensors.imu import (
    AccelerometerParams,
    GyroParams,
    simulate_accelerometer,
    simulate_gyro,
    specific_force,
)
from robotsim.sensors.sonar import SonarBeltParams, cone_distances, simulate_readings
from robotsim.world import World, WorldParams


@dataclass(frozen=True)
class SensorSuite:
    """The sensors of the robot (the time series are sampled at the world's ``step_hz``)."""

    encoders: EncoderParams = field(default_factory=EncoderParams)
    gyro: GyroParams = field(default_factory=GyroParams)
    accelerometer: AccelerometerParams = field(default_factory=AccelerometerParams)
    sonar: SonarBeltParams = field(default_factory=SonarBeltParams.default_belt)


@dataclass(frozen=True)
class KidnapEvent:
    """At the first sample at or after ``t_s`` the robot is moved to ``pose`` =
    ``(x_m, y_m, theta_rad)`` without the wheels turning (no odometry of the jump)."""

    t_s: float
    pose: tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class SimulationLog:
    """Everything a run produced; arrays with units and shapes in their names/docs.

    Time series at ``rate_hz`` (N samples, ``t_s[i] = i / rate_hz``):
        t_s (N,); pose (N, 3) truth (heading wrapped to [-pi, pi));
        velocity (N, 2) true (v_m_s, omega_rad_s), body frame;
        command (N, 2) the controller's wanted (v_m_s, omega_rad_s) before the limits
        (row N-1 repeats row N-2: no step follows the last sample);
        wheel_ticks (N, 2) int64 tick increments (left, right) since the previous sample
        (row 0 is zero); gyro_rad_s (N,); accel_m_s2 (N, 2) specific force (body x, y);
        gyro_bias_rad_s (N,), accel_bias_m_s2 (N, 2): the true biases (truth, tests only).
    Sonar scans at ``sensors.sonar.rate_hz`` (M scans, on the nearest samples):
        sonar_t_s (M,); sonar_pose (M, 3) truth; sonar_range_m (M, k) readings, inf = no
        echo; sonar_fault (M, k) bool (outlier or lost echo; truth, tests only);
        sonar_true_range_m (M, k) exact cone distances, no range limit (truth).
    kidnap_t_s (K,): the sample times at which the robot was kidnapped.
    wall_contact (N,) bool: pymunk resolved a contact between the robot and a wall during
    the step that starts at the sample (the last sample, which no step follows, is False).
    """

    t_s: np.ndarray
    pose: np.ndarray
    velocity: np.ndarray
    command: np.ndarray
    wheel_ticks: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    gyro_bias_rad_s: np.ndarray
    accel_bias_m_s2: np.ndarray
    sonar_t_s: np.ndarray
    sonar_pose: np.ndarray
    sonar_range_m: np.ndarray
    sonar_fault: np.ndarray
    sonar_true_range_m: np.ndarray
    kidnap_t_s: np.ndarray
    wall_contact: np.ndarray
    rate_hz: float
    robot: RobotParams
    sensors: SensorSuite
    world: WorldParams

    def __post_init__(self) -> None:
        for value in vars(self).values():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)


def simulate(
    segment_map: SegmentMap,
    plan: Plan,
    *,
    start_pose,
    duration_s: float,
    rng: np.random.Generator,
    robot: RobotParams = RobotParams(),
    sensors: SensorSuite = SensorSuite(),
    world: WorldParams = WorldParams(),
    kidnaps: tuple[KidnapEvent, ...] = (),
    progress: Callable[[float], None] | None = None,
) -> SimulationLog:
    """Simulate ``duration_s`` seconds of the robot following ``plan`` in ``segment_map``.

    Args:
        segment_map: the walls.
        plan: a :class:`~robotsim.control.Route` or :class:`~robotsim.control.ScriptedProfile`.
        start_pose: ``(x_m, y_m, theta_rad)``; the robot's disk must fit there.
        duration_s: simulated time; ``round(duration_s * step_hz) + 1`` samples.
        rng: the only source of randomness (sensor noise and faults).
        robot, sensors, world: settings.
        kidnaps: teleports during the run.
        progress: told the fraction of the physics loop done (0 to 1, in steps of about
            1 %), for a progress bar; the sensors after the loop take a small share.

    Raises:
        RobotsimError: a bad duration, or a start or kidnap pose that collides with a wall.
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise RobotsimError(f"duration_s must be positive and finite, got {duration_s}")
    rate_hz = world.step_hz
    count = round(duration_s * rate_hz) + 1
    sim_world = World(segment_map, robot, start_pose, world)
    schedule = _kidnap_schedule(kidnaps, rate_hz, count, sim_world)

    states, commands, contact = _run_physics(
        sim_world, plan.controller(robot), robot, count, schedule, progress
    )
    t_s = np.arange(count) / rate_hz
    pose = np.column_stack([states[:, :2], wrap_angle(states[:, 2])])
    velocity = states[:, 3:5]

    encoder_rng, gyro_rng, accel_rng, sonar_rng = rng.spawn(4)
    rotation = wheel_rotation_increments(states[:, :3], robot)
    kidnapped = np.array(sorted(schedule), dtype=np.int64)
    if kidnapped.size:  # the jump is not odometry: the wheels turned as the robot drove
        before = velocity[kidnapped - 1]
        rotation[kidnapped] = wheel_rates(before, robot.true_radii_m, robot.wheel_base_m) / rate_hz
    wheel_ticks = simulate_ticks(rotation, robot.ticks_per_rev, sensors.encoders, encoder_rng)
    gyro, gyro_bias = simulate_gyro(velocity[:, 1], sensors.gyro, rate_hz, gyro_rng)
    accel, accel_bias = simulate_accelerometer(
        specific_force(velocity, rate_hz), sensors.accelerometer, rate_hz, accel_rng
    )

    belt = sensors.sonar
    scans = np.unique(np.round(np.arange(0.0, duration_s + 1e-9, 1.0 / belt.rate_hz) * rate_hz))
    scans = scans[scans < count].astype(np.int64)
    true_range = cone_distances(
        pose[scans],
        segment_map.segments,
        belt.mount_xy,
        belt.mount_angle_rad,
        belt.half_aperture_rad,
    )
    readings, fault = simulate_readings(true_range, belt, sonar_rng)

    return SimulationLog(
        t_s=t_s,
        pose=pose,
        velocity=velocity,
        command=commands,
        wheel_ticks=wheel_ticks,
        gyro_rad_s=gyro,
        accel_m_s2=accel,
        gyro_bias_rad_s=gyro_bias,
        accel_bias_m_s2=accel_bias,
        sonar_t_s=t_s[scans],
        sonar_pose=pose[scans],
        sonar_range_m=readings,
        sonar_fault=fault,
        sonar_true_range_m=true_range,
        kidnap_t_s=t_s[kidnapped],
        wall_contact=contact,
        rate_hz=rate_hz,
        robot=robot,
        sensors=sensors,
        world=world,
    )


def _kidnap_schedule(
    kidnaps, rate_hz: float, count: int, sim_world: World
) -> dict[int, np.ndarray]:
    """Sample index -> pose of each kidnap (validated: inside the run, a free pose)."""
    schedule = {}
    for event in kidnaps:
        index = math.ceil(event.t_s * rate_hz - 1e-9)
        if not 0 < index < count:
            raise RobotsimError(
                f"kidnap time {event.t_s} s is outside the run (0, {(count - 1) / rate_hz}] s"
            )
        schedule[index] = sim_world.check_free(event.pose)
    return schedule


#: Number of progress reports over a run's physics loop.
PROGRESS_REPORTS = 100


def _run_physics(
    sim_world: World, controller, robot: RobotParams, count: int, schedule, progress=None
):
    """The per-step loop: returns states ``(count, 5)`` = (x, y, theta unwrapped, v, omega),
    the wanted commands ``(count, 2)`` and the wall-contact flags ``(count,)`` bool.

    Contacts come from :meth:`World.on_wall_contact` (pymunk's solver): its callback sets a
    flag that the loop reads and clears after each step.
    """
    dt_s = sim_world.dt_s
    # wanted (v, omega) -> wheel rates with nominal radii -> true body velocity (a 2x2 map)
    to_true = body_velocity(
        wheel_rates(np.eye(2), robot.nominal_radii_m, robot.wheel_base_m),
        robot.true_radii_m,
        robot.wheel_base_m,
    ).tolist()
    (vv, wv), (vw, ww) = to_true  # true = v * row 0 + omega * row 1
    states: list[tuple[float, float, float, float, float]] = []
    commands: list[tuple[float, float]] = []
    touched = [False]

    def note_contact() -> None:
        touched[0] = True

    sim_world.on_wall_contact(note_contact)
    contact = np.zeros(count, dtype=bool)
    report_every = max(1, count // PROGRESS_REPORTS)
    target = (0.0, 0.0)
    step, state, command = sim_world.step, sim_world.state, controller.command
    for k in range(count):
        if progress is not None and k % report_every == 0:
            progress(k / count)
        if k in schedule:
            sim_world.teleport(schedule[k])
        now = state()
        states.append(now)
        if k == count - 1:
            break
        x, y, theta, _, _ = now
        wanted = command(k * dt_s, x, y, theta)
        commands.append(wanted)
        wanted_v, wanted_omega = wanted
        target = limit_command(
            wanted_v * vv + wanted_omega * vw,
            wanted_v * wv + wanted_omega * ww,
            target,
            dt_s,
            robot,
        )
        step(*target)
        if touched[0]:
            contact[k] = True
            touched[0] = False
    if progress is not None:
        progress(1.0)
    commands.append(commands[-1] if count > 1 else (0.0, 0.0))  # the last sample repeats
    return np.array(states), np.array(commands, dtype=np.float64), contact
