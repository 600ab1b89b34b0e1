"""``robotsim campaign``: its rows equal the same runs done one by one, whatever the executor;
a real ``kill -9`` then ``--resume`` loses no finished run and repeats none; a failing run is
recorded; a bad campaign file is refused with its file, key and reason."""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from scenarios import campaign as campaign_module
from scenarios.cli import EXIT_USER_ERROR, main
from scenarios.runner import run_scenario
from scenarios.spec import load_scenario
from tests.helpers import recording_columns

REPO = Path(__file__).resolve().parents[2]

CAMPAIGN = """
scenarios = ["hall"]
seed = 7
seeds = { first = 0, count = 2 }
duration_s = 5.0
[grid]
"estimation.fusion" = ["clamp", "truncated"]
"""


def write(folder: Path, text: str, name: str = "c.toml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def rows(results: Path) -> list[dict]:
    return pq.read_table(results).to_pylist()


def without_timing(row: dict) -> dict:
    return {k: v for k, v in row.items() if not k.startswith("timing.")}


def equal_values(a, b) -> bool:
    """Equal, with NaN equal to NaN (a float figure without data is NaN, not None)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


@pytest.fixture(scope="module")
def local_results(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("campaign")
    path = write(folder, CAMPAIGN)
    status = main(["campaign", str(path), "--out", str(folder / "out"), "--workers", "2"])
    assert status == 0
    return folder / "out" / campaign_module.RESULTS_FILE


@pytest.mark.slow
def test_campaign_rows_equal_the_same_runs_done_one_by_one(local_results):
    table = rows(local_results)
    assert [r["run_index"] for r in table] == [0, 1, 2, 3]
    assert [r["setting.estimation.fusion"] for r in table] == ["clamp", "truncated"] * 2
    # replicate i runs with child i of SeedSequence(7).spawn, for every setting
    children = np.random.SeedSequence(7).spawn(2)
    expected_seeds = [int(c.generate_state(1, np.uint64)[0]) // 2 for c in children]
    assert [r["seed"] for r in table] == [s for s in expected_seeds for _ in range(2)]
    for row in table:
        assert row["status"] == "ok" and row["error"] is None
        spec = (
            load_scenario("hall")
            .with_run(seed=row["seed"], duration_s=5.0)
            .with_estimation(fusion=row["setting.estimation.fusion"])
        )
        alone = campaign_module.flatten(run_scenario(spec).summary)
        assert alone, "the summary has figures"
        for key, value in alone.items():
            assert equal_values(row[key], value), key
        assert row["nees.fused.pose.band.1"] > row["nees.fused.pose.band.0"] > 0
        assert row["timing.cpu_s"] > 0 and row["timing.cpu_per_epoch_ms"] > 0


@pytest.mark.slow
def test_a_dask_local_cluster_gives_the_same_rows_as_the_local_pool(local_results, tmp_path):
    pytest.importorskip("distributed")
    path = write(tmp_path, CAMPAIGN)
    out = tmp_path / "out"
    status = main(
        ["campaign", str(path), "--out", str(out), "--cluster", "local", "--workers", "2"]
    )
    assert status == 0
    on_dask = [without_timing(r) for r in rows(out / campaign_module.RESULTS_FILE)]
    local = [without_timing(r) for r in rows(local_results)]
    assert len(on_dask) == len(local) == 4
    for a, b in zip(on_dask, local, strict=True):
        assert a.keys() == b.keys()
        assert all(equal_values(a[k], b[k]) for k in a), a["run_index"]


@pytest.mark.slow
def test_kill_minus_nine_then_resume_loses_no_finished_run_and_repeats_none(tmp_path):
    text = CAMPAIGN.replace("count = 2", "count = 3")  # 6 runs
    path = write(tmp_path, text)
    out = tmp_path / "out"
    command = [sys.executable, "-m", "scenarios.cli", "campaign", str(path), "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    first = subprocess.Popen(
        [*command, "--workers", "1"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # its own process group: the kill reaches its workers too
    )
    parts = out / campaign_module.PARTS_DIR
    deadline = time.monotonic() + 300
    try:
        while time.monotonic() < deadline and len(list(parts.glob("*.parquet"))) < 2:
            assert first.poll() is None, "the campaign ended before it could be killed"
            time.sleep(0.05)
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
    finished = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("*.parquet")}
    assert 2 <= len(finished) < 6
    assert not (out / campaign_module.RESULTS_FILE).exists()

    resumed = subprocess.run(
        [*command, "--resume", "--workers", "2"], env=env, capture_output=True, text=True
    )
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(finished)} already done, {6 - len(finished)} to run" in resumed.stderr
    after = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("*.parquet")}
    assert len(after) == 6
    assert all(after[name] == stamp for name, stamp in finished.items()), (
        "a finished run was redone"
    )
    assert not list(parts.glob(".*")), "no temporary part left behind"
    table = rows(out / campaign_module.RESULTS_FILE)
    assert sorted(r["run_index"] for r in table) == list(range(6))
    assert len({r["run_key"] for r in table}) == 6
    assert all(r["status"] == "ok" for r in table)


def with_failing_run(campaign, index: int):
    """``campaign`` with run ``index`` failing at run time (a setting forced past its
    validation, as a defect would let through: the tracker meets an infinite heading scale)."""
    forced = dataclasses.replace(campaign.runs[index].spec.estimation.intervals)
    object.__setattr__(forced, "heading_scale_m_per_rad", np.inf)
    spec = campaign.runs[index].spec
    broken = dataclasses.replace(
        spec, estimation=dataclasses.replace(spec.estimation, intervals=forced)
    )
    runs = list(campaign.runs)
    runs[index] = dataclasses.replace(runs[index], spec=broken)
    return dataclasses.replace(campaign, runs=tuple(runs))


def run_on_pool(campaign, out: Path) -> list[dict]:
    """The campaign's runs on the real local pool (two workers), committed to ``out``."""
    folder = campaign_module.ResultsFolder(out)
    folder.prepare(campaign, resume=False)

    def sink(batch_rows):
        for row in batch_rows:
            folder.commit(row)

    campaign_module.execute_local(campaign.runs, 2, sink)
    return rows(folder.merge(campaign))


@pytest.mark.slow
def test_a_failing_run_is_recorded_with_its_error_and_the_others_finish(tmp_path):
    """A real failure at run time on the real pool."""
    campaign = with_failing_run(campaign_module.load_campaign(write(tmp_path, CAMPAIGN)), 1)
    table = run_on_pool(campaign, tmp_path / "out")
    assert [r["status"] for r in table] == ["ok", "failed", "ok", "ok"]
    # a defect of ours, not the user's mistake: the IntervalError itself is recorded
    assert "IntervalError" in table[1]["error"] and "scale must be" in table[1]["error"]
    assert table[1]["rmse_position_m.fused"] is None
    assert (
        table[1]["seed"] == table[0]["seed"]
        and table[1]["setting.estimation.fusion"] == "truncated"
    )
    assert all(r["rmse_position_m.fused"] > 0 for r in table if r["status"] == "ok")


@pytest.mark.parametrize(
    ("edit", "key", "reason"),
    [
        (("seed = 7", "seed = 7\nsed = 1"), "sed", "unknown key"),
        (('"clamp", "truncated"', '"clamp", "bogus"'), "grid.estimation.fusion", "bogus"),
        (('"estimation.fusion"', '"run.seed"'), "grid.run.seed", "seeds come from the campaign"),
        (('"estimation.fusion"', '"robot.radius_m"'), "grid.robot.radius_m", "not a setting"),
        (("count = 2", "count = 0"), "seeds.count", ">= 1"),
        (('["hall"]', '["nowhere"]'), "scenarios[0]", "neither a built-in scenario"),
        (('["hall"]', "[]"), "scenarios", "non-empty array"),
        (('["hall"]', '["hall", "hall"]'), "scenarios", "twice"),
        (('"clamp", "truncated"', '"clamp", "clamp"'), "grid.estimation.fusion", "twice"),
        (("duration_s = 5.0", "duration_s = -1.0"), "duration_s", "> 0"),
        (("duration_s = 5.0", 'duration_s = 5.0\nrecord = "some"'), "record", "'failures'"),
        (("duration_s = 5.0", "duration_s = 5.0\nrecord = 5"), "record", "from 1 to 4, got 5"),
        (("duration_s = 5.0", "duration_s = 5.0\nrecord = true"), "record", "got True"),
    ],
)
def test_a_bad_campaign_file_is_refused_with_file_key_and_reason(
    tmp_path, capsys, edit, key, reason
):
    path = write(tmp_path, CAMPAIGN.replace(*edit))
    status = main(["campaign", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_USER_ERROR
    assert len(err.splitlines()) == 1
    assert err.startswith(f"robotsim: error: {path}: {key}: "), err
    assert reason in err, err
    assert not (tmp_path / "out").exists(), "nothing written for a refused campaign"


def test_a_bad_campaign_file_is_refused_before_a_cluster_starts(tmp_path):
    """``--cluster local`` with a bad file: the one-line refusal, and dask never imported
    (the cluster starts in a thread only once the file is read; a fresh process, since
    other tests import dask here)."""
    path = write(tmp_path, CAMPAIGN.replace("count = 2", "count = 0"))
    probe = (
        "import sys\n"
        "from scenarios.cli import main\n"
        f"status = main(['campaign', {str(path)!r}, '--cluster', 'local', '--workers', '1',"
        f" '--out', {str(tmp_path / 'out')!r}])\n"
        "print(status, 'distributed' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert done.stdout.split() == [str(EXIT_USER_ERROR), "False"], done.stderr
    assert done.stderr.strip().startswith(f"robotsim: error: {path}: seeds.count: ")
    assert not (tmp_path / "out").exists()


def test_a_folder_that_is_not_empty_is_never_written_into_without_resume(tmp_path, capsys):
    path = write(tmp_path, CAMPAIGN)
    out = tmp_path / "out"
    out.mkdir()
    mine = out / "notes.txt"
    mine.write_text("mine")
    assert main(["campaign", str(path), "--out", str(out)]) == EXIT_USER_ERROR
    assert "--out" in capsys.readouterr().err
    assert main(["campaign", str(path), "--out", str(out), "--resume"]) == EXIT_USER_ERROR
    assert "holds no campaign" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"] and mine.read_text() == "mine"


def test_flatten_joins_keys_and_list_positions_with_dots():
    tree = {"a": {"b": [1, 2], "c": None}, "d": "x"}
    assert campaign_module.flatten(tree) == {"a.b.0": 1, "a.b.1": 2, "a.c": None, "d": "x"}


def pool_workers(pid: int) -> list[int]:
    """The process-pool workers among the children of ``pid`` (not multiprocessing's
    resource tracker)."""
    children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    workers = []
    for child in map(int, children):
        try:
            command = Path(f"/proc/{child}/cmdline").read_bytes()
        except FileNotFoundError:
            continue
        if b"spawn_main" in command:
            workers.append(child)
    return workers


@pytest.mark.slow
def test_dask_tasks_hold_about_thirty_simulated_seconds_and_leave_every_worker_several(tmp_path):
    """:func:`dask_batch`: long runs one a task; short runs grouped up to the task's simulated
    time, but never into fewer than ``TASKS_PER_WORKER`` tasks a worker."""
    text = CAMPAIGN.replace("count = 2", "count = COUNT").replace("5.0", "DURATION")

    def batch(count: int, duration_s: float, workers: int) -> int:
        edited = text.replace("COUNT", str(count)).replace("DURATION", str(duration_s))
        runs = campaign_module.load_campaign(write(tmp_path, edited)).runs
        assert len(runs) == 2 * count
        return campaign_module.dask_batch(runs, workers)

    per_task = campaign_module.DASK_TASK_SIMULATED_S
    tasks_per_worker = campaign_module.TASKS_PER_WORKER
    assert batch(50, per_task, 1) == batch(50, 2 * per_task, 2) == 1
    assert batch(200, per_task / 10, 1) == 10  # 400 runs, 40 tasks
    assert batch(200, per_task / 10, 20) == 400 // (tasks_per_worker * 20)  # 5: spread first
    assert batch(2, 1.0, 8) == 1  # fewer runs than the workers can share: one a task


@pytest.mark.slow
def test_local_cluster_workers_run_one_thread_with_the_pools_environment(monkeypatch):
    """A ``LocalCluster`` worker runs like a pool worker: one thread, numba and BLAS on one
    thread, and none of dask's ``MALLOC_TRIM_THRESHOLD_`` (which made every run take 35 to
    40 % more CPU: its arrays mapped and faulted in again and again)."""
    pytest.importorskip("distributed")
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    names = [*campaign_module.WORKER_ENVIRONMENT, "MALLOC_TRIM_THRESHOLD_"]
    with campaign_module.worker_environment():
        client = campaign_module._start_dask(None, 1)
    try:
        environments = client.run(lambda: {name: os.environ.get(name) for name in names})
        threads = client.nthreads()
    finally:
        cluster = client.cluster
        client.close()
        cluster.close()
    assert list(threads.values()) == [1]
    expected = {**campaign_module.WORKER_ENVIRONMENT, "MALLOC_TRIM_THRESHOLD_": None}
    assert list(environments.values()) == [expected]


def test_a_worker_killed_by_the_system_leaves_its_runs_missing_not_failed(tmp_path):
    """A worker process that dies (the kernel's OOM killer, an operator) is no failure of
    its runs: the campaign stops with status 1 and a hint, and ``--resume`` runs the rest.
    The runs are long enough (30 s simulated, a few tenths of a second each) that the ten
    runs cannot all end between the first committed row and the kill."""
    text = CAMPAIGN.replace("count = 2", "count = 5").replace(
        "duration_s = 5.0", "duration_s = 30.0"
    )
    path = write(tmp_path, text)
    out = tmp_path / "out"
    command = [sys.executable, "-m", "scenarios.cli", "campaign", str(path), "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    campaign_process = subprocess.Popen(
        [*command, "--workers", "1"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    parts = out / campaign_module.PARTS_DIR
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not list(parts.glob("*.parquet")):
        assert campaign_process.poll() is None, "the campaign ended before a worker was killed"
        time.sleep(0.05)
    workers = pool_workers(campaign_process.pid)
    assert len(workers) == 1
    os.kill(workers[0], signal.SIGKILL)
    _, stderr = campaign_process.communicate(timeout=300)
    assert campaign_process.returncode == 1
    assert "a worker process died" in stderr and "--resume" in stderr
    done = len(list(parts.glob("*.parquet")))
    assert 1 <= done < 10

    resumed = subprocess.run([*command, "--resume"], env=env, capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    table = rows(out / campaign_module.RESULTS_FILE)
    assert len(table) == 10 and all(r["status"] == "ok" for r in table)


@pytest.mark.slow
def test_record_failures_writes_recordings_for_the_failed_runs_only(tmp_path):
    text = CAMPAIGN.replace("duration_s = 5.0", 'duration_s = 5.0\nrecord = "failures"')
    campaign = with_failing_run(campaign_module.load_campaign(write(tmp_path, text)), 1)
    out = tmp_path / "out"
    table = run_on_pool(campaign, out)
    assert [r["status"] for r in table] == ["ok", "failed", "ok", "ok"]
    assert all(r["guarantee"] is None for r in table)  # no fault-free run broke it
    name = f"recordings/{campaign.runs[1].key}.rrd"
    assert [r["recording"] for r in table] == [None, name, None, None]
    assert sorted(p.name for p in (out / "recordings").iterdir()) == [f"{campaign.runs[1].key}.rrd"]
    # the failed run's world, truth and sensors, read back; no estimates (it has none)
    entities = {entity for entity, _ in recording_columns(out / name)}
    assert "/world/robot/footprint" in entities and "/world/sonar/echoes" in entities
    assert not any(entity.startswith("/world/estimates") for entity in entities)


@pytest.mark.slow
def test_record_a_count_records_that_many_runs_drawn_from_the_campaign_seed(tmp_path):
    text = CAMPAIGN.replace("duration_s = 5.0", "duration_s = 2.0\nrecord = 2")
    campaign = campaign_module.load_campaign(write(tmp_path, text))
    chosen = [run.index for run in campaign.runs if run.record == campaign_module.Record.ALL]
    assert len(chosen) == 2
    assert chosen == [  # the same draw on every load (so on --resume)
        run.index
        for run in campaign_module.load_campaign(write(tmp_path, text, "again.toml")).runs
        if run.record == campaign_module.Record.ALL
    ]
    folder = campaign_module.ResultsFolder(tmp_path / "out")
    folder.prepare(campaign, resume=False)
    for run in campaign.runs:
        folder.commit(campaign_module.run_one(run))
    table = rows(folder.merge(campaign))
    assert [r["recording"] is not None for r in table] == [i in chosen for i in range(len(table))]
    for row in table:
        if row["recording"]:
            from scenarios.recording import verify_recording

            verify_recording(tmp_path / "out" / row["recording"], f"hall-seed{row['seed']}")
