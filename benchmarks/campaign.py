"""Benchmark of campaign throughput: the local process pool against a dask ``LocalCluster``.

    python benchmarks/campaign.py [--runs N] [--duration S] [--workers 1 2]

Runs the same campaign (``hall``, ``N`` seeds, ``S`` simulated seconds each) on the local
pool and on a ``LocalCluster`` of the same number of worker processes, for each worker
count, and prints the throughput (simulated seconds per wall second, from the first task
submitted to the last row committed, parts written as ``robotsim campaign`` writes them)
and dask's overhead against the pool. numba is compiled once before (as the command does).
The target of issue 15: dask at most 10 % slower than the pool. On a shared machine the
figures move with the other load; the machine line says what it was.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

from _common import machine_line, markdown_table

from scenarios import campaign as cm


def campaign_text(runs: int, duration_s: float) -> str:
    return f'scenarios = ["hall"]\nseed = 1\nseeds = {{ first = 0, count = {runs} }}\nduration_s = {duration_s}\n'


def throughput(campaign: cm.Campaign, executor: str, workers: int) -> tuple[float, float]:
    """Simulated seconds per wall second of the whole campaign on ``executor`` (workers'
    start included), and the seconds to the first committed row (mostly that start)."""
    with tempfile.TemporaryDirectory() as folder_name:
        folder = cm.ResultsFolder(Path(folder_name) / "out")
        folder.prepare(campaign, resume=False)

        first_row: list[float] = []

        def sink(rows):
            for row in rows:
                folder.commit(row)
            first_row.append(time.perf_counter())

        start = time.perf_counter()
        if executor == "pool":
            cm.execute_local(cm.batched(campaign.runs, cm.LOCAL_BATCH), workers, sink)
        else:
            size = min(
                cm.MAX_DASK_BATCH,
                max(1, math.ceil(len(campaign.runs) / (cm.TASKS_PER_WORKER * workers))),
            )
            cm.execute_dask(cm.batched(campaign.runs, size), None, workers, sink)
        wall_s = time.perf_counter() - start
    simulated = sum(run.spec.run.duration_s for run in campaign.runs)
    return simulated / wall_s, first_row[0] - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.toml"
        path.write_text(campaign_text(args.runs, args.duration))
        campaign = cm.load_campaign(path)
    cm.warm_up(campaign.runs)
    table = []
    for workers in args.workers:
        pool, pool_first_s = throughput(campaign, "pool", workers)
        dask, dask_first_s = throughput(campaign, "dask", workers)
        table.append(
            [
                str(workers),
                f"{pool:.1f} ({pool_first_s:.1f} s)",
                f"{dask:.1f} ({dask_first_s:.1f} s)",
                f"{(pool / dask - 1) * 100:+.0f} %",
            ]
        )
    print(machine_line("numba", "distributed", "pyarrow"))
    print(f"campaign: hall, {args.runs} runs x {args.duration:g} s simulated")
    print(
        markdown_table(
            [
                "workers",
                "pool: sim s / wall s (first row after)",
                "dask LocalCluster: sim s / wall s (first row after)",
                "dask overhead",
            ],
            table,
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
