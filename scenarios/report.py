"""``robotsim report RESULTS``: a campaign's table aggregated per setting, with figures.

``RESULTS`` is a campaign's ``results.parquet`` (or its folder). The runs are grouped by
scenario and grid setting (``setting.*`` columns); for each group and each figure of
:data:`FIGURES` the report gives the mean over the successful runs with its 95 % Student-t
confidence interval (``mean +- t_{0.975, n-1} s / sqrt(n)``, ``s`` the sample standard
deviation; runs of different seeds are independent), and the failed runs' count. It writes
``report.md`` (the table) and three PNG figures: the position and heading error per group
and branch, the containment and set area per group, and the CPU time per interval epoch.
The report folder (``--out``, default ``<results folder>/report``) is written whole or not at
all, replacing a previous report there (never a folder that holds anything else).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from scenarios import outputs
from scenarios.campaign import RESULTS_FILE
from scenarios.errors import ScenarioError

#: The figures aggregated per setting: column and label. The fused branch's figures are the
#: estimator's own: on the rows of the particle filter (``estimation.estimator = "mcl"``)
#: they are taken from its columns (:data:`ESTIMATOR_COLUMNS`), so the two estimators sit
#: side by side in one column, and in the paired table.
FIGURES = (
    ("rmse_position_m.ukf_only", "position RMSE, UKF-only (m)"),
    ("rmse_position_m.fused", "position RMSE, fused or MCL (m)"),
    ("rmse_heading_rad.ukf_only", "heading RMSE, UKF-only (rad)"),
    ("rmse_heading_rad.fused", "heading RMSE, fused or MCL (rad)"),
    ("nees.ukf_only.pose.mean", "pose NEES mean, UKF-only"),
    ("nees.fused.pose.mean", "pose NEES mean, fused or MCL"),
    ("nees.fused.pose.share_in_band", "share of fused or MCL NEES in its 95 % band"),
    ("nis.fused.share_in_band", "share of fused NIS in its 95 % band"),
    ("containment", "containment"),
    ("box.mean_area_m2", "set area (m2)"),
    ("box.mean_heading_width_rad", "set heading width (rad)"),
    ("empty_epochs", "empty epochs"),
    ("kidnaps.0.recovery_s", "first kidnap: recovery (s; recovered runs)"),
    ("kidnaps.0.recovered", "first kidnap: share recovered"),
    ("timing.cpu_per_epoch_ms", "CPU per epoch or MCL update (ms)"),
)

#: The particle filter's column of a fused-branch figure (used where the fused one is null).
ESTIMATOR_COLUMNS = {
    "rmse_position_m.fused": "rmse_position_m.mcl",
    "rmse_heading_rad.fused": "rmse_heading_rad.mcl",
    "nees.fused.pose.mean": "nees.mcl.pose.mean",
    "nees.fused.pose.share_in_band": "nees.mcl.pose.share_in_band",
}

CONFIDENCE = 0.95

#: The figures compared run against run (same scenario and seed) in the paired table.
PAIRED = ("rmse_position_m.fused", "rmse_heading_rad.fused", "nees.fused.pose.mean")


def confidence_interval(values: np.ndarray) -> tuple[float, float, int]:
    """``(mean, half width, n)`` of the finite ``values``: the Student-t interval at
    :data:`CONFIDENCE` (half width NaN below two values)."""
    finite = values[np.isfinite(values)]
    n = len(finite)
    if n == 0:
        return math.nan, math.nan, 0
    if n == 1:
        return float(finite[0]), math.nan, 1
    from scipy import stats  # here, not at the top: ``robotsim report --help`` starts without it

    t = stats.t.ppf(0.5 + CONFIDENCE / 2.0, n - 1)
    return float(finite.mean()), float(t * finite.std(ddof=1) / math.sqrt(n)), n


def load_results(path: Path) -> dict[str, list[Any]]:
    """The columns of a campaign's results table (``path``: the file or its folder)."""
    import pyarrow.parquet as pq

    file = path / RESULTS_FILE if path.is_dir() else path
    if not file.is_file():
        raise ScenarioError(str(file), None, "no such file (a campaign's results.parquet)")
    try:
        table = pq.read_table(file)
    except Exception as exc:  # pyarrow raises several kinds for a file that is not Parquet
        raise ScenarioError(str(file), None, f"not a Parquet table: {exc}") from None
    columns = table.to_pydict()
    for needed in ("scenario", "status"):
        if needed not in columns:
            raise ScenarioError(str(file), needed, "missing column: not a campaign's results")
    return columns


