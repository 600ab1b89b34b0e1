"""Issue 15's first campaign: every estimator on the built-in plans, with and without faults.

    robotsim reproduce estimators [--out DIR] [--seeds N] [--duration S]
                                  [--scenarios NAME ...] [--workers N] [--quick]

Five estimators on the same simulated worlds (common random numbers, seed by seed):

- ``ukf_only``: the dead reckoning alone (the UKF-only branch of the interval runs);
- ``clamp``, ``clamp_heading``, ``truncated``: the interval pipeline with that fusion rule
  (``[estimation] fusion``; the paper's rule is ``clamp``);
- ``mcl``: Monte Carlo localisation from a uniform prior (``estimator = "mcl"``, with the
  ``[estimation.mcl]`` settings of :data:`MCL_SETTINGS`).

Each built-in plan of :data:`SCENARIOS` runs twice: as shipped (no sensor faults) and as
``<name>_faults``: sonar outliers (``outlier_prob``) and lost echoes (``lost_echo_prob``),
:data:`FAULTS`; two obstacles the map lacks (``[world] obstacles``, :func:`fault_obstacles`):
a static box and a box pacing to and fro, each placed as near the route as it may be while
its whole sweep stays clear of the route, the start, the kidnap pose and the walls (a box
with no such place is left out: ``corridor`` has room for neither); and a
kidnapping halfway through the run to the free pose farthest from the route (no odometry of
the jump). Every run follows its route on the true pose (``[route] follow = "truth"``): the
same world for every estimator, seed by seed.

It is an ordinary campaign (``scenarios.campaign``): the scenario files and the campaign
file are written to ``DIR/inputs/`` (``robotsim campaign DIR/inputs/estimators.toml`` runs
the same campaign by hand, with ``--resume``), the grid is ``estimator`` x ``fusion`` less
the MCL runs with a fusion rule other than the first (MCL has none: they would repeat it).
Writes ``DIR/campaign/results.parquet`` (one row per run, as any campaign), ``DIR/report/``
(``robotsim report`` of it) and ``DIR/estimators.md``, ``DIR/estimators.png``: per scenario
and estimator the mean and 95 % interval of the position and heading RMSE, the pose NEES
(mean, share in its band), the kidnap recovery and the CPU time per epoch (per update for
MCL).

``--quick``: ``hall`` only, 2 seeds, 20 s (a smoke test, under a minute on two cores). The
full campaign (9 plans x 2 fault settings x 20 seeds x 4 runs of 300 s) is for users; its
running time is in ``docs/reproductions.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from localization.fusion import FusionRule
from robotsim.control import Route
from robotsim.maps import nearest_segment_distance
from robotsim.world import WorldParams
from scenarios import report as report_module
from scenarios.campaign import Campaign, ResultsFolder, load_campaign, run_campaign
from scenarios.errors import ScenarioError
from scenarios.mcl_pipeline import Estimator
from scenarios.mcl_ranges import free_space_sampler
from scenarios.outputs import atomic_directory, write_text
from scenarios.spec import BUILTIN_FOLDER, load_scenario

HELP = (
    "issue 15: UKF-only, clamp, clamp_heading, truncated and MCL on the built-in plans, with "
    "and without faults (a campaign; table, report and figures)"
)

#: The estimators compared, in the table's order.
ESTIMATORS = ("ukf_only", "clamp", "clamp_heading", "truncated", "mcl")
FUSIONS = (FusionRule.CLAMP, FusionRule.CLAMP_HEADING, FusionRule.TRUNCATED)

#: Every built-in plan (``hall_mcl`` is ``hall`` with the estimator set, which the grid does).
SCENARIOS = (
    "hall",
    "office",
    "symmetric",
    "apartment",
    "cluttered_room",
    "apartment_lived_in",
    "corridor",
    "office_floor",
    "big_hall",
)

#: The sonar faults of the ``_faults`` variants (``[sensors.sonar]``).
FAULTS = {"outlier_prob": 0.02, "lost_echo_prob": 0.02}
#: The kidnapping of the ``_faults`` variants, as a share of the run's duration.
KIDNAP_AT = 0.5
#: Clearance of the kidnap pose from the walls beyond the robot's radius, m.
KIDNAP_CLEARANCE_M = 0.15

#: The unmapped obstacles of the ``_faults`` variants, width x depth, m: a static box (an
#: armchair) and a box pacing to and fro (a person seen from above).
STATIC_BOX_M = (0.6, 0.6)
PACING_BOX_M = (0.4, 0.3)
#: How far the pacing box walks from its start before it turns back, m (the longest that
#: fits), and its speed, m/s.
PACE_M = (1.5, 1.0, 0.5)
PACE_SPEED_M_S = 0.5
#: The clearance of an obstacle's sweep from the route, the kidnap pose and the other
#: obstacle beyond the robot's radius (and the lookahead at the waypoints), m; and from the
#: walls beyond their thickness, m.
OBSTACLE_CLEARANCE_M = 0.25
OBSTACLE_WALL_GAP_M = 0.05
#: Candidate positions (drawn uniformly over the free space, seed 1) and pacing directions.
OBSTACLE_CANDIDATES = 2000
#: The faulty variant's description of its unmapped boxes, by how many found a place.
BOXES_PLACED = ("no box (no room off the route)", "one box", "a static and a pacing box")
PACE_DIRECTIONS = 8

#: The particle filter's settings (``[estimation.mcl]``): a prior dense enough for global
#: localisation on these floors, and random particles to find a kidnapped robot.
MCL_SETTINGS = {"max_particles": 10000, "recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1}

CAMPAIGN_SEED = 2026
DEFAULT_SEEDS = 20
DEFAULT_DURATION_S = 300.0
#: ``--quick``: the plans, seeds and duration of the smoke test.
QUICK_SCENARIOS = ("hall",)
QUICK_SEEDS = 2
QUICK_DURATION_S = 20.0

CAMPAIGN_NAME = "estimators"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``robotsim reproduce estimators``."""
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("runs/reproduce/estimators"),
        help="output folder (default: %(default)s)",
    )
    parser.add_argument(
        "--seeds", type=int, metavar="N", help=f"replicates (default: {DEFAULT_SEEDS})"
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help=f"simulated time of every run, s (default: {DEFAULT_DURATION_S:g})",
    )
    parser.add_argument(
        "--scenarios",
        nargs="+",
        metavar="NAME",
        choices=SCENARIOS,
        help=f"built-in plans (default: {' '.join(SCENARIOS)})",
    )
    parser.add_argument(
        "--workers", type=int, metavar="N", help="worker processes (default: every core)"
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"a smoke test: {', '.join(QUICK_SCENARIOS)}, {QUICK_SEEDS} seeds, "
        f"{QUICK_DURATION_S:g} s (options given still apply)",
    )


