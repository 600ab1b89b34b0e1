"""The scenario file: its TOML schema, its validation, and the frozen spec it becomes.

A scenario file has the tables below; every key is optional unless marked, and the
defaults are the ones written here (for the robot and the sensors: the defaults of the
``robotsim`` parameter classes, so they are stated once, where the simulator uses them).

``description`` (top level)
    One line shown by ``robotsim scenarios``.
``[run]``
    ``duration_s`` (60.0), ``seed`` (0), and the sample rate of the simulation and of the
    proprioceptive sensors: ``rate_hz`` (100.0, from :data:`MIN_RATE_HZ` to
    :data:`MAX_RATE_HZ`) or ``dt_s`` (0.01), not both. A run has from 1 to
    :data:`MAX_SAMPLES` samples (``duration_s * rate_hz``).
``[map]``
    Exactly one of ``builtin`` (a name of ``robotsim.maps.BUILTIN_MAP_NAMES``),
    ``segments`` (an array of ``[[ax, ay], [bx, by]]`` in metres) or ``file`` (a ``.wkt``,
    ``.geojson`` or ``.json`` file of line strings, relative to the scenario file). Default:
    ``builtin = "hall"``.
``[robot]``
    ``start_xy_m`` (required) and ``start_heading_deg`` (0.0), then any field of
    ``robotsim.robot.RobotParams``.
``[route]``
    Either ``waypoints_m`` (an array of ``[x, y]``, followed by pure pursuit; the other keys
    are the fields of ``robotsim.control.Route``) or ``[[route.profile]]`` steps
    ``{duration_s, v_m_s, omega_rad_s | omega_deg_s}`` played in order, then a stop. Without
    a route the robot stands still. ``follow`` (:class:`Follow`; :func:`default_follow`:
    ``"estimate"`` for waypoints): the pose the pure pursuit steers on, the true one or,
    closed loop, the estimate of a localisation branch (waypoints only: a profile ignores
    the pose).
``[sensors.encoders]``, ``[sensors.gyro]``, ``[sensors.accelerometer]``, ``[sensors.sonar]``
    The fields of the simulator's sensor parameter classes; for the sonar also ``count``
    (an even belt on the robot's rim, the default) in place of ``mount_xy`` and
    ``mount_angle_rad``. A field named ``*_rad*`` may be written in degrees under the same
    name with ``_deg`` in place of ``_rad`` (``half_aperture_deg``); never both. The sonar's
    ``rate_hz`` must divide ``run.rate_hz`` a whole number of times (a scan is taken at a
    sample; a faster or off-beat sonar is refused rather than silently slowed).
    ``safety_margin_m`` (0.1): the clearance from the walls the summary checks the robot and
    its interval sets against (``scenarios.metrics.safety_stats``). ``control_rate_hz``
    (10.0, dividing ``run.rate_hz`` a whole number of times): in a closed loop, how often
    the controller is given the estimate and recomputes its command (held in between);
    steering on the truth it runs at every sample.
``[world]``
    What the world holds that the map lacks: ``[[world.obstacles]]``, each exactly one of
    ``polygon_m`` (``[[x, y], ...]``, at least 3 vertices, a simple polygon of non-zero
    area) or ``segment_m`` (``[[ax, ay], [bx, by]]``), in world coordinates at the start;
    with ``path_m`` (``[[x, y], ...]``) it moves: its centroid visits the points in order at
    ``speed_m_s`` (1.0), then stops, or with ``loop`` (false) goes back round from where
    it started (``robotsim.obstacles``). Each lies inside the map's outer wall (moving ones
    over their whole sweep, which crosses no wall), clear of the start footprint. The
    physics and the sonar see them; the estimator's map does not.
``[[events]]``
    Things that happen to the robot during the run, each ``{kind, t_s, ...}`` with ``t_s``
    in ``(0, duration_s]`` (:class:`EventKind`): ``kind = "kidnap"`` moves the robot at
    ``t_s`` to ``xy_m`` (required) and ``heading_deg`` (0.0) without odometry; the pose must
    be free, and two kidnaps may not fall on one sample. ``kind = "sonar_failure"``: from
    ``t_s`` for ``duration_s`` (required, > 0) the ``sensors`` (``"all"``, the default, or
    an array of belt indices) return ``reading_m`` (default: no echo; or a range in
    ``[0, d_max_m]``, a reading stuck at that value).
``[estimation]``
    The localisation pipeline (paper 002), read into the records of the packages that use
    it: ``filter`` (``localization.dead_reckoning.DeadReckoningSettings``: ``"ukf"``; or
    ``"iukf"``, ``"ekf"``, ``"iekf"``); ``tracker`` (``"sivia"`` or ``"imagesp"``), ``eps_m``
    (0.05), ``q_max`` (1), ``guaranteed`` (true), ``heading_scale_m_per_rad`` (1.0),
    ``imagesp_pitch_m`` (0.2) and ``ray_test`` (default: true exactly when the sonar's
    half-aperture is at most 0.1 rad) (``intervals.tracker.TrackerSettings``, with the
    robot's limits); ``fusion`` (``"clamp"``, the paper's rule, or another
    ``localization.fusion.FusionRule``), ``interval_rate_hz`` (the sonar's rate: an epoch at
    every scan) and ``free_space`` (default: true exactly when the sonar never loses an
    echo); ``estimator`` (:class:`scenarios.mcl_pipeline.Estimator`: ``"intervals"``, that
    pipeline, or ``"mcl"``, the particle filter) and its ``[estimation.mcl]`` table (the
    fields of ``localization.mcl.MclSettings``). See :class:`EstimationSpec`.

Every number is checked against the bounds declared beside its field in the record that
holds it (``records.bounded``: physical limits that keep every integer and float the
simulator and the filters compute in range), every choice against its ``StrEnum``; the
records check themselves the same way when built in code. Every mistake raises
``ScenarioError(file, "table.key", reason)``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import tomllib
import types
import typing
from collections.abc import Callable
from enum import Enum, StrEnum
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from intervals.tracker import TrackerSettings
from localization.dead_reckoning import DeadReckoningSettings
from localization.fusion import FusionRule
from localization.mcl import MclSettings
from robotsim.control import Plan, Route, ScriptedProfile
from robotsim.errors import RobotsimError
from robotsim.maps import BUILTIN_MAP_NAMES, SegmentMap, builtin_map, outer_wall
from robotsim.obstacles import NO_OBSTACLES, Obstacle, Obstacles
from robotsim.robot import RobotParams, wrap_angle
from robotsim.sensors.encoders import EncoderParams
from robotsim.sensors.imu import AccelerometerParams, GyroParams
from robotsim.sensors.sonar import MAX_BELT_COUNT, SonarBeltParams
from robotsim.simulation import KidnapEvent, SonarFailure
from robotsim.world import World, WorldParams
from scenarios.catalog import BUILTIN_FOLDER, DEFAULT_MAP, builtin_names
from scenarios.errors import ScenarioError
from scenarios.feasibility import check_feasible
from scenarios.mcl_pipeline import Estimator
from scenarios.tables import Table
from validated_records import Bounds, bounded, choices, declared_bounds, validate_fields

DEFAULT_DURATION_S = 60.0
DEFAULT_SEED = 0
DEFAULT_RATE_HZ = 100.0

#: The most samples (``duration_s * rate_hz``) a run may have: ten million samples take
#: about 10 GB of logs and hours of simulation; beyond, refused before anything runs.
MAX_SAMPLES = 10_000_000

#: The range of the simulation rate, hertz: below 1 Hz the physics and the encoders lose
#: the motion; above 10 kHz a run of any length is mostly overhead. With
#: :data:`MAX_SAMPLES` they bound a run to 1e7 s, which keeps the encoders' cumulative tick
#: counts inside int64 (``robotsim.robot.MAX_TICKS_PER_REV``).
MIN_RATE_HZ = 1.0
MAX_RATE_HZ = 10_000.0

#: Tolerance on the whole number of samples between two sonar scans.
RATE_RATIO_TOL = 1e-9

#: The plan of a scenario without a route: no motion.
STAND_STILL = ScriptedProfile(t_s=np.zeros(1), v_m_s=np.zeros(1), omega_rad_s=np.zeros(1))

#: The keys of ``[estimation]`` that are fields of ``localization``'s and ``intervals``'
#: settings records (same names); the table's other keys are the fields of
#: :class:`EstimationSpec` itself.
DEAD_RECKONING_KEYS = ("filter",)
#: The prefix of the ``[estimation.mcl]`` keys when written in one level (campaign grids,
#: :meth:`EstimationSpec.with_keys`): ``mcl.max_particles``.
MCL_PREFIX = "mcl."
TRACKER_KEYS = (
    "tracker",
    "eps_m",
    "eps_cells",
    "q_max",
    "guaranteed",
    "heading_scale_m_per_rad",
    "imagesp_pitch_m",
    "ray_test",
    "max_boxes",
    "contractor",
    "shave_rounds",
    "tighten_levels",
    "tighten_max_tested",
)


class Follow(StrEnum):
    """The pose the route's controller steers on (``[route] follow``)."""

    TRUTH = "truth"
    """The true pose: the estimator runs beside the motion without steering it (studying
    the estimator alone)."""
    ESTIMATE = "estimate"
    """Closed loop on the fused branch (dead reckoning fused with the interval sets)."""
    UKF_ONLY = "ukf_only"
    """Closed loop on the UKF-only branch (dead reckoning alone: it drifts)."""


