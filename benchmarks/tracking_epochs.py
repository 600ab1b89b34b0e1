"""Benchmark: the interval tracker's epochs on built-in plans, in CPU time, side by side.

    python benchmarks/tracking_epochs.py [PLAN ...] [--duration S] [--repeat R] [--compare DIR]

For each plan (default: corridor, office_floor, symmetric, hall, apartment) the scenario is
simulated for ``--duration`` seconds (open loop: the robot follows its route on the true
pose) and the tracker of its ``[estimation]`` settings is stepped on the scans, as
``robotsim run`` steps it (:class:`intervals.tracker.IntervalTracker`, previous set and
refinement carried from epoch to epoch). Each epoch is run ``--repeat`` times on the same
input and its best *process CPU time* kept: on a machine shared with other jobs the wall
time of a few-millisecond epoch mostly measures the other jobs (``benchmarks/buildings.py``
reports wall time, for the whole pipeline). Reported per plan: the tracking epochs' median,
95th percentile and largest CPU time, the mean (x, y) area of the sets, how many sets hold
the true pose, and a digest of every epoch's set (equal digests: the same boxes).
A plan may be a variant of a built-in one, ``"PLAN[, lost_echo_prob P][, seed N]"``
(``"hall, lost_echo_prob 0.5, seed 2"``), as in ``benchmarks/buildings.py``.

``--set KEY=VALUE`` (repeatable) replaces a key of the scenarios' ``[estimation]`` table in
every run (the value read as JSON: ``--set tighten_levels=6``), for both trees.

``--compare DIR`` runs each plan a second time with another source tree's code (a checkout
of another commit; the scenario files are always this checkout's), one child process per
plan and tree, the trees interleaved plan by plan.
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
from _common import (
    add_set_argument,
    code_label,
    load_variant,
    machine_and_load,
    markdown_table,
    parsed_settings,
    settings_arguments,
)

REPOSITORY = Path(__file__).resolve().parent.parent
SCENARIO_FOLDER = REPOSITORY / "scenarios" / "builtin"
PLANS = ("corridor", "office_floor", "symmetric", "hall", "apartment")


def child(plan: str, duration_s: float, repeat: int, out: Path, changes: dict | None = None) -> int:
    """Step the tracker on one plan's scans with the code on ``sys.path``; figures to ``out``;
    ``changes``: keys of ``[estimation]`` replaced in the plan's scenario."""
    from intervals.sonar.scan import SonarBelt, SonarScene
    from intervals.tracker import IntervalTracker
    from scenarios.runner import simulate_spec

    def load(name: str, seconds: float):
        spec = load_variant(name, SCENARIO_FOLDER).with_run(duration_s=seconds)
        return spec.with_estimation(**(changes or {}))

    def epochs(spec, rounds: int):
        est = spec.estimation
        belt = SonarBelt.from_params(spec.sensors.sonar, echoes_never_lost=est.free_space)
        scene = SonarScene(spec.map.segments, belt, spec.map.boundary)
        tracker = IntervalTracker(est.intervals, spec.map.bounds)
        log = simulate_spec(spec)
        scans = np.arange(0, len(log.sonar_t_s), est.scan_stride(spec.sensors.sonar.rate_hz))
        previous, refinement, last_t = None, None, log.sonar_t_s[scans[0]]
        for index in scans:
            scan = scene.scan(log.sonar_range_m[index])
            dt_s, last_t = float(log.sonar_t_s[index] - last_t), log.sonar_t_s[index]
            best_s, result = np.inf, None
            for _ in range(rounds):
                start = time.process_time()
                result = tracker.step(previous, scan, dt_s, refinement)
                best_s = min(best_s, time.process_time() - start)
            assert result is not None
            previous, refinement = result.paving, result.refinement
            yield result, best_s, log.sonar_pose[index]

    for _ in epochs(load("hall", 3.0), 1):  # loads the compiled kernels, not timed
        pass
    cpu_ms, areas, held, coarse, digest = [], [], 0, 0, hashlib.sha256()
    for result, best_s, truth in epochs(load(plan, duration_s), repeat):
        if result.status == "tracking":
            cpu_ms.append(1e3 * best_s)
        if result.paving is not None:
            areas.append(result.paving.area_xy())
            coarse += int(result.coarse)
            held += int(result.paving.contains(truth[None])[0])
            digest.update(np.ascontiguousarray(result.paving.outer).tobytes())
        digest.update(str(result.status).encode())
    figures = {
        "epochs": len(areas),
        "mean_ms": float(np.mean(cpu_ms)),
        "median_ms": float(np.median(cpu_ms)),
        "p95_ms": float(np.percentile(cpu_ms, 95)),
        "max_ms": float(np.max(cpu_ms)),
        "mean_area_m2": float(np.mean(areas)),
        "held": held,
        "coarse": coarse,
        "digest": digest.hexdigest()[:10],
    }
    out.write_text(json.dumps(figures), encoding="utf-8")
    return 0


