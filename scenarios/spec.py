"""The scenario file: its TOML schema, its validation, and the frozen spec it becomes.

A scenario file has the tables below; every key is optional unless marked, and the
defaults are the ones written here (for the robot and the sensors: the defaults of the
``robotsim`` parameter classes, so they are stated once, where the simulator uses them).

``description`` (top level)
    One line shown by ``robotsim scenarios``.
``[run]``
    ``duration_s`` (60.0), ``seed`` (0), and the sample rate of the simulation and of the
    proprioceptive sensors: ``rate_hz`` (100.0) or ``dt_s`` (0.01), not both. A run has
    from 1 to :data:`MAX_SAMPLES` samples (``duration_s * rate_hz``).
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
    a route the robot stands still.
``[sensors.encoders]``, ``[sensors.gyro]``, ``[sensors.accelerometer]``, ``[sensors.sonar]``
    The fields of the simulator's sensor parameter classes; for the sonar also ``count``
    (an even belt on the robot's rim, the default) in place of ``mount_xy`` and
    ``mount_angle_rad``. A field named ``*_rad*`` may be written in degrees under the same
    name with ``_deg`` in place of ``_rad`` (``half_aperture_deg``); never both. The sonar's
    ``rate_hz`` must divide ``run.rate_hz`` a whole number of times (a scan is taken at a
    sample; a faster or off-beat sonar is refused rather than silently slowed).
``[estimation]``
    The localisation pipeline (paper 002): ``filter`` (``"ukf"``; or ``"iukf"``, ``"ekf"``,
    ``"iekf"``), ``tracker`` (``"sivia"`` or ``"imagesp"``), ``fusion`` (``"clamp"``, the
    paper's rule, or another rule of ``localization.fusion``), ``eps_m`` (0.05),
    ``q_max`` (1), ``guaranteed`` (true), ``interval_rate_hz`` (the sonar's rate: an epoch at every scan),
    ``heading_scale_m_per_rad`` (1.0), ``imagesp_pitch_m`` (0.2), ``free_space``
    (default: true exactly when the sonar never loses an echo) and ``ray_test`` (default: true
    exactly when the sonar's half-aperture is at most 0.1 rad). See :class:`EstimationSpec`.

Every mistake raises ``ScenarioError(file, "table.key", reason)``.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from intervals.tracker import TRACKERS
from localization.fusion import FUSION_RULES
from robotsim.control import Plan, Route, ScriptedProfile
from robotsim.errors import RobotsimError
from robotsim.maps import BUILTIN_MAP_NAMES, SegmentMap, builtin_map, outer_wall
from robotsim.robot import RobotParams, wrap_angle
from robotsim.sensors.encoders import EncoderParams
from robotsim.sensors.imu import AccelerometerParams, GyroParams
from robotsim.sensors.sonar import SonarBeltParams
from robotsim.world import World
from scenarios.errors import ScenarioError
from scenarios.feasibility import check_feasible
from scenarios.tables import Table

#: The built-in scenarios: one TOML file per built-in map, in ``scenarios/builtin/``.
BUILTIN_FOLDER = resources.files("scenarios") / "builtin"

DEFAULT_DURATION_S = 60.0
DEFAULT_SEED = 0
DEFAULT_RATE_HZ = 100.0
DEFAULT_MAP = "hall"

#: The most samples (``duration_s * rate_hz``) a run may have: ten million samples take
#: about 10 GB of logs and hours of simulation; beyond, refused before anything runs.
MAX_SAMPLES = 10_000_000

#: The smallest SIVIA precision ``eps_m``, metres: finer boxes multiply beyond any memory
#: (a millimetre is far below the sonar's error bounds).
MIN_EPS_M = 1e-3

#: Tolerance on the whole number of samples between two sonar scans.
RATE_RATIO_TOL = 1e-9

#: The plan of a scenario without a route: no motion.
STAND_STILL = ScriptedProfile(t_s=np.zeros(1), v_m_s=np.zeros(1), omega_rad_s=np.zeros(1))

#: Filters the dead reckoning may run (``localization``): UKF, iterated UKF, EKF, iterated EKF.
FILTERS = ("ukf", "iukf", "ekf", "iekf")


# ---------------------------------------------------------------------------------------
# The spec: a frozen tree
# ---------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class RunSpec:
    """Length, randomness and sampling of one run."""

    duration_s: float = DEFAULT_DURATION_S
    """Simulated time, seconds (> 0)."""
    seed: int = DEFAULT_SEED
    """Seed of the run's ``numpy.random.Generator`` (>= 0)."""
    rate_hz: float = DEFAULT_RATE_HZ
    """Simulation and proprioceptive sensor rate, hertz (> 0); ``dt_s = 1 / rate_hz``."""

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
    an interval epoch at the sonar scans, the fusion of the two."""

    filter: str = "ukf"
    """The dead-reckoning filter: one of :data:`FILTERS`."""
    tracker: str = "sivia"
    """The interval tracker's prediction: ``"sivia"`` (hull grown by the physical limits,
    inverted as one box) or ``"imagesp"`` (every box mapped, then contracted)."""
    fusion: str = "clamp"
    """The fusion rule of ``localization.fusion``; ``"clamp"`` is the paper's (section 4)."""
    eps_m: float = 0.05
    """SIVIA precision: boxes narrower than this (scaled widths) are not bisected, m (>= MIN_EPS_M)."""
    q_max: int = 1
    """Largest number of outlying sonar readings GOMNE may assume per epoch (0 to the belt size less one)."""
    guaranteed: bool = True
    """Keep the ``q_max``-relaxed set, which holds the truth whenever a scan has at most
    ``q_max`` outliers (true), or GOMNE's set at the smallest ``q`` explaining the scan
    (false: tighter, but outliers that happen to fit another pose make it miss the truth)."""
    interval_rate_hz: float = 1.0
    """Interval epochs per second: one every ``sonar.rate_hz / interval_rate_hz`` scans (a
    whole number); a scenario file's default is the sonar's rate (an epoch at every scan)."""
    heading_scale_m_per_rad: float = 1.0
    """Metres per radian when the heading width is compared with position widths."""
    imagesp_pitch_m: float = 0.2
    """Grid pitch of the IMAGESP prediction (scaled like ``eps_m``; at least ``eps_m``)."""
    free_space: bool = True
    """Use no-echo readings as free space up to ``d_max``: sound only when the sonar never
    loses an echo, hence the default ``lost_echo_prob == 0``."""
    ray_test: bool | None = None
    """Add the ray test of ``intervals.rays`` to the sonar box test: tighter sets (on ``hall``'s
    600 s run a quarter smaller, up to 60 % on thin cones) for about 4 ms more per epoch;
    ``None`` (the key absent): only when the half-aperture is at most 0.1 rad."""

    def scan_stride(self, sonar_rate_hz: float) -> int:
        """Scans per interval epoch (1: every scan)."""
        return int(round(sonar_rate_hz / self.interval_rate_hz))


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

    def with_run(self, *, seed: int | None = None, duration_s: float | None = None) -> ScenarioSpec:
        """This scenario with the seed and/or duration replaced (the CLI's ``--seed``/``--duration``)."""
        run = self.run
        if seed is not None:
            if seed < 0:
                raise ScenarioError(None, "--seed", f"must be >= 0, got {seed}")
            run = dataclasses.replace(run, seed=seed)
        if duration_s is not None:
            if not (math.isfinite(duration_s) and duration_s > 0):
                raise ScenarioError(
                    None, "--duration", f"must be a finite number > 0, got {duration_s}"
                )
            reason = _sample_count_problem(duration_s, run.rate_hz)
            if reason is not None:
                raise ScenarioError(None, "--duration", reason)
            run = dataclasses.replace(run, duration_s=duration_s)
        return dataclasses.replace(self, run=run)


