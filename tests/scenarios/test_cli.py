"""``robotsim run`` and ``robotsim scenarios`` end to end, through the installed console script."""

from __future__ import annotations

import json
import os
import pty
import signal
import subprocess
import sys
import time
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
    for line, name in zip(lines, builtin_names(), strict=True):
        assert line.split(None, 1)[1] == load_scenario(name).description


def test_a_reader_that_leaves_early_stops_the_listing_quietly(tmp_path):
    """``robotsim scenarios | head -1``: the pipe's read end is closed before the listing is
    written, so its write fails; the command exits as SIGPIPE would, saying nothing."""
    listing = subprocess.Popen(
        [ROBOTSIM, "scenarios"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert listing.stdout is not None and listing.stderr is not None
    listing.stdout.close()  # long before the interpreter has started and written
    stderr = listing.stderr.read()
    assert listing.wait(timeout=120) == 128 + signal.SIGPIPE
    assert stderr == ""


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


# --- issue 12: data safety and hostile input -----------------------------------------------
def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its bytes: what "untouched" is checked against."""
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def cli(*args: str, capsys) -> tuple[int, str]:
    """``robotsim ARGS`` in this process: the exit status and stderr."""
    from scenarios.cli import main

    try:
        status = main(list(args))
    except SystemExit as exit_:
        status = int(exit_.code or 0)
    return status, capsys.readouterr().err


def test_reproduce_out_replaces_only_a_folder_it_wrote(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    (tmp_path / "notes.txt").write_text("keep")
    before = tree(tmp_path)
    small = ("reproduce", "iukf-examples", "--runs", "2", "--steps", "3")
    for out, why in (
        ("mine", "not written by robotsim reproduce"),
        ("notes.txt", "not a folder"),
        (".", "current folder"),
        (str(tmp_path), "current folder"),
    ):
        status, err = cli(*small, "--out", out, capsys=capsys)
        assert status == 2, err
        assert err.startswith("robotsim: error: --out: ") and why in err and err.count("\n") == 1, (
            err
        )
        assert tree(tmp_path) == before
        assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "notes.txt"]

    assert cli(*small, "--out", "rep", capsys=capsys)[0] == 0
    first = tree(tmp_path / "rep")
    assert ".robotsim-reproduce" in first and "table.json" in first
    (tmp_path / "rep" / "stray.txt").write_text("from the last run")
    assert cli(*small, "--seed", "1", "--out", "rep", capsys=capsys)[0] == 0
    assert sorted(tree(tmp_path / "rep")) == sorted(first)  # replaced as a whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "notes.txt", "rep"]


def test_no_output_may_overwrite_an_input_of_the_run(tmp_path):
    (tmp_path / "room.wkt").write_text("POLYGON ((0 0, 6 0, 6 5, 0 5, 0 0))\n")
    scenario = tmp_path / "s.toml"
    scenario.write_text(
        '[run]\nduration_s = 1.0\n[map]\nfile = "room.wkt"\n[robot]\nstart_xy_m = [3.0, 2.5]\n'
    )
    before = tree(tmp_path)
    for option, path in (
        ("--summary", "s.toml"),
        ("--rrd", "./s.toml"),
        ("--rrd", "room.wkt"),
        ("--summary", "sub/../room.wkt"),
    ):
        other = "--rrd" if option == "--summary" else "--summary"
        done = robotsim("run", "s.toml", option, path, other, "x.out", cwd=tmp_path)
        assert done.returncode == 2, done.stderr
        assert (
            done.stderr.startswith(f"robotsim: error: {option}: ") and "is an input" in done.stderr
        )
        assert done.stderr.count("\n") == 1
        assert tree(tmp_path) == before


def test_a_full_disk_during_the_recording_is_one_line_and_leaves_nothing(tmp_path):
    """``ulimit -f``: the recording cannot be written whole. Before, rerun only logged the
    failure and a truncated .rrd was moved into place with exit 0."""
    from tests.helpers import small_file_limit

    out = tmp_path / "out"
    done = subprocess.run(
        [
            ROBOTSIM,
            "run",
            "hall",
            "--duration",
            "5",
            "--rrd",
            str(out / "h.rrd"),
            "--summary",
            str(out / "h.json"),
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=180,
        preexec_fn=small_file_limit(50_000),
    )
    assert done.returncode == 2
    assert done.stderr == f"robotsim: error: {out / 'h.rrd'}: File too large\n"
    assert list(out.iterdir()) == []


def wait_for(predicate, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.005)
    return False


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_while_writing_removes_the_temporaries(tmp_path, signum):
    """SIGTERM or SIGHUP once the outputs' temporary files exist: they are removed and the
    exit status is 128 + n (before, only SIGINT was handled: a 40 MB .part stayed)."""
    out = tmp_path / "out"
    out.mkdir()
    child = subprocess.Popen(
        [
            ROBOTSIM,
            "run",
            "hall",
            "--duration",
            "120",
            "--rrd",
            str(out / "h.rrd"),
            "--summary",
            str(out / "h.json"),
        ],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert wait_for(lambda: any(out.iterdir()) or child.poll() is not None, 170)
        child.send_signal(signum)
        _, err = child.communicate(timeout=60)
    finally:
        child.kill()
    assert child.returncode == 128 + signum, err
    assert err == f"robotsim: stopped by {signal.Signals(signum).name}\n"
    assert list(out.iterdir()) == []


def test_version():
    done = subprocess.run([ROBOTSIM, "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.startswith("robotsim ") and done.stderr == ""
    assert done.stdout.split()[1][0].isdigit()


def test_huge_monte_carlo_sizes_are_refused_in_one_line(tmp_path, capsys, monkeypatch):
    """Before: a MemoryError traceback."""
    monkeypatch.chdir(tmp_path)
    for args, key in (
        (("--runs", str(10**12)), "--runs"),
        (("--runs", "1000", "--steps", str(10**9)), "--steps"),
    ):
        status, err = cli("reproduce", "mukf-example", *args, capsys=capsys)
        assert (
            status == 2 and err.startswith(f"robotsim: error: {key}: ") and err.count("\n") == 1
        ), err
    assert not any(tmp_path.iterdir())


def test_usage_errors_are_one_line(capsys):
    for args in (["run", "--seed", "x"], ["nonsense"], [], ["reproduce"], ["run", "--bogus"]):
        status, err = cli(*args, capsys=capsys)
        assert status == 2 and err.count("\n") == 1 and err.startswith("robotsim"), (args, err)


def a_numerical_failure(args) -> int:
    """A real numerical failure of ours: a singular system given to the filters' solve."""
    import numpy as np

    from localization.linalg import solve

    solve(np.zeros((2, 3, 3)), np.ones((2, 3, 1)))
    return 0


def test_a_defect_of_the_tool_is_exit_3_with_a_crash_file(tmp_path, capsys, monkeypatch):
    """Before: an EstimationError or IntervalError printed as the user's mistake, exit 2."""
    from scenarios import commands

    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    monkeypatch.setattr(commands, "list_scenarios", a_numerical_failure)
    status, err = cli("scenarios", capsys=capsys)
    assert status == 3 and err.count("\n") == 1, err
    assert "a defect of robotsim, not of your input" in err and "NumericalError" in err
    crash = Path(err.rstrip("\n").rsplit("traceback in ", 1)[1])
    assert crash.parent == tmp_path
    report = crash.read_text()
    assert "Traceback (most recent call last)" in report and "a_numerical_failure" in report

    status, err = cli("--debug", "scenarios", capsys=capsys)
    assert status == 3 and "Traceback (most recent call last)" in err
    assert err.splitlines()[-1].startswith("robotsim: internal error")
    assert len(list(tmp_path.iterdir())) == 1  # --debug: no second crash file


def test_a_folder_given_as_the_scenario_is_called_a_folder(tmp_path, capsys):
    status, err = cli("run", str(tmp_path), capsys=capsys)
    assert status == 2 and err == f"robotsim: error: {tmp_path}: is a folder, not a scenario file\n"


def test_an_empty_or_lost_epoch_breaks_the_guarantee_without_faults():
    """Before: only ``containment < 1`` was checked; an epoch with no set passed unflagged."""
    from scenarios.commands import guarantee_failure

    spec = load_scenario("hall")
    assert spec.sensors.sonar.outlier_prob == 0.0 and spec.sensors.sonar.lost_echo_prob == 0.0
    summary = {
        "containment": 1.0,
        "empty_epochs": 2,
        "epoch_status": {"inconsistent": 1, "lost": 1},
    }
    failure = guarantee_failure(spec, summary)
    assert failure is not None and "2 epoch(s) found no set (1 inconsistent, 1 lost)" in failure
    every_epoch_empty = {**summary, "containment": None}
    assert guarantee_failure(spec, every_epoch_empty) is not None
    assert guarantee_failure(spec, {**summary, "empty_epochs": 0}) is None