def default_follow(plan: Plan) -> Follow:
    """The ``[route] follow`` a scenario file gets when it does not say: the closed loop on
    the fused estimate for waypoints (``benchmarks/closed_loop.py``: on hall, office and the
    apartment, every seed completes its route with containment 1), the truth for a scripted
    profile or no route (nothing steers on a pose). A scenario with ``estimator = "mcl"``
    gets the truth instead (:func:`follow_for_estimator`)."""
    return Follow.ESTIMATE if isinstance(plan, Route) else Follow.TRUTH


def follow_for_estimator(follow: Follow, estimator: Estimator) -> Follow:
    """The rule "an MCL run follows the truth": ``follow``, or the truth when ``estimator``
    is MCL, since the closed loop steers on the interval pipeline's estimate, which an MCL
    run does not have. Applied where the follow is not the user's explicit choice: a
    scenario file without ``[route] follow`` and :meth:`ScenarioSpec.with_estimation` (an
    explicit closed loop with MCL is refused, :class:`ScenarioSpec`)."""
    return Follow.TRUTH if estimator == Estimator.MCL else follow


def default_fusion(follow: Follow) -> FusionRule:
    """The ``[estimation] fusion`` a scenario file gets when it does not say: the paper's
    clamp, except when the robot steers on the fused branch. The clamp moves the position
    only, so the fused heading drifts with the gyro's bias (0.7 rad after ten minutes on
    ``hall``, seed 1) and a robot steered on it crabs into the walls; the truncation with
    the heading (``localization.fusion``) keeps the heading inside the set's interval and
    lets the bias be learnt through the covariance."""
    return FusionRule.TRUNCATED_HEADING if follow == Follow.ESTIMATE else FusionRule.CLAMP


class EventKind(StrEnum):
    """What an ``[[events]]`` entry does."""

    KIDNAP = "kidnap"
    """The robot moved to another pose without the wheels turning (no odometry of the jump)."""
    SONAR_FAILURE = "sonar_failure"
    """Some sonars return no echo (or a stuck value) for a while."""


#: ``[route] safety_margin_m``: its default and bounds, m.
DEFAULT_SAFETY_MARGIN_M = 0.1
SAFETY_MARGIN_BOUNDS = Bounds(minimum=0.0, maximum=10.0)

#: ``[route] control_rate_hz``: the closed loop's control rate, Hz (a robot's navigation
#: loop runs at 10 to 20 Hz over its 100 Hz odometry), and its bounds.
DEFAULT_CONTROL_RATE_HZ = 10.0
CONTROL_RATE_BOUNDS = Bounds(above=0.0, maximum=MAX_RATE_HZ)


# ---------------------------------------------------------------------------------------
# The spec: a frozen tree
# ---------------------------------------------------------------------------------------
#: A spec record built in code with a bad field: ``ScenarioError`` without file or key.
_CodeError = functools.partial(ScenarioError, None, None)