# ---------------------------------------------------------------------------------------
# The campaign's inputs
# ---------------------------------------------------------------------------------------
def builtin_tables(name: str) -> dict[str, Any]:
    """The tables of built-in scenario ``name``, its map file (if any) made absolute."""
    data = tomllib.loads((BUILTIN_FOLDER / f"{name}.toml").read_text(encoding="utf-8"))
    map_file = data.get("map", {}).get("file")
    if map_file is not None:
        data["map"]["file"] = str(Path(str(BUILTIN_FOLDER)) / map_file)
    return data


def kidnap_pose(name: str) -> tuple[float, float, float]:
    """The free pose of built-in ``name`` farthest from its route (start and waypoints):
    the best of 500 positions drawn uniformly over the free space (seed 0), heading 180 deg."""
    spec = load_scenario(name)
    sample = free_space_sampler(spec.map, spec.robot.radius_m + KIDNAP_CLEARANCE_M)
    candidates = sample(np.random.default_rng(0), 500)
    path = np.vstack([np.array(spec.start_pose[:2])[None], _waypoints(spec)])
    legs = np.array([(a, b) for a, b in itertools.pairwise(path) if np.any(a != b)])
    distance = nearest_segment_distance(candidates, legs)
    x, y = candidates[int(np.argmax(distance))]
    return float(x), float(y), 180.0


