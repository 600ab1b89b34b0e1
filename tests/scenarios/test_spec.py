"""The scenario schema: every built-in parses, good files give the values they say, and every
mistake is refused with one message naming the file, the key and the reason."""

from __future__ import annotations

import math

import numpy as np
import pytest

from intervals.tracker import TrackerSettings
from robotsim.control import Route, ScriptedProfile
from robotsim.maps import BUILTIN_MAP_NAMES
from robotsim.robot import RobotParams
from robotsim.sensors.imu import GyroParams
from robotsim.sensors.sonar import SonarBeltParams
from scenarios.errors import ScenarioError
from scenarios.spec import (
    MAX_SAMPLES,
    STAND_STILL,
    EstimationSpec,
    builtin_names,
    load_scenario,
    parse_scenario,
)

BASE = """
[map]
segments = [[[0, 0], [10, 0]], [[10, 0], [10, 8]], [[10, 8], [0, 8]], [[0, 8], [0, 0]]]
[robot]
start_xy_m = [2.0, 2.0]
"""


def parse(text: str, **kwargs):
    return parse_scenario(text, source="test.toml", **kwargs)


def refused(text: str, **kwargs) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        parse(text, **kwargs)
    return info.value


def test_every_builtin_scenario_parses_and_uses_its_map():
    # a scenario per built-in map; the floor plans of scenarios/builtin/maps are map files
    assert set(BUILTIN_MAP_NAMES) <= set(builtin_names())
    for name in builtin_names():
        spec = load_scenario(name)
        assert spec.name == name
        assert spec.description and "\n" not in spec.description
        # named after its map: hall_mcl is the hall localised by the particle filter; the
        # furnished plans with unmapped obstacles use the plan of their name's first word
        assert spec.map.name == (name.split("_")[0] if spec.obstacles else name.split("_mcl")[0])
        assert isinstance(spec.plan, (Route, ScriptedProfile)) and spec.plan is not STAND_STILL
        assert spec.run.duration_s > 0


def test_defaults_come_from_the_simulator_classes():
    spec = parse(BASE)
    assert spec.run.duration_s == 60.0 and spec.run.seed == 0 and spec.run.rate_hz == 100.0
    assert spec.robot == RobotParams()
    belt = SonarBeltParams.default_belt(robot_radius_m=spec.robot.radius_m)
    np.testing.assert_array_equal(spec.sensors.sonar.mount_xy, belt.mount_xy)
    assert spec.sensors.sonar.d_max_m == belt.d_max_m == 3.0 and spec.sensors.sonar.count == 16
    assert spec.sensors.gyro == GyroParams()
    assert spec.plan is STAND_STILL
    assert spec.start_pose == (2.0, 2.0, 0.0)


def test_values_units_and_degree_keys():
    spec = parse(
        BASE
        + """
start_heading_deg = 90
v_max_m_s = 0.8
wheel_radius_m = 0.052
omega_max_deg_s = 90
[run]
dt_s = 0.02
seed = 7
duration_s = 5
[sensors.sonar]
half_aperture_deg = 10
d_max_m = 2.5
[route]
waypoints_m = [[2, 2], [8, 2], [8, 6]]
cruise_speed_m_s = 0.5
loop = false
"""
    )
    assert (
        spec.run.rate_hz == pytest.approx(50.0)
        and spec.run.dt_s == pytest.approx(0.02)
        and spec.run.seed == 7
    )
    assert spec.start_pose[2] == pytest.approx(math.pi / 2)
    assert spec.robot.wheel_radius_m == 0.052  # "radius" is not a radian key
    assert spec.robot.v_max_m_s == 0.8 and spec.robot.omega_max_rad_s == pytest.approx(math.pi / 2)
    assert spec.sensors.sonar.half_aperture_rad == pytest.approx(math.radians(10))
    assert spec.sensors.sonar.d_max_m == 2.5
    assert isinstance(spec.plan, Route) and not spec.plan.loop and spec.plan.cruise_speed_m_s == 0.5
    np.testing.assert_array_equal(spec.plan.waypoints_m, [[2, 2], [8, 2], [8, 6]])


