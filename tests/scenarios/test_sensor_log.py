"""The sensor log: ``robotsim run --sensor-log`` writes it, ``robotsim replay`` localises it
without the simulator and gives back the run's estimation figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from scenarios.cli import main

ROBOTSIM = str(Path(sys.executable).with_name("robotsim"))


@pytest.fixture(scope="module")
def office_log(tmp_path_factory):
    """A real ``robotsim run`` (a subprocess) that wrote its sensor log."""
    folder = tmp_path_factory.mktemp("run")
    done = subprocess.run(
        [
            ROBOTSIM,
            "run",
            "office",
            "--duration",
            "20",
            "--seed",
            "3",
            "--sensor-log",
            "run.parquet",
        ]
        + ["--rrd", "run.rrd", "--summary", "run.json"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return folder, json.loads((folder / "run.json").read_text())


@pytest.mark.slow
def test_replaying_a_runs_log_reproduces_its_estimation_figures(office_log):
    folder, summary = office_log
    done = subprocess.run(
        [ROBOTSIM, "replay", "run.parquet", "--summary", "replay.json"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    replayed = json.loads((folder / "replay.json").read_text())
    assert replayed["scenario"] == "office" and replayed["samples"] == summary["samples"] == 2001
    estimation_keys = set(replayed) - {"scenario", "samples", "scans"}
    assert {"rmse_position_m", "containment", "epoch_status", "fusion"} <= estimation_keys
    for key in estimation_keys:
        assert replayed[key] == summary[key], key


@pytest.mark.slow
def test_the_log_is_the_documented_columns(office_log):
    folder, summary = office_log
    table = pq.read_table(folder / "run.parquet")
    assert table.num_rows == summary["samples"]
    assert {
        "t_s",
        "ticks_left",
        "ticks_right",
        "gyro_rad_s",
        "accel_x_m_s2",
        "accel_y_m_s2",
    } <= set(table.column_names)
    scans = [scan for scan in table.column("sonar_range_m").to_pylist() if scan is not None]
    assert len(scans) == summary["scans"] and {len(scan) for scan in scans} == {16}
    assert (
        table.column("ticks_left").to_numpy().sum()
        == summary["sensors"]["encoders"]["ticks_total"][0]
    )


@pytest.mark.slow
def test_another_estimation_table_changes_the_replay(office_log, tmp_path, capsys):
    folder, summary = office_log
    coarse = tmp_path / "coarse.toml"
    coarse.write_text("[estimation]\neps_m = 0.2\n")
    assert main(["replay", str(folder / "run.parquet"), "--estimation", str(coarse)]) == 0
    replayed = json.loads(capsys.readouterr().out)
    assert replayed["containment"] == 1.0
    assert replayed["box"]["mean_area_m2"] > summary["box"]["mean_area_m2"]


@pytest.mark.slow
def test_bad_inputs_are_refused_in_one_line(office_log, tmp_path, capsys):
    folder, _ = office_log
    log = str(folder / "run.parquet")
    cases = {
        "other table": ("[run]\nseed = 1\n", "other.toml: run: only an [estimation] table"),
        "bad key": ("[estimation]\neps_m = -1\n", "bad.toml: estimation.eps_m: "),
    }
    for name, (text, message) in cases.items():
        path = tmp_path / message.split(":")[0]
        path.write_text(text)
        assert main(["replay", log, "--estimation", str(path)]) == 2, name
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and message in err, err
    table = pq.read_table(log).drop_columns(["gyro_rad_s"])
    pq.write_table(table, tmp_path / "no-gyro.parquet")
    assert main(["replay", str(tmp_path / "no-gyro.parquet")]) == 2
    assert "gyro_rad_s: missing column" in capsys.readouterr().err
    existing = tmp_path / "summary.json"
    existing.mkdir()
    assert main(["replay", log, "--summary", str(existing)]) == 2  # a folder is not overwritten
    assert existing.is_dir()
