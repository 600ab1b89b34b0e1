"""Benchmark: the tightening pass's cost a piece, on its recorded calls, against another tree.

    python benchmarks/tighten_pass.py [PLAN ...] [--duration S] [--set KEY=VALUE]
                                      [--compare DIR] [--rounds R] [--alternations A]

For each plan (default: corridor, office_floor, symmetric, hall, apartment) a child process
steps the tracker over ``--duration`` simulated seconds as ``benchmarks/tracking_epochs.py``
does (its scenario loading, with the ``[estimation]`` changes of ``--set``; default
``tighten_levels=12``, the 2000-piece default budget), recording the arguments of every call
of :func:`intervals.tighten.tighten` that :func:`intervals.localize.localize` makes (the
tests and contractor it is handed keep their scan), then replays those calls ``--rounds``
times and keeps the best round's process CPU time and wall time: the whole pass (bisection,
piece test, in-room test, contractor, numpy glue), divided by the pieces the pass tested.
With ``--compare DIR`` the same is done with another source tree's code, the two trees
alternating plan by plan, ``--alternations`` times (the best of each kept), and the digests of
the replayed outputs (boxes and counts of every call) are compared: equal digests, the same
sets.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import code_label, machine_and_load, markdown_table

REPOSITORY = Path(__file__).resolve().parent.parent
SCENARIO_FOLDER = REPOSITORY / "scenarios" / "builtin"
PLANS = ("corridor", "office_floor", "symmetric", "hall", "apartment")


def child(plan: str, duration_s: float, changes: dict, rounds: int, out: Path) -> int:
    """Record one plan's tightening calls and replay them with the code on ``sys.path``."""
    import intervals.localize as localize
    from intervals.sonar.scan import SonarBelt, SonarScene
    from intervals.tracker import IntervalTracker
    from scenarios.runner import simulate_spec
    from scenarios.spec import parse_scenario

    path = SCENARIO_FOLDER / f"{plan}.toml"
    text = path.read_text(encoding="utf-8")
    spec = parse_scenario(text, source=str(path), base_dir=path.parent, name=plan)
    spec = spec.with_run(duration_s=duration_s).with_estimation(**changes)
    est = spec.estimation
    belt = SonarBelt.from_params(spec.sensors.sonar, echoes_never_lost=est.free_space)
    scene = SonarScene(spec.map.segments, belt, spec.map.boundary)
    tracker = IntervalTracker(est.intervals, spec.map.bounds)
    log = simulate_spec(spec)
    tighten, calls = localize.tighten, []

    def recording(*args, **kwargs):
        calls.append((args, kwargs))
        return tighten(*args, **kwargs)

    localize.tighten = recording
    scans = np.arange(0, len(log.sonar_t_s), est.scan_stride(spec.sensors.sonar.rate_hz))
    previous, refinement, last_t = None, None, log.sonar_t_s[scans[0]]
    for index in scans:
        dt_s, last_t = float(log.sonar_t_s[index] - last_t), log.sonar_t_s[index]
        result = tracker.step(previous, scene.scan(log.sonar_range_m[index]), dt_s, refinement)
        previous, refinement = result.paving, result.refinement
    localize.tighten = tighten
    digest, tested = hashlib.sha256(), 0
    for args, kwargs in calls:  # also compiles every kernel before the timed rounds
        boxes, counts, seen = tighten(*args, **kwargs)
        digest.update(np.ascontiguousarray(boxes).tobytes())
        digest.update(np.asarray(counts, dtype=np.int64).tobytes())
        tested += seen
    cpu_s, wall_s = np.inf, np.inf
    for _ in range(rounds):
        cpu, wall = time.process_time(), time.perf_counter()
        for args, kwargs in calls:
            tighten(*args, **kwargs)
        cpu_s = min(cpu_s, time.process_time() - cpu)
        wall_s = min(wall_s, time.perf_counter() - wall)
    figures = {"calls": len(calls), "pieces": tested, "cpu_s": cpu_s, "wall_s": wall_s}
    figures["digest"] = digest.hexdigest()[:10]
    out.write_text(json.dumps(figures), encoding="utf-8")
    return 0


def run_child(plan: str, args, code: Path, changes: dict) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "figures.json"
        command = [sys.executable, __file__, "--child", plan, "--duration", str(args.duration)]
        command += ["--rounds", str(args.rounds), "--out", str(out)]
        for key, value in changes.items():
            command += ["--set", f"{key}={json.dumps(value)}"]
        env = {**os.environ, "PYTHONPATH": str(code)}
        subprocess.run(command, env=env, check=True)
        return json.loads(out.read_text(encoding="utf-8"))


def _per_piece(got: dict) -> str:
    pieces = max(got["pieces"], 1)
    return f"{got['cpu_s'] / pieces * 1e6:.3f} / {got['wall_s'] / pieces * 1e6:.3f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("plans", nargs="*", help=f"built-in scenarios (default: {' '.join(PLANS)})")
    parser.add_argument("--duration", type=float, default=20.0, help="simulated seconds")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--compare", type=Path, metavar="DIR", help="another source tree")
    parser.add_argument("--rounds", type=int, default=3, help="replays in a child (best kept)")
    parser.add_argument("--alternations", type=int, default=3, help="children per plan and tree")
    parser.add_argument("--child", metavar="PLAN", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    changes: dict = {"tighten_levels": 12}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            parser.error(f"--set {item}: expected KEY=VALUE")
        changes[key] = json.loads(value)
    if args.child:
        return child(args.child, args.duration, changes, args.rounds, args.out)
    if not (args.duration > 0 and args.rounds >= 1 and args.alternations >= 1):
        parser.error("--duration must be > 0, --rounds and --alternations >= 1")
    trees = [REPOSITORY] + ([args.compare.resolve()] if args.compare else [])
    labels = [code_label(tree) for tree in trees]
    load_before = os.getloadavg()[0]
    rows = []
    for plan in args.plans or PLANS:
        best: list[dict | None] = [None] * len(trees)
        for _ in range(args.alternations):
            for t, tree in enumerate(trees):
                got = run_child(plan, args, tree, changes)
                old = best[t]
                if old is None:
                    best[t] = got
                else:
                    old["cpu_s"] = min(old["cpu_s"], got["cpu_s"])
                    old["wall_s"] = min(old["wall_s"], got["wall_s"])
        figures = [b for b in best if b is not None]
        row = [plan, f"{figures[0]['calls']} / {figures[0]['pieces']}"]
        row += [_per_piece(f) for f in figures]
        if len(figures) == 2:
            row.append(f"{figures[1]['cpu_s'] / figures[0]['cpu_s']:.2f}")
            row.append("equal" if figures[0]["digest"] == figures[1]["digest"] else "DIFFER")
        else:
            row.append(figures[0]["digest"])
        rows.append(row)
        print(" | ".join(row), file=sys.stderr, flush=True)
    header = ["plan", "calls / pieces tested"]
    header += [f"{label}: us a piece, CPU / wall" for label in labels]
    header += ["CPU ratio", "digests"] if len(trees) == 2 else ["digest"]
    print(markdown_table(header, rows))
    print("\n" + machine_and_load(load_before, os.getloadavg()[0], "numba"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