def groups(columns: dict[str, list[Any]]) -> dict[tuple[Any, ...], np.ndarray]:
    """Row indices per setting: ``(scenario, setting values...)`` in order of first appearance."""
    keys = ["scenario", *sorted(name for name in columns if name.startswith("setting."))]
    found: dict[tuple[Any, ...], list[int]] = {}
    for i in range(len(columns["scenario"])):
        found.setdefault(tuple(columns[k][i] for k in keys), []).append(i)
    return {group: np.array(rows) for group, rows in found.items()}


def setting_names(columns: dict[str, list[Any]]) -> list[str]:
    return [
        "scenario",
        *sorted(n.removeprefix("setting.") for n in columns if n.startswith("setting.")),
    ]


def column_values(columns: dict[str, list[Any]], name: str, rows: np.ndarray) -> np.ndarray:
    """The float values of figure ``name`` at ``rows`` (NaN where null or absent): its
    column, else the particle filter's (:data:`ESTIMATOR_COLUMNS`); for
    ``kidnaps.0.recovered``, 1 where the first kidnap's recovery time is set, 0 where the run
    had a kidnap and never recovered."""
    if name == "kidnaps.0.recovered":
        times = _raw_values(columns, "kidnaps.0.recovery_s", rows)
        kidnapped = ~np.isnan(_raw_values(columns, "kidnaps.0.t_s", rows))
        return np.where(kidnapped, (~np.isnan(times)).astype(float), np.nan)
    values = _raw_values(columns, name, rows)
    if name in ESTIMATOR_COLUMNS:
        other = _raw_values(columns, ESTIMATOR_COLUMNS[name], rows)
        values = np.where(np.isnan(values), other, values)
    return values


def _raw_values(columns: dict[str, list[Any]], name: str, rows: np.ndarray) -> np.ndarray:
    if name not in columns:
        return np.full(len(rows), np.nan)
    values = [columns[name][i] for i in rows]
    return np.array([np.nan if v is None else float(v) for v in values])


