"""``robotsim reproduce estimators``: the campaign's inputs, and a quick run end to end."""

from __future__ import annotations

import tomllib

import numpy as np
import pyarrow.parquet as pq
import pytest
import shapely

from scenarios.cli import main
from scenarios.reproduce import estimators
from scenarios.runner import simulate_spec
from scenarios.spec import BUILTIN_FOLDER, builtin_names, load_scenario


@pytest.mark.parametrize("name", builtin_names())
def test_toml_text_reads_back_to_the_same_tables(name):
    data = tomllib.loads((BUILTIN_FOLDER / f"{name}.toml").read_text(encoding="utf-8"))
    assert tomllib.loads(estimators.toml_text(data)) == data


def test_the_faults_variant_adds_outliers_lost_echoes_and_a_kidnap_to_a_free_pose(tmp_path):
    variants = estimators.scenario_variants("office", 40.0)
    assert set(variants) == {"office", "office_faults"}
    for name, tables in variants.items():
        (tmp_path / f"{name}.toml").write_text(estimators.toml_text(tables))
    clean = load_scenario(tmp_path / "office.toml")
    faulty = load_scenario(tmp_path / "office_faults.toml")  # validated: the pose is free
    assert clean.run.duration_s == faulty.run.duration_s == 40.0
    assert clean.sensors.sonar.outlier_prob == 0.0 and not clean.kidnaps
    assert faulty.sensors.sonar.outlier_prob == estimators.FAULTS["outlier_prob"]
    assert faulty.sensors.sonar.lost_echo_prob == estimators.FAULTS["lost_echo_prob"]
    assert faulty.estimation.free_space is False  # lost echoes prove nothing
    (kidnap,) = faulty.kidnaps
    assert kidnap.t_s == 20.0
    start = np.array(faulty.start_pose[:2])
    assert np.hypot(*(np.array(kidnap.pose[:2]) - start)) > 1.0
    assert clean.estimation.mcl.max_particles == estimators.MCL_SETTINGS["max_particles"]


def variant_specs(name: str, duration_s: float, folder, *, only_obstacles: bool = False):
    """The clean and faulty specs of ``name`` (the faulty one with its obstacles alone when
    ``only_obstacles``: no sonar faults, no kidnap), read back from the files written."""
    variants = estimators.scenario_variants(name, duration_s)
    faulty = variants[f"{name}_faults"]
    if only_obstacles:
        faulty.pop("events")
        for key in estimators.FAULTS:
            faulty["sensors"]["sonar"].pop(key)
    specs = []
    for variant, tables in variants.items():
        (folder / f"{variant}.toml").write_text(estimators.toml_text(tables))
        specs.append(load_scenario(folder / f"{variant}.toml"))
    return specs


#: The plans with no room for a box beside the route (1.8 m of corridor).
NO_ROOM = ("corridor",)


@pytest.mark.parametrize("name", estimators.SCENARIOS)
def test_the_faults_variant_has_a_static_and_a_pacing_box_clear_of_the_route(name, tmp_path):
    """Validated by the loader (inside the walls, clear of the start) and, here, clear of the
    route by the robot's radius beyond the clearance: the obstacles' sweeps against the
    route's legs, recomputed from the specs. The boxes come after the plan's own obstacles
    (``apartment_lived_in``'s); a plan with no room for them gets none and says so."""
    clean, faulty = variant_specs(name, 40.0, tmp_path)
    own = clean.obstacles.items
    added = faulty.obstacles.items[len(own) :]
    for mine, kept in zip(own, faulty.obstacles.items, strict=False):
        np.testing.assert_array_equal(mine.vertices_m, kept.vertices_m)
    if name in NO_ROOM:
        assert not added and "no box" in faulty.description
        return
    assert "world.obstacles" in faulty.injected_faults
    static, pacing = added
    assert not static.moving and pacing.moving and pacing.loop
    waypoints = faulty.plan.waypoints_m
    path = np.vstack([np.array(faulty.start_pose[:2])[None], waypoints, waypoints[:1]])
    route = shapely.LineString(path)
    for obstacle in (static, pacing):
        gap = obstacle.swept().distance(route)
        assert gap >= faulty.robot.radius_m + estimators.OBSTACLE_CLEARANCE_M - 1e-9, (name, gap)
    (kidnap,) = faulty.kidnaps
    assert static.swept().distance(shapely.Point(kidnap.pose[:2])) > faulty.robot.radius_m


