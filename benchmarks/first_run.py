"""First run: the CLI's start-up and the first ``robotsim run`` after an install, cold and
warmed up (issue 17).

Every figure is one new process on a code tree (its ``PYTHONPATH``); an empty folder as
``NUMBA_CACHE_DIR`` stands for a fresh install (numba's disk cache empty; Python's byte code
is there, as pip compiles it). Wall time and CPU time (user + system of the child) of:

- start-up: ``python -c "import scenarios.cli"``, ``robotsim --help``, ``robotsim scenarios``
  (best of ``--repeats``);
- cold: ``robotsim run hall --duration D`` twice in an empty cache (the first compiles);
- warmed: ``robotsim warmup`` in another empty cache, then the same run twice (target: the
  first within 2x of the second);
- the first compiled UKF step (CTRV, predict and GPS update) and EKF step of a new process,
  in an empty cache and after the warm-up (the imports not counted).

``--compare TREE``: the start-up and the cold runs of another code tree (a clone of the code
before) too, each figure interleaved with this tree's (it has no warm-up command).

    python benchmarks/first_run.py [--duration 10] [--repeats 5] [--compare TREE
                                   [--compare-label TEXT]] [--write]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import machine_line, markdown_table, write_section

TREE = Path(__file__).resolve().parent.parent

#: A filter step in a new process: prints the wall and CPU seconds of its first step (the
#: imports excluded).
STEP = """
import json, time
import numpy as np
from localization.ekf import ExtendedKalmanFilter
from localization.gaussian import Gaussian
from localization.motion_models import CTRV, gps_model
from localization.ukf import UnscentedKalmanFilter
kalman = {kind}()
belief = Gaussian(np.array([0.0, 0.0, 0.1, 1.0, 0.0]), 0.1 * np.eye(5), CTRV.angle_indices)
process, gps = CTRV.process_model(0.01 * np.eye(5)), gps_model(np.eye(2))
start, cpu = time.perf_counter(), time.process_time()
kalman.update(kalman.predict(belief, process, 0.01), np.zeros(2), gps)
print(json.dumps([time.perf_counter() - start, time.process_time() - cpu]))
"""


def measure(args: list[str], tree: Path, cache: Path, cwd: Path) -> tuple[float, float, str]:
    """``(wall s, CPU s, stdout)`` of ``python ARGS`` on ``tree`` with numba's cache ``cache``."""
    environment = {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": str(cache)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, env=environment, cwd=cwd
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(args)} on {tree} failed: {done.stderr.strip()[-500:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done.stdout


def cell(wall: float, cpu: float) -> str:
    return f"{wall:.2f} / {cpu:.2f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="simulated s of the runs")
    parser.add_argument("--repeats", type=int, default=5, help="start-up: best of this many")
    parser.add_argument("--compare", type=Path, help="another code tree, measured alongside")
    parser.add_argument("--compare-label", default="compared tree", help="its column's title")
    parser.add_argument("--write", action="store_true", help="write the section of BENCHMARKS.md")
    args = parser.parse_args()
    trees = {"this tree": TREE} | ({args.compare_label: args.compare} if args.compare else {})
    machine = machine_line("numba")
    rows: list[list[str]] = []
    with tempfile.TemporaryDirectory() as scratch:
        work = Path(scratch)
        empty = {name: work / f"cache-{i}" for i, name in enumerate(trees)}
        for cache in empty.values():
            cache.mkdir()
        startup = {
            "`import scenarios.cli`": ["-c", "import scenarios.cli"],
            "`robotsim --help`": ["-m", "scenarios.cli", "--help"],
            "`robotsim scenarios`": ["-m", "scenarios.cli", "scenarios"],
        }
        for label, command in startup.items():
            best = {name: (float("inf"), float("inf")) for name in trees}
            for _ in range(args.repeats):  # interleaved: one of each tree in turn
                for name, tree in trees.items():
                    wall, cpu, _ = measure(command, tree, empty[name], work)
                    best[name] = (min(best[name][0], wall), min(best[name][1], cpu))
            rows.append([label, *(cell(*best[name]) for name in trees)])

        run = ["-m", "scenarios.cli", "run", "hall", "--duration", f"{args.duration:g}"]
        run += ["--rrd", "h.rrd", "--summary", "h.json"]
        label = f"`robotsim run hall --duration {args.duration:g}`"
        cold: dict[str, list[tuple[float, float]]] = {name: [] for name in trees}
        for which in ("first", "second"):
            for name, tree in trees.items():
                wall, cpu, _ = measure(run, tree, empty[name], work)
                cold[name].append((wall, cpu))
            rows.append([f"{label}, {which}, empty cache", *(cell(*cold[n][-1]) for n in trees)])

        blank = [""] * (len(trees) - 1)
        warmed = work / "cache-warmed"
        warmed.mkdir()
        steps_cold = {}
        for kind in ("UnscentedKalmanFilter", "ExtendedKalmanFilter"):
            cache = work / f"cache-{kind}"  # one each: no kernel compiled for the other
            cache.mkdir()
            steps_cold[kind] = json.loads(
                measure(["-c", STEP.format(kind=kind)], TREE, cache, work)[2]
            )
        wall, cpu, _ = measure(["-m", "scenarios.cli", "warmup"], TREE, warmed, work)
        rows.append(["`robotsim warmup`, empty cache", cell(wall, cpu), *blank])
        after = [measure(run, TREE, warmed, work)[:2] for _ in range(2)]
        rows.append([f"{label}, first after the warm-up", cell(*after[0]), *blank])
        rows.append([f"{label}, second after the warm-up", cell(*after[1]), *blank])
        ratio = f"{after[0][0] / after[1][0]:.2f} / {after[0][1] / after[1][1]:.2f}"
        rows.append(["first / second after the warm-up", ratio, *blank])
        for kind, name in (("UnscentedKalmanFilter", "UKF"), ("ExtendedKalmanFilter", "EKF")):
            warm = json.loads(measure(["-c", STEP.format(kind=kind)], TREE, warmed, work)[2])
            label = f"first compiled {name} step (CTRV) of a process"
            rows.append([f"{label}, empty cache", cell(*steps_cold[kind]), *blank])
            rows.append([f"{label}, after the warm-up", cell(*warm), *blank])
    header = ["figure (wall s / CPU s)", *trees]
    body = "\n\n".join(
        [
            "`python benchmarks/first_run.py"
            + (f" --compare TREE --compare-label '{args.compare_label}'" if args.compare else "")
            + f" --duration {args.duration:g} --repeats {args.repeats}`; each figure a new process,"
            " numba's cache an empty folder (a fresh install) unless warmed; wall and CPU time"
            " (user + system) of the process.",
            markdown_table(header, rows),
            f"Machine: {machine}; load {os.getloadavg()[0]:.1f} at the end.",
        ]
    )
    print(body)
    if args.write:
        write_section("First run (issue 17)", body)
    return 0


if __name__ == "__main__":
    sys.exit(main())