def fault_obstacles(name: str, kidnap_xy_m: tuple[float, float]) -> list[dict[str, Any]]:
    """The ``[[world.obstacles]]`` tables of ``name_faults``: a :data:`STATIC_BOX_M` box and a
    :data:`PACING_BOX_M` box walking to and fro (the longest of :data:`PACE_M` that fits),
    each as near the route as it may be (so that the sonars meet it) with its whole sweep
    clear of the robot: beyond the robot's radius plus :data:`OBSTACLE_CLEARANCE_M` from the
    route's legs (from the start through every waypoint, back to the first on a loop), the
    kidnap pose ``kidnap_xy_m`` and the first box, and beyond that plus the lookahead from
    every waypoint (pure pursuit cuts a corner by at most its lookahead); and
    :data:`OBSTACLE_WALL_GAP_M` beyond the walls' thickness from every wall. A box's sweep
    lies within its half diagonal of the segment its centre travels, so these distances are
    taken from that segment (a point for the static box), for every candidate at once. A box
    with no such place is left out (``corridor``: 1.8 m leaves no room beside the robot).
    """
    spec = load_scenario(name)
    plan = spec.plan
    lookahead_m = plan.lookahead_m if isinstance(plan, Route) else 0.0
    clear_m = spec.robot.radius_m + OBSTACLE_CLEARANCE_M
    path = np.vstack([np.array(spec.start_pose[:2])[None], _waypoints(spec)])
    if isinstance(plan, Route) and plan.loop:
        path = np.vstack([path, path[1:2]])
    legs = shapely.LineString(path) if len(path) > 1 else shapely.Point(path[0])
    corners = shapely.MultiPoint(path)
    walls = shapely.MultiLineString(list(spec.map.segments))
    wall_gap_m = WorldParams().wall_radius_m + OBSTACLE_WALL_GAP_M
    keep_off = [shapely.Point(kidnap_xy_m)]
    sample = free_space_sampler(spec.map, math.hypot(*STATIC_BOX_M) / 2.0 + wall_gap_m)
    centres = sample(np.random.default_rng(1), OBSTACLE_CANDIDATES)
    angles = np.arange(PACE_DIRECTIONS) * (2.0 * math.pi / PACE_DIRECTIONS)
    tables: list[dict[str, Any]] = []
    for size_m, paces in ((STATIC_BOX_M, (0.0,)), (PACING_BOX_M, PACE_M)):
        half_m = math.hypot(*size_m) / 2.0
        for pace_m in paces:
            steps = pace_m * np.column_stack([np.cos(angles), np.sin(angles)])
            starts = np.repeat(centres, len(steps) if pace_m else 1, axis=0)
            goals = starts + (np.tile(steps, (len(centres), 1)) if pace_m else 0.0)
            # what a box's centre covers: the segment it paces, or the point it stands on
            sweeps = (
                shapely.linestrings(np.stack([starts, goals], axis=1))
                if pace_m
                else shapely.points(starts)
            )
            to_route = shapely.distance(sweeps, legs)
            fits = (
                (to_route >= clear_m + half_m)
                & (shapely.distance(sweeps, corners) >= clear_m + lookahead_m + half_m)
                & (shapely.distance(sweeps, walls) >= wall_gap_m + half_m)
            )
            for other in keep_off:
                fits &= shapely.distance(sweeps, other) >= clear_m + half_m
            if fits.any():
                best = int(np.flatnonzero(fits)[np.argmin(to_route[fits])])
                tables.append(_box_table(starts[best], size_m, goals[best] if pace_m else None))
                keep_off.append(sweeps[best].buffer(half_m))
                break
    return tables


def _box_table(
    centre: np.ndarray, size_m: tuple[float, float], goal: np.ndarray | None
) -> dict[str, Any]:
    """The ``[[world.obstacles]]`` table of a box of ``size_m`` centred on ``centre``, walking
    to ``goal`` and back for ever when one is given."""
    (x, y), (half_w, half_d) = centre, (size_m[0] / 2.0, size_m[1] / 2.0)
    corners = [(x - half_w, y - half_d), (x + half_w, y - half_d), (x + half_w, y + half_d)]
    corners.append((x - half_w, y + half_d))
    table: dict[str, Any] = {"polygon_m": [[float(a), float(b)] for a, b in corners]}
    if goal is not None:
        table.update(path_m=[[float(goal[0]), float(goal[1])]], speed_m_s=PACE_SPEED_M_S, loop=True)
    return table