@pytest.mark.slow  # two 60 s simulations
def test_the_obstacles_are_seen_by_the_sonars_and_do_not_block_the_route(tmp_path):
    """On hall, the faulty variant with its obstacles alone: the robot's path is the clean
    run's, sample for sample (no contact), and the sonars' readings differ on many scans."""
    clean, obstructed = variant_specs("hall", 60.0, tmp_path, only_obstacles=True)
    assert obstructed.obstacles and not obstructed.kidnaps
    a, b = simulate_spec(clean), simulate_spec(obstructed)
    np.testing.assert_array_equal(a.pose, b.pose)
    changed = (a.sonar_range_m != b.sonar_range_m).any(axis=1)
    assert changed.mean() > 0.2, changed.mean()


@pytest.mark.slow
def test_quick_reproduction_runs_every_estimator_with_and_without_faults(tmp_path, capsys):
    out = tmp_path / "est"
    status = main(
        ["reproduce", "estimators", "--quick", "--duration", "12", "--out", str(out)]
        + ["--workers", "2"]
    )
    assert status == 0, capsys.readouterr().err
    rows = pq.read_table(out / "campaign" / "results.parquet").to_pylist()
    settings = {
        (r["scenario"], r["setting.estimation.estimator"], r["setting.estimation.fusion"])
        for r in rows
    }
    expected = {
        (scenario, "intervals", fusion)
        for scenario in ("hall", "hall_faults")
        for fusion in ("clamp", "clamp_heading", "truncated")
    } | {("hall", "mcl", "clamp"), ("hall_faults", "mcl", "clamp")}
    assert settings == expected and len(rows) == len(expected) * 2  # two seeds
    assert all(r["status"] == "ok" for r in rows)
    # the same worlds for every setting: the UKF-only branch, untouched by any fusion rule,
    # is the same digit for digit in the clamp and truncated rows of each seed
    by_key = {
        (r["scenario"], r["seed"], r["setting.estimation.fusion"], r["estimator"]): r for r in rows
    }
    for (scenario, seed, fusion, estimator), row in by_key.items():
        if estimator == "intervals" and fusion == "truncated":
            clamp = by_key[(scenario, seed, "clamp", "intervals")]
            assert row["rmse_position_m.ukf_only"] == clamp["rmse_position_m.ukf_only"]
    mcl_rows = [r for r in rows if r["setting.estimation.estimator"] == "mcl"]
    assert all(
        r["rmse_position_m.mcl"] > 0 and r["rmse_position_m.fused"] is None for r in mcl_rows
    )
    faulty = [r for r in rows if r["scenario"] == "hall_faults"]
    assert all(r["kidnaps.0.t_s"] == 6.0 for r in faulty)
    assert all(r["sensors.sonar.faults"] > 0 for r in faulty)
    faulty_spec = load_scenario(out / "inputs" / "hall_faults.toml")
    assert (
        len(faulty_spec.obstacles.items) == 2
        and not load_scenario(out / "inputs" / "hall.toml").obstacles
    )
    table = (out / "estimators.md").read_text()
    for estimator in estimators.ESTIMATORS:
        assert (
            f"| hall | {estimator} | 2 |" in table and f"| hall_faults | {estimator} | 2 |" in table
        )
    for name in ("estimators.png", "report/errors.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "inputs" / "estimators.toml").is_file()
