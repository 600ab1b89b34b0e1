"""Benchmark of campaign throughput: the local process pool against a dask ``LocalCluster``.

    python benchmarks/campaign.py [--runs 8 32] [--duration S] [--workers 1 2] [--rounds R] [--write]

Times ``robotsim campaign`` itself, in a subprocess, on a ``hall`` campaign of ``N`` seeds
of ``S`` simulated seconds, for each ``N`` of ``--runs``: on the local pool (``--workers W``)
and on a dask ``LocalCluster`` of the same number of worker processes (``--cluster local
--workers W``). What a user waits for: the interpreter's start and imports, the workers'
start, the warm-up (numba's cache is warm: the benchmark warms it first), every run and its
committed part, the merged table. Wall time and CPU time (the command and every process it
started, ``RUSAGE_CHILDREN``) of each campaign.

The executors alternate, the order swapped every round and every campaign size (pool then
dask, dask then pool, ...), so that a change of the machine's other load falls on both. Per
executor and worker count, ``wall = a + b * N`` is fitted over every campaign timed (least
squares), and the same for the CPU time: ``a`` the fixed cost (start, warm-up, merge), ``b``
the cost of a run. The
overhead of dask is the median over the rounds of the ratio of the two executors' walls for
the same campaign. The target of issue 15: dask at most 10 % slower than the pool. On a
shared machine the figures move with the other load; the load average before and after is
printed.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import machine_line, markdown_table, write_section

SECTION = "Campaign throughput: local pool against dask LocalCluster (issue 15)"
EXECUTORS = {"pool": (), "dask": ("--cluster", "local")}


TABLE_HEADER = [
    "workers",
    "N runs",
    "pool wall, s (rounds)",
    "dask wall, s (rounds)",
    "sim s / wall s, pool / dask (medians)",
    "dask overhead, wall: median of the rounds (rounds)",
    "dask overhead, CPU (medians)",
]
FIT_HEADER = [
    "workers",
    "time",
    "pool",
    "dask LocalCluster",
    "fixed: dask - pool",
    "per run: dask / pool - 1",
]


def campaign_text(runs: int, duration_s: float) -> str:
    return f'scenarios = ["hall"]\nseed = 1\nseeds = {{ first = 0, count = {runs} }}\nduration_s = {duration_s}\n'


def timed_campaign(path: Path, executor: str, workers: int) -> tuple[float, float]:
    """Wall and CPU seconds of ``robotsim campaign path`` on ``executor`` (a new folder)."""
    with tempfile.TemporaryDirectory() as out:
        command = [
            sys.executable,
            "-m",
            "scenarios.cli",
            "campaign",
            str(path),
            "--out",
            str(Path(out) / "results"),
            "--workers",
            str(workers),
            *EXECUTORS[executor],
        ]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, timeout=3600)
        wall_s = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"campaign on {executor} failed: {done.stderr[-2000:]}")
    cpu_s = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return wall_s, cpu_s


def fit(points: list[tuple[int, float]]) -> tuple[float, float]:
    """``(a, b)`` of the least-squares line ``wall = a + b * runs`` through ``points``."""
    runs = np.array([n for n, _ in points], dtype=float)
    wall = np.array([w for _, w in points])
    b, a = np.polyfit(runs, wall, 1)
    return float(a), float(b)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, nargs="+", default=[8, 32], help="campaign sizes")
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--rounds", type=int, default=2, help="rounds per executor")
    parser.add_argument("--write", action="store_true", help="update this section of BENCHMARKS.md")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="campaign-bench-"))
    files = {}
    for runs in args.runs:
        files[runs] = folder / f"bench{runs}.toml"
        files[runs].write_text(campaign_text(runs, args.duration))
    # numba's cache warm (a first campaign compiles), not counted
    timed_campaign(files[min(args.runs)], "pool", 1)
    load_before = os.getloadavg()
    table, fits = [], []
    swap = 0
    for workers in args.workers:
        wall: dict[tuple[str, int], list[float]] = {}
        cpu: dict[tuple[str, int], list[float]] = {}
        for _ in range(args.rounds):
            for runs in args.runs:
                order = list(EXECUTORS) if swap % 2 == 0 else list(EXECUTORS)[::-1]
                swap += 1
                for executor in order:
                    w, c = timed_campaign(files[runs], executor, workers)
                    wall.setdefault((executor, runs), []).append(w)
                    cpu.setdefault((executor, runs), []).append(c)
                    print(
                        f"workers {workers}, {runs} runs, {executor}: wall {w:.2f} s, CPU "
                        f"{c:.2f} s, load {os.getloadavg()[0]:.1f}",
                        flush=True,
                    )
        for what, seconds in (("wall", wall), ("CPU", cpu)):
            lines = {
                executor: fit([(n, v) for n in args.runs for v in seconds[(executor, n)]])
                for executor in EXECUTORS
            }
            (a_pool, b_pool), (a_dask, b_dask) = lines["pool"], lines["dask"]
            fits.append(
                [
                    str(workers),
                    what,
                    f"{a_pool:.2f} + {b_pool:.3f} N",
                    f"{a_dask:.2f} + {b_dask:.3f} N",
                    f"{a_dask - a_pool:+.2f} s",
                    f"{(b_dask / b_pool - 1) * 100:+.0f} %",
                ]
            )
        for runs in args.runs:
            ratios = np.array(wall[("dask", runs)]) / np.array(wall[("pool", runs)])
            cpu_ratio = np.median(cpu[("dask", runs)]) / np.median(cpu[("pool", runs)])
            simulated = runs * args.duration
            table.append(
                [
                    str(workers),
                    str(runs),
                    " / ".join(f"{w:.1f}" for w in wall[("pool", runs)]),
                    " / ".join(f"{w:.1f}" for w in wall[("dask", runs)]),
                    f"{simulated / np.median(wall[('pool', runs)]):.0f} / "
                    f"{simulated / np.median(wall[('dask', runs)]):.0f}",
                    f"{(np.median(ratios) - 1) * 100:+.0f} % ("
                    + ", ".join(f"{(r - 1) * 100:+.0f} %" for r in ratios)
                    + ")",
                    f"{(cpu_ratio - 1) * 100:+.0f} %",
                ]
            )
    load_after = os.getloadavg()
    sizes = " ".join(map(str, args.runs))
    body = (
        f"`python benchmarks/campaign.py --runs {sizes} --duration {args.duration:g} "
        f"--workers {' '.join(map(str, args.workers))} --rounds {args.rounds}`: `robotsim "
        f"campaign` in a subprocess on a `hall` campaign of N runs x {args.duration:g} s "
        f"simulated, on the local pool and on a dask `LocalCluster` of the same number of "
        f"worker processes, alternating (the order swapped every campaign). Wall: what a user "
        f"waits for (start, imports, workers' start, warm-up on a warm cache, runs, merge); "
        f"CPU: the command and every process it started. Load average (1, 5, 15 min) before "
        f"{_load(load_before)}, after {_load(load_after)}. "
        f"{machine_line('numba', 'distributed', 'pyarrow')}."
        f"\n\n{markdown_table(TABLE_HEADER, table)}"
        f"\n\nFit over every campaign timed, seconds = a + b N:\n\n"
        f"{markdown_table(FIT_HEADER, fits)}"
    )
    print(body)
    if args.write:
        write_section(SECTION, body)
    return 0


def _load(values: tuple[float, float, float]) -> str:
    return ", ".join(f"{v:.1f}" for v in values)


if __name__ == "__main__":
    raise SystemExit(main())
