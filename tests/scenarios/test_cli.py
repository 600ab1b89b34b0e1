"""``robotsim run`` and ``robotsim scenarios`` end to end, through the installed console script."""

from __future__ import annotations

import json
import os
import pty
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from scenarios.spec import builtin_names, load_scenario

ROBOTSIM = str(Path(sys.executable).with_name("robotsim"))

pytestmark = pytest.mark.slow  # every test runs the console script in a subprocess


def robotsim(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([ROBOTSIM, *args], cwd=cwd, capture_output=True, text=True, timeout=120)


def rows_by_entity(path: Path) -> tuple[Counter, set[str]]:
    """Rows per entity path of the recording store, and the static entities."""
    rows: Counter = Counter()
    static = set()
    for chunk in RrdReader(path).store().stream():
        rows[chunk.entity_path] += chunk.num_rows
        if chunk.is_static:
            static.add(chunk.entity_path)
    return rows, static


def test_scenarios_lists_every_builtin_with_its_description(tmp_path):
    done = robotsim("scenarios", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert [line.split()[0] for line in lines] == list(builtin_names())
    for line, name in zip(lines, builtin_names()):
        assert line.split(None, 1)[1] == load_scenario(name).description


def test_run_writes_a_recording_and_summary_that_read_back(tmp_path):
    rrd, summary_path = tmp_path / "out" / "hall.rrd", tmp_path / "out" / "hall.json"
    done = robotsim(
        "run",
        "hall",
        "--duration",
        "3",
        "--seed",
        "4",
        "--rrd",
        str(rrd),
        "--summary",
        str(summary_path),
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # not a terminal: no progress bar
    summary = json.loads(summary_path.read_text())
    assert summary["scenario"] == "hall" and summary["seed"] == 4 and summary["duration_s"] == 3.0
    samples, scans = summary["samples"], summary["scans"]
    spec = load_scenario("hall")
    assert samples == pytest.approx(3.0 * spec.run.rate_hz, abs=1)
    assert scans == pytest.approx(3.0 * spec.sensors.sonar.rate_hz, abs=1)
    assert summary["timing"]["realtime_factor"] > 0

    rows, static = rows_by_entity(rrd)
    assert {"/world/map/walls", "/world/robot/path"} <= static
    assert rows["/world/map/walls"] == 1
    for entity in (
        "/world/robot/footprint",
        "/world/robot/heading",
        "/sensors/encoders/left",
        "/sensors/encoders/right",
        "/sensors/gyro/rate_rad_s",
        "/sensors/accelerometer/x_m_s2",
        "/sensors/accelerometer/y_m_s2",
        "/truth/v_m_s",
    ):
        assert rows[entity] == samples, entity
    assert rows["/world/sonar/cones"] == scans
    assert rows["/world/sonar/echoes"] == scans
    # the localisation pipeline: one row per epoch (a scan), estimates at every 10th sample
    assert summary["epochs"] == scans and summary["containment"] == 1.0
    for entity in ("/world/intervals/boxes", "/intervals/box_width_m", "/intervals/q_used"):
        assert rows[entity] == scans, entity
    assert rows["/world/intervals/hull"] == scans + 1  # and its static style
    for branch in ("ukf_only", "fused"):
        assert rows[f"/world/estimates/{branch}/position"] == -(-samples // 10) + 1, (
            branch
        )  # + static style
        assert rows[f"/world/estimates/{branch}/ellipse"] == -(-samples // 10) + 1, branch
        assert f"/world/estimates/{branch}/path" in static
    for key in ("rmse_position_m", "rmse_heading_rad"):
        assert set(summary[key]) == {"ukf_only", "fused"}
    for key in ("ukf_step_us_median", "ia_epoch_ms_median", "ia_epoch_ms_p95", "realtime_factor"):
        assert summary["timing"][key] > 0, key
    assert len(RrdReader(rrd).blueprints()) == 1
    assert sorted(p.name for p in rrd.parent.iterdir()) == ["hall.json", "hall.rrd"]


def test_run_defaults_write_under_runs(tmp_path):
    done = robotsim("run", "--duration", "1", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    seed = load_scenario("hall").run.seed
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == [
        f"hall-seed{seed}.json",
        f"hall-seed{seed}.rrd",
    ]


BAD_FILES = {
    "unknown key": ("[run]\nduraton_s = 2\n", "run.duraton_s"),
    "negative rate": ("[run]\nrate_hz = -5\n", "run.rate_hz"),
    "empty map": ("[map]\nsegments = []\n", "map.segments"),
    "NaN": ("[run]\nduration_s = nan\n", "run.duration_s"),
}


@pytest.mark.parametrize("case", [*sorted(BAD_FILES), "missing file"])
def test_bad_scenarios_exit_2_with_one_line_and_no_output(tmp_path, case):
    scenario = tmp_path / "bad.toml"
    if case in BAD_FILES:
        text, key = BAD_FILES[case]
        scenario.write_text(text + "[robot]\nstart_xy_m = [1.0, 1.0]\n")
        expected = f"robotsim: error: {scenario}: {key}: "
    else:
        expected = f"robotsim: error: {scenario}: no such file"
    out = tmp_path / "out"
    done = robotsim(
        "run",
        str(scenario),
        "--rrd",
        str(out / "x.rrd"),
        "--summary",
        str(out / "x.json"),
        cwd=tmp_path,
    )
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and done.stderr.startswith(expected), done.stderr
    assert not out.exists() or not any(out.iterdir())
    assert not (tmp_path / "runs").exists()


def test_a_failing_output_leaves_no_file(tmp_path):
    summary_dir = tmp_path / "taken"
    summary_dir.mkdir()  # the summary cannot replace a folder: the run fails at the very end
    rrd = tmp_path / "x.rrd"
    done = robotsim(
        "run", "--duration", "1", "--rrd", str(rrd), "--summary", str(summary_dir), cwd=tmp_path
    )
    assert done.returncode != 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]
    assert not any(summary_dir.iterdir())


def test_a_terminal_gets_a_progress_bar(tmp_path):
    controller, terminal = pty.openpty()
    try:
        done = subprocess.run(
            [ROBOTSIM, "run", "--duration", "1", "--rrd", "x.rrd", "--summary", "x.json"],
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=terminal,
            text=True,
            timeout=120,
        )
        os.close(terminal)
        terminal = None
        shown = b""
        while chunk := _read_or_none(controller):
            shown += chunk
    finally:
        if terminal is not None:
            os.close(terminal)
        os.close(controller)
    assert done.returncode == 0
    bar = shown.decode()
    assert "hall-seed0 [" in bar and bar.rstrip().endswith("100%")
    assert bar.index("  0%") < bar.index("100%")


def _read_or_none(fd: int) -> bytes:
    try:
        return os.read(fd, 4096)
    except OSError:  # Linux reports the end of a closed pty as EIO
        return b""


@pytest.mark.parametrize("taken", ["--rrd", "--summary"])
def test_an_output_at_a_folder_is_refused_before_running_and_writes_nothing(tmp_path, taken):
    folder = tmp_path / "taken"
    folder.mkdir()
    paths = {"--rrd": tmp_path / "x.rrd", "--summary": tmp_path / "x.json", taken: folder}
    done = robotsim(
        "run",
        "--duration",
        "1",
        "--rrd",
        str(paths["--rrd"]),
        "--summary",
        str(paths["--summary"]),
        cwd=tmp_path,
    )
    assert done.returncode == 2
    assert done.stderr == f"robotsim: error: {taken}: {folder} exists and is not a file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"] and not any(folder.iterdir())


def test_the_same_file_for_recording_and_summary_is_refused(tmp_path):
    done = robotsim(
        "run", "--duration", "1", "--rrd", "out.x", "--summary", "./out.x", cwd=tmp_path
    )
    assert done.returncode == 2
    assert done.stderr == "robotsim: error: --summary: same file as --rrd\n"
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("option", "value", "reason"),
    [
        ("--seed", "-1", "must be >= 0, got -1"),
        ("--duration", "nan", "must be finite, got nan"),
        ("--duration", "1e300", "more than the 1e+07 a run may have"),
    ],
)
def test_a_bad_override_is_blamed_on_its_option(tmp_path, option, value, reason):
    """The spec checks the values against ``[run]``'s bounds; the command names its option."""
    done = robotsim("run", option, value, cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.startswith(f"robotsim: error: {option}: ") and done.stderr.count("\n") == 1
    assert reason in done.stderr
    assert not any(tmp_path.iterdir())
