"""Physical bounds declared beside the settings' fields: every number a scenario file may give
stays in range, and a value beyond a declared bound is refused naming the file and the key.

Issue 12 item 6 (and the OverflowErrors of item 5): before the bounds, ``wheel_radius_m = 1e300``
and a gyro noise of ``1e200`` ended in an ``OverflowError`` traceback, ``mass_kg = 1e-300`` and
``wheel_radius_m = 1e10`` "succeeded" with a robot that never moved, ``2^62`` ticks per
revolution overflowed the int64 tick counters, and a huge accelerometer bias gave "Gaussian:
mean or cov is not finite" with no file or key.
"""

from __future__ import annotations

import dataclasses
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from intervals.tracker import TrackerSettings
from robotsim.control import Route
from robotsim.errors import RobotsimError
from robotsim.robot import RobotParams
from robotsim.sensors.encoders import EncoderParams
from robotsim.sensors.imu import AccelerometerParams, GyroParams
from robotsim.sensors.sonar import SonarBeltParams
from scenarios.errors import ScenarioError
from scenarios.runner import run_scenario
from scenarios.spec import TRACKER_KEYS, EstimationSpec, RunSpec, parse_scenario
from validated_records import declared_bounds

ROBOTSIM = str(Path(sys.executable).with_name("robotsim"))

BASE = """
[map]
builtin = "hall"
[run]
duration_s = 3
"""
START = "[robot]\nstart_xy_m = [3.0, 3.0]\n"

#: The defects of issue 12, each a table, key and value, and the bound that now refuses it.
DEFECTS = {
    "huge wheel radius": ("robot", "wheel_radius_m", "1e300", "must be <= 1, got 1e+300"),
    "huge gyro noise": (
        "sensors.gyro",
        "noise_density_rad_s_sqrt_hz",
        "1e200",
        "must be <= 1, got 1e+200",
    ),
    "feather mass": ("robot", "mass_kg", "1e-300", "must be >= 0.1, got 1e-300"),
    "giant nominal wheel": ("robot", "wheel_radius_m", "1e10", "must be <= 1, got 1e+10"),
    "int64 ticks": (
        "robot",
        "ticks_per_rev",
        str(2**62),
        f"must be <= 16777216, got {2**62}",
    ),
    "a belt of 2^62 sonars": ("sensors.sonar", "count", str(2**62), f"must be <= 64, got {2**62}"),
    "huge accelerometer bias": (
        "sensors.accelerometer",
        "turn_on_bias_std_m_s2",
        "1e200",
        "must be <= 10, got 1e+200",
    ),
}