def _waypoints(spec) -> np.ndarray:
    return spec.plan.waypoints_m if isinstance(spec.plan, Route) else np.zeros((0, 2))


def scenario_variants(name: str, duration_s: float) -> dict[str, dict[str, Any]]:
    """The tables of ``name`` and ``name_faults`` (module docstring), with the MCL settings
    and the duration."""
    clean = builtin_tables(name)
    clean.setdefault("run", {})["duration_s"] = duration_s
    # the robot follows its route on the true pose, so that every estimator sees the same
    # world seed by seed (a closed loop would steer each run on its own estimate)
    clean.setdefault("route", {})["follow"] = "truth"
    clean.setdefault("estimation", {})["mcl"] = dict(MCL_SETTINGS)
    faulty = json.loads(json.dumps(clean))
    faulty.setdefault("sensors", {}).setdefault("sonar", {}).update(FAULTS)
    x, y, heading = kidnap_pose(name)
    boxes = fault_obstacles(name, (x, y))
    faulty.setdefault("world", {}).setdefault("obstacles", []).extend(boxes)
    faulty["events"] = [
        {"kind": "kidnap", "t_s": KIDNAP_AT * duration_s, "xy_m": [x, y], "heading_deg": heading}
    ]
    faulty["description"] = (
        f"{name} with sonar outliers and lost echoes ({FAULTS['outlier_prob']:g}, "
        f"{FAULTS['lost_echo_prob']:g}), {BOXES_PLACED[len(boxes)]} the map lacks, and a "
        f"kidnapping at {KIDNAP_AT * duration_s:g} s"
    )
    return {name: clean, f"{name}_faults": faulty}


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def toml_text(data: dict[str, Any]) -> str:
    """``data`` (tables of strings, booleans, numbers and arrays of them, sub-tables and
    arrays of tables: what a scenario file holds) as TOML text that ``tomllib`` reads back
    to ``data``."""
    lines: list[str] = []

    def key(name: str) -> str:
        return name if _BARE_KEY.match(name) else json.dumps(name)

    def value(item: Any) -> str:
        if isinstance(item, bool):
            return "true" if item else "false"
        if isinstance(item, int | float):
            if not math.isfinite(item):
                raise ValueError(f"toml_text: {item!r} is not a TOML number here")
            return repr(item)
        if isinstance(item, str):
            return json.dumps(item)
        if isinstance(item, list):
            return "[" + ", ".join(value(v) for v in item) + "]"
        raise ValueError(f"toml_text: cannot write {type(item).__name__}")

    def table(body: dict[str, Any], prefix: str) -> None:
        for name, item in body.items():
            if not isinstance(item, dict) and not _is_table_array(item):
                lines.append(f"{key(name)} = {value(item)}")
        for name, item in body.items():
            path = f"{prefix}.{key(name)}" if prefix else key(name)
            if isinstance(item, dict):
                lines.extend(["", f"[{path}]"])
                table(item, path)
            elif _is_table_array(item):
                for entry in item:
                    lines.extend(["", f"[[{path}]]"])
                    table(entry, path)

    table(data, "")
    return "\n".join(lines).lstrip("\n") + "\n"


def _is_table_array(item: Any) -> bool:
    return isinstance(item, list) and bool(item) and all(isinstance(v, dict) for v in item)


def campaign_text(files: list[str], seeds: int, duration_s: float) -> str:
    """The campaign file: the scenario files, the seeds, estimator x fusion."""
    return toml_text(
        {
            "scenarios": files,
            "seed": CAMPAIGN_SEED,
            "seeds": {"first": 0, "count": seeds},
            "duration_s": duration_s,
            "grid": {
                "estimation.estimator": [str(e) for e in Estimator],
                "estimation.fusion": [str(f) for f in FUSIONS],
            },
        }
    )


