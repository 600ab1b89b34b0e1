"""The README's scenario documentation: its example parses and runs, and its key tables list
every parameter with the default the code really uses."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from intervals.tracker import TrackerSettings
from robotsim.control import Route
from robotsim.robot import RobotParams
from robotsim.sensors.encoders import EncoderParams
from robotsim.sensors.imu import AccelerometerParams, GyroParams
from robotsim.sensors.sonar import SonarBeltParams
from scenarios.runner import run_scenario
from scenarios.spec import EstimationSpec, RunSpec, parse_scenario

README = Path(__file__).resolve().parents[2] / "README.md"


def format_section() -> str:
    text = README.read_text(encoding="utf-8")
    start = text.index("## Scenario file format")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else None]


def key_tables() -> dict[str, dict[str, str]]:
    """``{"[table]": {key: default as written}}`` from the section's markdown tables."""
    tables: dict[str, dict[str, str]] = {}
    current = None
    for line in format_section().splitlines():
        heading = re.match(r"^`(\[[a-z.]+\])`", line)
        if heading:
            current = tables.setdefault(heading.group(1), {})
        row = re.match(r"^\| `([a-z0-9_]+)` \|\s*([^|]*?)\s*\|", line)
        if row and current is not None:
            current[row.group(1)] = row.group(2).strip().strip("`")
    return tables


def test_the_example_parses_and_runs():
    example = re.search(r"```toml\n(.*?)```", format_section(), re.S).group(1)
    spec = parse_scenario(example, source="README.md")
    assert spec.run.seed == 7 and spec.sensors.sonar.outlier_prob == 0.02
    assert spec.map.boundary is not None  # the inline outer wall was recognised
    assert isinstance(spec.plan, Route) and spec.plan.loop
    result = run_scenario(spec.with_run(duration_s=10.0))
    assert result.summary["walls"]["contact_samples"] == 0
    assert result.summary["distance_m"] > 2.0


ROBOT = RobotParams()
DOCUMENTED = {
    "[run]": RunSpec(),
    "[robot]": ROBOT,
    "[route]": Route(waypoints_m=[[0.0, 0.0]]),
    "[sensors.encoders]": EncoderParams(),
    "[sensors.gyro]": GyroParams(),
    "[sensors.accelerometer]": AccelerometerParams(),
    "[sensors.sonar]": SonarBeltParams.default_belt(robot_radius_m=RobotParams().radius_m),
    "[estimation]": EstimationSpec(
        intervals=TrackerSettings(ROBOT.v_max_m_s, ROBOT.omega_max_rad_s)
    ),
}


def documented_keys(defaults) -> dict:
    """The keys a table takes and their defaults: the record's fields, or for ``[estimation]``
    the keys of the records it holds."""
    if isinstance(defaults, EstimationSpec):
        return defaults.as_keys()
    return {f.name: getattr(defaults, f.name) for f in dataclasses.fields(defaults)}


@pytest.mark.parametrize("table", sorted(DOCUMENTED))
def test_every_parameter_is_documented_with_its_true_default(table):
    rows = key_tables()[table]
    defaults = documented_keys(DOCUMENTED[table])
    fields = set(defaults)
    assert fields <= set(rows), f"undocumented in {table}: {fields - set(rows)}"
    checked = 0
    for key, written in rows.items():
        if not written or written.startswith("*") or key not in defaults:
            continue
        value = defaults[key]
        if isinstance(value, bool):
            assert written == str(value).lower(), key
        elif isinstance(value, np.ndarray):
            continue
        elif isinstance(value, str):
            assert written == f'"{value}"', key
        else:
            assert float(written) == pytest.approx(value, rel=1e-3), key
        checked += 1
    assert checked >= len(fields) // 2