def scenario_text(table: str, key: str, value: str) -> str:
    """The base scenario with ``table.key = value`` (the robot table always present)."""
    if table == "robot":
        return BASE + START + f"{key} = {value}\n"
    return BASE + START + f"[{table}]\n{key} = {value}\n"


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(DEFECTS))
def test_each_defect_of_issue_12_exits_2_with_one_line_naming_file_and_key(tmp_path, case):
    table, key, value, reason = DEFECTS[case]
    scenario = tmp_path / "extreme.toml"
    scenario.write_text(scenario_text(table, key, value))
    rrd, summary = tmp_path / "out.rrd", tmp_path / "out.json"
    done = subprocess.run(
        [ROBOTSIM, "run", str(scenario), "--rrd", str(rrd), "--summary", str(summary)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr == f"robotsim: error: {scenario}: {table}.{key}: {reason}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["extreme.toml"]


@pytest.mark.parametrize("case", sorted(DEFECTS))
def test_each_defect_of_issue_12_is_refused_by_the_loader(case):
    table, key, value, reason = DEFECTS[case]
    with pytest.raises(ScenarioError) as refusal:
        parse_scenario(scenario_text(table, key, value), source="extreme.toml")
    assert (refusal.value.source, refusal.value.key, refusal.value.reason) == (
        "extreme.toml",
        f"{table}.{key}",
        reason,
    )


#: The tables the reader fills from records, with the records (and the fields they take).
READ_RECORDS = {
    "run": (RunSpec, None),
    "robot": (RobotParams, None),
    "route": (Route, None),
    "sensors.encoders": (EncoderParams, None),
    "sensors.gyro": (GyroParams, None),
    "sensors.accelerometer": (AccelerometerParams, None),
    "sensors.sonar": (SonarBeltParams, None),
    "estimation": (TrackerSettings, TRACKER_KEYS),
    "estimation ": (EstimationSpec, None),  # its own fields, same table
}


def beyond_each_bound(bounds) -> list[float | int]:
    """Values just out of ``bounds``, one per declared limit (whole numbers for integers)."""
    values: list[float] = []
    if bounds.minimum is not None:
        low = bounds.minimum
        values.append(low * 1e-3 if low > 0 else low - 1.0)
    if bounds.above is not None:
        values.append(bounds.above)
    if bounds.maximum is not None:
        values.append(bounds.maximum * 10.0 + 1.0)
    if bounds.below is not None:
        values.append(bounds.below)
    if bounds.integer:
        return [math.floor(v) if v < 1 else math.ceil(v) + 1 for v in values]
    return values


def bounded_keys() -> list[tuple[str, str, float | int]]:
    cases = []
    for table, (record, keys) in READ_RECORDS.items():
        for field in dataclasses.fields(record):
            if keys is not None and field.name not in keys:
                continue
            bounds = declared_bounds(record, field.name)
            if bounds is None:
                continue
            cases += [(table.strip(), field.name, v) for v in beyond_each_bound(bounds)]
    return cases


def test_every_read_field_declares_its_bounds():
    """A number a scenario file gives has bounds beside its field (none guessed from names)."""
    undeclared = []
    for table, (record, keys) in READ_RECORDS.items():
        hints = {f.name: f.type for f in dataclasses.fields(record)}
        for name, kind in hints.items():
            if keys is not None and name not in keys:
                continue
            if kind in ("float", "int") and declared_bounds(record, name) is None:
                undeclared.append(f"{table.strip()}.{name}")
    assert undeclared == []
    assert len(bounded_keys()) > 40


@pytest.mark.parametrize(("table", "key", "value"), bounded_keys())
def test_a_value_beyond_a_declared_bound_is_refused_naming_the_key(table, key, value):
    route = "[route]\nwaypoints_m = [[5.0, 3.0]]\n"
    body = f"{key} = {value!r}\n"
    if table == "robot":
        text = BASE + START + body + route
    elif table == "route":
        text = BASE + START + route + body
    elif table == "run":
        text = f"[map]\nbuiltin = 'hall'\n[run]\n{body}" + START + route
    else:
        text = BASE + START + route + f"[{table}]\n{body}"
    with pytest.raises(ScenarioError) as refusal:
        parse_scenario(text, source="bound.toml")
    assert refusal.value.key == f"{table}.{key}", refusal.value
    assert refusal.value.reason.startswith("must be "), refusal.value


def test_records_built_in_code_are_validated_too():
    """The same declared bounds refuse a record built without a scenario file."""
    for make, words in (
        (lambda: RobotParams(mass_kg=1e-300), "RobotParams.mass_kg must be >= 0.1"),
        (lambda: RobotParams(ticks_per_rev=2**62), "RobotParams.ticks_per_rev must be <="),
        (lambda: GyroParams(noise_density_rad_s_sqrt_hz=1e200), "noise_density_rad_s_sqrt_hz"),
        (lambda: RobotParams(ticks_per_rev=2048.0), "ticks_per_rev must be an integer"),
    ):
        with pytest.raises(RobotsimError, match=re.escape(words)):
            make()
    with pytest.raises(ScenarioError, match=re.escape("RunSpec.rate_hz must be >= 1")):
        RunSpec(rate_hz=0.5)


def test_true_wheel_radii_must_stay_near_the_nominal_one():
    """A nominal radius far from the true ones (the robot would barely move, the odometry be
    off by the ratio) is refused: the calibration error is at most 10 %."""
    with pytest.raises(ScenarioError) as refusal:
        parse_scenario(BASE + START + "wheel_radius_m = 0.5\n", source="wheel.toml")
    assert refusal.value.key == "robot.wheel_radius_m"
    assert "true_wheel_radius_left_m must be within 10% of wheel_radius_m" in refusal.value.reason
    ok = parse_scenario(
        BASE
        + START
        + "wheel_radius_m = 0.5\ntrue_wheel_radius_left_m = 0.52\ntrue_wheel_radius_right_m = 0.49\n",
        source="wheel.toml",
    )
    assert ok.robot.wheel_radius_m == 0.5


EXTREME = """
[map]
builtin = "hall"
[run]
duration_s = 3
[robot]
start_xy_m = [3.0, 3.0]
wheel_radius_m = 1.0
true_wheel_radius_left_m = 1.0
true_wheel_radius_right_m = 1.0
ticks_per_rev = 16777216
mass_kg = 10000
v_max_m_s = 10
omega_max_rad_s = 20
a_max_m_s2 = 20
[route]
waypoints_m = [[8, 3], [8, 6]]
cruise_speed_m_s = 10
[sensors.encoders]
slip_std = 1.0
[sensors.gyro]
noise_density_rad_s_sqrt_hz = 1
turn_on_bias_std_rad_s = 1
bias_random_walk_rad_s_sqrt_s = 1
[sensors.accelerometer]
noise_density_m_s2_sqrt_hz = 10
turn_on_bias_std_m_s2 = 10
bias_random_walk_m_s2_sqrt_s = 1
"""


@pytest.mark.slow
def test_a_robot_at_the_upper_bounds_runs_with_every_number_finite():
    """The bounds are where the simulator and the filter still compute: a run with every robot
    and sensor figure at its upper bound completes, its estimates finite."""
    result = run_scenario(parse_scenario(EXTREME, source="extreme.toml"))
    assert result.summary["distance_m"] > 1.0  # it moved
    assert math.isfinite(result.summary["rmse_position_m"]["ukf_only"])
    assert math.isfinite(result.summary["rmse_position_m"]["fused"])