@dataclasses.dataclass(frozen=True)
class RunSpec:
    """Length, randomness and sampling of one run (from 1 to :data:`MAX_SAMPLES` samples)."""

    duration_s: float = bounded(DEFAULT_DURATION_S, above=0.0)
    """Simulated time, seconds."""
    seed: int = bounded(DEFAULT_SEED, minimum=0, integer=True)
    """Seed of the run's ``numpy.random.Generator``."""
    rate_hz: float = bounded(DEFAULT_RATE_HZ, minimum=MIN_RATE_HZ, maximum=MAX_RATE_HZ)
    """Simulation and proprioceptive sensor rate, hertz; ``dt_s = 1 / rate_hz``."""

    def __post_init__(self) -> None:
        validate_fields(self, _CodeError)
        reason = _sample_count_problem(self.duration_s, self.rate_hz)
        if reason is not None:
            raise ScenarioError(None, None, f"RunSpec.duration_s: {reason}")

    @property
    def dt_s(self) -> float:
        """The sample period, seconds."""
        return 1.0 / self.rate_hz


@dataclasses.dataclass(frozen=True, eq=False)
class SensorsSpec:
    """The parameters of each simulated sensor (the simulator's own classes)."""

    encoders: EncoderParams
    gyro: GyroParams
    accelerometer: AccelerometerParams
    sonar: SonarBeltParams


@dataclasses.dataclass(frozen=True)
class EstimationSpec:
    """Settings of the localisation pipeline (paper 002): dead reckoning at the run's rate,
    an interval epoch at the sonar scans, the fusion of the two.

    It holds the records of the packages that use them (each setting defined and validated
    once, there) and the settings of the pipeline itself.
    """

    intervals: TrackerSettings
    """The interval tracker (``intervals.tracker``): its prediction ``tracker``, ``eps_m``,
    ``q_max``, ``guaranteed``, ``heading_scale_m_per_rad``, ``imagesp_pitch_m``, ``ray_test``
    (the keys of the same names) and the robot's limits (from ``[robot]``)."""
    dead_reckoning: DeadReckoningSettings = dataclasses.field(default_factory=DeadReckoningSettings)
    """The dead-reckoning filter (``localization.dead_reckoning``; the key ``filter``)."""
    fusion: FusionRule = FusionRule.CLAMP
    """The fusion rule (``localization.fusion``); ``"clamp"`` is the paper's (section 4)."""
    interval_rate_hz: float = bounded(1.0, above=0.0)
    """Interval epochs per second: one every ``sonar.rate_hz / interval_rate_hz`` scans (a
    whole number); a scenario file's default is the sonar's rate (an epoch at every scan)."""
    free_space: bool = True
    """Use no-echo readings as free space up to ``d_max``: sound only when the sonar never
    loses an echo, hence the file's default ``lost_echo_prob == 0``."""
    estimator: Estimator = Estimator.INTERVALS
    """What localises the robot: the interval pipeline above, or the particle filter."""
    mcl: MclSettings = dataclasses.field(default_factory=MclSettings)
    """The particle filter's settings (``localization.mcl``; the ``[estimation.mcl]`` table,
    keys ``mcl.<field>`` in :meth:`with_keys`), used when ``estimator = "mcl"``."""

    def __post_init__(self) -> None:
        validate_fields(self, _CodeError)
        for name, kind in (
            ("intervals", TrackerSettings),
            ("dead_reckoning", DeadReckoningSettings),
            ("mcl", MclSettings),
        ):
            if not isinstance(getattr(self, name), kind):
                raise ScenarioError(None, None, f"EstimationSpec.{name} must be a {kind.__name__}")

    def scan_stride(self, sonar_rate_hz: float) -> int:
        """Scans per interval epoch (1: every scan)."""
        return round(sonar_rate_hz / self.interval_rate_hz)

    @classmethod
    def _own_keys(cls) -> tuple[str, ...]:
        """The keys of ``[estimation]`` that are fields of this record (not of the parts)."""
        parts = ("intervals", "dead_reckoning", "mcl")
        return tuple(f.name for f in dataclasses.fields(cls) if f.name not in parts)

    def as_keys(self) -> dict[str, Any]:
        """The settings as the keys of an ``[estimation]`` table (choices as their strings;
        the ``[estimation.mcl]`` sub-table's apart, :data:`MCL_PREFIX` keys of :meth:`with_keys`)."""
        records = (
            (self.dead_reckoning, DEAD_RECKONING_KEYS),
            (self.intervals, TRACKER_KEYS),
            (self, self._own_keys()),
        )
        keys = {key: getattr(record, key) for record, names in records for key in names}
        return {key: str(v) if isinstance(v, Enum) else v for key, v in keys.items()}

    def with_keys(self, **changes: Any) -> EstimationSpec:
        """These settings with keys of the ``[estimation]`` table replaced (``tracker="imagesp"``,
        ``q_max=2``, ``filter="ekf"``, ``**{"mcl.max_particles": 5000}``...), each in the
        record that holds it."""
        own = self._own_keys()
        mcl_fields = {f.name for f in dataclasses.fields(MclSettings)}
        mcl = {
            key.removeprefix(MCL_PREFIX): value
            for key, value in changes.items()
            if key.startswith(MCL_PREFIX) and key.removeprefix(MCL_PREFIX) in mcl_fields
        }
        known = {*own, *TRACKER_KEYS, *DEAD_RECKONING_KEYS, *(MCL_PREFIX + key for key in mcl)}
        unknown = set(changes) - known
        if unknown:
            raise ScenarioError(
                None, None, f"not keys of [estimation]: {', '.join(sorted(unknown))}"
            )

        def part(keys: typing.Iterable[str]) -> dict[str, Any]:
            return {key: value for key, value in changes.items() if key in keys}

        return dataclasses.replace(
            self,
            intervals=dataclasses.replace(self.intervals, **part(TRACKER_KEYS)),
            dead_reckoning=dataclasses.replace(self.dead_reckoning, **part(DEAD_RECKONING_KEYS)),
            mcl=dataclasses.replace(self.mcl, **mcl),
            **part(own),
        )


