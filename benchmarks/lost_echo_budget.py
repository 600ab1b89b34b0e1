"""Benchmark: the tracking budget of a belt that may lose its echoes, swept.

    python benchmarks/lost_echo_budget.py [BUDGET ...] [--plan PLAN] [--duration S] [--repeat R]

For each budget (SIVIA tests of a tracking epoch, default 40000 4000 2000 1000 800 600 500)
one child process sets :data:`intervals.tracker.LOST_ECHO_TRACKING_TESTS` to it and steps the
tracker on ``--plan`` (default ``big_hall, lost_echo_prob 0.5``; any built-in plan or variant
``"PLAN[, lost_echo_prob P][, seed N]"``, as in ``benchmarks/buildings.py``) as
``benchmarks/tracking_epochs.py`` does (:func:`tracking_epochs.child`: each epoch run
``--repeat`` times, its best process CPU time kept). Reported per budget: the tracking epochs'
CPU mean / median / p95 / max, the mean (x, y) set area, the sets holding the truth, the coarse
epochs and the sets' digest. 40 000 is the budget of a belt that never loses its echoes at the
default ``max_boxes`` (:data:`intervals.tracker.TRACKING_MIN_TESTS`).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import code_label, machine_and_load, markdown_table

REPOSITORY = Path(__file__).resolve().parent.parent
BUDGETS = (40_000, 4000, 2000, 1000, 800, 600, 500)

HEADER = [
    "tests per tracking epoch",
    "tracking CPU mean / median / p95 / max (ms)",
    "mean set area (m²)",
    "sets holding the truth",
    "coarse epochs",
    "sets digest",
]


def child(budget: int, plan: str, duration_s: float, repeat: int, out: Path) -> int:
    """One budget: :func:`tracking_epochs.child` with the lost-echo budget set to ``budget``."""
    import tracking_epochs

    from intervals import tracker

    tracker.LOST_ECHO_TRACKING_TESTS = budget
    return tracking_epochs.child(plan, duration_s, repeat, out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("budgets", nargs="*", type=int, help=f"default: {BUDGETS}")
    parser.add_argument("--plan", default="big_hall, lost_echo_prob 0.5")
    parser.add_argument("--duration", type=float, default=60.0, help="simulated seconds")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each epoch (best kept)")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        return child(args.child, args.plan, args.duration, args.repeat, args.out)
    load_before = os.getloadavg()
    rows = []
    for budget in args.budgets or BUDGETS:
        with tempfile.TemporaryDirectory() as folder:
            out = Path(folder) / "figures.json"
            command = [sys.executable, __file__, "--child", str(budget), "--plan", args.plan]
            command += ["--duration", str(args.duration), "--repeat", str(args.repeat)]
            command += ["--out", str(out)]
            done = subprocess.run(command, capture_output=True, text=True, check=False)
            if done.returncode != 0 or not out.is_file():
                lines = done.stderr.strip().splitlines()
                rows.append([str(budget), f"failed: {lines[-1] if lines else done.returncode}"])
                rows[-1] += ["-"] * (len(HEADER) - 2)
            else:
                got = json.loads(out.read_text(encoding="utf-8"))
                cpu = (got[k] for k in ("mean_ms", "median_ms", "p95_ms", "max_ms"))
                rows.append(
                    [
                        str(budget),
                        " / ".join(f"{ms:.1f}" for ms in cpu),
                        f"{got['mean_area_m2']:.1f}",
                        f"{got['held']} / {got['epochs']}",
                        str(got["coarse"]),
                        got["digest"],
                    ]
                )
        print(" | ".join(rows[-1]), file=sys.stderr, flush=True)
    load_after = os.getloadavg()
    print(f"`{args.plan}`, {args.duration:g} s, code {code_label(REPOSITORY)}:\n")
    print(markdown_table(HEADER, rows))
    print("\n" + machine_and_load(load_before[0], load_after[0], "numba"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