def build_campaign(inputs: Path, names: tuple[str, ...], seeds: int, duration_s: float) -> Campaign:
    """Write the scenario files and the campaign file into ``inputs``; the campaign, less
    the MCL runs of the fusion rules after the first (module docstring)."""
    inputs.mkdir(parents=True, exist_ok=True)
    files = []
    for name in names:
        for variant, tables in scenario_variants(name, duration_s).items():
            write_text(inputs / f"{variant}.toml", toml_text(tables))
            files.append(f"{variant}.toml")
    path = inputs / f"{CAMPAIGN_NAME}.toml"
    write_text(path, campaign_text(files, seeds, duration_s))
    campaign = load_campaign(path)
    kept = [
        run
        for run in campaign.runs
        if run.settings["estimation.estimator"] != Estimator.MCL
        or run.settings["estimation.fusion"] == FUSIONS[0]
    ]
    runs = tuple(dataclasses.replace(run, index=i) for i, run in enumerate(kept))
    return dataclasses.replace(campaign, runs=runs)


# ---------------------------------------------------------------------------------------
# The estimators table
# ---------------------------------------------------------------------------------------
#: The figures of the estimators table: label, and the column per kind of estimator
#: (``ukf_only``, an interval fusion rule, ``mcl``; None: no such figure).
TABLE_FIGURES = (
    (
        "position RMSE (m)",
        ("rmse_position_m.ukf_only", "rmse_position_m.fused", "rmse_position_m.mcl"),
    ),
    (
        "heading RMSE (rad)",
        ("rmse_heading_rad.ukf_only", "rmse_heading_rad.fused", "rmse_heading_rad.mcl"),
    ),
    ("pose NEES mean", ("nees.ukf_only.pose.mean", "nees.fused.pose.mean", "nees.mcl.pose.mean")),
    (
        "pose NEES in band",
        (
            "nees.ukf_only.pose.share_in_band",
            "nees.fused.pose.share_in_band",
            "nees.mcl.pose.share_in_band",
        ),
    ),
    ("kidnap recovered", (None, "kidnaps.0.recovered", "kidnaps.0.recovered")),
    ("kidnap recovery (s)", (None, "kidnaps.0.recovery_s", "kidnaps.0.recovery_s")),
    ("CPU per epoch (ms)", (None, "timing.cpu_per_epoch_ms", "timing.cpu_per_epoch_ms")),
)


def estimator_rows(columns: dict[str, list[Any]], scenario: str, estimator: str) -> np.ndarray:
    """The successful rows of ``estimator`` on ``scenario`` (``ukf_only``: the rows of the
    first fusion rule, whose UKF-only branch it is)."""
    want_mcl = estimator == "mcl"
    fusion = FUSIONS[0] if estimator in ("ukf_only", "mcl") else estimator
    picked = [
        i
        for i in range(len(columns["scenario"]))
        if columns["scenario"][i] == scenario
        and columns["status"][i] == "ok"
        and (columns["setting.estimation.estimator"][i] == Estimator.MCL) == want_mcl
        and columns["setting.estimation.fusion"][i] == fusion
    ]
    return np.array(picked, dtype=np.int64)


