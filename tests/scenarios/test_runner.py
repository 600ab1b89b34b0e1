"""One run of a scenario: deterministic by seed, and its summary agrees with the log."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenarios.runner import run_scenario
from scenarios.spec import builtin_names, load_scenario


@pytest.fixture(scope="module")
def hall_runs():
    spec = load_scenario("hall").with_run(duration_s=20.0)
    return run_scenario(spec), run_scenario(spec), run_scenario(spec.with_run(seed=1))


def test_same_scenario_and_seed_give_the_same_summary_and_log(hall_runs):
    first, again, _ = hall_runs
    assert json.dumps(first.summary) == json.dumps(again.summary)
    for name in ("pose", "wheel_ticks", "gyro_rad_s", "accel_m_s2", "sonar_range_m"):
        np.testing.assert_array_equal(getattr(first.log, name), getattr(again.log, name))
    with_timing = first.summary_with_timing(recording_s=0.1, wall_s=0.5)
    assert {k: v for k, v in with_timing.items() if k != "timing"} == first.summary
    assert with_timing["timing"]["realtime_factor"] == pytest.approx(20.0 / 0.5)


def test_another_seed_changes_the_sensors_but_not_the_truth(hall_runs):
    first, _, other = hall_runs
    assert other.summary["seed"] == 1
    assert other.summary["sensors"] != first.summary["sensors"]
    # the noise does not steer the robot (the controller sees the true pose)
    np.testing.assert_array_equal(first.log.pose, other.log.pose)
    assert not np.array_equal(first.log.gyro_rad_s, other.log.gyro_rad_s)


def test_summary_figures_match_the_log(hall_runs):
    run = hall_runs[0]
    summary, log = run.summary, run.log
    assert summary["samples"] == len(log.t_s) and summary["scans"] == len(log.sonar_t_s)
    steps = np.linalg.norm(np.diff(log.pose[:, :2], axis=0), axis=1)
    assert summary["distance_m"] == pytest.approx(steps.sum())
    assert summary["distance_m"] > 0.5 * 0.4 * 20.0  # the route was followed at cruise speed
    sonar = summary["sensors"]["sonar"]
    assert sonar["readings"] == log.sonar_range_m.size
    assert sonar["echoes"] == np.isfinite(log.sonar_range_m).sum() > 0
    assert 0.0 < sonar["error_bound_share_max"] <= 1.0
    assert summary["sensors"]["encoders"]["ticks_total"] == log.wheel_ticks.sum(axis=0).tolist()


@pytest.mark.parametrize("name", builtin_names())
def test_builtin_routes_stay_clear_of_the_walls_for_the_whole_run(name):
    result = run_scenario(load_scenario(name))
    walls = result.summary["walls"]
    assert walls["contact_samples"] == 0 and walls["min_gap_m"] > 0.05
    assert result.summary["distance_m"] > 0.5 * 0.3 * result.summary["duration_s"]
