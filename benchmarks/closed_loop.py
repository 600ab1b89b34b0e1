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
median fused and UKF-only position RMSE. Not a timing benchmark: every figure is
deterministic (same scenario and seed, same line).
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

import numpy as np

from scenarios.runner import run_scenario
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
    args = parser.parse_args(argv)
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