def aggregate(columns: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """One record per setting: its key, run and failure counts, and per figure the mean,
    half width and count of the successful runs."""
    ok = np.array([s == "ok" for s in columns["status"]])
    records = []
    for group, rows in groups(columns).items():
        good = rows[ok[rows]]
        record: dict[str, Any] = {
            "group": group,
            "runs": len(rows),
            "failed": int(len(rows) - len(good)),
            "figures": {},
            "values": {},
        }
        for name, _ in FIGURES:
            values = column_values(columns, name, good)
            record["figures"][name] = confidence_interval(values)
            record["values"][name] = values[np.isfinite(values)]
        records.append(record)
    return records


def markdown(records: list[dict[str, Any]], names: list[str]) -> str:
    """The aggregated table: one row per setting, ``mean +- half width`` per figure."""
    header = [*names, "runs", "failed", *(label for _, label in FIGURES)]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for record in records:
        cells = [str(v) for v in record["group"]] + [str(record["runs"]), str(record["failed"])]
        for name, _ in FIGURES:
            mean, half, n = record["figures"][name]
            if n == 0:
                cells.append("")
            elif math.isnan(half):
                cells.append(f"{mean:.4g}")
            else:
                cells.append(f"{mean:.4g} ± {half:.2g}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def paired_differences(columns: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """Each setting against the first setting of its scenario, run against run: the
    campaign gives every setting the same seeds (the same simulated worlds), so the mean of
    the per-seed differences and its t interval (``confidence_interval`` of the differences)
    say whether a setting beats the baseline with far fewer runs than two separate means.
    Only seeds where both runs succeeded count."""
    ok = [s == "ok" for s in columns["status"]]
    seeds = columns.get("seed") or [None] * len(ok)
    found = groups(columns)
    baselines: dict[Any, tuple[Any, ...]] = {}
    for group in found:
        baselines.setdefault(group[0], group)
    records = []
    for group, rows in found.items():
        baseline = baselines[group[0]]
        if group == baseline:
            continue
        base_row = {seeds[i]: i for i in found[baseline] if ok[i]}
        pairs = [(i, base_row[seeds[i]]) for i in rows if ok[i] and seeds[i] in base_row]
        mine, theirs = np.array([p[0] for p in pairs], int), np.array([p[1] for p in pairs], int)
        record: dict[str, Any] = {"group": group, "baseline": baseline, "figures": {}}
        for name in PAIRED:
            difference = column_values(columns, name, mine) - column_values(columns, name, theirs)
            record["figures"][name] = confidence_interval(difference)
        records.append(record)
    return records


def paired_markdown(records: list[dict[str, Any]], names: list[str]) -> str:
    """The paired table: per setting, ``mean difference +- half width (pairs)`` against its
    scenario's baseline setting."""
    if not records:
        return ""
    labels = dict(FIGURES)
    header = [*names, "baseline", *(f"Δ {labels[name]}" for name in PAIRED)]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for record in records:
        cells = [str(v) for v in record["group"]] + [" ".join(map(str, record["baseline"][1:]))]
        for name in PAIRED:
            mean, half, n = record["figures"][name]
            cells.append("" if n == 0 else f"{mean:+.3g} ± {half:.2g} ({n})")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n## Paired against the baseline (same seeds)\n\n" + "\n".join(lines) + "\n"


def figures(records: list[dict[str, Any]], folder: Path) -> list[Path]:
    """The four PNG figures of the report, in ``folder``: errors, containment and set area,
    time per epoch, kidnap recovery."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = ["\n".join(str(v) for v in record["group"]) for record in records]
    written = []

    def boxplots(axis, name: str, title: str) -> None:
        data = [record["values"][name] for record in records]
        axis.boxplot([d if len(d) else [np.nan] for d in data], tick_labels=labels)
        axis.set_title(title)
        axis.tick_params(axis="x", labelsize=7)

    fig, axes = plt.subplots(2, 2, figsize=(12, 8), constrained_layout=True)
    for axis, (name, title) in zip(axes.flat, FIGURES[:4], strict=True):
        boxplots(axis, name, title)
    written.append(folder / "errors.png")
    fig.savefig(written[-1], dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), constrained_layout=True)
    for axis, name in zip(axes, ("containment", "box.mean_area_m2"), strict=True):
        means = [record["figures"][name][0] for record in records]
        halves = [np.nan_to_num(record["figures"][name][1]) for record in records]
        axis.bar(range(len(records)), means, yerr=halves, capsize=4)
        axis.set_xticks(range(len(records)), labels, fontsize=7)
        axis.set_title(dict(FIGURES)[name] + " (mean, 95 % CI)")
    written.append(folder / "containment_area.png")
    fig.savefig(written[-1], dpi=100)
    plt.close(fig)

    fig, axis = plt.subplots(figsize=(8, 4.5), constrained_layout=True)
    boxplots(axis, "timing.cpu_per_epoch_ms", "CPU time per interval epoch (ms)")
    written.append(folder / "time_per_epoch.png")
    fig.savefig(written[-1], dpi=100)
    plt.close(fig)

    fig, axis = plt.subplots(figsize=(8, 4.5), constrained_layout=True)
    boxplots(axis, "kidnaps.0.recovery_s", "first kidnap: time to recover (s; recovered runs)")
    for place, record in enumerate(records, start=1):  # the share recovered, at the top
        share = record["figures"]["kidnaps.0.recovered"]
        text = "no kidnap" if share[2] == 0 else f"{share[0]:.0%} of {share[2]} recovered"
        axis.annotate(
            text, (place, 0.98), xycoords=("data", "axes fraction"), ha="center", va="top"
        )
    axis.set_ylim(bottom=0.0, top=axis.get_ylim()[1] * 1.12)  # room for the shares
    written.append(folder / "kidnap_recovery.png")
    fig.savefig(written[-1], dpi=100)
    plt.close(fig)
    return written


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``robotsim report``."""
    parser.add_argument(
        "results", type=Path, metavar="RESULTS", help="a campaign's results.parquet or its folder"
    )
    parser.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="report folder, replaced whole (default: report/ beside the results)",
    )


def main(args: argparse.Namespace) -> int:
    """``robotsim report``: aggregate, write the table and the figures."""
    columns = load_results(args.results)
    base = args.results if args.results.is_dir() else args.results.parent
    out = args.out or base / "report"
    if out.exists() and not out.is_dir():
        raise ScenarioError(None, "--out", f"{out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / "report.md").is_file():
        raise ScenarioError(None, "--out", f"{out} is a folder that holds no report: not replaced")
    records = aggregate(columns)
    names = setting_names(columns)
    table = markdown(records, names) + paired_markdown(paired_differences(columns), names)
    with outputs.atomic_directory(out) as tmp:
        (tmp / "report.md").write_text(table, encoding="utf-8")
        figures(records, tmp)
    print(table, end="")
    print(
        f"wrote {out}/report.md, errors.png, containment_area.png, time_per_epoch.png, "
        "kidnap_recovery.png"
    )
    return 0
