"""Benchmark of ``robotsim run``: simulate a scenario and write its recording, stage by stage.

    python benchmarks/simulation.py [SCENARIO] [--duration S] [--repeat R]

Times the work of ``robotsim run`` (default: ``hall``, 600 s of robot time, all sensors):
loading the scenario, the simulation, the summary, and the rerun recording written to a
temporary file. Prints the wall time, the real-time factor (simulated seconds per wall
second) and each stage's share, for the first (cold) run and the best of ``R`` repeats.
The target of issue 2: 600 s simulated in at most 3 s of wall time, recording included.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from scenarios.metrics import summarize
from scenarios.recording import write_recording
from scenarios.runner import simulate_spec
from scenarios.spec import load_scenario


def time_stages(scenario: str, duration_s: float) -> dict[str, float]:
    """Wall seconds of each stage of one ``robotsim run`` of ``scenario`` for ``duration_s``."""
    stages: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        stages[name] = now - clock
        clock = now

    spec = load_scenario(scenario).with_run(duration_s=duration_s)
    lap("load scenario")
    log = simulate_spec(spec)
    lap("simulate")
    summarize(spec, log)
    lap("summary")
    with tempfile.TemporaryDirectory() as folder:
        write_recording(Path(folder) / "run.rrd", spec, log)
        lap("recording")
    return stages


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="hall")
    parser.add_argument(
        "--duration", type=float, default=600.0, help="simulated seconds (default: %(default)s)"
    )
    parser.add_argument(
        "--repeat", type=int, default=3, help="repeats, best kept per stage (default: %(default)s)"
    )
    args = parser.parse_args(argv)

    runs = [time_stages(args.scenario, args.duration) for _ in range(args.repeat)]
    first = runs[0]
    best = {name: min(run[name] for run in runs) for name in first}
    print(
        f"robotsim run {args.scenario}: {args.duration:g} s simulated; "
        f"first run (cold, as one command) and best of {args.repeat}"
    )
    print(f"{'stage':<16}{'first s':>10}{'best s':>10}{'share':>9}")
    for name in first:
        print(
            f"{name:<16}{first[name]:>10.3f}{best[name]:>10.3f}{best[name] / sum(best.values()):>9.1%}"
        )
    print(f"{'total':<16}{sum(first.values()):>10.3f}{sum(best.values()):>10.3f}{1:>9.0%}")
    print(
        f"realtime factor: {args.duration / sum(first.values()):.0f}x first, "
        f"{args.duration / sum(best.values()):.0f}x best"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