@dataclasses.dataclass(frozen=True, eq=False)
class ScenarioSpec:
    """A validated scenario, ready for ``scenarios.runner.run_scenario``."""

    name: str
    """The built-in name, or the file's stem."""
    source: str
    """The file it was read from (the messages name it)."""
    description: str
    run: RunSpec
    map: SegmentMap
    start_pose: tuple[float, float, float]
    """``(x_m, y_m, theta_rad)`` world frame."""
    robot: RobotParams
    plan: Plan
    """What the robot is told to do: a ``Route`` (pure pursuit) or a ``ScriptedProfile``."""
    sensors: SensorsSpec
    estimation: EstimationSpec
    follow: Follow = Follow.TRUTH
    """The pose the route's controller steers on (:class:`Follow`)."""
    kidnaps: tuple[KidnapEvent, ...] = ()
    """The ``kidnap`` events, in time order."""
    obstacles: Obstacles = NO_OBSTACLES
    """``[world] obstacles``: in the physics and the sonar, not in the estimator's map."""
    sonar_failures: tuple[SonarFailure, ...] = ()
    """The ``sonar_failure`` events, in time order."""
    safety_margin_m: float = DEFAULT_SAFETY_MARGIN_M
    """``[route] safety_margin_m``: the clearance from the walls the summary checks, m."""
    control_rate_hz: float = DEFAULT_CONTROL_RATE_HZ
    """``[route] control_rate_hz``: the closed loop's control rate, Hz."""

    @property
    def control_stride(self) -> int:
        """Samples from one control tick of the closed loop to the next (1 steering on the truth)."""
        if self.follow == Follow.TRUTH:
            return 1
        return round(self.run.rate_hz / self.control_rate_hz)

    @property
    def injected_faults(self) -> tuple[str, ...]:
        """What the scenario declares that breaks the guarantee's assumptions (a world that
        differs from the map, a robot moved without odometry, failed sonars): the names of
        those keys, empty for none."""
        declared = {
            "world.obstacles": bool(self.obstacles),
            "events kidnap": bool(self.kidnaps),
            "events sonar_failure": bool(self.sonar_failures),
        }
        return tuple(name for name, present in declared.items() if present)

    def __post_init__(self) -> None:
        if self.follow != Follow.TRUTH and not isinstance(self.plan, Route):
            raise ScenarioError(
                self.source, "route.follow", "a closed loop needs waypoints_m (a route)"
            )
        if self.follow != Follow.TRUTH and self.estimation.estimator == Estimator.MCL:
            raise ScenarioError(
                self.source,
                "route.follow",
                'a closed loop steers on the interval pipeline: not with estimator = "mcl"',
            )
        problem = estimation_problem(self.estimation, self.robot, self.sensors.sonar)
        if problem is not None:
            key, reason = problem
            raise ScenarioError(self.source, f"estimation.{key}", reason)

    def with_run(self, *, seed: int | None = None, duration_s: float | None = None) -> ScenarioSpec:
        """This scenario with the seed and/or duration replaced.

        Raises:
            ScenarioError: a value out of :class:`RunSpec`'s bounds, keyed ``run.seed`` or
                ``run.duration_s`` (without a file: the values do not come from it).
        """
        changes = {"seed": seed, "duration_s": duration_s}
        for name, value in changes.items():
            bounds = declared_bounds(RunSpec, name)
            reason = None if value is None or bounds is None else bounds.problem(value)
            if reason is not None:
                raise ScenarioError(None, f"run.{name}", reason)
        if duration_s is not None:
            reason = _sample_count_problem(duration_s, self.run.rate_hz)
            if reason is not None:
                raise ScenarioError(None, "run.duration_s", reason)
        run = dataclasses.replace(
            self.run,
            seed=self.run.seed if seed is None else seed,
            duration_s=self.run.duration_s if duration_s is None else duration_s,
        )
        return dataclasses.replace(self, run=run)

    def with_estimation(self, **changes: Any) -> ScenarioSpec:
        """This scenario with keys of ``[estimation]`` replaced (:meth:`EstimationSpec.with_keys`).
        Switching to ``estimator = "mcl"`` also puts the route on the truth
        (:func:`follow_for_estimator`), as a scenario file with that estimator gets by default."""
        estimation = self.estimation.with_keys(**changes)
        follow = follow_for_estimator(self.follow, estimation.estimator)
        return dataclasses.replace(self, estimation=estimation, follow=follow)


# ---------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------
def load_scenario(name_or_path: str | Path) -> ScenarioSpec:
    """A built-in scenario by name, or a scenario file by path, validated."""
    text = str(name_or_path)
    if text in builtin_names():
        with resources.as_file(BUILTIN_FOLDER / f"{text}.toml") as path:
            return _load_file(Path(path), name=text, source=str(path))
    path = Path(name_or_path)
    if not path.is_file():
        reason = "no such file" if not path.exists() else "not a file"
        if path.suffix != ".toml" and not path.exists():
            reason += f" (and not a built-in scenario: {', '.join(builtin_names())})"
        raise ScenarioError(str(path), None, reason)
    return _load_file(path, name=path.stem, source=str(path))