def test_profile_route():
    spec = parse(
        BASE
        + """
[[route.profile]]
duration_s = 2
v_m_s = 0.3
[[route.profile]]
duration_s = 1
omega_deg_s = 45
"""
    )
    assert isinstance(spec.plan, ScriptedProfile)
    np.testing.assert_allclose(spec.plan.t_s, [0.0, 2.0, 3.0])
    np.testing.assert_allclose(spec.plan.v_m_s, [0.3, 0.0, 0.0])
    np.testing.assert_allclose(spec.plan.omega_rad_s, [0.0, math.pi / 4, 0.0])


def test_a_custom_sonar_belt_in_degrees():
    spec = parse(
        BASE + "[sensors.sonar]\nmount_xy = [[0.2, 0.0], [0.0, 0.2]]\nmount_angle_deg = [0, 90]\n"
    )
    assert spec.sensors.sonar.count == 2
    np.testing.assert_allclose(spec.sensors.sonar.mount_angle_rad, [0.0, math.pi / 2])
    error = refused(BASE + "[sensors.sonar]\nmount_xy = [[0.2, 0.0], [0.0, 0.2]]\n")
    assert error.key.startswith("sensors.sonar") and "mount_angle_rad" in error.reason
    error = refused(BASE + "[sensors.sonar]\ncount = 8\nmount_xy = [[0.2, 0.0]]\n")
    assert error.key == "sensors.sonar.count" and "not both" in error.reason


def test_map_files_are_read_relative_to_the_scenario(tmp_path):
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "room.wkt").write_text("POLYGON ((0 0, 6 0, 6 5, 0 5, 0 0))")
    (tmp_path / "maps" / "room.geojson").write_text(
        '{"type": "LineString", "coordinates": [[0, 0], [6, 0], [6, 5], [0, 5], [0, 0]]}'
    )
    robot = "[robot]\nstart_xy_m = [3, 2]\n"
    for name in ("room.wkt", "room.geojson"):
        scenario = tmp_path / f"s_{name}.toml"
        scenario.write_text(f'[map]\nfile = "maps/{name}"\n' + robot)
        spec = load_scenario(scenario)
        assert spec.map.segments.shape == (4, 2, 2)
        assert spec.name == scenario.stem


