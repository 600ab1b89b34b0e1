"""``robotsim campaign FILE``: every combination of scenarios, seeds and settings, in parallel.

A campaign file (TOML) names what to run::

    scenarios = ["hall", "my_building.toml"]   # built-in names or files (relative to this file)
    seed = 2026                                # the campaign seed (default 0)
    seeds = { first = 0, count = 20 }          # the replicates (the seed range)
    duration_s = 60.0                          # optional: every run's duration, seconds
    record = "failures"                        # optional: "none", "failures", "all" or a count

    [grid]                                     # optional: settings overrides, every combination
    "estimation.fusion" = ["clamp", "truncated"]
    "estimation.tracker" = ["sivia", "imagesp"]

A grid key is a key of a scenario's ``[estimation]`` table (``estimation.<key>``) or
``run.duration_s``; the runs' seeds come from the campaign. Replicate ``i`` runs with the
seed of child ``i`` of ``numpy.random.SeedSequence(seed).spawn``, the same for every scenario
and every setting (common random numbers: two settings are compared on the same simulated
worlds, which is what makes paired differences tight), and whatever worker runs it.

The results folder holds one Parquet part per finished run (``parts/<run key>.parquet``,
written under a temporary name and renamed, so a run is either wholly there or absent) and,
once every run is done, the merged table ``results.parquet``: one row per run, the run's
settings (``scenario``, ``replicate``, ``seed``, ``setting.<grid key>``), its ``status``
(``ok`` or ``failed``) and ``error``, every figure of its summary as a column (nested keys
joined by dots: ``rmse_position_m.fused``, ``nees.fused.pose.share_in_band``) and its
``timing.*`` (wall and CPU seconds, CPU per interval epoch). A failed run is recorded with
its error and the campaign goes on. ``--resume`` runs only the runs without a part, so a
campaign killed at any moment (``kill -9`` included) loses at most the runs in flight.

Execution: a local process pool (``--workers``, default all cores) or, with the ``[cluster]``
extra, ``dask.distributed`` (``--cluster local`` starts a ``LocalCluster``; ``--scheduler
tcp://HOST:PORT`` joins one). numba's kernels are compiled once in this process before any
worker runs, so local workers load them from the disk cache instead of compiling them in
parallel into the same cache; workers run with ``NUMBA_NUM_THREADS=1``. The workers start,
and import what a run needs (:func:`import_run_path`), while this process compiles: the
start of the pool is hidden behind the warm-up; a dask cluster, slower to start, starts (or
is joined) before the campaign file is even read (:func:`dask_client`). A dask task holds runs
worth :data:`DASK_TASK_SIMULATED_S` simulated seconds, fewer when that would leave a worker
less than :data:`TASKS_PER_WORKER` tasks (:func:`dask_batch`).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import hashlib
import importlib
import importlib.util
import itertools
import json
import math
import multiprocessing
import os
import sys
import time
import tomllib
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import (
    FIRST_COMPLETED,
    Future,
    ProcessPoolExecutor,
    ThreadPoolExecutor,
    wait,
)
from concurrent.futures.process import BrokenProcessPool
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from intervals.errors import IntervalError
from localization.errors import EstimationError
from robotsim.errors import RobotsimError
from scenarios import outputs
from scenarios.catalog import builtin_names
from scenarios.errors import ScenarioError
from scenarios.tables import Table

if TYPE_CHECKING:  # the scenarios (and with them numba) are read when a campaign loads
    from scenarios.spec import ScenarioSpec

#: Where ``robotsim campaign`` writes when no ``--out`` is given: ``runs/<campaign stem>``.
DEFAULT_OUT_DIR = Path("runs")

PARTS_DIR = "parts"
RESULTS_FILE = "results.parquet"
#: The campaign's description written beside the parts; ``--resume`` requires it.
MANIFEST_FILE = "campaign.json"

#: The most runs a campaign may have (a typo in a range must not queue a billion runs).
MAX_RUNS = 1_000_000

#: The recordings of the runs (``record = ...``): ``recordings/<run key>.rrd``.
RECORDINGS_DIR = "recordings"
#: The row key under which a worker hands a run's recording (bytes) to the writer.
RECORDING_BYTES = "_recording_bytes"


class Record(StrEnum):
    """Which runs of a campaign get a recording (``record``; an integer: that many runs,
    drawn from the campaign seed)."""

    NONE = "none"
    FAILURES = "failures"
    """The runs that failed (the simulation recorded without estimates, when it runs) and
    the runs that broke their own guarantee (``scenarios.commands.guarantee_failure``)."""
    ALL = "all"


#: The grid keys outside ``[estimation]`` a campaign may vary.
RUN_KEYS = ("run.duration_s",)

#: The duration of the short runs that compile numba's kernels before the workers start, s.
WARM_UP_DURATION_S = 1.0

#: Runs per task when the pool is local: one, so a kill loses at most the runs in flight.
LOCAL_BATCH = 1
#: The simulated seconds of the runs of one dask task: dask costs a few milliseconds a task
#: (scheduler, worker and client each handle it; BENCHMARKS.md, "Campaign throughput"), and
#: 30 simulated seconds take about a third of a second on ``hall``: a run of 30 s or more is
#: a task of its own, shorter runs are grouped.
DASK_TASK_SIMULATED_S = 30.0
#: The fewest tasks per worker a dask campaign is cut into, so that its last tasks still
#: spread over the workers (a larger task is a longer wait for the last worker).
TASKS_PER_WORKER = 4
#: dask settings of a ``LocalCluster`` started here. Its background work costs CPU for as long
#: as the campaign lasts, whatever the runs do: each event loop's tick (every 20 ms by
#: default), the memory and system monitors, work stealing and the workers' statistical
#: profiler. Idle, a cluster of two workers took 1.1 s of CPU per 10 s with dask's defaults
#: and 0.18 s with these (BENCHMARKS.md, "Campaign throughput"); tasks of a third of a second
#: and more need no finer polling, and there is no dashboard to feed. And the workers start
#: without the ``MALLOC_TRIM_THRESHOLD_=65536`` dask's nannies set by default: with it glibc
#: gives the free top of its heap beyond 64 KB back to the system and keeps its mmap threshold
#: at 128 KB (never raised), so a run's arrays are mapped and faulted in again and again
#: (40 000 page faults instead of 1 000 on a 30 s ``hall`` run, 35 to 40 % more CPU a run).
LOCAL_CLUSTER_CONFIG = {
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.scheduler.work-stealing-interval": "1s",
    "distributed.worker.profile.enabled": False,
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
}


# ---------------------------------------------------------------------------------------
# The campaign file
# ---------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class CampaignRun:
    """One run of a campaign: which scenario, replicate and settings, and the spec they make."""

    index: int
    """Position in the campaign's run order (scenario, replicate, grid point)."""
    scenario: str
    """The scenario's name (the built-in name or the file's stem)."""
    written: str
    """The scenario as the campaign file names it (unique within the campaign)."""
    replicate: int
    settings: dict[str, Any]
    """The grid point: ``{"estimation.fusion": "clamp", ...}`` (empty without a grid)."""
    spec: ScenarioSpec
    record: Record = Record.NONE
    """Whether this run is recorded: ``ALL`` (always), ``FAILURES`` (if it fails) or not."""

    @property
    def key(self) -> str:
        """A name of the run that depends on what it runs only (scenario, seed, settings,
        duration), not on its place in the campaign: it names the run's part."""
        described = {
            "scenario": self.written,
            "seed": self.spec.run.seed,
            "duration_s": self.spec.run.duration_s,
            "settings": self.settings,
        }
        return hashlib.sha256(json.dumps(described, sort_keys=True).encode()).hexdigest()[:20]


