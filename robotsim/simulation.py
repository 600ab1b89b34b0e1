"""One simulated run: the pymunk world stepped at a fixed rate, then every sensor.

The per-step Python loop holds only the physics and the controller. The sensors are
computed afterwards, vectorised over time, with their noise drawn in bulk from child
generators of the run's ``Generator`` (one child per sensor, so switching one sensor's
faults on leaves the other sensors' draws unchanged).

Closed loop (an :class:`Observer`: the robot's estimator): the noise does not depend on the
motion, so it is drawn before the loop; at each control tick (every ``control_stride``
steps) the loop computes the readings of the samples since the last tick from it (the
same arithmetic as the vectorised pass, which still writes the odometry and IMU log; the
sonar scans, the costly part, are logged as the loop computed them), hands them to the
observer and steers on the pose the observer gives back, the command held until the next
tick. The controller thus sees the estimate one sample late (the accelerometer's central
difference at a sample needs the next one), a 10 ms latency at 100 Hz.

Commands: the controller asks for a body velocity; the robot's software turns it into
wheel rates with the NOMINAL radius, and the wheels move the body with the TRUE radii
(docs/models.md section 2). The resulting true velocity target is clamped to the robot's
limits (``v_max``, ``omega_max``, ``a_max``) and handed to the world.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from robotsim.control import Plan, limit_command, speed_limited
from robotsim.errors import RobotsimError
from robotsim.maps import SegmentMap
from robotsim.obstacles import NO_OBSTACLES, Obstacles
from robotsim.robot import RobotParams, body_velocity, wheel_rates, wrap_angle
from robotsim.sensors.encoders import EncoderParams, ticks_from_slip, wheel_rotation_increments
from robotsim.sensors.imu import (
    AccelerometerParams,
    GyroParams,
    accelerometer_noise,
    gyro_noise,
    specific_force,
)
from robotsim.sensors.sonar import (
    SonarBeltParams,
    readings_from_draws,
    sonar_draws,
)
from robotsim.sensors.stream_kernel import sample_block
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


@dataclass(frozen=True)
class SonarFailure:
    """The sonars ``sensors`` (indices into the belt) fail at the scans taken from
    ``start_s`` (included) to ``end_s`` (excluded): each returns ``reading_m`` (``inf``: no
    echo, the default; a number: a reading stuck at that value)."""

    start_s: float
    end_s: float
    sensors: tuple[int, ...]
    reading_m: float = math.inf

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensors", tuple(int(i) for i in self.sensors))
        if not (math.isfinite(self.start_s) and self.start_s < self.end_s):
            raise RobotsimError(
                f"sonar failure: start_s must be finite and before end_s, got {self.start_s}, {self.end_s}"
            )
        if not self.sensors or min(self.sensors) < 0:
            raise RobotsimError(f"sonar failure: sensors must be indices >= 0, got {self.sensors}")
        if not (
            self.reading_m == math.inf or (math.isfinite(self.reading_m) and self.reading_m >= 0)
        ):
            raise RobotsimError(
                f"sonar failure: reading_m must be inf (no echo) or a range >= 0, got {self.reading_m}"
            )


def apply_failures(
    readings_m: np.ndarray, fault: np.ndarray, scan_t_s: np.ndarray, failures
) -> tuple[np.ndarray, np.ndarray]:
    """The readings ``(M, k)`` and fault mask of the scans at ``scan_t_s (M,)`` with the
    failed sensors' readings replaced (:class:`SonarFailure`; a failed reading is a fault)."""
    readings_m, fault = readings_m.copy(), fault.copy()
    for failure in failures:
        rows = (scan_t_s >= failure.start_s) & (scan_t_s < failure.end_s)
        cells = np.ix_(rows, np.array(failure.sensors))
        readings_m[cells] = failure.reading_m
        fault[cells] = True
    return readings_m, fault


class Observer(Protocol):
    """The robot's estimator in a closed loop: fed every sample as the robot gets it, asked
    for the pose the controller steers on."""

    def odometry_block(self, t_s, ticks, gyro_rad_s, accel_m_s2) -> None:
        """Consecutive samples at ``t_s (n,)``: tick increments ``(n, 2)`` int64, yaw rates
        ``(n,)``, specific forces ``(n, 2)``."""

    def scan(self, t_s: float, readings_m) -> None:
        """The sonar scan ``(k,)`` taken at ``t_s`` (after that sample's odometry)."""

    def pose(self) -> tuple[float, float, float]:
        """The estimated ``(x_m, y_m, theta_rad)`` the controller is fed."""
        ...