def parse_scenario(
    text: str, *, source: str = "<string>", base_dir: Path | None = None, name: str = "scenario"
) -> ScenarioSpec:
    """Validate scenario TOML ``text``; map files are resolved against ``base_dir``."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(source, None, f"not valid TOML: {exc}") from None
    return check_feasible(
        _from_dict(data, source=source, base_dir=base_dir or Path.cwd(), name=name)
    )


def scenario_from_tables(
    data: dict[str, Any], *, source: str, base_dir: Path, name: str
) -> ScenarioSpec:
    """Validate a scenario already read into tables (``tomllib``'s dict), as
    :func:`parse_scenario` does its text (a replay swaps the ``[estimation]`` table)."""
    return _from_dict(data, source=source, base_dir=base_dir, name=name)


def _load_file(path: Path, *, name: str, source: str) -> ScenarioSpec:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(source, None, f"cannot read: {exc}") from None
    return parse_scenario(text, source=source, base_dir=path.parent, name=name)


def _from_dict(data: dict[str, Any], *, source: str, base_dir: Path, name: str) -> ScenarioSpec:
    top = Table(source, "", data)
    description = top.take_str("description", "")
    run = _read_run(top.take_table("run"))
    segment_map = _read_map(top.take_table("map"), base_dir)
    robot_table = top.take_table("robot")
    start_xy = robot_table.take_array("start_xy_m", (2,))
    heading_deg = robot_table.take_float("start_heading_deg", 0.0)
    robot = _read_params(robot_table, RobotParams())
    start_pose = (
        float(start_xy[0]),
        float(start_xy[1]),
        float(wrap_angle(math.radians(heading_deg))),
    )
    _check_start(robot_table, segment_map, start_pose, robot)
    obstacles = _read_world(top.take_table("world"), segment_map, start_pose, robot)
    route_table = top.take_table("route")
    given_follow = route_table.take_str("follow", None, choices=choices(Follow))
    safety_margin_m = route_table.take_float(
        "safety_margin_m", DEFAULT_SAFETY_MARGIN_M, bounds=SAFETY_MARGIN_BOUNDS
    )
    control_rate_hz = route_table.take_float(
        "control_rate_hz", DEFAULT_CONTROL_RATE_HZ, bounds=CONTROL_RATE_BOUNDS
    )
    ratio = run.rate_hz / control_rate_hz
    if ratio < 1.0 - RATE_RATIO_TOL or abs(ratio - round(ratio)) > RATE_RATIO_TOL:
        raise route_table.error(
            "control_rate_hz",
            f"must divide the simulation rate (run.rate_hz = {run.rate_hz:g} Hz) a whole number "
            f"of times, got {control_rate_hz:g}",
        )
    plan = _read_route(route_table, segment_map, robot)
    follow = default_follow(plan) if given_follow is None else Follow(given_follow)
    sensors = _read_sensors(top.take_table("sensors"), robot, run)
    estimation = _read_estimation(top.take_table("estimation"), robot, sensors.sonar, follow)
    if given_follow is None:
        follow = follow_for_estimator(follow, estimation.estimator)
    kidnaps, failures = _read_events(
        top.take_tables("events"), segment_map, robot, run, obstacles, start_pose, sensors.sonar
    )
    top.finish()
    return ScenarioSpec(
        name=name,
        source=source,
        description=description,
        run=run,
        map=segment_map,
        start_pose=start_pose,
        robot=robot,
        plan=plan,
        sensors=sensors,
        estimation=estimation,
        follow=follow,
        kidnaps=kidnaps,
        obstacles=obstacles,
        sonar_failures=failures,
        safety_margin_m=safety_margin_m,
        control_rate_hz=control_rate_hz,
    )


# ---------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------
def _read_run(table: Table) -> RunSpec:
    def bounds(name: str) -> Bounds | None:
        return declared_bounds(RunSpec, name)

    duration_s = table.take_float("duration_s", DEFAULT_DURATION_S, bounds=bounds("duration_s"))
    seed = table.take_int("seed", DEFAULT_SEED, bounds=bounds("seed"))
    if table.has("rate_hz") and table.has("dt_s"):
        raise table.error("dt_s", "give rate_hz or dt_s, not both")
    rate_key = "dt_s" if table.has("dt_s") else "rate_hz"
    if table.has("dt_s"):
        period = Bounds(minimum=1.0 / MAX_RATE_HZ, maximum=1.0 / MIN_RATE_HZ)
        rate_hz = 1.0 / table.take_float("dt_s", bounds=period)
        table.take_float("rate_hz", None)
    else:
        rate_hz = table.take_float("rate_hz", DEFAULT_RATE_HZ, bounds=bounds("rate_hz"))
        table.take_float("dt_s", None)
    table.finish()
    reason = _sample_count_problem(duration_s, rate_hz)
    if reason is not None:
        # blame the rate when the duration alone would be fine at the default rate
        too_fast = (
            duration_s * rate_hz > MAX_SAMPLES and duration_s * DEFAULT_RATE_HZ <= MAX_SAMPLES
        )
        raise table.error(rate_key if too_fast else "duration_s", reason)
    return RunSpec(duration_s=duration_s, seed=seed, rate_hz=rate_hz)


def _sample_count_problem(duration_s: float, rate_hz: float) -> str | None:
    """Why a run of ``duration_s`` at ``rate_hz`` cannot be simulated, or None."""
    samples = duration_s * rate_hz
    if samples < 1.0:
        return f"shorter than one sample at {rate_hz:g} Hz (duration {duration_s:g} s)"
    if samples > MAX_SAMPLES:
        return (
            f"{duration_s:g} s at {rate_hz:g} Hz is {samples:.3g} samples, more than the "
            f"{MAX_SAMPLES:.0e} a run may have"
        )
    return None


def _read_map(table: Table, base_dir: Path) -> SegmentMap:
    given = [k for k in ("builtin", "segments", "file") if table.has(k)]
    if len(given) > 1:
        raise table.error(
            given[1], f"give one of builtin, segments or file, not {' and '.join(given)}"
        )
    kind = given[0] if given else "builtin"
    if kind == "builtin":
        name = table.take_str("builtin", DEFAULT_MAP, choices=tuple(BUILTIN_MAP_NAMES))
        table.finish()
        return _map_or_error(table, "builtin", lambda: builtin_map(name))
    if kind == "segments":
        if table.peek("segments") == []:
            raise table.error(
                "segments", "the map is empty: give at least one segment [[ax, ay], [bx, by]]"
            )
        raw = table.take_array("segments", (None, 2, 2))
        table.finish()
        return _map_or_error(
            table,
            "segments",
            lambda: SegmentMap.from_segments(raw, name="inline", boundary=outer_wall(raw)),
        )
    relative = table.take_str("file")
    table.finish()
    path = base_dir / relative
    if not path.is_file():
        raise table.error("file", f"no such file: {path}")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise table.error("file", f"cannot read {path}: {exc}") from None
    suffix = path.suffix.lower()
    if suffix == ".wkt":
        return _map_or_error(table, "file", lambda: SegmentMap.from_wkt(text, name=path.stem))
    if suffix in (".geojson", ".json"):
        return _map_or_error(table, "file", lambda: SegmentMap.from_geojson(text, name=path.stem))
    raise table.error("file", f"unknown map format {suffix!r} (use .wkt, .geojson or .json)")


def _map_or_error(table: Table, key: str, make: Callable[[], SegmentMap]) -> SegmentMap:
    try:
        return make()
    except RobotsimError as exc:
        raise table.error(key, str(exc)) from None


def _check_start(
    table: Table, segment_map: SegmentMap, pose: tuple[float, float, float], robot: RobotParams
) -> None:
    """The start footprint must lie inside the outer wall and clear of every wall.

    The simulator's own check decides: a world is built at the start pose (cheap: the walls
    and one body), as the runner will.
    """
    try:
        World(segment_map, robot, pose)
    except RobotsimError as exc:
        raise table.error("start_xy_m", str(exc)) from None


def _read_world(
    table: Table,
    segment_map: SegmentMap,
    start_pose: tuple[float, float, float],
    robot: RobotParams,
) -> Obstacles:
    """``[world] obstacles`` (module docstring), each checked: a valid shape, inside the
    map's outer wall (or its bounds) over its whole sweep, a moving one crossing no wall,
    clear of the robot's start footprint."""
    items = []
    for entry in table.take_tables("obstacles"):
        kinds = [key for key in ("polygon_m", "segment_m") if entry.has(key)]
        if len(kinds) != 1:
            raise entry.error(
                kinds[1] if kinds else "polygon_m",
                "give exactly one of polygon_m or segment_m",
            )
        shape_key = kinds[0]
        polygon = shape_key == "polygon_m"
        vertices = entry.take_array(shape_key, (None, 2) if polygon else (2, 2))
        path = entry.take_array("path_m", (None, 2), np.zeros((0, 2)))
        speed = entry.take_float("speed_m_s", None, bounds=declared_bounds(Obstacle, "speed_m_s"))
        loop = entry.take_bool("loop", False)
        entry.finish()
        given = {} if speed is None else {"speed_m_s": speed}
        try:
            obstacle = Obstacle(vertices, polygon=polygon, path_m=path, loop=loop, **given)
        except RobotsimError as exc:
            raise entry.error("loop" if loop and not len(path) else shape_key, str(exc)) from None
        _check_obstacle(entry, shape_key, obstacle, segment_map, start_pose, robot)
        items.append(obstacle)
    table.finish()
    return Obstacles(tuple(items))