@dataclasses.dataclass(frozen=True, eq=False)
class Campaign:
    """A validated campaign file: its runs, in order."""

    name: str
    source: str
    seed: int
    runs: tuple[CampaignRun, ...]


def replicate_seeds(campaign_seed: int, first: int, count: int) -> list[int]:
    """The run seeds of replicates ``first .. first + count - 1``: one 63-bit integer from
    each child of ``SeedSequence(campaign_seed).spawn``."""
    children = np.random.SeedSequence(campaign_seed).spawn(first + count)[first:]
    return [int(child.generate_state(1, np.uint64)[0] >> np.uint64(1)) for child in children]


def load_campaign(path: str | Path) -> Campaign:
    """Read and validate a campaign file; every scenario and grid point is built (and so
    checked) here, before anything runs.

    Raises:
        ScenarioError: ``(file, key, reason)`` for the first mistake.
    """
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise ScenarioError(source, None, "no such file" if not path.exists() else "not a file")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(source, None, f"not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise ScenarioError(source, None, "not a UTF-8 text file") from None
    top = Table(source, "", data)
    names = _take_strings(top, "scenarios")
    seed = top.take_int("seed", 0, minimum=0)
    seeds = top.take_table("seeds")
    first = seeds.take_int("first", 0, minimum=0)
    count = seeds.take_int("count", minimum=1)
    seeds.finish()
    duration_s = top.take_float("duration_s", None, above=0.0)
    record = top.take_raw("record", str(Record.NONE))
    grid = _read_grid(source, top.take_raw("grid", {}))
    top.finish()

    total = len(names) * count * math.prod(len(v) for v in grid.values())
    if total > MAX_RUNS:
        raise ScenarioError(source, "seeds.count", f"{total} runs, more than {MAX_RUNS}")
    recorded = _recorded_runs(source, record, total, seed)
    base_dir = path.parent
    specs = []
    for i, name in enumerate(names):
        scenario = _load_named(name, base_dir, source, f"scenarios[{i}]")
        if duration_s is not None:
            scenario = _apply(scenario, "run.duration_s", duration_s, source, "duration_s")
        specs.append(scenario)

    run_seeds = replicate_seeds(seed, first, count)
    points = [dict(zip(grid, values, strict=True)) for values in itertools.product(*grid.values())]
    runs: list[CampaignRun] = []
    for written, spec_base in zip(names, specs, strict=True):
        for replicate, run_seed in zip(range(first, first + count), run_seeds, strict=True):
            seeded = spec_base.with_run(seed=run_seed)
            for point in points:
                spec = seeded
                for key, value in point.items():
                    spec = _apply(spec, key, value, source, f"grid.{key}")
                runs.append(
                    CampaignRun(
                        index=len(runs),
                        scenario=spec_base.name,
                        written=written,
                        replicate=replicate,
                        settings=point,
                        spec=spec,
                        record=recorded(len(runs)),
                    )
                )
    return Campaign(path.stem, source, seed, tuple(runs))


def _recorded_runs(source: str, record: object, total: int, seed: int) -> Callable[[int], Record]:
    """Which runs ``record`` asks to record, as ``run index -> Record``: a :class:`Record`
    name, or a number of runs from 1 to ``total`` drawn without replacement with the
    campaign ``seed`` (the same runs on every ``--resume``)."""
    if isinstance(record, str) and record in set(Record):
        mode = Record(record)
        return lambda index: mode
    if isinstance(record, int) and not isinstance(record, bool) and 1 <= record <= total:
        chosen = set(np.random.default_rng(seed).choice(total, record, replace=False).tolist())
        return lambda index: Record.ALL if index in chosen else Record.NONE
    raise ScenarioError(
        source,
        "record",
        f"must be one of {', '.join(repr(str(r)) for r in Record)} or a number of runs from 1 "
        f"to {total}, got {record!r}",
    )


def _take_strings(table: Table, name: str) -> list[str]:
    """A required non-empty array of strings."""
    value = table.take_raw(name)
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise table.error(name, "must be a non-empty array of strings")
    if len(set(value)) != len(value):
        raise table.error(name, "lists a scenario twice")
    return list(value)


def _read_grid(source: str, data: object) -> dict[str, list[Any]]:
    """The ``[grid]`` table: each key an ``estimation.<key>`` or a :data:`RUN_KEYS` key
    (quoted, ``"estimation.fusion" = [...]``, or as sub-tables, ``estimation.fusion = [...]``),
    each value a non-empty array of distinct values to try."""
    if not isinstance(data, dict):
        raise ScenarioError(source, "grid", "must be a table")
    grid: dict[str, list[Any]] = {}
    for key, values in flatten_tables(data).items():
        where = f"grid.{key}"
        if key == "run.seed":
            raise ScenarioError(source, where, "the seeds come from the campaign (seed, seeds)")
        if not (key.startswith("estimation.") or key in RUN_KEYS):
            raise ScenarioError(
                source,
                where,
                f"not a setting a campaign can vary (estimation.<key> or {', '.join(RUN_KEYS)})",
            )
        if not isinstance(values, list) or not values:
            raise ScenarioError(source, where, "must be a non-empty array of the values to try")
        if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
            raise ScenarioError(source, where, "lists a value twice")
        grid[key] = values
    return grid


def flatten_tables(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested TOML tables as dotted keys (``{"a": {"b": 1}}`` -> ``{"a.b": 1}``)."""
    flat: dict[str, Any] = {}
    for key, value in data.items():
        name = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict):
            flat.update(flatten_tables(value, name))
        else:
            flat[name] = value
    return flat


def _load_named(name: str, base_dir: Path, source: str, key: str) -> ScenarioSpec:
    """A built-in scenario, or a scenario file relative to the campaign file's folder."""
    from scenarios.spec import load_scenario

    if name in builtin_names():
        return load_scenario(name)
    path = Path(name)
    if not path.is_absolute():
        path = base_dir / path
    if not path.is_file():
        raise ScenarioError(
            source,
            key,
            f"{name!r} is neither a built-in scenario ({', '.join(builtin_names())}) nor a file",
        )
    return load_scenario(path)


def _apply(spec: ScenarioSpec, key: str, value: Any, source: str, where: str) -> ScenarioSpec:
    """``spec`` with the setting ``key`` (``estimation.<key>``, ``run.duration_s``) set to
    ``value``; a refusal is reported against the campaign file and ``where``."""
    try:
        if key == "run.duration_s":
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ScenarioError(None, None, f"must be a number, got {value!r}")
            return spec.with_run(duration_s=float(value))
        return spec.with_estimation(**{key.removeprefix("estimation."): value})
    except (ScenarioError, IntervalError, EstimationError, RobotsimError) as exc:
        reason = exc.reason if isinstance(exc, ScenarioError) else str(exc)
        raise ScenarioError(source, where, f"{value!r}: {reason}") from None


# ---------------------------------------------------------------------------------------
# One run, one row
# ---------------------------------------------------------------------------------------
#: Set in every worker before it imports numba: one thread per worker process (the pool is
#: the parallelism; BLAS threads on top of it would only compete for the same cores).
WORKER_ENVIRONMENT = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


def flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    """A nested summary as flat columns: dict keys and list positions joined by dots
    (``{"a": {"b": [1, 2]}}`` -> ``{"a.b.0": 1, "a.b.1": 2}``)."""
    if isinstance(tree, dict):
        items: Iterable[tuple[Any, Any]] = tree.items()
    elif isinstance(tree, list | tuple):
        items = enumerate(tree)
    else:
        return {prefix: tree}
    columns: dict[str, Any] = {}
    for name, value in items:
        columns.update(flatten(value, f"{prefix}.{name}" if prefix else str(name)))
    return columns


def run_columns(run: CampaignRun) -> dict[str, Any]:
    """The columns that say which run a row is (the same for a failed run)."""
    return {
        "run_index": run.index,
        "run_key": run.key,
        "scenario": run.scenario,
        "replicate": run.replicate,
        "seed": run.spec.run.seed,
        "duration_s": run.spec.run.duration_s,
        **{f"setting.{key}": value for key, value in run.settings.items()},
    }


def run_one(run: CampaignRun) -> dict[str, Any]:
    """Run ``run`` with ``scenarios.runner.run_scenario``; its row: the run's columns, its
    ``status`` and ``error``, ``guarantee`` (why it broke its own guarantee, or None), its
    flattened summary and its ``timing.*`` (wall and CPU seconds, CPU milliseconds per
    epoch, simulated seconds per wall second); and, when the run is to be recorded, its
    recording's bytes under :data:`RECORDING_BYTES` (taken out by the writer)."""
    from scenarios.commands import guarantee_failure
    from scenarios.runner import run_scenario

    row = {**run_columns(run), "recording": None}
    wall_start, cpu_start = time.perf_counter(), time.process_time()
    try:
        result = run_scenario(run.spec)
    except Exception as exc:  # any failure of one run is recorded; the campaign goes on
        row.update(status="failed", error=f"{type(exc).__name__}: {exc}", guarantee=None)
        if run.record != Record.NONE:
            row[RECORDING_BYTES] = _failed_run_recording(run)
        return row
    wall_s = time.perf_counter() - wall_start
    cpu_s = time.process_time() - cpu_start
    epochs = result.summary.get("epochs") or 0
    broken = guarantee_failure(run.spec, result.summary)
    if run.record == Record.ALL or (run.record == Record.FAILURES and broken):
        from scenarios.recording import recording_bytes

        row[RECORDING_BYTES] = recording_bytes(run.spec, result.log, result.estimation)
    return {
        **row,
        "status": "ok",
        "error": None,
        "guarantee": broken,
        **flatten(result.summary),
        "timing.wall_s": wall_s,
        "timing.cpu_s": cpu_s,
        "timing.cpu_per_epoch_ms": cpu_s / epochs * 1e3 if epochs else None,
        "timing.realtime_factor": run.spec.run.duration_s / wall_s if wall_s > 0 else None,
    }


def _failed_run_recording(run: CampaignRun) -> bytes | None:
    """The recording of a run that failed: its simulation (truth and sensors) without
    estimates, or None when the simulation itself fails."""
    from scenarios.recording import recording_bytes
    from scenarios.runner import simulate_spec

    try:
        return recording_bytes(run.spec, simulate_spec(run.spec))
    except Exception:  # the failure is in the row already; no recording to add
        return None


def run_batch(runs: Sequence[CampaignRun]) -> list[dict[str, Any]]:
    """The rows of ``runs``, run one after the other (a task of the pool or of dask)."""
    for name, value in WORKER_ENVIRONMENT.items():
        os.environ.setdefault(name, value)  # in effect where numba is not imported yet
    return [run_one(run) for run in runs]


# ---------------------------------------------------------------------------------------
# The results folder
# ---------------------------------------------------------------------------------------
class ResultsFolder:
    """``OUT/parts/<run key>.parquet`` (one per finished run), ``OUT/campaign.json``, and
    ``OUT/results.parquet`` (all rows, in run order) once every run is done."""

    def __init__(self, path: Path):
        self.path = path
        self.parts = path / PARTS_DIR
        self.recordings = path / RECORDINGS_DIR

    def prepare(self, campaign: Campaign, resume: bool) -> None:
        """Check the folder can take this campaign; without ``resume`` it must be new or
        empty, with it new or a campaign folder. Leftover temporary parts of a killed run
        are removed (they are this folder's own, never a finished run)."""
        manifest = self.path / MANIFEST_FILE
        if self.path.exists() and not self.path.is_dir():
            raise ScenarioError(None, "--out", f"{self.path} exists and is not a folder")
        exists = self.path.is_dir() and any(self.path.iterdir())
        if exists and not resume:
            raise ScenarioError(
                None, "--out", f"{self.path} is not empty (--resume continues a campaign there)"
            )
        if exists and not manifest.is_file():
            raise ScenarioError(None, "--out", f"{self.path} holds no campaign ({MANIFEST_FILE})")
        reason = outputs.check_destination(manifest)
        if reason is not None:
            raise ScenarioError(None, "--out", reason)
        self.parts.mkdir(parents=True, exist_ok=True)
        for leftover in [*self.parts.glob(".*.part"), *self.recordings.glob(".*.part")]:
            leftover.unlink()
        if not manifest.is_file():
            outputs.write_json(
                manifest,
                {"campaign": campaign.source, "seed": campaign.seed, "runs": len(campaign.runs)},
            )

    def done_keys(self) -> set[str]:
        """The keys of the runs with a part."""
        return {part.name[: -len(".parquet")] for part in self.parts.glob("*.parquet")}

    def commit(self, row: dict[str, Any]) -> None:
        """Write one run's row as its part, atomically (a temporary name, then a rename);
        its recording first, if it has one (``recordings/<run key>.rrd``, read back before
        it is moved into place), so that a run with a part has its recording."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        data = row.pop(RECORDING_BYTES, None)
        if data is not None:
            from scenarios.recording import verify_recording

            self.recordings.mkdir(exist_ok=True)
            name = f"{RECORDINGS_DIR}/{row['run_key']}.rrd"
            with outputs.atomic_path(self.path / name) as tmp:
                outputs.write_bytes(tmp, data)
                verify_recording(tmp, f"{row['scenario']}-seed{row['seed']}")
            row["recording"] = name
        with outputs.atomic_path(self.parts / f"{row['run_key']}.parquet") as tmp:
            pq.write_table(pa.Table.from_pylist([row]), tmp)

    def merge(self, campaign: Campaign) -> Path:
        """``results.parquet``: the rows of the campaign's runs, in run order (columns a run
        lacks, a failed run's figures, are null)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        tables = [pq.read_table(self.parts / f"{run.key}.parquet") for run in campaign.runs]
        merged = pa.concat_tables(tables, promote_options="permissive")
        destination = self.path / RESULTS_FILE
        with outputs.atomic_path(destination) as tmp:
            pq.write_table(merged, tmp)
        return destination


# ---------------------------------------------------------------------------------------
# Executors
# ---------------------------------------------------------------------------------------
#: What an executor is given: the batches to run and what to do with each finished batch.
RowsSink = Callable[[list[dict[str, Any]]], None]


@contextlib.contextmanager
def worker_environment() -> Iterator[None]:
    """:data:`WORKER_ENVIRONMENT` in this process's environment while workers start (they
    inherit it), then the previous values back."""
    previous = {name: os.environ.get(name) for name in WORKER_ENVIRONMENT}
    os.environ.update(WORKER_ENVIRONMENT)
    try:
        yield
    finally:
        for name, value in previous.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


#: The modules :func:`run_one` runs with (they import the rest of the run path).
RUN_PATH_MODULES = ("scenarios.runner", "scenarios.commands")


def import_run_path() -> None:
    """Import what a run needs (the simulator, the estimators and numba), so that a worker
    started while the campaign's process compiles spends that time importing, not its first
    run. Nothing is compiled or loaded from numba's cache here: that waits for the first run,
    after the warm-up (:func:`warm_up`)."""
    for module in RUN_PATH_MODULES:
        importlib.import_module(module)


def execute_local(
    runs: Sequence[CampaignRun],
    workers: int,
    sink: RowsSink,
    *,
    batch: int = LOCAL_BATCH,
    prepare: Callable[[], None] | None = None,
) -> None:
    """Run ``runs``, ``batch`` per task, on a pool of ``workers`` fresh (spawned) processes,
    handing each finished task's rows to ``sink``. ``prepare`` (the warm-up) runs here once
    the workers are starting (they import the run path meanwhile) and before any run."""
    context = multiprocessing.get_context("spawn")
    with (
        worker_environment(),
        ProcessPoolExecutor(workers, mp_context=context, initializer=import_run_path) as pool,
    ):
        for _ in range(workers):  # each submit to a pool without an idle worker starts one
            pool.submit(int)
        if prepare is not None:
            prepare()
        pending: set[Future[list[dict[str, Any]]]] = {
            pool.submit(run_batch, tasked) for tasked in batched(runs, batch)
        }
        try:
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    sink(future.result())
        finally:
            for future in pending:
                future.cancel()


def dask_batch(runs: Sequence[CampaignRun], workers: int) -> int:
    """Runs per dask task: as many as make :data:`DASK_TASK_SIMULATED_S` simulated seconds
    (on the runs' mean duration), at most as many as leave every one of ``workers``
    :data:`TASKS_PER_WORKER` tasks, at least one."""
    mean_s = sum(run.spec.run.duration_s for run in runs) / max(len(runs), 1)
    wanted = math.ceil(DASK_TASK_SIMULATED_S / mean_s) if mean_s > 0 else 1
    spread = len(runs) // (TASKS_PER_WORKER * workers)
    return max(1, min(wanted, spread))


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int) -> Iterator[Future[Any]]:
    """The future of a dask client, started in a thread: of the scheduler at ``scheduler``
    (``tcp://HOST:PORT``), or of a new ``LocalCluster`` of ``workers`` processes when None;
    ``distributed`` is imported and the workers import the run path in that thread, so that
    what is done here meanwhile (reading the campaign, the warm-up) hides the start. The
    client and its cluster are closed on exit."""
    if importlib.util.find_spec("distributed") is None:  # imported in the starting thread
        raise ScenarioError(
            None,
            "--scheduler" if scheduler else "--cluster",
            "dask.distributed is not installed (pip install 'robotsim-testbed[cluster]')",
        )
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            stack.enter_context(worker_environment())
        starter = stack.enter_context(ThreadPoolExecutor(1, thread_name_prefix="dask-start"))
        starting = starter.submit(_start_dask, scheduler, workers)
        stack.callback(_close_dask, starting)
        yield starting


def execute_dask(
    runs: Sequence[CampaignRun],
    starting: Future[Any],
    sink: RowsSink,
    *,
    batch: int | None = None,
    prepare: Callable[[], None] | None = None,
) -> None:
    """Run ``runs`` on the dask client ``starting`` will give (:func:`dask_client`), ``batch``
    runs per task (default :func:`dask_batch` for the workers the scheduler has), after
    ``prepare`` (the warm-up), which runs here while the client starts."""
    if prepare is not None:
        prepare()
    client = starting.result()
    from distributed import as_completed

    size = batch or dask_batch(runs, max(1, sum(client.nthreads().values())))
    futures = client.map(run_batch, batched(runs, size), pure=False)
    for future in as_completed(futures):
        sink(future.result())


def _start_dask(scheduler: str | None, workers: int) -> Any:
    """A client of the scheduler at ``scheduler`` or of a new ``LocalCluster`` (closed with
    the client: :func:`_close_dask`), its workers having imported the run path."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler is None:
        with dask.config.set(LOCAL_CLUSTER_CONFIG):  # read as the servers start
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            )
        try:
            client = Client(cluster)
        except BaseException:
            cluster.close()
            raise
    else:
        try:
            client = Client(scheduler, timeout=30)
        except OSError as exc:
            raise ScenarioError(None, "--scheduler", f"cannot reach {scheduler}: {exc}") from None
    client.run(import_run_path)
    return client


def _close_dask(starting: Future[Any]) -> None:
    """Close the client :func:`_start_dask` made (waiting for it), and its ``LocalCluster``."""
    try:
        client = starting.result()
    except BaseException:  # it did not start: nothing to close (its error is raised already)
        return
    cluster = client.cluster  # None when the client joined a running scheduler
    client.close()
    if cluster is not None:
        cluster.close()


def batched(runs: Sequence[CampaignRun], size: int) -> list[list[CampaignRun]]:
    """``runs`` cut into consecutive batches of ``size`` (the last one shorter)."""
    return [list(runs[i : i + size]) for i in range(0, len(runs), size)]


def warm_up(runs: Sequence[CampaignRun]) -> None:
    """Compile numba's kernels here, once, before any worker starts: one short run per
    distinct ``[estimation]`` setting of the campaign (each may use other kernels); the
    workers then load them from the disk cache. Under the warm-up lock
    (:func:`scenarios.warmup.turn`): campaigns and warm-ups started side by side take turns."""
    from scenarios.runner import run_scenario
    from scenarios.warmup import turn

    seen: set[str] = set()
    with turn():
        for run in runs:
            estimation = json.dumps(run.spec.estimation.as_keys(), sort_keys=True, default=str)
            if estimation in seen:
                continue
            seen.add(estimation)
            short = min(WARM_UP_DURATION_S, run.spec.run.duration_s)
            with contextlib.suppress(Exception):  # a failing run fails (and is recorded) later
                run_scenario(run.spec.with_run(duration_s=short))


# ---------------------------------------------------------------------------------------
# Progress
# ---------------------------------------------------------------------------------------
class CampaignProgress:
    """``campaign NAME: done/total runs, F failed, ETA`` on ``stream``: redrawn in place on a
    terminal, one line per tenth of the campaign otherwise."""

    def __init__(self, stream: TextIO, name: str, total: int, done: int):
        self._stream, self._name = stream, name
        self._total, self._done, self._at_start = total, done, done
        self._failed = 0
        self._start = time.perf_counter()
        self._tty = stream.isatty()
        self._shown_tenth = -1
        self._closed = False
        self.update([])

    def update(self, rows: list[dict[str, Any]]) -> None:
        """Count the finished ``rows`` and redraw."""
        self._done += len(rows)
        self._failed += sum(row["status"] != "ok" for row in rows)
        ran = self._done - self._at_start
        remaining = self._total - self._done
        elapsed = time.perf_counter() - self._start
        eta = _duration(elapsed / ran * remaining) if ran else "?"
        line = (
            f"campaign {self._name}: {self._done}/{self._total} runs, {self._failed} failed, "
            f"ETA {eta}"
        )
        if self._tty:
            self._stream.write(f"\r{line}\033[K")
        else:
            tenth = 10 * self._done // max(self._total, 1)
            if tenth == self._shown_tenth:
                return
            self._shown_tenth = tenth
            self._stream.write(line + "\n")
        self._stream.flush()

    def close(self) -> None:
        """End the bar's line on a terminal (once)."""
        if self._tty and not self._closed:
            self._stream.write("\n")
            self._stream.flush()
        self._closed = True


def _duration(seconds: float) -> str:
    seconds = round(seconds)
    if seconds < 60:
        return f"{seconds}s"
    minutes, seconds = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes}m{seconds:02d}s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m"