@dataclass(frozen=True, eq=False)
class SensorNoise:
    """Every random draw of a run's sensors (``N`` samples, ``M`` scans, ``k`` sonars), drawn
    before the motion from one child generator per sensor: encoder slip ``(N, 2)``; gyro bias
    and white noise ``(N,)``; accelerometer bias and white noise ``(N, 2)``; the sonar draws
    (:func:`robotsim.sensors.sonar.sonar_draws`, each ``(M, k)``)."""

    slip: np.ndarray
    gyro_bias: np.ndarray
    gyro_white: np.ndarray
    accel_bias: np.ndarray
    accel_white: np.ndarray
    sonar: tuple[np.ndarray, ...]

    @classmethod
    def draw(
        cls, count: int, scans: int, sensors: SensorSuite, rate_hz: float, rng: np.random.Generator
    ) -> SensorNoise:
        encoder_rng, gyro_rng, accel_rng, sonar_rng = rng.spawn(4)
        slip = encoder_rng.standard_normal((count, 2))
        gyro_bias, gyro_white = gyro_noise(count, sensors.gyro, rate_hz, gyro_rng)
        accel_bias, accel_white = accelerometer_noise(
            count, sensors.accelerometer, rate_hz, accel_rng
        )
        sonar = sonar_draws((scans, sensors.sonar.count), sensors.sonar, sonar_rng)
        return cls(slip, gyro_bias, gyro_white, accel_bias, accel_white, sonar)


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
    the step that starts at the sample (the last sample, which no step follows, is False);
    obstacle_contact (N,) bool: the same for the unmapped obstacles.
    Sonar faults include the readings of failed sensors (:class:`SonarFailure`), and the
    true ranges are to the walls and the obstacles as they were at the scan.
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
    obstacle_contact: np.ndarray
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
    observer: Observer | None = None,
    obstacles: Obstacles = NO_OBSTACLES,
    sonar_failures: tuple[SonarFailure, ...] = (),
    control_stride: int = 1,
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
        observer: None (the controller steers on the true pose), or the estimator the
            controller steers on (closed loop, module docstring).
        obstacles: things in the world that ``segment_map`` lacks (``robotsim.obstacles``):
            in the physics and in the sonar's view.
        sonar_failures: windows in which some sonars return a failure value.
        control_stride: with an ``observer``, the steps from one control tick to the next
            (the controller's period in samples; without an observer it runs every step).

    Raises:
        RobotsimError: a bad duration, a start or kidnap pose that collides with a wall or
            an obstacle, a failure naming a sensor the belt lacks.
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise RobotsimError(f"duration_s must be positive and finite, got {duration_s}")
    rate_hz = world.step_hz
    count = round(duration_s * rate_hz) + 1
    sim_world = World(segment_map, robot, start_pose, world, obstacles)
    schedule = _kidnap_schedule(kidnaps, rate_hz, count, sim_world)
    belt = sensors.sonar
    for failure in sonar_failures:
        if max(failure.sensors) >= belt.count:
            raise RobotsimError(
                f"sonar failure: sensor {max(failure.sensors)} is not on the belt of {belt.count}"
            )
    sonar = _SonarWorld(segment_map, obstacles, belt, tuple(sonar_failures))
    scans = np.unique(np.round(np.arange(0.0, duration_s + 1e-9, 1.0 / belt.rate_hz) * rate_hz))
    scans = scans[scans < count].astype(np.int64)
    noise = SensorNoise.draw(count, len(scans), sensors, rate_hz, rng)
    stream = None
    if observer is not None:
        stream = _SensorStream(noise, scans, sonar, robot, sensors, rate_hz, count, schedule)

    if int(control_stride) != control_stride or control_stride < 1:
        raise RobotsimError(f"control_stride must be an integer >= 1, got {control_stride}")
    states, commands, contact, obstacle_contact = _run_physics(
        sim_world,
        plan.controller(robot),
        robot,
        count,
        schedule,
        progress,
        stream,
        observer,
        int(control_stride),
    )
    t_s = np.arange(count) / rate_hz
    pose = np.column_stack([states[:, :2], wrap_angle(states[:, 2])])
    velocity = states[:, 3:5]

    rotation = wheel_rotation_increments(states[:, :3], robot)
    kidnapped = np.array(sorted(schedule), dtype=np.int64)
    if kidnapped.size:  # the jump is not odometry: the wheels turned as the robot drove
        before = velocity[kidnapped - 1]
        rotation[kidnapped] = wheel_rates(before, robot.true_radii_m, robot.wheel_base_m) / rate_hz
    wheel_ticks = ticks_from_slip(rotation, robot.ticks_per_rev, sensors.encoders, noise.slip)
    gyro = velocity[:, 1] + noise.gyro_bias + noise.gyro_white
    accel = specific_force(velocity, rate_hz) + noise.accel_bias + noise.accel_white
    gyro_bias, accel_bias = noise.gyro_bias, noise.accel_bias

    if stream is not None:  # the closed loop computed every scan as it came
        true_range, readings, fault = stream.sonar_log()
    else:
        true_range, readings, fault = sonar.scans(pose[scans], t_s[scans], noise.sonar)

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
        obstacle_contact=obstacle_contact,
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
        schedule[index] = sim_world.check_free(event.pose, t_s=index / rate_hz)
    return schedule


class _SonarWorld:
    """What the sonar belt sees: the map's walls and the obstacles at the scan's time, then
    the error model and the failures (the same arithmetic for a block of scans or one)."""

    def __init__(
        self,
        segment_map: SegmentMap,
        obstacles: Obstacles,
        belt: SonarBeltParams,
        failures: tuple[SonarFailure, ...],
    ) -> None:
        self.segments, self.obstacles, self.belt, self.failures = (
            segment_map.segments,
            obstacles,
            belt,
            failures,
        )

    def scans(
        self, poses: np.ndarray, t_s: np.ndarray, draws: tuple[np.ndarray, ...]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """True ranges, readings and fault mask ``(M, k)`` of the scans at ``poses (M, 3)``,
        times ``t_s (M,)``, from the sonar draws of those scans."""
        belt = self.belt
        true_range = self.obstacles.cone_distances(
            poses, t_s, self.segments, belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad
        )
        readings, fault = readings_from_draws(true_range, belt, draws)
        readings, fault = apply_failures(readings, fault, t_s, self.failures)
        return true_range, readings, fault


#: Number of progress reports over a run's physics loop.
PROGRESS_REPORTS = 100


def _run_physics(
    sim_world: World,
    controller,
    robot: RobotParams,
    count: int,
    schedule,
    progress=None,
    stream: _SensorStream | None = None,
    observer: Observer | None = None,
    control_stride: int = 1,
):
    """The per-step loop: returns states ``(count, 5)`` = (x, y, theta unwrapped, v, omega),
    the wanted commands ``(count, 2)`` and the wall- and obstacle-contact flags ``(count,)``
    bool.

    Contacts come from :meth:`World.on_wall_contact` and :meth:`World.on_obstacle_contact`
    (pymunk's solver): their callbacks note the step under way. With an ``observer``, the
    controller runs every ``control_stride`` steps (its command held in between): at each
    such step ``stream`` gives the observer the samples whose next state is known, and the
    controller steers on the observer's pose; without one it runs every step on the truth.
    Between two control steps only the physics runs: the state read, the acceleration ramp
    towards the held command (skipped once reached: :func:`limit_command` would return its
    input) and the pymunk step.
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
    closed = None  # with an observer: hand the samples before a stop over; read the pose
    if stream is not None and observer is not None:
        closed = (functools.partial(stream.emit, states=states, observer=observer), observer.pose)
    stride = control_stride if closed is not None else 1
    commands = np.zeros((count, 2))
    touched: tuple[list[int], list[int]] = ([], [])  # the steps with a wall, an obstacle contact
    sim_world.on_wall_contact(lambda: touched[0].append(sim_world.steps))
    sim_world.on_obstacle_contact(lambda: touched[1].append(sim_world.steps))
    report_every = max(1, count // PROGRESS_REPORTS)
    next_report = 0
    last = count - 1
    target = reached = wanted_true = (0.0, 0.0)
    step, state, command = sim_world.step, sim_world.state, controller.command
    for k in range(count):
        if k in schedule:
            sim_world.teleport(schedule[k])
        now = state()
        states.append(now)
        if k == last:
            if closed is not None:
                closed[0](count)
            break
        if k % stride == 0:  # a control tick: the samples so far, then the pose, the command
            if progress is not None and k >= next_report:
                progress(k / count)
                next_report = (k // report_every + 1) * report_every
            if closed is not None:
                closed[0](k)
                x, y, theta = closed[1]()
            else:
                x, y, theta, _, _ = now
            wanted_v, wanted_omega = command(k * dt_s, x, y, theta)
            commands[k : k + stride] = wanted_v, wanted_omega
            wanted_true = (wanted_v * vv + wanted_omega * vw, wanted_v * wv + wanted_omega * ww)
            reached = speed_limited(*wanted_true, robot)
        if target != reached:
            target = limit_command(*wanted_true, target, dt_s, robot)
        step(*target)
    if progress is not None:
        progress(1.0)
    if count > 1:
        commands[last] = commands[last - 1]  # the last sample repeats
    contact = np.zeros(count, dtype=bool)
    obstacle_contact = np.zeros(count, dtype=bool)
    contact[touched[0]], obstacle_contact[touched[1]] = True, True
    return np.array(states), commands, contact, obstacle_contact


class _SensorStream:
    """The readings of the samples so far from the drawn noise and the states: the
    arithmetic of the vectorised pass of :func:`simulate` on a window of rows, in sample
    order (each row's value is the one the whole-run pass computes: element-wise formulas,
    the central difference over the row's neighbours, the cumulative turn continued), one
    compiled call a block (:func:`robotsim.sensors.stream_kernel.sample_block`)."""

    def __init__(
        self,
        noise: SensorNoise,
        scans: np.ndarray,
        sonar: _SonarWorld,
        robot: RobotParams,
        sensors: SensorSuite,
        rate_hz: float,
        count: int,
        schedule: dict[int, np.ndarray],
    ) -> None:
        self.noise, self.robot, self.sensors = noise, robot, sensors
        self.sonar = sonar
        self.scans = scans
        self._scan_samples = scans.tolist()
        self.rate_hz, self.count, self.schedule = rate_hz, count, schedule
        self.done = 0  # samples handed over so far
        self.t_s = np.arange(count) / rate_hz  # the log's sample times
        self.turned = np.zeros(2)  # cumulative wheel turns with slip so far (left, right), rad
        # the per-sample factors of ticks_from_slip and the counting scale, once per run
        self._slip_factor = 1.0 + sensors.encoders.slip_std * noise.slip  # (N, 2)
        self._ticks_per_rad = robot.ticks_per_rev / (2.0 * np.pi)
        self._kidnapped = np.zeros(count, dtype=bool)
        self._kidnapped[list(schedule)] = True
        # the readings of every sample, written block by block as the samples are handed over
        self._ticks = np.zeros((count, 2), dtype=np.int64)
        self._gyro, self._accel = np.zeros(count), np.zeros((count, 2))
        shape = (len(scans), sensors.sonar.count)  # the scans handed over, for the log
        self._true_range, self._readings = np.full(shape, np.nan), np.full(shape, np.nan)
        self._fault = np.zeros(shape, dtype=bool)
        self._scans_done = 0

    def sonar_log(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """True ranges, readings and fault mask ``(M, k)`` of every scan, as handed over (the
        rows the whole-run pass computes: a row depends on its own pose, time and draws).

        Raises:
            RobotsimError: some scans were not handed over (the run stopped early).
        """
        if self._scans_done != len(self.scans):
            raise RobotsimError(
                f"sonar: {self._scans_done} of {len(self.scans)} scans were handed over"
            )
        return self._true_range, self._readings, self._fault

    def emit(self, stop: int, states: list, observer: Observer) -> None:
        """Hand samples ``done .. stop - 1`` (and their scans) to ``observer``; ``states``
        holds rows ``0..stop`` (``0..stop - 1`` when ``stop`` is the sample count)."""
        start = self.done
        if stop <= start:
            return
        robot, noise, rate_hz = self.robot, self.noise, self.rate_hz
        low, high = max(start - 1, 0), min(stop + 1, self.count)  # rows for the differences
        window = np.array(states[low:high])
        sample_block(
            window,
            low,
            start,
            stop,
            self._kidnapped,
            0.5 * robot.wheel_base_m,
            robot.true_wheel_radius_left_m,
            robot.true_wheel_radius_right_m,
            rate_hz,
            self._slip_factor,
            self._ticks_per_rad,
            self.turned,
            noise.gyro_bias,
            noise.gyro_white,
            noise.accel_bias,
            noise.accel_white,
            self._ticks,
            self._gyro,
            self._accel,
        )
        ticks, gyro = self._ticks[start:stop], self._gyro[start:stop]
        accel = self._accel[start:stop]
        t_s = self.t_s[start:stop]
        first = end_scan = self._scans_done  # the scans are handed over in order
        samples = self._scan_samples
        while end_scan < len(samples) and samples[end_scan] < stop:
            end_scan += 1
        begin = 0
        if end_scan > first:
            m = slice(first, end_scan)
            in_block = self.scans[m]
            pose = window[in_block - low, :3].copy()
            pose[:, 2] = wrap_angle(pose[:, 2])
            draws = tuple(draw[m] for draw in noise.sonar)
            true_range, readings, fault = self.sonar.scans(pose, in_block / rate_hz, draws)
            self._true_range[m], self._readings[m], self._fault[m] = true_range, readings, fault
            self._scans_done = end_scan
            for scan, sample in enumerate(samples[m]):  # each scan after its sample
                end = sample - start + 1
                observer.odometry_block(
                    t_s[begin:end], ticks[begin:end], gyro[begin:end], accel[begin:end]
                )
                observer.scan(float(t_s[end - 1]), readings[scan])
                begin = end
        if begin == 0:
            observer.odometry_block(t_s, ticks, gyro, accel)
        elif begin < stop - start:
            observer.odometry_block(t_s[begin:], ticks[begin:], gyro[begin:], accel[begin:])
        self.done = stop
