"""``[estimation] estimator = "mcl"``: the particle filter as a scenario's estimator.

The settings read and refused (file, key, reason), the odometry carry between updates
against SE(2) matrices, the summary under the interval pipeline's metric names, convergence
on hall from a uniform prior over several seeds, and ``robotsim run hall_mcl`` end to end
with its recording read back.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from localization.mcl import BeamCombination, MclSettings
from scenarios.errors import ScenarioError
from scenarios.mcl_pipeline import MCL_BRANCH, Estimator, MclEstimation, carried_poses
from scenarios.runner import run_scenario
from scenarios.spec import Follow, follow_for_estimator, load_scenario, parse_scenario
from tests.helpers import annotation_labels, recording_columns

ROBOTSIM = str(Path(sys.executable).with_name("robotsim"))

BASE = """
[robot]
start_xy_m = [0.9, 1.0]
[route]
waypoints_m = [[5.0, 1.0], [9.0, 3.5]]
"""


def parse(extra: str):
    return parse_scenario(BASE + extra, source="mcl.toml")


def refused(extra: str) -> ScenarioError:
    with pytest.raises(ScenarioError) as caught:
        parse(extra)
    return caught.value


# -- the settings ---------------------------------------------------------------------


def test_mcl_settings_are_read_into_mcl_settings():
    spec = parse(
        """