def estimator_table(columns: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """Per scenario and estimator: the run count and, per figure of :data:`TABLE_FIGURES`,
    ``(mean, half width, n)`` (``report.confidence_interval``) and the values."""
    records = []
    for scenario in dict.fromkeys(columns["scenario"]):
        for estimator in ESTIMATORS:
            rows = estimator_rows(columns, scenario, estimator)
            kind = 0 if estimator == "ukf_only" else 2 if estimator == "mcl" else 1
            figures, values = {}, {}
            for label, names in TABLE_FIGURES:
                name = names[kind]
                data = (
                    report_module.column_values(columns, name, rows)
                    if name is not None
                    else np.full(len(rows), np.nan)
                )
                figures[label] = report_module.confidence_interval(data)
                values[label] = data[np.isfinite(data)]
            records.append(
                {
                    "scenario": scenario,
                    "estimator": estimator,
                    "runs": len(rows),
                    "figures": figures,
                    "values": values,
                }
            )
    return records


def table_markdown(records: list[dict[str, Any]]) -> str:
    """The estimators table: one row per scenario and estimator, ``mean ± half width``."""
    header = ["scenario", "estimator", "runs", *(label for label, _ in TABLE_FIGURES)]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for record in records:
        cells = [record["scenario"], record["estimator"], str(record["runs"])]
        for label, _ in TABLE_FIGURES:
            mean, half, n = record["figures"][label]
            cells.append(
                "" if n == 0 else f"{mean:.4g}" if math.isnan(half) else f"{mean:.4g} ± {half:.2g}"
            )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def table_figure(records: list[dict[str, Any]], path: Path) -> None:
    """Box plots of the position and heading RMSE per estimator (log scale): one row per
    plan, its clean run's two panels beside its ``_faults`` variant's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenarios = list(dict.fromkeys(r["scenario"] for r in records))
    plans = list(dict.fromkeys(s.removesuffix("_faults") for s in scenarios))
    labels = ("position RMSE (m)", "heading RMSE (rad)")
    fig, axes = plt.subplots(
        len(plans), 4, figsize=(16, 3.2 * len(plans)), squeeze=False, constrained_layout=True
    )
    for row, plan in enumerate(plans):
        for pair, scenario in enumerate((plan, f"{plan}_faults")):
            mine = [r for r in records if r["scenario"] == scenario]
            for offset, label in enumerate(labels):
                axis = axes[row, 2 * pair + offset]
                if not mine:
                    axis.set_axis_off()
                    continue
                data = [r["values"][label] for r in mine]
                axis.boxplot(
                    [d if len(d) else [np.nan] for d in data],
                    tick_labels=[r["estimator"] for r in mine],
                )
                axis.set_yscale("log")
                axis.set_title(f"{scenario}: {label}", fontsize=9)
                axis.tick_params(axis="x", labelsize=7, rotation=30)
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------------------------------
# The command
# ---------------------------------------------------------------------------------------
def main(args: argparse.Namespace) -> int:
    """Build and run the campaign; write its table, report and the estimators table."""
    names = tuple(args.scenarios or (QUICK_SCENARIOS if args.quick else SCENARIOS))
    seeds = args.seeds or (QUICK_SEEDS if args.quick else DEFAULT_SEEDS)
    duration_s = args.duration or (QUICK_DURATION_S if args.quick else DEFAULT_DURATION_S)
    for option, value in (("--seeds", seeds), ("--workers", args.workers)):
        if value is not None and value < 1:
            raise ScenarioError(None, option, f"must be at least 1, got {value}")
    if not duration_s > 0:
        raise ScenarioError(None, "--duration", f"must be > 0, got {duration_s:g}")
    with atomic_directory(args.out) as folder:
        campaign = build_campaign(folder / "inputs", names, seeds, duration_s)
        results = ResultsFolder(folder / "campaign")
        results.prepare(campaign, resume=False)
        if not run_campaign(campaign, results, workers=args.workers):
            raise ScenarioError(None, "--workers", "a worker process died (out of memory?)")
        merged = results.merge(campaign)
        columns = report_module.load_results(merged)
        records = report_module.aggregate(columns)
        names_ = report_module.setting_names(columns)
        (folder / "report").mkdir()
        write_text(
            folder / "report" / "report.md",
            report_module.markdown(records, names_)
            + report_module.paired_markdown(report_module.paired_differences(columns), names_),
        )
        report_module.figures(records, folder / "report")
        table = estimator_table(columns)
        text = table_markdown(table)
        write_text(folder / "estimators.md", text)
        table_figure(table, folder / "estimators.png")
    failed = sum(status != "ok" for status in columns["status"])
    print(text, end="")
    print(
        f"estimators: {len(campaign.runs)} runs ({len(names)} plans x 2 fault settings x "
        f"{seeds} seeds x {len(ESTIMATORS) - 1} runs of {duration_s:g} s), {failed} failed; "
        f"wrote {args.out}"
    )
    return 1 if failed else 0
