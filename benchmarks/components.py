"""Micro-benchmark: ``intervals.boxes.connected_components`` per call against the set size.

    python benchmarks/components.py [--sizes N ...] [--repeat R] [--compare DIR]

The boxes are pose cells of a regular paving (``(x, y, theta)`` cells of 1/16, exact binary
bounds, so that neighbours share faces, edges and corners, as SIVIA's do), ``N`` of them drawn
at random from a grid holding about ``1.4 N`` cells (several components, most of the cells in
one), the heading axis periodic. Reported per size: the best process CPU time of a call (the
best of ``--repeat`` rounds, each of enough calls for about 50 ms), and, for the largest size,
the peak memory the call adds to the process (``ru_maxrss`` after it, less before it; the boxes
are built first). Each source tree (this one and ``--compare DIR``) runs in a child process,
the trees one after the other.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from _common import code_label, machine_and_load, markdown_table

REPOSITORY = Path(__file__).resolve().parent.parent
SIZES = (10, 100, 1_000, 10_000, 100_000)
CELL = 1.0 / 16.0


def paving(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` cells ``(n, 3, 2)`` of a grid of about ``1.4 n`` cells, four times longer in x
    than in y and heading (module doc)."""
    side = max(2, int(np.ceil((1.4 * n / 4.0) ** (1.0 / 3.0))))
    shape = (4 * side, side, side)
    chosen = rng.choice(int(np.prod(shape)), size=n, replace=False)
    index = np.stack(np.unravel_index(chosen, shape), axis=-1).astype(float)
    low = index * CELL - [0.0, 0.0, np.pi]
    return np.stack([low, low + CELL], axis=-1)


def child(sizes: list[int], repeat: int) -> dict:
    """The figures of the code on ``sys.path`` (module doc)."""
    from intervals.boxes import connected_components

    rng = np.random.default_rng(1)
    connected_components(paving(10, rng), 2)  # compiles or loads the kernels, not timed
    cpu_ms = {}
    for n in sizes:
        boxes = paving(n, rng)
        start = time.process_time()
        connected_components(boxes, 2)
        calls = max(1, int(0.05 / max(time.process_time() - start, 1e-6)))
        best = np.inf
        for _ in range(repeat):
            start = time.process_time()
            for _ in range(calls):
                connected_components(boxes, 2)
            best = min(best, (time.process_time() - start) / calls)
        cpu_ms[str(n)] = 1e3 * best
    return {"cpu_ms": cpu_ms}


def child_memory(n: int) -> dict:
    """Peak memory in MiB that one call on ``n`` boxes adds (module doc), in a fresh process."""
    from intervals.boxes import connected_components

    rng = np.random.default_rng(1)
    connected_components(paving(10, rng), 2)
    boxes = paving(n, rng)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    count, _ = connected_components(boxes, 2)
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"peak_mib": (after - before) / 1024.0, "count": count}


def run_child(code: Path, arguments: list[str]) -> dict:
    """A child process importing the code tree ``code``: its JSON figures."""
    done = subprocess.run(
        [sys.executable, __file__, *arguments],
        env={**os.environ, "PYTHONPATH": str(code)},
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="box counts")
    parser.add_argument("--repeat", type=int, default=5, help="timed rounds a size (best kept)")
    parser.add_argument("--compare", type=Path, metavar="DIR", help="another source tree")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--memory", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.sizes, args.repeat)))
        return 0
    if args.memory:
        print(json.dumps(child_memory(args.memory)))
        return 0
    if not (all(n >= 1 for n in args.sizes) and args.repeat >= 1):
        parser.error("--sizes must be >= 1 and --repeat >= 1")
    trees = [REPOSITORY] + ([args.compare.resolve()] if args.compare else [])
    load_before = os.getloadavg()
    sizes = [str(n) for n in args.sizes]
    rows = []
    for tree in trees:
        got = run_child(tree, ["--child", "--sizes", *sizes, "--repeat", str(args.repeat)])
        memory = run_child(tree, ["--memory", sizes[-1]])
        times = [f"{got['cpu_ms'][n]:.3f}" for n in sizes]
        rows.append([code_label(tree), *times, f"{memory['peak_mib']:.1f}"])
        print(" | ".join(rows[-1]), file=sys.stderr, flush=True)
    load_after = os.getloadavg()
    header = ["code", *(f"N = {n} (ms)" for n in sizes), f"peak memory, N = {sizes[-1]} (MiB)"]
    print(markdown_table(header, rows))
    print("\n" + machine_and_load(load_before[0], load_after[0], "numba", "scipy"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
