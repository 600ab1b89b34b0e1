"""``robotsim report``: per-setting aggregation with Student-t intervals, and its outputs."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from scipy import stats

from scenarios.cli import EXIT_USER_ERROR, main
from scenarios.report import aggregate, confidence_interval, load_results, paired_differences


def test_confidence_interval_is_scipys_t_interval():
    values = np.random.default_rng(1).normal(3.0, 2.0, size=12)
    mean, half, n = confidence_interval(np.append(values, np.nan))
    low, high = stats.t.interval(0.95, len(values) - 1, loc=values.mean(), scale=stats.sem(values))
    assert n == 12 and np.isclose(mean, values.mean())
    assert np.isclose(mean - half, low) and np.isclose(mean + half, high)
    assert np.isnan(confidence_interval(np.array([1.0]))[1])


def results_table(path):
    """A results table of two settings x 3 seeds, one failed run."""
    rows = []
    for i, (fusion, seed) in enumerate([(f, s) for f in ("clamp", "truncated") for s in range(3)]):
        failed = fusion == "truncated" and seed == 2
        rows.append(
            {
                "run_index": i,
                "scenario": "hall",
                "seed": 100 + seed,
                "setting.estimation.fusion": fusion,
                "status": "failed" if failed else "ok",
                "error": "ScenarioError: boom" if failed else None,
                "rmse_position_m.fused": None if failed else 0.1 * (seed + 1) + (fusion == "clamp"),
                "containment": None if failed else 1.0,
                "timing.cpu_per_epoch_ms": None if failed else 5.0 + seed,
            }
        )
    pq.write_table(pa.Table.from_pylist(rows), path)


def test_aggregate_groups_by_setting_and_counts_failures(tmp_path):
    path = tmp_path / "results.parquet"
    results_table(path)
    records = {r["group"]: r for r in aggregate(load_results(tmp_path))}
    clamp, truncated = records[("hall", "clamp")], records[("hall", "truncated")]
    assert (clamp["runs"], clamp["failed"], truncated["runs"], truncated["failed"]) == (3, 0, 3, 1)
    assert np.isclose(clamp["figures"]["rmse_position_m.fused"][0], 1.2)
    assert truncated["figures"]["rmse_position_m.fused"][2] == 2  # the failed run is left out
    assert np.isclose(truncated["figures"]["rmse_position_m.fused"][0], 0.15)


def test_report_writes_its_table_and_figures_and_never_replaces_a_foreign_folder(tmp_path, capsys):
    results_table(tmp_path / "results.parquet")
    assert main(["report", str(tmp_path / "results.parquet")]) == 0
    out = tmp_path / "report"
    assert "| hall | clamp | 3 | 0 |" in (out / "report.md").read_text()
    for name in ("errors.png", "containment_area.png", "time_per_epoch.png", "kidnap_recovery.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["report", str(tmp_path)]) == 0  # a previous report is replaced

    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(["report", str(tmp_path), "--out", str(foreign)]) == EXIT_USER_ERROR
    assert "holds no report" in capsys.readouterr().err
    assert [p.name for p in foreign.iterdir()] == ["notes.txt"]

    assert main(["report", str(tmp_path / "nothing.parquet")]) == EXIT_USER_ERROR
    assert "nothing.parquet" in capsys.readouterr().err


def test_paired_differences_match_seeds_and_skip_failed_pairs(tmp_path):
    """truncated - clamp, seed by seed: 0.1 (s + 1) - (0.1 (s + 1) + 1) = -1 for seeds 0
    and 1 (seed 2 failed for truncated): two pairs, a difference of exactly -1."""
    results_table(tmp_path / "results.parquet")
    (record,) = paired_differences(load_results(tmp_path))
    assert record["group"] == ("hall", "truncated") and record["baseline"] == ("hall", "clamp")
    mean, half, n = record["figures"]["rmse_position_m.fused"]
    assert n == 2 and np.isclose(mean, -1.0) and np.isclose(half, 0.0, atol=1e-12)


def test_mcl_rows_give_the_estimate_figures_beside_the_fused_ones(tmp_path):
    """Rows of the particle filter have ``rmse_position_m.mcl`` and no fused column: the
    report's fused-or-MCL figure takes it, and the pairs compare it seed by seed."""
    rows = []
    for estimator in ("intervals", "mcl"):
        for seed in range(3):
            row = {
                "scenario": "hall",
                "seed": seed,
                "setting.estimation.estimator": estimator,
                "status": "ok",
                "kidnaps.0.t_s": 30.0,
            }
            if estimator == "mcl":
                row["rmse_position_m.mcl"] = 0.05 * (seed + 1)
                row["kidnaps.0.recovery_s"] = 4.0 if seed else None  # seed 0 never recovers
            else:
                row["rmse_position_m.fused"] = 0.02 * (seed + 1)
                row["kidnaps.0.recovery_s"] = 1.0
            rows.append(row)
    # one table per row, merged as the campaign merges its parts (the columns differ)
    merged = pa.concat_tables(
        [pa.Table.from_pylist([row]) for row in rows], promote_options="permissive"
    )
    pq.write_table(merged, tmp_path / "results.parquet")
    columns = load_results(tmp_path)
    records = {r["group"]: r for r in aggregate(columns)}
    mcl = records[("hall", "mcl")]["figures"]
    assert np.isclose(mcl["rmse_position_m.fused"][0], 0.1) and mcl["rmse_position_m.fused"][2] == 3
    assert np.isclose(mcl["kidnaps.0.recovered"][0], 2 / 3)
    assert np.isclose(mcl["kidnaps.0.recovery_s"][0], 4.0) and mcl["kidnaps.0.recovery_s"][2] == 2
    (pair,) = paired_differences(columns)
    mean, _, n = pair["figures"]["rmse_position_m.fused"]
    assert n == 3 and np.isclose(mean, 0.03 * 2)  # mean of 0.03 (s + 1) over s = 0, 1, 2
