"""Benchmark of campaign throughput: the local process pool against a dask ``LocalCluster``.

    python benchmarks/campaign.py [--runs N] [--duration S] [--workers 1 2] [--rounds R] [--write]

Runs the same campaign (``hall``, ``N`` seeds, ``S`` simulated seconds each) on the local
pool and on a ``LocalCluster`` of the same number of worker processes, for each worker
count, and prints the throughput (simulated seconds per wall second, from the first task
submitted to the last row committed, parts written as ``robotsim campaign`` writes them)
and dask's overhead against the pool. numba is compiled once before (as the command does).
The two executors alternate, ``R`` rounds each, the order swapped every round (pool then
dask, dask then pool, ...), so that a change of the machine's other load falls on both; the
overhead is the median over the rounds of the ratio of the two throughputs of a round.
The target of issue 15: dask at most 10 % slower than the pool. On a shared machine the
figures move with the other load; the load average before and after is printed.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import machine_line, markdown_table, write_section

from scenarios import campaign as cm

SECTION = "Campaign throughput: local pool against dask LocalCluster (issue 15)"


def campaign_text(runs: int, duration_s: float) -> str:
    return f'scenarios = ["hall"]\nseed = 1\nseeds = {{ first = 0, count = {runs} }}\nduration_s = {duration_s}\n'


def throughput(campaign: cm.Campaign, executor: str, workers: int) -> tuple[float, float, float]:
    """Simulated seconds per wall second of the whole campaign on ``executor`` (workers'
    start included), the seconds to the first committed batch (mostly that start), and the
    steady throughput: the simulated seconds committed after the first batch per wall second
    from the first batch to the last (the scheduling cost without the start)."""
    with tempfile.TemporaryDirectory() as folder_name:
        folder = cm.ResultsFolder(Path(folder_name) / "out")
        folder.prepare(campaign, resume=False)

        committed: list[tuple[float, float]] = []  # (time, simulated seconds) per batch

        def sink(rows):
            for row in rows:
                folder.commit(row)
            committed.append((time.perf_counter(), sum(row["duration_s"] for row in rows)))

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
    (first_t, _), (last_t, _) = committed[0], committed[-1]
    after_first = sum(seconds for _, seconds in committed[1:])
    steady = after_first / (last_t - first_t) if last_t > first_t else float("nan")
    return simulated / wall_s, first_t - start, steady


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--rounds", type=int, default=2, help="rounds per executor")
    parser.add_argument("--write", action="store_true", help="update this section of BENCHMARKS.md")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.toml"
        path.write_text(campaign_text(args.runs, args.duration))
        campaign = cm.load_campaign(path)
    cm.warm_up(campaign.runs)
    load_before = os.getloadavg()
    table = []
    for workers in args.workers:
        found: dict[str, list[float]] = {"pool": [], "dask": []}
        first: dict[str, list[float]] = {"pool": [], "dask": []}
        steady: dict[str, list[float]] = {"pool": [], "dask": []}
        for round_ in range(args.rounds):
            order = ("pool", "dask") if round_ % 2 == 0 else ("dask", "pool")
            for executor in order:
                rate, first_s, steady_rate = throughput(campaign, executor, workers)
                found[executor].append(rate)
                first[executor].append(first_s)
                steady[executor].append(steady_rate)
        ratios = np.array(found["pool"]) / np.array(found["dask"])
        steady_ratios = np.array(steady["pool"]) / np.array(steady["dask"])
        table.append(
            [
                str(workers),
                " / ".join(f"{v:.1f}" for v in found["pool"])
                + f" ({np.median(first['pool']):.1f} s)",
                " / ".join(f"{v:.1f}" for v in found["dask"])
                + f" ({np.median(first['dask']):.1f} s)",
                f"{(np.median(ratios) - 1) * 100:+.0f} % (rounds: "
                + ", ".join(f"{(r - 1) * 100:+.0f} %" for r in ratios)
                + ")",
                " / ".join(f"{v:.1f}" for v in steady["pool"])
                + " vs "
                + " / ".join(f"{v:.1f}" for v in steady["dask"])
                + f": {(np.median(steady_ratios) - 1) * 100:+.0f} %",
            ]
        )
    load_after = os.getloadavg()
    header = [
        "workers",
        "pool: sim s / wall s per round (first row after, median)",
        "dask LocalCluster: sim s / wall s per round (first row after, median)",
        "dask overhead, median of the rounds' ratios",
        "after the first batch: pool vs dask sim s / wall s, overhead",
    ]
    body = (
        f"`python benchmarks/campaign.py --runs {args.runs} --duration {args.duration:g} "
        f"--workers {' '.join(map(str, args.workers))} --rounds {args.rounds}`: a `hall` "
        f"campaign of {args.runs} runs x {args.duration:g} s simulated, on the local process "
        f"pool and on a dask `LocalCluster` of the same number of worker processes, "
        f"alternating (the order swapped every round). Throughput: simulated seconds per wall "
        f"second, from the first task submitted to the last row committed, the workers' start "
        f"included; the last column leaves out the workers' start (from the first committed "
        f"batch to the last). Load average (1, 5, 15 min) before {_load(load_before)}, after "
        f"{_load(load_after)}: the machine was shared with other jobs, so the rounds differ "
        f"by more than the executors do. {machine_line('numba', 'distributed', 'pyarrow')}."
        f"\n\n{markdown_table(header, table)}"
    )
    print(body)
    if args.write:
        write_section(SECTION, body)
    return 0


def _load(values: tuple[float, float, float]) -> str:
    return ", ".join(f"{v:.1f}" for v in values)


if __name__ == "__main__":
    raise SystemExit(main())