# ---------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------
def builtin_names() -> tuple[str, ...]:
    """Names of the built-in scenarios (the TOML files of ``scenarios/builtin``)."""
    files = BUILTIN_FOLDER.iterdir()
    return tuple(sorted(f.name[: -len(".toml")] for f in files if f.name.endswith(".toml")))


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
    plan = _read_route(top.take_table("route"), segment_map, robot)
    sensors = _read_sensors(top.take_table("sensors"), robot, run)
    estimation = _read_estimation(top.take_table("estimation"), sensors.sonar)
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
    )


# ---------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------
def _read_run(table: Table) -> RunSpec:
    duration_s = table.take_float("duration_s", DEFAULT_DURATION_S, above=0.0)
    seed = table.take_int("seed", DEFAULT_SEED, minimum=0)
    if table.has("rate_hz") and table.has("dt_s"):
        raise table.error("dt_s", "give rate_hz or dt_s, not both")
    rate_key = "dt_s" if table.has("dt_s") else "rate_hz"
    if table.has("dt_s"):
        rate_hz = 1.0 / table.take_float("dt_s", above=0.0)
        table.take_float("rate_hz", None)
    else:
        rate_hz = table.take_float("rate_hz", DEFAULT_RATE_HZ, above=0.0)
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
    count = table.take_int("count", None, minimum=1)
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