def _check_obstacle(
    entry: Table,
    shape_key: str,
    obstacle: Obstacle,
    segment_map: SegmentMap,
    start_pose: tuple[float, float, float],
    robot: RobotParams,
) -> None:
    """An obstacle inside the map (its whole sweep), a moving one through no wall, and
    clear of the start footprint (the simulator's clearance: radius plus wall thickness)."""
    key = "path_m" if obstacle.moving else shape_key
    swept = obstacle.swept()
    if segment_map.boundary is not None:
        room = shapely.Polygon(segment_map.boundary)
    else:
        (x_lo, y_lo), (x_hi, y_hi) = segment_map.bounds
        room = shapely.box(x_lo, y_lo, x_hi, y_hi)
    if not room.covers(swept):
        where = "moves outside" if obstacle.moving else "lies outside"
        raise entry.error(key, f"{where} the map's outer wall (or its bounds)")
    if obstacle.moving:
        walls = shapely.linestrings(segment_map.segments)
        crossed = np.flatnonzero(shapely.intersects(walls, swept))
        if crossed.size:
            raise entry.error(key, f"the moving obstacle crosses wall segment {int(crossed[0])}")
    needed = robot.radius_m + WorldParams().wall_radius_m
    gap = shapely.distance(shapely.Point(start_pose[:2]), obstacle.geometry(0.0))
    if gap < needed:
        raise entry.error(
            shape_key,
            f"overlaps the robot's start footprint at ({start_pose[0]:g}, {start_pose[1]:g}) "
            f"(clearance {gap:.3f} m < {needed:.3f} m)",
        )


def _read_events(
    tables: list[Table],
    segment_map: SegmentMap,
    robot: RobotParams,
    run: RunSpec,
    obstacles: Obstacles,
    start_pose: tuple[float, float, float],
    sonar: SonarBeltParams,
) -> tuple[tuple[KidnapEvent, ...], tuple[SonarFailure, ...]]:
    """The ``[[events]]`` entries (module docstring), checked: a time inside the run; for a
    kidnap a free pose at that time (the simulator's own check), one kidnap per sample; for
    a sonar failure a window of positive length, sensors of the belt, a range it can read."""
    kidnaps: dict[int, KidnapEvent] = {}
    failures = []
    world = World(segment_map, robot, start_pose, obstacles=obstacles)
    for table in tables:
        kind = EventKind(table.take_str("kind", choices=choices(EventKind)))
        t_s = table.take_float("t_s", above=0.0, maximum=run.duration_s)
        if kind == EventKind.SONAR_FAILURE:
            failures.append(_read_failure(table, t_s, sonar))
            continue
        xy = table.take_array("xy_m", (2,))
        heading_deg = table.take_float("heading_deg", 0.0)
        table.finish()
        pose = (float(xy[0]), float(xy[1]), float(wrap_angle(math.radians(heading_deg))))
        sample = math.ceil(t_s * run.rate_hz - 1e-9)  # the simulator's rule
        try:
            world.check_free(pose, t_s=sample / run.rate_hz)
        except RobotsimError as exc:
            raise table.error("xy_m", str(exc)) from None
        if sample in kidnaps:
            raise table.error("t_s", f"another kidnap falls on the same sample ({sample})")
        kidnaps[sample] = KidnapEvent(t_s, pose)
    ordered = tuple(kidnaps[sample] for sample in sorted(kidnaps))
    return ordered, tuple(sorted(failures, key=lambda f: f.start_s))


def _read_failure(table: Table, t_s: float, sonar: SonarBeltParams) -> SonarFailure:
    """A ``sonar_failure`` event: ``duration_s``, ``sensors`` and ``reading_m``."""
    duration_s = table.take_float("duration_s", above=0.0)
    raw = table.take_raw("sensors", "all")
    if raw == "all":
        sensors = tuple(range(sonar.count))
    else:
        if (
            not isinstance(raw, list)
            or not raw
            or not all(isinstance(i, int) and not isinstance(i, bool) for i in raw)
        ):
            raise table.error(
                "sensors", f'must be "all" or a non-empty array of integers, got {raw!r}'
            )
        bad = [i for i in raw if not 0 <= i < sonar.count]
        if bad:
            raise table.error(
                "sensors", f"sensor {bad[0]} is not on the belt (indices 0 to {sonar.count - 1})"
            )
        if len(set(raw)) != len(raw):
            raise table.error("sensors", f"a sensor is named twice: {raw}")
        sensors = tuple(raw)
    reading = table.take_float("reading_m", None, minimum=0.0, maximum=sonar.d_max_m)
    table.finish()
    return SonarFailure(t_s, t_s + duration_s, sensors, math.inf if reading is None else reading)


