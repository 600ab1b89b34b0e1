"""Time and peak memory of one union-area call (``intervals.boxes.area_xy``) against the raster
it replaced, on ``N`` boxes, each measurement in a fresh process.

    python benchmarks/union_area.py [--sizes N ...] [--cap-gib G]

Two families of boxes in a 40 m x 40 m hall: ``distinct``, boxes of random corners and sizes
(every edge coordinate distinct: the raster has ``(2N + 1)^2`` cells, the worst case), and
``paving``, cells of a dyadic grid of 2^-6 m (a subpaving's coordinates: few distinct edges).
Each child builds its set, warms the kernel up on 10 boxes, then makes one call; it reports the
call's wall and CPU seconds and its peak memory (the process's peak resident set ``ru_maxrss``
after the call less its resident set just before). Its address space is capped at
``--cap-gib`` GiB, so a call asking for more fails with ``MemoryError`` (reported as such)
instead of exhausting the machine. The old and new children of one size run one after the
other.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np
from _common import machine_line

HALL_M = 40.0
GRID_M = 2.0**-6


def make_boxes(n: int, family: str) -> np.ndarray:
    """``n`` boxes ``(n, 3, 2)`` of the family (x, y in the hall; theta in [0, 0.1])."""
    rng = np.random.default_rng(n)
    if family == "distinct":
        lo = rng.uniform(0.0, HALL_M, (n, 2))
        hi = lo + rng.exponential(0.2, (n, 2))
    else:
        lo = rng.integers(0, int(HALL_M / GRID_M), (n, 2)) * GRID_M
        hi = lo + GRID_M * 2.0 ** rng.integers(0, 4, (n, 2))
    boxes = np.zeros((n, 3, 2))
    boxes[:, :2, 0], boxes[:, :2, 1], boxes[:, 2, 1] = lo, hi, 0.1
    return boxes


def resident_kib() -> int:
    """The process's resident set now, in KiB (``VmRSS`` of ``/proc/self/status``)."""
    with open("/proc/self/status") as status:
        line = next(line for line in status if line.startswith("VmRSS:"))
    return int(line.split()[1])


def child(impl: str, n: int, family: str, cap_gib: float) -> dict:
    """One measurement (run in its own process)."""
    cap = int(cap_gib * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    from intervals.boxes import area_xy
    from tests.intervals.test_union_area import raster_area

    fn = area_xy if impl == "new" else raster_area
    boxes = make_boxes(n, family)
    fn(make_boxes(10, family))
    before_kib = resident_kib()
    wall, cpu = time.perf_counter(), time.process_time()
    try:
        area = fn(boxes)
    except MemoryError:
        return {"status": f"MemoryError (cap {cap_gib:g} GiB)"}
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before_kib
    return {
        "status": "ok",
        "wall_s": wall,
        "cpu_s": cpu,
        "peak_mib": max(peak_kib, 0) / 1024,
        "area": area,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 5000, 10000])
    parser.add_argument("--cap-gib", type=float, default=6.0)
    parser.add_argument("--child", nargs=3, metavar=("IMPL", "N", "FAMILY"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        impl, n, family = args.child
        print(json.dumps(child(impl, int(n), family, args.cap_gib)))
        return
    print(machine_line("numba"))
    print("| family | N | code | wall s | CPU s | peak MiB | area m^2 |")
    print("|---|---:|---|---:|---:|---:|---:|")
    for family in ("distinct", "paving"):
        for n in args.sizes:
            for impl in ("raster", "new"):
                cmd = [sys.executable, __file__, "--child", impl, str(n), family]
                out = subprocess.run(
                    cmd + ["--cap-gib", str(args.cap_gib)], capture_output=True, text=True
                )
                r = (
                    json.loads(out.stdout.splitlines()[-1])
                    if out.returncode == 0
                    else {"status": out.stderr[-200:]}
                )
                if r["status"] != "ok":
                    print(f"| {family} | {n} | {impl} | {r['status']} | | | |")
                    continue
                print(
                    f"| {family} | {n} | {impl} | {r['wall_s']:.4f} | {r['cpu_s']:.4f} "
                    f"| {r['peak_mib']:.1f} | {r['area']:.17g} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