BAD = {
    "unknown key": ("[run]\ndurration_s = 5\n", "run.durration_s", "did you mean 'duration_s'"),
    "unknown table": ("[sensor.sonar]\nd_max_m = 3\n", "sensor", "unknown key"),
    "unknown sensor key": ("[sensors.gyro]\nbias = 1.0\n", "sensors.gyro.bias", "unknown key"),
    "negative rate": ("[run]\nrate_hz = -100\n", "run.rate_hz", "must be >= 1"),
    "rate beyond the simulator's": ("[run]\nrate_hz = 1e9\n", "run.rate_hz", "must be <= 10000"),
    "period below the simulator's": ("[run]\ndt_s = 1e-9\n", "run.dt_s", "must be >= 0.0001"),
    "negative sonar rate": (
        "[sensors.sonar]\nrate_hz = -1\n",
        "sensors.sonar.rate_hz",
        "must be > 0",
    ),
    "NaN duration": ("[run]\nduration_s = nan\n", "run.duration_s", "finite"),
    "infinite speed": ("[robot]\nv_max_m_s = inf\n", "robot.v_max_m_s", "finite"),
    "d_max zero": ("[sensors.sonar]\nd_max_m = 0\n", "sensors.sonar.d_max_m", "must be > 0"),
    "v_max negative": ("[robot]\nv_max_m_s = -1.0\n", "robot.v_max_m_s", "must be > 0"),
    "probability above one": (
        "[sensors.sonar]\noutlier_prob = 1.5\n",
        "sensors.sonar.outlier_prob",
        "<= 1",
    ),
    "wrong type": ('[run]\nseed = "one"\n', "run.seed", "must be an integer"),
    "float seed": ("[run]\nseed = 1.5\n", "run.seed", "must be an integer"),
    "rate and dt": ("[run]\nrate_hz = 50\ndt_s = 0.02\n", "run.dt_s", "not both"),
    "degrees and radians": (
        "[sensors.sonar]\nhalf_aperture_deg = 10\nhalf_aperture_rad = 0.2\n",
        "sensors.sonar.half_aperture_deg",
        "not both",
    ),
    "estimation filter": (
        "[estimation]\nfilter = 'pf'\n",
        "estimation.filter",
        "must be one of 'ukf'",
    ),
    "estimation tracker": (
        "[estimation]\ntracker = 'kalman'\n",
        "estimation.tracker",
        "'sivia', 'imagesp'",
    ),
    "estimation fusion": ("[estimation]\nfusion = 'average'\n", "estimation.fusion", "'clamp'"),
    "estimation eps": ("[estimation]\neps_m = 0\n", "estimation.eps_m", "must be >= 0.001"),
    "estimation eps tiny": (
        "[estimation]\neps_m = 1e-300\n",
        "estimation.eps_m",
        "must be >= 0.001",
    ),
    "estimation q_max negative": ("[estimation]\nq_max = -1\n", "estimation.q_max", "must be >= 0"),
    "estimation q_max too large": (
        "[estimation]\nq_max = 17\n",
        "estimation.q_max",
        "less than the number of sonars (16)",
    ),
    "estimation q_max every sonar": (
        "[estimation]\nq_max = 16\n",
        "estimation.q_max",
        "constrains nothing",
    ),
    "too many samples (rate)": (
        "[run]\nrate_hz = 1e4\nduration_s = 1e4\n",
        "run.rate_hz",
        "more than the 1e+07",
    ),
    "too many samples (dt)": (
        "[run]\ndt_s = 1e-4\nduration_s = 1e4\n",
        "run.dt_s",
        "more than the 1e+07",
    ),
    "too many samples (duration)": (
        "[run]\nduration_s = 1e300\n",
        "run.duration_s",
        "more than the 1e+07",
    ),
    "sonar faster than the simulation": (
        "[run]\nrate_hz = 10\n[sensors.sonar]\nrate_hz = 20\n",
        "sensors.sonar.rate_hz",
        "faster than the simulation",
    ),
    "sonar off the sample beat": (
        "[sensors.sonar]\nrate_hz = 3\n",
        "sensors.sonar.rate_hz",
        "whole number",
    ),
    "estimation rate": (
        "[estimation]\ninterval_rate_hz = 0.3\n",
        "estimation.interval_rate_hz",
        "whole number",
    ),
    "estimation rate above sonar": (
        "[estimation]\ninterval_rate_hz = 2\n",
        "estimation.interval_rate_hz",
        "whole number",
    ),
    "estimation pitch": (
        "[estimation]\nimagesp_pitch_m = 0.01\n",
        "estimation.imagesp_pitch_m",
        ">= eps_m",
    ),
    "estimation guaranteed": (
        "[estimation]\nguaranteed = 'yes'\n",
        "estimation.guaranteed",
        "true or false",
    ),
    "estimation ray test": (
        "[estimation]\nray_test = 'auto'\n",
        "estimation.ray_test",
        "true or false",
    ),
    "estimation contractor": (
        "[estimation]\ncontractor = 1\n",
        "estimation.contractor",
        "true or false",
    ),
    "estimation shave rounds": (
        "[estimation]\nshave_rounds = 9\n",
        "estimation.shave_rounds",
        "<= 8",
    ),
    "estimation tighten levels": (
        "[estimation]\ntighten_levels = 13\n",
        "estimation.tighten_levels",
        "<= 12",
    ),
    "estimation eps cells": (
        "[estimation]\neps_cells = -1\n",
        "estimation.eps_cells",
        ">= 0",
    ),
    "estimation typo": ("[estimation]\nqmax = 2\n", "estimation.qmax", "did you mean 'q_max'"),
    "free space with lost echoes": (
        "[sensors.sonar]\nlost_echo_prob = 0.1\n[estimation]\nfree_space = true\n",
        "estimation.free_space",
        "unsound",
    ),
    "profile too fast": (
        "[[route.profile]]\nduration_s = 1\nv_m_s = 9.0\n",
        "route.profile[0].v_m_s",
        "must be <=",
    ),
    "waypoint outside": (
        "[route]\nwaypoints_m = [[2, 2], [12, 2]]\n",
        "route.waypoints_m[1]",
        "outside",
    ),
    "run not a table": ("run = 5\n", "run", "must be a table"),
    "follow not a choice": (
        "[route]\nwaypoints_m = [[5, 2]]\nfollow = 'map'\n",
        "route.follow",
        "must be one of 'truth', 'estimate', 'ukf_only'",
    ),
    "follow without waypoints": (
        "[route]\nfollow = 'estimate'\n[[route.profile]]\nduration_s = 1\nv_m_s = 0.1\nomega_rad_s = 0\n",
        "route.follow",
        "needs waypoints_m",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_settings_are_refused_naming_file_and_key(case):
    text, key, reason = BAD[case]
    error = refused(_merge(BASE, text))
    assert error.source == "test.toml"
    assert error.key == key
    assert reason in error.reason
    assert str(error).startswith(f"test.toml: {key}: ")


def _merge(base: str, extra: str) -> str:
    """``base`` with ``extra``'s lines added (a ``[robot]`` extra goes into base's robot
    table, top-level keys go first)."""
    if not extra.startswith("["):
        return extra + base
    if extra.startswith("[robot]\n"):
        return base + extra[len("[robot]\n") :]
    return base + extra


def test_estimation_defaults_and_values():
    spec = parse(BASE)
    limits = TrackerSettings(spec.robot.v_max_m_s, spec.robot.omega_max_rad_s)
    assert spec.estimation == EstimationSpec(intervals=limits, free_space=True)
    assert spec.estimation.intervals.q_max == 1  # the documented default, the tracker's own
    assert spec.estimation.scan_stride(spec.sensors.sonar.rate_hz) == 1
    lossy = parse(BASE + "[sensors.sonar]\nlost_echo_prob = 0.1\nrate_hz = 2.0\n")
    assert lossy.estimation.free_space is False and lossy.estimation.interval_rate_hz == 2.0
    text = (
        "[sensors.sonar]\nrate_hz = 4.0\n[estimation]\nfilter = 'iekf'\ntracker = 'imagesp'\n"
        "fusion = 'clamp_heading'\neps_m = 0.1\nq_max = 3\nguaranteed = false\ninterval_rate_hz = 1.0\n"
        "free_space = false\nray_test = true\n"
    )
    est = parse(BASE + text).estimation
    tracker = est.intervals
    assert (
        est.dead_reckoning.filter,
        tracker.tracker,
        est.fusion,
        tracker.eps_m,
        tracker.q_max,
    ) == (
        "iekf",
        "imagesp",
        "clamp_heading",
        0.1,
        3,
    )
    assert est.scan_stride(4.0) == 4 and est.free_space is False and tracker.guaranteed is False
    assert tracker.ray_test is True and spec.estimation.intervals.ray_test is None  # by aperture
    assert spec.estimation.intervals.contractor is True  # on by default
    assert (
        parse(BASE + "[estimation]\ncontractor = false\n").estimation.intervals.contractor is False
    )
    assert spec.estimation.intervals.shave_rounds == 0  # off by default
    assert parse(BASE + "[estimation]\nshave_rounds = 2\n").estimation.intervals.shave_rounds == 2
    assert spec.estimation.intervals.tighten_levels == 0  # off by default
    tightened = parse(BASE + "[estimation]\ntighten_levels = 9\n").estimation.intervals
    assert tightened.tighten_levels == 9
    assert spec.estimation.intervals.eps_cells == 8  # large sets paved at their own scale
    assert parse(BASE + "[estimation]\neps_cells = 0\n").estimation.intervals.eps_cells == 0
    assert (tracker.v_max_m_s, tracker.omega_max_rad_s) == (0.6, 1.5)  # the robot's limits


def test_empty_map_is_refused():
    error = refused("[map]\nsegments = []\n[robot]\nstart_xy_m = [1, 1]\n")
    assert error.key == "map.segments" and "empty" in error.reason


def test_nan_in_a_segment_is_refused():
    error = refused("[map]\nsegments = [[[0, 0], [1, nan]]]\n[robot]\nstart_xy_m = [1, 1]\n")
    assert error.key == "map.segments[0][1][1]" and "finite" in error.reason


def test_start_outside_the_outer_wall_is_refused(tmp_path):
    (tmp_path / "room.wkt").write_text("POLYGON ((0 0, 6 0, 6 5, 0 5, 0 0))")
    (tmp_path / "s.toml").write_text('[map]\nfile = "room.wkt"\n[robot]\nstart_xy_m = [7, 2]\n')
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "s.toml")
    assert info.value.key == "robot.start_xy_m" and "outside" in info.value.reason


def test_start_overlapping_a_wall_is_refused():
    error = refused(BASE.replace("[2.0, 2.0]", "[0.05, 2.0]"))
    assert error.key == "robot.start_xy_m" and "overlaps wall" in error.reason


def test_missing_start_is_refused():
    error = refused(BASE.replace("start_xy_m = [2.0, 2.0]", ""))
    assert error.key == "robot.start_xy_m" and "missing" in error.reason


def test_missing_files(tmp_path):
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "nope.toml")
    assert info.value.source == str(tmp_path / "nope.toml") and "no such file" in info.value.reason
    (tmp_path / "s.toml").write_text('[map]\nfile = "absent.wkt"\n[robot]\nstart_xy_m = [1, 1]\n')
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "s.toml")
    assert info.value.key == "map.file" and "no such file" in info.value.reason