def _read_route(table: Table, segment_map: SegmentMap, robot: RobotParams) -> Plan:
    """Waypoints for pure pursuit, scripted profile steps, or (neither) standing still."""
    steps = table.take_tables("profile")
    if table.has("waypoints_m") and steps:
        raise table.error("profile", "give waypoints_m or profile steps, not both")
    if steps:
        table.finish()
        return _profile(steps, robot)
    if not table.has("waypoints_m"):
        table.finish()
        return STAND_STILL
    waypoints = table.take_array("waypoints_m", (None, 2))
    if segment_map.boundary is not None:
        inside = shapely.contains_xy(
            shapely.Polygon(segment_map.boundary), waypoints[:, 0], waypoints[:, 1]
        )
        if not np.all(inside):
            raise table.error(
                f"waypoints_m[{int(np.argmin(inside))}]", "lies outside the map's outer wall"
            )
    route = _read_params(table, Route(waypoints_m=waypoints), skip=("waypoints_m",))
    if route.cruise_speed_m_s > robot.v_max_m_s:
        raise table.error(
            "cruise_speed_m_s", f"exceeds the robot's v_max_m_s = {robot.v_max_m_s:g}"
        )
    return route


def _profile(steps: list[Table], robot: RobotParams) -> ScriptedProfile:
    """Steps ``{duration_s, v_m_s, omega_rad_s}`` played in order, then a stop."""
    durations, speeds, rates = [], [], []
    for step in steps:
        durations.append(step.take_float("duration_s", above=0.0))
        speeds.append(
            step.take_float("v_m_s", 0.0, minimum=-robot.v_max_m_s, maximum=robot.v_max_m_s)
        )
        rates.append(_take_angle(step, "omega_rad_s", 0.0))
        if abs(rates[-1]) > robot.omega_max_rad_s:
            raise step.error(
                "omega_rad_s", f"exceeds the robot's omega_max_rad_s = {robot.omega_max_rad_s:g}"
            )
        step.finish()
    starts = np.concatenate([[0.0], np.cumsum(durations)])
    return ScriptedProfile(
        t_s=starts, v_m_s=np.append(speeds, 0.0), omega_rad_s=np.append(rates, 0.0)
    )


def _read_sensors(table: Table, robot: RobotParams, run: RunSpec) -> SensorsSpec:
    sensors = SensorsSpec(
        encoders=_read_params(table.take_table("encoders"), EncoderParams()),
        gyro=_read_params(table.take_table("gyro"), GyroParams()),
        accelerometer=_read_params(table.take_table("accelerometer"), AccelerometerParams()),
        sonar=_read_sonar(table.take_table("sonar"), robot, run),
    )
    table.finish()
    return sensors


def _read_sonar(table: Table, robot: RobotParams, run: RunSpec) -> SonarBeltParams:
    """The default belt (``count`` sensors evenly round the robot's rim) or explicit mounts.

    The simulator takes a scan at a sample, so the sonar's rate must divide the run's a
    whole number of times (a faster or off-beat sonar would be silently slowed or jittered).
    """
    if table.has("count") and (
        table.has("mount_xy") or table.has("mount_angle_rad") or table.has("mount_angle_deg")
    ):
        raise table.error(
            "count", "give count (an even belt) or mount_xy and mount_angle_rad, not both"
        )
    count = table.take_int(
        "count", None, bounds=Bounds(minimum=1, maximum=MAX_BELT_COUNT, integer=True)
    )
    belt = {} if count is None else {"count": count}
    try:
        default = SonarBeltParams.default_belt(robot_radius_m=robot.radius_m, **belt)
    except RobotsimError as exc:
        raise table.error("count", str(exc)) from None
    sonar = _read_params(table, default)
    ratio = run.rate_hz / sonar.rate_hz
    if ratio < 1.0 - RATE_RATIO_TOL:
        raise table.error(
            "rate_hz",
            f"faster than the simulation (run.rate_hz = {run.rate_hz:g} Hz), got {sonar.rate_hz:g}",
        )
    if abs(ratio - round(ratio)) > RATE_RATIO_TOL:
        raise table.error(
            "rate_hz",
            f"must divide the simulation rate (run.rate_hz = {run.rate_hz:g} Hz) a whole number of times, "
            f"got {sonar.rate_hz:g}",
        )
    return sonar


def _read_estimation(
    table: Table, robot: RobotParams, sonar: SonarBeltParams, follow: Follow
) -> EstimationSpec:
    """The ``[estimation]`` table, checked against the robot and the sonar belt it will read
    (``follow``: the pose the controller steers on, for the default fusion rule)."""
    limits = TrackerSettings(v_max_m_s=robot.v_max_m_s, omega_max_rad_s=robot.omega_max_rad_s)
    own_defaults = EstimationSpec(
        intervals=limits,
        fusion=default_fusion(follow),
        interval_rate_hz=sonar.rate_hz,
        free_space=sonar.lost_echo_prob == 0.0,
    )
    mcl = _read_params(table.take_table("mcl"), own_defaults.mcl)
    estimation = _read_params(
        table,
        dataclasses.replace(own_defaults, mcl=mcl),
        skip=("intervals", "dead_reckoning", "mcl"),
        parts={
            "intervals": (limits, TRACKER_KEYS),
            "dead_reckoning": (own_defaults.dead_reckoning, DEAD_RECKONING_KEYS),
        },
    )
    problem = estimation_problem(estimation, robot, sonar)
    if problem is not None:
        raise table.error(*problem)
    return estimation