# ---------------------------------------------------------------------------------------
# The sub-command
# ---------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``robotsim campaign``."""
    parser.add_argument("campaign", metavar="FILE", type=Path, help="the campaign file (TOML)")
    parser.add_argument(
        "--out", type=Path, metavar="DIR", help="results folder (default: runs/<campaign stem>)"
    )
    parser.add_argument(
        "--resume", action="store_true", help="continue the campaign in --out: run what is missing"
    )
    parser.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes (default: every core of this machine)",
    )
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on a dask.distributed scheduler (tcp://HOST:PORT)",
    )
    where.add_argument(
        "--cluster",
        choices=("local",),
        help="run on a dask LocalCluster of --workers processes started here",
    )
    parser.add_argument(
        "--batch", type=int, metavar="N", help="runs per task (default: 1 locally; a few on dask)"
    )


def main(args: argparse.Namespace) -> int:
    """``robotsim campaign``: run what is missing, merge the table; exit 1 if a run failed."""
    for option, value in (("--workers", args.workers), ("--batch", args.batch)):
        if value is not None and value < 1:
            raise ScenarioError(None, option, f"must be at least 1, got {value}")
    workers = worker_count(args.workers)
    campaign = load_campaign(args.campaign)  # a bad file is refused before a cluster starts
    with contextlib.ExitStack() as stack:
        dask = None
        if args.scheduler is not None or args.cluster is not None:
            dask = stack.enter_context(dask_client(args.scheduler, workers))
        folder = ResultsFolder(args.out or DEFAULT_OUT_DIR / campaign.name)
        folder.prepare(campaign, args.resume)
        finished = run_campaign(
            campaign, folder, workers=workers, scheduler=args.scheduler, dask=dask, batch=args.batch
        )
    if not finished:
        left = len(campaign.runs) - len(folder.done_keys())
        print(
            f"robotsim: a worker process died; {left} run(s) not done: "
            f"robotsim campaign {args.campaign} --out {folder.path} --resume runs them",
            file=sys.stderr,
        )
        return 1
    results = folder.merge(campaign)
    failed = _failed_count(results)
    print(f"campaign {campaign.name}: {len(campaign.runs)} runs, {failed} failed; wrote {results}")
    return 1 if failed else 0