[estimation]
estimator = "mcl"
[estimation.mcl]
alpha1 = 0.05
z_hit = 0.9
sigma_hit_m = 0.1
beam_combination = "amcl_cube"
min_particles = 100
max_particles = 4000
update_min_a_deg = 10.0
recovery_alpha_slow = 0.001
recovery_alpha_fast = 0.1
"""
    )
    assert spec.estimation.estimator == Estimator.MCL
    expected = MclSettings(
        alpha1=0.05,
        z_hit=0.9,
        sigma_hit_m=0.1,
        beam_combination=BeamCombination.AMCL_CUBE,
        min_particles=100,
        max_particles=4000,
        update_min_a_rad=math.radians(10.0),
        recovery_alpha_slow=0.001,
        recovery_alpha_fast=0.1,
    )
    assert spec.estimation.mcl == expected


def test_the_default_estimator_is_the_interval_pipeline_with_default_mcl_settings():
    spec = parse("")
    assert spec.estimation.estimator == Estimator.INTERVALS
    assert spec.estimation.mcl == MclSettings()


@pytest.mark.parametrize(
    ("extra", "key", "reason"),
    [
        ('[estimation]\nestimator = "pf"', "estimation.estimator", "mcl"),
        ("[estimation.mcl]\nsigma_hit = 0.1", "estimation.mcl.sigma_hit", "sigma_hit_m"),
        ("[estimation.mcl]\nz_hit = -1.0", "estimation.mcl.z_hit", ">= 0"),
        ("[estimation.mcl]\nmax_particles = 2.5", "estimation.mcl.max_particles", "integer"),
        (
            "[estimation.mcl]\nmin_particles = 600\nmax_particles = 500",
            "estimation.mcl.min_particles",
            "min_particles <= max_particles",
        ),
        (
            "[estimation.mcl]\nrecovery_alpha_slow = 0.2\nrecovery_alpha_fast = 0.1",
            "estimation.mcl.recovery_alpha_slow",
            "recovery_alpha_slow < recovery_alpha_fast",
        ),
        ('[estimation]\nestimator = "mcl"\n[route]\nfollow = "estimate"', "route.follow", "mcl"),
    ],
)
def test_bad_mcl_settings_are_refused_naming_file_key_and_reason(extra, key, reason):
    text = extra
    if "[route]" in extra:  # the follow key belongs in the base's [route] table
        text = extra.replace('\n[route]\nfollow = "estimate"', "")
        with pytest.raises(ScenarioError) as caught:
            parse_scenario(BASE + 'follow = "estimate"\n' + text, source="mcl.toml")
        error = caught.value
    else:
        error = refused(text)
    assert error.source == "mcl.toml" and error.key == key and reason in error.reason, error


def test_mcl_keys_can_be_set_one_level_down_as_a_campaign_grid_does():
    spec = load_scenario("hall")
    changed = spec.with_estimation(estimator="mcl", **{"mcl.max_particles": 5000})
    assert changed.estimation.estimator == Estimator.MCL
    assert changed.estimation.mcl.max_particles == 5000
    with pytest.raises(ScenarioError, match=r"mcl\.bogus"):
        spec.with_estimation(**{"mcl.bogus": 1})


def test_an_mcl_run_follows_the_truth_whether_read_from_a_file_or_switched_in_code():
    """One rule (``follow_for_estimator``) for both ways of asking for MCL: the waypoints of
    ``BASE`` give a closed loop by default, which MCL cannot steer."""
    closed = parse("")
    assert closed.follow == Follow.ESTIMATE
    from_file = parse('[estimation]\nestimator = "mcl"')
    switched = closed.with_estimation(estimator="mcl")
    assert from_file.follow == switched.follow == Follow.TRUTH
    assert closed.with_estimation(fusion="truncated").follow == Follow.ESTIMATE
    for follow in Follow:
        assert follow_for_estimator(follow, Estimator.MCL) == Follow.TRUTH
        assert follow_for_estimator(follow, Estimator.INTERVALS) == follow


# -- the estimate between updates -----------------------------------------------------


def se2(pose: np.ndarray) -> np.ndarray:
    x, y, theta = pose
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def test_carried_poses_compose_the_update_estimate_with_the_odometry_since():
    rng = np.random.default_rng(4)
    odom = np.column_stack([rng.normal(0, 3, 50), rng.normal(0, 3, 50), rng.uniform(-3, 3, 50)])
    update_index = np.array([0, 7, 20, 41])
    mean = np.column_stack([rng.uniform(0, 9, 4), rng.uniform(0, 7, 4), rng.uniform(-3, 3, 4)])
    carried = carried_poses(mean, odom[update_index], odom, update_index)
    for k in range(50):
        u = np.searchsorted(update_index, k, side="right") - 1
        direct = se2(mean[u]) @ np.linalg.inv(se2(odom[update_index[u]])) @ se2(odom[k])
        np.testing.assert_allclose(carried[k, :2], direct[:2, 2], atol=1e-9)
        heading = math.atan2(direct[1, 0], direct[0, 0])
        assert abs((carried[k, 2] - heading + math.pi) % (2 * math.pi) - math.pi) < 1e-9
    # at an update the estimate is the update's own
    np.testing.assert_allclose(carried[update_index, :2], mean[:, :2], atol=1e-12)


# -- runs -----------------------------------------------------------------------------


def position_error(result) -> np.ndarray:
    return np.hypot(*(result.estimation.pose[:, :2] - result.log.pose[:, :2]).T)


def test_mcl_summary_uses_the_pipeline_metric_names_and_is_deterministic():
    spec = load_scenario("hall_mcl").with_run(duration_s=12.0, seed=5)
    first, again = run_scenario(spec), run_scenario(spec)
    assert first.summary == again.summary
    summary = first.summary
    assert summary["estimator"] == "mcl" and isinstance(first.estimation, MclEstimation)
    truth, estimate = first.log.pose, first.estimation.pose
    rmse = math.sqrt(np.mean(np.sum((estimate[:, :2] - truth[:, :2]) ** 2, axis=1)))
    assert summary["rmse_position_m"] == {MCL_BRANCH: pytest.approx(rmse, rel=1e-12)}
    assert set(summary["nees"]) == {MCL_BRANCH}
    assert summary["nees"][MCL_BRANCH]["pose"]["dof"] == 3
    assert summary["epochs"] == summary["mcl"]["updates"] == first.estimation.updates > 0
    assert "containment" not in summary  # no interval sets: no containment to claim


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_mcl_converges_on_hall_from_a_uniform_prior(seed):
    """From a prior spread over the whole hall, the estimate is within 0.3 m and 0.15 rad of
    the truth at every sample after 20 s (the bound holds from the first few updates on)."""
    result = run_scenario(load_scenario("hall_mcl").with_run(duration_s=45.0, seed=seed))
    late = result.log.t_s >= 20.0
    heading = np.abs(
        (result.estimation.pose[:, 2] - result.log.pose[:, 2] + math.pi) % (2 * math.pi) - math.pi
    )
    assert position_error(result)[late].max() < 0.3
    assert heading[late].max() < 0.15
    # the prior was spread over the hall (10 x 8 m), not told the start
    prior = result.estimation.particles[: result.estimation.shown_count[0]]
    assert result.estimation.particle_count[0] == 10_000
    assert np.ptp(prior[:, 0]) > 8.0 and np.ptp(prior[:, 1]) > 6.0


@pytest.mark.slow
def test_robotsim_run_with_mcl_writes_a_recording_with_the_particles_and_the_mcl_series(
    tmp_path,
):
    done = subprocess.run(
        [ROBOTSIM, "run", "hall_mcl", "--duration", "15", "--rrd", "m.rrd", "--summary", "m.json"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "m.json").read_text())
    assert summary["estimator"] == "mcl" and summary["rmse_position_m"]["mcl"] < 1.0
    data = recording_columns(tmp_path / "m.rrd")
    updates = summary["mcl"]["updates"]
    particles = data[("/world/mcl/particles", False)]["Points2D:positions"]
    assert len(particles) == updates + 1  # the prior and every update
    assert all(0 < len(row) <= 300 for row in particles)
    for entity in ("/world/estimates/mcl/position", "/errors/position_m/mcl"):
        assert (entity, False) in data, entity
    assert ("/mcl/particles", False) in data
    assert "MCL" in annotation_labels(data)
    assert not any(entity.startswith("/world/intervals") for entity, _ in data)


@pytest.mark.slow
def test_robotsim_run_refuses_a_bad_mcl_key_with_one_line_and_exit_2(tmp_path):
    scenario = tmp_path / "bad.toml"
    scenario.write_text(BASE + '[estimation]\nestimator = "mcl"\n[estimation.mcl]\nkld_err = 0\n')
    done = subprocess.run(
        [ROBOTSIM, "run", str(scenario)], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1
    assert f"{scenario}: estimation.mcl.kld_err: " in done.stderr and "> 0" in done.stderr
    assert list(tmp_path.iterdir()) == [scenario]  # nothing written