def estimation_problem(
    estimation: EstimationSpec, robot: RobotParams, sonar: SonarBeltParams
) -> tuple[str, str] | None:
    """``(key, reason)``: why ``estimation`` does not fit the robot and the sonar belt, or None."""
    tracker = estimation.intervals
    if tracker.q_max >= sonar.count:
        return (
            "q_max",
            f"must be less than the number of sonars ({sonar.count}): with every reading allowed "
            f"to be an outlier a scan constrains nothing; got {tracker.q_max}",
        )
    if estimation.free_space and sonar.lost_echo_prob > 0.0:
        return (
            "free_space",
            f"unsound: the sonar loses echoes (sensors.sonar.lost_echo_prob = {sonar.lost_echo_prob:g}), "
            "so a no-echo reading does not prove free space",
        )
    ratio = sonar.rate_hz / estimation.interval_rate_hz
    if ratio < 1.0 - RATE_RATIO_TOL or abs(ratio - round(ratio)) > RATE_RATIO_TOL:
        return (
            "interval_rate_hz",
            f"must divide the sonar rate ({sonar.rate_hz:g} Hz) a whole number of times, "
            f"got {estimation.interval_rate_hz:g}",
        )
    for name in ("v_max_m_s", "omega_max_rad_s"):
        if getattr(tracker, name) != getattr(robot, name):
            return (
                name,
                f"the tracker's {name} ({getattr(tracker, name):g}) must be the robot's "
                f"({getattr(robot, name):g})",
            )
    return None


# ---------------------------------------------------------------------------------------
# Simulator parameter classes read field by field
# ---------------------------------------------------------------------------------------
#: A unit token ``_rad`` in a key: ``half_aperture_rad``, ``omega_max_rad_s`` (not ``radius``).
_RADIAN_TOKEN = re.compile(r"_rad(?=_|$)")


def _is_radian(field_name: str) -> bool:
    return _RADIAN_TOKEN.search(field_name) is not None


def _deg_alias(field_name: str) -> str:
    """The degree spelling of a radian key (``half_aperture_rad`` -> ``half_aperture_deg``)."""
    return _RADIAN_TOKEN.sub("_deg", field_name, count=1)


def _take_angle(
    table: Table,
    name: str,
    default: Any,
    *,
    shape: tuple[int | None, ...] | None = None,
    bounds: Bounds | None = None,
) -> Any:
    """A ``*_rad*`` key (a number, or an array of ``shape``) that may instead be given in
    degrees under its ``*_deg*`` spelling, never both; returned in radians.

    ``bounds`` (in radians) apply to the number, checked in the unit it is written in.
    """
    alias = _deg_alias(name)
    if table.has(name) and table.has(alias):
        raise table.error(alias, f"give {name} or {alias}, not both")
    key, scale = (alias, math.pi / 180.0) if table.has(alias) else (name, 1.0)
    if shape is None:
        written = None if bounds is None else bounds.scaled(1.0 / scale)
        value = table.take_float(key, None, bounds=written)
    else:
        value = table.take_array(key, shape, None)
    table.mention(alias if key == name else name)
    return default if value is None else value * scale


#: A settings record read from one table: its defaults and the keys (fields) it takes there.
Part = tuple[Any, tuple[str, ...]]


def _read_params(
    table: Table,
    defaults: Any,
    skip: tuple[str, ...] = (),
    parts: dict[str, Part] | None = None,
) -> Any:
    """A copy of the frozen settings record ``defaults`` with the table's keys replaced.

    Each field is a key (radian fields also in degrees) read by its annotated type: a
    number within the bounds declared beside the field (``records.bounded``), a boolean, a
    choice (a ``StrEnum``: one of its values) or an array; missing keys keep the defaults.
    ``parts``: fields that are records themselves, each read from the same table with its
    own keys (``[estimation]`` holds the tracker's and the filter's). Errors the records
    raise in their own validation (checks across fields) are reported against the table.
    """
    parts = parts or {}
    values = _read_fields(table, defaults, skip=(*skip, *parts))
    for name, (part_defaults, keys) in parts.items():
        part_values = _read_fields(table, part_defaults, keys=keys)
        values[name] = _replaced(table, part_defaults, part_values)
    table.finish()
    return _replaced(table, defaults, values)


def _read_fields(
    table: Table, defaults: Any, skip: tuple[str, ...] = (), keys: tuple[str, ...] | None = None
) -> dict[str, Any]:
    """The values the table gives for the fields of ``defaults`` (all but ``skip``, or
    ``keys`` only), taken out of the table."""
    hints = typing.get_type_hints(type(defaults))
    values: dict[str, Any] = {}
    for field in dataclasses.fields(defaults):
        name = field.name
        if not field.init or name in skip or (keys is not None and name not in keys):
            continue
        kind, bounds = _value_type(hints[name]), declared_bounds(defaults, name)
        if kind is bool:
            value = table.take_bool(name, None)
        elif kind is int:
            value = table.take_int(name, None, bounds=bounds or Bounds(integer=True))
        elif kind is float and _is_radian(name):
            value = _take_angle(table, name, None, bounds=bounds)
        elif kind is float:
            value = table.take_float(name, None, bounds=bounds)
        elif isinstance(kind, type) and issubclass(kind, Enum):
            value = table.take_str(name, None, choices=choices(kind))
        elif kind is np.ndarray:
            shape = (None, *getattr(defaults, name).shape[1:])
            value = (
                _take_angle(table, name, None, shape=shape)
                if _is_radian(name)
                else table.take_array(name, shape, None)
            )
        else:
            continue
        if value is not None:
            values[name] = value
    return values


def _value_type(annotation: Any) -> Any:
    """The type a field holds, without ``| None`` (``bool | None`` -> ``bool``)."""
    if isinstance(annotation, types.UnionType):
        kinds = [kind for kind in typing.get_args(annotation) if kind is not type(None)]
        return kinds[0] if len(kinds) == 1 else annotation
    return annotation


def _replaced(table: Table, defaults: Any, values: dict[str, Any]) -> Any:
    """``defaults`` with ``values`` replaced; a refusal of the record's own validation is
    reported against the key its message names (longest match), else the table."""
    try:
        return dataclasses.replace(defaults, **values)
    except (ValueError, TypeError) as exc:
        named = [name for name in values if name in str(exc)]
        key = table.key(max(named, key=len)) if named else table.path
        raise ScenarioError(table.source, key, str(exc)) from None