def worker_count(workers: int | None) -> int:
    """The worker processes of a campaign: ``workers``, by default every core."""
    return workers or os.cpu_count() or 1


def run_campaign(
    campaign: Campaign,
    folder: ResultsFolder,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    dask: Future[Any] | None = None,
    batch: int | None = None,
) -> bool:
    """Run the runs of ``campaign`` without a part in the prepared ``folder``, committing
    each row as it comes, with the progress on stderr: on a local pool of ``workers``
    processes (default: every core), or on the dask client ``dask`` will give
    (:func:`dask_client`; of the scheduler at ``scheduler``, or of a ``LocalCluster`` when
    None), ``batch`` runs per task. Returns False when a worker process died (its runs
    stay missing, for a resume), True when every run has its part."""
    done = folder.done_keys()
    missing = [run for run in campaign.runs if run.key not in done]
    workers = worker_count(workers)
    total = len(campaign.runs)
    print(
        f"campaign {campaign.name}: {total} runs, {total - len(missing)} already done, "
        f"{len(missing)} to run on {workers} worker(s)",
        file=sys.stderr,
    )
    progress = CampaignProgress(sys.stderr, campaign.name, total, total - len(missing))

    def sink(rows: list[dict[str, Any]]) -> None:
        for row in rows:
            folder.commit(row)
        progress.update(rows)

    try:
        if missing:
            # the local workers load what this process compiles; a remote cluster's workers
            # compile on their own machines
            prepare = (lambda: warm_up(missing)) if scheduler is None else None
            if dask is not None:
                execute_dask(missing, dask, sink, batch=batch, prepare=prepare)
            else:
                execute_local(missing, workers, sink, batch=batch or LOCAL_BATCH, prepare=prepare)
    except BrokenProcessPool:
        # a worker process died (out of memory, killed): the runs it had are not recorded as
        # failures, since they did not fail on their own; they stay missing for --resume
        return False
    finally:
        progress.close()
    return True


def _failed_count(results: Path) -> int:
    import pyarrow.parquet as pq

    status = pq.read_table(results, columns=["status"]).column("status").to_pylist()
    return sum(value != "ok" for value in status)