def run_child(
    plan: str, duration_s: float, repeat: int, code: Path, changes: dict | None = None
) -> dict | str:
    """One plan in a child process importing the code tree ``code``: its figures, or the last
    line of its error."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "figures.json"
        command = [sys.executable, __file__, "--child", plan, "--duration", str(duration_s)]
        command += ["--repeat", str(repeat), "--out", str(out)]
        command += settings_arguments(changes or {})
        done = subprocess.run(
            command,
            env={**os.environ, "PYTHONPATH": str(code)},
            capture_output=True,
            text=True,
            check=False,
        )
        if done.returncode != 0 or not out.is_file():
            lines = done.stderr.strip().splitlines()
            return f"failed (exit {done.returncode}: {lines[-1] if lines else 'no message'})"
        return json.loads(out.read_text(encoding="utf-8"))


HEADER = [
    "plan",
    "code",
    "tracking CPU median / p95 / max (ms)",
    "mean set area (m²)",
    "sets holding the truth",
    "sets digest",
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "plans",
        nargs="*",
        help=f"built-in scenarios or benchmarks/buildings.py variants (default: {' '.join(PLANS)})",
    )
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each epoch (best kept)")
    parser.add_argument("--compare", type=Path, metavar="DIR", help="another source tree")
    add_set_argument(parser)
    parser.add_argument("--child", metavar="PLAN", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    changes = parsed_settings(parser, args.set)
    if args.child:
        return child(args.child, args.duration, args.repeat, args.out, changes)
    if not (args.duration > 0 and args.repeat >= 1):
        parser.error("--duration must be > 0 and --repeat >= 1")
    trees = [REPOSITORY]
    if args.compare:
        if not (args.compare / "intervals" / "tracker.py").is_file():
            parser.error(f"--compare {args.compare}: not a source tree (no intervals/tracker.py)")
        trees.append(args.compare.resolve())
    labels = {tree: code_label(tree) for tree in trees}
    load_before = os.getloadavg()
    rows = []
    for plan in args.plans or PLANS:
        for tree in trees:
            got = run_child(plan, args.duration, args.repeat, tree, changes)
            if isinstance(got, str):
                rows.append([plan, labels[tree], got, "-", "-", "-"])
            else:
                rows.append(
                    [
                        plan,
                        labels[tree],
                        f"{got['median_ms']:.1f} / {got['p95_ms']:.1f} / {got['max_ms']:.1f}",
                        f"{got['mean_area_m2']:.4f}",
                        f"{got['held']} / {got['epochs']}",
                        got["digest"],
                    ]
                )
            print(" | ".join(rows[-1]), file=sys.stderr, flush=True)
    load_after = os.getloadavg()
    print(markdown_table(HEADER, rows))
    print("\n" + machine_and_load(load_before[0], load_after[0], "numba"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