def _read_estimation(table: Table, sonar: SonarBeltParams) -> EstimationSpec:
    """The ``[estimation]`` table, checked against the sonar belt it will read."""
    default = EstimationSpec()
    values = {
        "filter": table.take_str("filter", default.filter, choices=FILTERS),
        "tracker": table.take_str("tracker", default.tracker, choices=TRACKERS),
        "fusion": table.take_str("fusion", default.fusion, choices=FUSION_RULES),
        "eps_m": table.take_float("eps_m", default.eps_m, minimum=MIN_EPS_M),
        "q_max": table.take_int("q_max", default.q_max, minimum=0),
        "guaranteed": table.take_bool("guaranteed", default.guaranteed),
        "interval_rate_hz": table.take_float("interval_rate_hz", sonar.rate_hz, above=0.0),
        "heading_scale_m_per_rad": table.take_float(
            "heading_scale_m_per_rad", default.heading_scale_m_per_rad, above=0.0
        ),
        "imagesp_pitch_m": table.take_float("imagesp_pitch_m", default.imagesp_pitch_m, above=0.0),
        "free_space": table.take_bool("free_space", sonar.lost_echo_prob == 0.0),
        "ray_test": table.take_bool("ray_test", default.ray_test),
    }
    table.finish()
    if values["q_max"] >= sonar.count:
        raise table.error(
            "q_max",
            f"must be less than the number of sonars ({sonar.count}): with every reading allowed to be "
            f"an outlier a scan constrains nothing; got {values['q_max']}",
        )
    if values["free_space"] and sonar.lost_echo_prob > 0.0:
        raise table.error(
            "free_space",
            f"unsound: the sonar loses echoes (sensors.sonar.lost_echo_prob = {sonar.lost_echo_prob:g}), "
            "so a no-echo reading does not prove free space",
        )
    ratio = sonar.rate_hz / values["interval_rate_hz"]
    if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9:
        raise table.error(
            "interval_rate_hz",
            f"must divide the sonar rate ({sonar.rate_hz:g} Hz) a whole number of times, got {values['interval_rate_hz']:g}",
        )
    if values["imagesp_pitch_m"] < values["eps_m"]:
        raise table.error(
            "imagesp_pitch_m",
            f"must be >= eps_m ({values['eps_m']:g}), got {values['imagesp_pitch_m']:g}",
        )
    return EstimationSpec(**values)


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
    **bounds: float,
) -> Any:
    """A ``*_rad*`` key (a number, or an array of ``shape``) that may instead be given in
    degrees under its ``*_deg*`` spelling, never both; returned in radians.

    ``bounds`` (at 0 or symmetric about it, so the same in both units) apply to the number.
    """
    alias = _deg_alias(name)
    if table.has(name) and table.has(alias):
        raise table.error(alias, f"give {name} or {alias}, not both")
    key, scale = (alias, math.pi / 180.0) if table.has(alias) else (name, 1.0)
    if shape is None:
        value = table.take_float(key, None, **bounds)
    else:
        value = table.take_array(key, shape, None)
    table.mention(alias if key == name else name)
    return default if value is None else value * scale


#: Bounds implied by a parameter's name (MODELS.md section 1 naming rules).
_NAME_BOUNDS: tuple[tuple[Callable[[str], bool], dict[str, float]], ...] = (
    (lambda n: n.endswith("_prob"), {"minimum": 0.0, "maximum": 1.0}),
    (
        lambda n: any(word in n for word in ("_std", "density", "random_walk", "_bound")),
        {"minimum": 0.0},
    ),
    (
        lambda n: n.endswith("rate_hz") or n.startswith(("d_max", "v_max", "omega_max", "a_max")),
        {"above": 0.0},
    ),
    (lambda n: "radius" in n or n.startswith(("wheel_base", "mass")), {"above": 0.0}),
)


def _bounds_for(field_name: str) -> dict[str, float]:
    for matches, bounds in _NAME_BOUNDS:
        if matches(field_name):
            return bounds
    return {}


def _read_params(table: Table, defaults: Any, skip: tuple[str, ...] = ()) -> Any:
    """A copy of the frozen parameter record ``defaults`` with the table's keys replaced.

    Each field is a key (radian fields also in degrees); its type is the type of the
    default's value; missing keys keep the defaults. Errors the class raises in its own
    validation are reported against the table.
    """
    values: dict[str, Any] = {}
    for field in dataclasses.fields(defaults):
        if not field.init or field.name in skip:
            continue
        name, current = field.name, getattr(defaults, field.name)
        if isinstance(current, bool):
            value = table.take_bool(name, None)
        elif isinstance(current, (int, np.integer)):
            value = table.take_int(name, None, minimum=0)
        elif isinstance(current, (float, np.floating)) and _is_radian(name):
            value = _take_angle(table, name, None, **_bounds_for(name))
        elif isinstance(current, (float, np.floating)):
            value = table.take_float(name, None, **_bounds_for(name))
        elif isinstance(current, np.ndarray):
            shape = (None, *current.shape[1:])
            value = (
                _take_angle(table, name, None, shape=shape)
                if _is_radian(name)
                else table.take_array(name, shape, None)
            )
        else:
            continue
        if value is not None:
            values[name] = value
    table.finish()
    try:
        return dataclasses.replace(defaults, **values)
    except (RobotsimError, ValueError, TypeError) as exc:
        key = _blamed_key(str(exc), values)
        raise ScenarioError(table.source, table.key(key) if key else table.path, str(exc)) from None


def _blamed_key(message: str, values: dict[str, Any]) -> str | None:
    """The key a parameter class's error message names (longest match), for the ``table.key``."""
    named = [name for name in values if name in message]
    return max(named, key=len) if named else None
