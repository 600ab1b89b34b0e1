"""The closed loop over many seeds: which pose the route's controller steers on, and how the
route goes.

    python benchmarks/closed_loop.py [--scenarios hall office apartment] [--seeds 10]
        [--follow estimate ukf_only] [--duration 600] [--out runs/closed_loop.jsonl]

For each scenario, each ``[route] follow`` and each seed (0 to ``--seeds - 1``) it runs
the built-in scenario with ``follow`` set in its ``[route]`` table (so the file's defaults
for that choice apply, the fusion rule included: ``scenarios.spec.default_fusion``), and
writes one JSON line per run to ``--out`` (the figures below), then prints one table row
per scenario and ``follow``: the runs whose interval sets always held the truth
(containment 1), the runs that did at least one lap of the route without touching a wall,
the median and worst path-following error (the true position's distance to the route's
polyline, m), the median laps, the wall contacts (pymunk contact steps, summed) and the
median fused and UKF-only position RMSE. Every figure of the sweep is deterministic (same
scenario and seed, same line).

    python benchmarks/closed_loop.py --timing [--scenarios hall] [--duration 600] [--repeat 3]

times instead, interleaved round by round on the first scenario, seed 0, the whole run
(simulation, estimation, summary; no recording) three ways: steered on the truth with the
online localiser fed the finished log (``follow = "truth"``), the same with the batch
pipeline on the finished arrays (``scenarios.pipeline.estimate_offline``), and the closed
loop (``follow = "estimate"``: the simulator and the localiser stepped together). Prints the
median wall time and real-time factor of each, and the ratios to the first.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

from scenarios.metrics import summarize
from scenarios.pipeline import estimate_offline, estimation_summary
from scenarios.runner import run_scenario, simulate_spec
from scenarios.spec import BUILTIN_FOLDER, Follow, scenario_from_tables
from validated_records import choices


def spec_for(name: str, follow: str, seed: int, duration_s: float):
    """The built-in scenario ``name`` with ``[route] follow`` set, at ``seed`` and ``duration_s``."""
    path = Path(str(BUILTIN_FOLDER / f"{name}.toml"))
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    data.setdefault("route", {})["follow"] = follow
    spec = scenario_from_tables(data, source=str(path), base_dir=path.parent, name=name)
    return spec.with_run(seed=seed, duration_s=duration_s)


def figures(name: str, follow: str, seed: int, duration_s: float) -> dict:
    """The figures of one run (one JSON line)."""
    summary = run_scenario(spec_for(name, follow, seed, duration_s)).summary
    route = summary["route"]
    return {
        "scenario": name,
        "follow": follow,
        "seed": seed,
        "duration_s": duration_s,
        "containment": summary["containment"],
        "inconsistent_epochs": summary["inconsistent_epochs"],
        "laps": route["laps"],
        "waypoints_reached": route["waypoints_reached"],
        "path_error_mean_m": route["path_error_m"]["mean"],
        "path_error_max_m": route["path_error_m"]["max"],
        "contact_steps": summary["walls"]["pymunk_contact_steps"],
        "min_gap_m": summary["walls"]["min_gap_m"],
        "rmse_fused_m": summary["rmse_position_m"]["fused"],
        "rmse_ukf_only_m": summary["rmse_position_m"]["ukf_only"],
    }


def table(rows: list[dict]) -> str:
    """One markdown row per (scenario, follow) of the runs ``rows``."""
    lines = [
        "| scenario | follow | runs | containment 1 | lap without contact | path error median / worst (m) "
        "| laps median | contact steps | RMSE fused / UKF-only median (m) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    keys = dict.fromkeys((r["scenario"], r["follow"]) for r in rows)
    for name, follow in keys:
        runs = [r for r in rows if r["scenario"] == name and r["follow"] == follow]
        held = sum(r["containment"] == 1.0 for r in runs)
        clean = sum((r["laps"] or 0) >= 1 and r["contact_steps"] == 0 for r in runs)
        error = [r["path_error_max_m"] for r in runs]
        lines.append(
            f"| {name} | {follow} | {len(runs)} | {held} | {clean} "
            f"| {np.median([r['path_error_mean_m'] for r in runs]):.3f} / {max(error):.2f} "
            f"| {np.median([r['laps'] or 0 for r in runs]):g} "
            f"| {sum(r['contact_steps'] for r in runs)} "
            f"| {np.median([r['rmse_fused_m'] for r in runs]):.3f} / "
            f"{np.median([r['rmse_ukf_only_m'] for r in runs]):.2f} |"
        )
    return "\n".join(lines)


def offline_run(spec) -> None:
    """The open-loop run with the batch pipeline: simulate, estimate on the arrays, summarise."""
    log = simulate_spec(spec)
    estimation, _ = estimate_offline(spec, log)
    summarize(spec, log).update(estimation_summary(log, estimation))


def timing(name: str, duration_s: float, repeat: int) -> str:
    """The three ways of running ``name`` timed round by round (module docstring)."""
    ways = {
        "open loop, online localiser (follow = truth)": lambda: run_scenario(
            spec_for(name, "truth", 0, duration_s)
        ),
        "open loop, batch pipeline": lambda: offline_run(spec_for(name, "truth", 0, duration_s)),
        "closed loop (follow = estimate)": lambda: run_scenario(
            spec_for(name, "estimate", 0, duration_s)
        ),
    }
    walls: dict[str, list[float]] = {way: [] for way in ways}
    for _ in range(max(1, repeat)):
        for way, run in ways.items():
            start = time.perf_counter()
            run()
            walls[way].append(time.perf_counter() - start)
    first = float(np.median(next(iter(walls.values()))))
    lines = [
        f"{name}, {duration_s:g} s, seed 0; median of {repeat} interleaved rounds; "
        f"load average {os.getloadavg()[0]:.1f} at the end",
        "| run | wall (s) | real-time factor | wall / open loop online |",
        "|---|---|---|---|",
    ]
    for way, seconds in walls.items():
        wall = float(np.median(seconds))
        lines.append(f"| {way} | {wall:.2f} | {duration_s / wall:.0f}x | {wall / first:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["hall", "office", "apartment"])
    parser.add_argument(
        "--seeds", type=int, default=10, help="seeds 0 .. N-1 (default: %(default)s)"
    )
    parser.add_argument(
        "--follow",
        nargs="+",
        default=[str(Follow.ESTIMATE), str(Follow.UKF_ONLY)],
        choices=choices(Follow),
    )
    parser.add_argument("--duration", type=float, default=600.0, help="simulated seconds")
    parser.add_argument("--out", type=Path, default=Path("runs/closed_loop.jsonl"))
    parser.add_argument("--timing", action="store_true", help="time the loops instead")
    parser.add_argument("--repeat", type=int, default=3, help="rounds of --timing")
    args = parser.parse_args(argv)
    if args.timing:
        print(timing(args.scenarios[0], args.duration, args.repeat))
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    with args.out.open("w", encoding="utf-8") as out:
        for name in args.scenarios:
            for follow in args.follow:
                for seed in range(args.seeds):
                    row = figures(name, follow, seed, args.duration)
                    rows.append(row)
                    out.write(json.dumps(row) + "\n")
                    out.flush()
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
