"""Where the wall time of a run goes outside the interval epochs: a per-phase split.

    python benchmarks/run_phases.py [PLAN ...] [--duration S] [--rounds R] [--compare DIR]

Runs what ``robotsim run`` runs (``run_scenario`` with the scenario's own settings, closed
loop by default, then the rerun recording to a temporary file) on each plan (default:
``hall office_floor corridor apartment_lived_in``, 60 s simulated), in a child process per
code tree, and splits its wall time into phases by timing the functions that make them
(each phase is the time inside its functions minus the time of the other timed phases
they call; what no phase covers is "loop and rest": the physics loop's own Python, the
controller). Before the timed run, each child runs 3 s of ``hall`` and records it, so
that loading the compiled kernels and the recording's first-use imports are not counted.

With ``--compare DIR`` each round runs the plan with this checkout's code and then with
the code tree ``DIR`` (an export of another commit), side by side, and ``--rounds`` such
pairs are taken (default 3); each phase reports its least time over the rounds (on a
shared machine the least is the one the other processes disturbed least). ``--clock cpu``
times the process's CPU time instead of the wall (on a machine with more runnable
processes than cores, the wall time mostly measures the waiting).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import machine_line, markdown_table

REPOSITORY = Path(__file__).resolve().parent.parent
DEFAULT_PLANS = ("hall", "office_floor", "corridor", "apartment_lived_in")

#: Phase name -> the functions timed for it, as (module, owner or "", attribute); a
#: function a code tree lacks is skipped (older trees name some steps differently).
PHASES: dict[str, tuple[tuple[str, str, str], ...]] = {
    "interval epochs (tracker)": (("intervals.tracker", "IntervalTracker", "step"),),
    "pymunk step": (("robotsim.world", "World", "step"),),
    "pymunk state read": (("robotsim.world", "World", "state"),),
    "command limits": (("robotsim.simulation", "", "limit_command"),),
    "sensor stream (closed loop)": (("robotsim.simulation", "_SensorStream", "emit"),),
    "sonar ranges and readings": (("robotsim.simulation", "_SonarWorld", "scans"),),
    "localiser: odometry in": (
        ("localization.localizer", "OnlineLocalizer", "push_odometry_block"),
    ),
    "localiser: dead reckoning": (
        ("localization.localizer", "OnlineLocalizer", "_advance"),
        ("localization.localizer", "OnlineLocalizer", "estimate"),
        ("localization.localizer", "OnlineLocalizer", "pose"),
    ),
    "localiser: scan (components, records)": (
        ("localization.localizer", "OnlineLocalizer", "push_scan"),
        ("intervals.sonar.scan", "SonarScene", "scan"),
    ),
    "fusion": (("localization.localizer", "", "fuse"),),
    "epoch log and estimates": (("scenarios.runner", "", "gathered"),),
    "summary": (
        ("scenarios.runner", "", "summarize"),
        ("scenarios.runner", "", "estimation_summary"),
        ("scenarios.runner", "", "route_stats"),
        ("scenarios.runner", "", "safety_stats"),
    ),
    "recording": (("scenarios.recording", "", "write_recording"),),
}
REST = "loop and rest"


def _instrument(seconds: dict[str, float], clock) -> None:
    """Wrap each phase's functions so that their own time on ``clock`` (without the timed
    phases they call) adds up in ``seconds``."""
    import importlib

    inner: list[float] = []  # the timed time of the callees of each open call

    def timed(phase: str, function):
        @functools.wraps(function)
        def wrapper(*args, **kwargs):
            start = clock()
            inner.append(0.0)
            try:
                return function(*args, **kwargs)
            finally:
                elapsed = clock() - start
                seconds[phase] = seconds.get(phase, 0.0) + elapsed - inner.pop()
                if inner:
                    inner[-1] += elapsed

        return wrapper

    for phase, places in PHASES.items():
        for module_name, owner_name, attribute in places:
            module = importlib.import_module(module_name)
            owner = getattr(module, owner_name) if owner_name else module
            if hasattr(owner, attribute):
                setattr(owner, attribute, timed(phase, getattr(owner, attribute)))


#: The clocks ``--clock`` chooses from.
CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}


def child(plan: str, duration_s: float, clock_name: str = "wall") -> dict[str, float]:
    """The phase split of one run of ``plan`` (this process's code), seconds on the clock."""
    clock = CLOCKS[clock_name]
    seconds: dict[str, float] = {}
    _instrument(seconds, clock)
    from scenarios import recording, runner
    from scenarios.spec import load_scenario

    folder = REPOSITORY / "scenarios" / "builtin"  # this checkout's scenario files
    warm = load_scenario(str(folder / "hall.toml")).with_run(duration_s=3.0)
    warm_run = runner.run_scenario(warm)
    spec = load_scenario(str(folder / f"{plan}.toml")).with_run(duration_s=duration_s)
    with tempfile.TemporaryDirectory() as temporary:
        recording.write_recording(
            Path(temporary) / "warm.rrd", warm, warm_run.log, warm_run.estimation
        )
        seconds.clear()
        start = clock()
        result = runner.run_scenario(spec)
        recording.write_recording(Path(temporary) / "run.rrd", spec, result.log, result.estimation)
        whole = clock() - start
    seconds[REST] = whole - sum(seconds.values())
    seconds["whole"] = whole
    return seconds


def run_child(code: Path, plan: str, duration_s: float, clock: str) -> dict[str, float]:
    """:func:`child` in a process importing the code tree ``code``."""
    command = [sys.executable, __file__, "--child", plan, "--duration", str(duration_s)]
    command += ["--clock", clock]
    environment = {**os.environ, "PYTHONPATH": str(code)}
    done = subprocess.run(command, env=environment, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("plans", nargs="*", default=list(DEFAULT_PLANS))
    parser.add_argument("--duration", type=float, default=60.0, help="simulated seconds")
    parser.add_argument("--rounds", type=int, default=3, help="runs per code tree")
    parser.add_argument("--compare", type=Path, help="another code tree, run side by side")
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall", help="what is timed")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.duration, args.clock)))
        return 0
    trees = {"this checkout": REPOSITORY}
    if args.compare is not None:
        trees[args.compare.name] = args.compare.resolve()
    print(machine_line("numba", "pymunk", "rerun-sdk"))
    for plan in args.plans:
        best: dict[str, dict[str, float]] = {name: {} for name in trees}
        for _ in range(max(1, args.rounds)):
            for name, code in trees.items():  # interleaved: each round runs every tree
                for phase, value in run_child(code, plan, args.duration, args.clock).items():
                    best[name][phase] = min(best[name].get(phase, float("inf")), value)
        phases = [p for p in (*PHASES, REST) if any(p in b for b in best.values())]
        rows = [
            [phase, *(f"{1e3 * best[name].get(phase, 0.0):.0f}" for name in trees)]
            for phase in phases
        ]
        walls = [best[name]["whole"] for name in trees]
        rows.append([f"whole run ({args.clock}, least)", *(f"{1e3 * w:.0f}" for w in walls)])
        rows.append(["real-time factor", *(f"{args.duration / w:.1f}x" for w in walls)])
        print(
            f"\n{plan}, {args.duration:g} s simulated, {args.clock} time, least of "
            f"{args.rounds} (ms):\n"
        )
        print(markdown_table(["phase", *trees], rows))
    print("\n" + machine_line("numba", "pymunk", "rerun-sdk"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