def test_invalid_toml_names_the_line():
    error = refused("[run\nseed = 1\n")
    assert "not valid TOML" in error.reason and "line 1" in error.reason


def test_run_overrides_are_checked_against_the_run_bounds():
    spec = parse(BASE)
    assert spec.with_run(seed=3, duration_s=2.5).run.seed == 3
    for changes, key, reason in (
        ({"duration_s": float("nan")}, "run.duration_s", "must be finite"),
        ({"seed": -1}, "run.seed", "must be >= 0, got -1"),
        ({"duration_s": 1e-9}, "run.duration_s", "shorter than one sample"),
        ({"duration_s": 1e300}, "run.duration_s", "more than the 1e+07"),
    ):
        with pytest.raises(ScenarioError) as refusal:
            spec.with_run(**changes)
        assert (refusal.value.source, refusal.value.key) == (None, key)
        assert reason in refusal.value.reason


def test_the_sample_limit_and_the_sonar_beat_admit_the_edges():
    at_limit = parse(BASE + "[run]\nduration_s = 1e5\nrate_hz = 100\n")
    assert at_limit.run.duration_s * at_limit.run.rate_hz == MAX_SAMPLES
    same_rate = parse(BASE + "[run]\nrate_hz = 10\n[sensors.sonar]\nrate_hz = 10\n")
    assert same_rate.sensors.sonar.rate_hz == same_rate.run.rate_hz
    assert (
        parse(BASE + "[sensors.sonar]\nrate_hz = 4\n").sensors.sonar.rate_hz == 4.0
    )  # 25 samples a scan
    edge = parse(BASE + "[estimation]\nq_max = 15\neps_m = 1e-3\n").estimation.intervals
    assert edge.q_max == 15 and edge.eps_m == 1e-3


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("room.wkt", "MULTILINESTRING ((0 0, 6 0, 6 5), (6 5, 0 5, 0 0))"),
        (
            "room.geojson",
            '{"type": "LineString", "coordinates": [[0, 0], [6, 0], [6, 5], [0, 5], [0, 0]]}',
        ),
    ],
)
def test_a_room_of_line_strings_has_an_outer_wall_for_the_start_and_waypoints(tmp_path, name, text):
    (tmp_path / name).write_text(text)
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'[map]\nfile = "{name}"\n[robot]\nstart_xy_m = [7, 2]\n')
    with pytest.raises(ScenarioError) as info:
        load_scenario(scenario)
    assert info.value.key == "robot.start_xy_m" and "outside" in info.value.reason
    scenario.write_text(
        f'[map]\nfile = "{name}"\n[robot]\nstart_xy_m = [3, 2]\n[route]\nwaypoints_m = [[3, 2], [8, 2]]\n'
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(scenario)
    assert info.value.key == "route.waypoints_m[1]" and "outside" in info.value.reason
