"""``robotsim reproduce estimators``: the campaign's inputs, and a quick run end to end."""

from __future__ import annotations

import tomllib

import numpy as np
import pyarrow.parquet as pq
import pytest

from scenarios.cli import main
from scenarios.reproduce import estimators
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
    table = (out / "estimators.md").read_text()
    for estimator in estimators.ESTIMATORS:
        assert (
            f"| hall | {estimator} | 2 |" in table and f"| hall_faults | {estimator} | 2 |" in table
        )
    for name in ("estimators.png", "report/errors.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "inputs" / "estimators.toml").is_file()
