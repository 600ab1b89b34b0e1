"""Paper 002, sections 3-4: the UKF clamped to the interval boxes, SIVIA against IMAGESP.

    robotsim reproduce ia-fusion [--out DIR] [--duration S] [--seed N]

The built-in ``hall`` scenario (10 x 8 m, four sparse landmarks, 16 sonars limited to 3 m,
a loop round the hall) is simulated once; the localisation pipeline then runs twice on the
same sensor data, once with each interval tracker:

- ``sivia``: the hull of the previous set grown by the robot's physical limits, inverted as
  one box;
- ``imagesp``: every box of the previous set mapped through the same limits (IMAGESP),
  then contracted by the sonar tests.

Writes ``DIR/table.json`` and ``DIR/table.md`` (per tracker: position and heading RMSE of the
UKF-only and the fused branch, mean box width and area, median and 95th-percentile time per
epoch, containment of the truth, and the paper's qualitative claims checked) and figures
like the paper's: ``fig7_ukf_only.png`` (truth and UKF-only estimate),
``fig8_fused_sivia.png`` and ``fig9_fused_imagesp.png`` (truth, UKF-only, fused estimate and
the boxes), ``fig10_box_area.png`` (box area per epoch, both trackers).

The paper's claims (section 4): the clamp improves the UKF position markedly; IMAGESP boxes
are smaller than SIVIA's, at a higher computational cost.

The run checks its own guarantee: the hall's sonar has no faults, so every set must hold the
truth. When a tracker's containment is below 1 the outputs are still written (to look at),
one line names the tracker on stderr, and the exit status is 1.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

from intervals.tracker import Tracker
from scenarios.commands import with_run_options
from scenarios.outputs import atomic_directory, write_json, write_text
from scenarios.pipeline import FUSED, UKF_ONLY, Estimation, estimate, estimation_summary
from scenarios.runner import simulate_spec
from scenarios.spec import Follow, load_scenario

HELP = "paper 002: UKF dead reckoning clamped to interval boxes, SIVIA vs IMAGESP trackers on hall (table, figures 7-9)"

TRACKERS = tuple(Tracker)
SCENARIO = "hall"

#: Boxes are drawn at every this many epochs in the figures (all of them would hide the paths).
BOX_EVERY = 5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``robotsim reproduce ia-fusion``."""
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("runs/reproduce/ia-fusion"),
        help="output folder (default: %(default)s)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="simulated time, s (default: the scenario's, 600)",
    )
    parser.add_argument("--seed", type=int, metavar="N", help="seed (default: the scenario's, 0)")


def main(args: argparse.Namespace) -> int:
    """Run both trackers on the same simulated data; write the table and the figures."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # the paper's setting: the robot on its route (the true pose steers), the clamp
    loaded = with_run_options(load_scenario(SCENARIO), args.seed, args.duration)
    spec = dataclasses.replace(loaded, follow=Follow.TRUTH).with_estimation(fusion="clamp")
    log = simulate_spec(spec)
    rows: dict[str, dict[str, Any]] = {}
    runs: dict[str, Estimation] = {}
    for tracker in TRACKERS:
        variant = dataclasses.replace(spec, estimation=spec.estimation.with_keys(tracker=tracker))
        estimation, _ = estimate(variant, log)
        runs[tracker] = estimation
        rows[tracker] = table_row(estimation_summary(log, estimation), estimation)
    claims = check_claims(rows)
    table = {
        "scenario": spec.name,
        "seed": spec.run.seed,
        "duration_s": spec.run.duration_s,
        "estimation": {k: v for k, v in spec.estimation.as_keys().items() if k != "tracker"},
        "trackers": rows,
        "claims": claims,
    }
    with atomic_directory(args.out) as folder:
        write_json(folder / "table.json", table)
        write_text(folder / "table.md", markdown(table))
        figures(plt, folder, spec, log, runs)
    verdict = (
        "all hold"
        if all(claims.values())
        else "NOT all hold: " + ", ".join(k for k, v in claims.items() if not v)
    )
    print(
        f"ia-fusion: {spec.run.duration_s:g} s of {spec.name}, seed {spec.run.seed}; "
        f"paper's claims {verdict}; wrote {args.out}"
    )
    missed = missed_guarantee(rows)
    if missed:
        print(
            f"ia-fusion: the guarantee failed: the truth left the interval set ({missed})",
            file=sys.stderr,
        )
        return 1
    return 0


def missed_guarantee(rows: dict[str, dict[str, Any]]) -> str:
    """The trackers whose sets missed the truth at some epoch (containment < 1), as text;
    empty when the guarantee held. The hall's sonar has no faults, so it must hold."""
    return ", ".join(
        f"{tracker} containment {row['containment']:.4g}"
        for tracker, row in rows.items()
        if row["containment"] is not None and row["containment"] < 1.0
    )


def table_row(summary: dict[str, Any], estimation: Estimation) -> dict[str, Any]:
    """One tracker's figures: accuracy (deterministic) and time per epoch."""
    epoch_ms = estimation.epochs.elapsed_s * 1e3
    return {
        "rmse_position_m": summary["rmse_position_m"],
        "rmse_heading_rad": summary["rmse_heading_rad"],
        "fused_to_ukf_only_position_rmse": summary["fused_to_ukf_only_position_rmse"],
        "containment": summary["containment"],
        "box": summary["box"],
        "q_used_max": summary["q_used_max"],
        "empty_epochs": summary["empty_epochs"],
        "lost_epochs": summary["lost_epochs"],
        "fused_in_box": summary["fusion"]["fused_in_box"],
        "epochs": summary["epochs"],
        "epoch_ms_median": float(np.median(epoch_ms)),
        "epoch_ms_p95": float(np.percentile(epoch_ms, 95)),
    }


def check_claims(rows: dict[str, dict[str, Any]]) -> dict[str, bool]:
    """Paper 002's qualitative results, and the guarantee, on this run."""
    sivia, imagesp = rows["sivia"], rows["imagesp"]
    return {
        "containment is 1 for both trackers": sivia["containment"] == 1.0
        and imagesp["containment"] == 1.0,
        "fused position RMSE below UKF-only (both trackers)": all(
            r["rmse_position_m"]["fused"] < r["rmse_position_m"]["ukf_only"] for r in rows.values()
        ),
        "IMAGESP boxes smaller than SIVIA's (mean area)": imagesp["box"]["mean_area_m2"]
        < sivia["box"]["mean_area_m2"],
        "IMAGESP slower than SIVIA (median time per epoch)": imagesp["epoch_ms_median"]
        > sivia["epoch_ms_median"],
    }


def markdown(table: dict[str, Any]) -> str:
    """``table.md``: the figures per tracker and the claims."""
    lines = [
        f"# Paper 002: UKF clamped to interval boxes on `{table['scenario']}` "
        f"({table['duration_s']:g} s, seed {table['seed']})",
        "",
        "| tracker | RMSE pos. UKF-only (m) | RMSE pos. fused (m) | fused / UKF-only "
        "| RMSE heading UKF-only / fused (rad) | mean box area (m²) | mean box width (m) "
        "| median ms / epoch | p95 ms | containment | empty / lost epochs |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in table["trackers"].items():
        pos, head = r["rmse_position_m"], r["rmse_heading_rad"]
        lines.append(
            f"| {name} | {pos['ukf_only']:.3f} | {pos['fused']:.3f} "
            f"| {r['fused_to_ukf_only_position_rmse']:.2f} "
            f"| {head['ukf_only']:.4f} / {head['fused']:.4f} | {r['box']['mean_area_m2']:.4f} "
            f"| {r['box']['mean_width_m']:.3f} | {r['epoch_ms_median']:.1f} | {r['epoch_ms_p95']:.1f} "
            f"| {r['containment']:.3f} | {r['empty_epochs']} / {r['lost_epochs']} |"
        )
    lines += [
        "",
        "Box area: (x, y) area of the union of the outer boxes of each epoch, mean over epochs.",
        "",
    ]
    lines += ["## The paper's claims on this run", ""]
    lines += [
        f"- {'holds' if ok else 'DOES NOT HOLD'}: {claim}" for claim, ok in table["claims"].items()
    ]
    lines += [
        "",
        "## Settings",
        "",
        "```",
        *(f"{k} = {'auto' if v is None else v}" for k, v in table["estimation"].items()),
        "```",
        "",
    ]
    return "\n".join(lines)


def figures(plt, folder: Path, spec, log, runs: dict[str, Estimation]) -> None:
    """Figures 7-9 of the paper (trajectories and boxes on the map) and the box areas."""
    fig, ax = _map_axes(plt, spec)
    ax.plot(log.pose[:, 0], log.pose[:, 1], color="tab:green", lw=1.2, label="truth")
    ukf = runs[TRACKERS[0]].pose[UKF_ONLY]
    ax.plot(ukf[:, 0], ukf[:, 1], color="tab:blue", lw=1.0, label="UKF only")
    ax.set_title("Fig. 7: UKF-only estimate (encoders, gyro, accelerometer)")
    _save(plt, fig, ax, folder / "fig7_ukf_only.png")
    for number, tracker in ((8, "sivia"), (9, "imagesp")):
        estimation = runs[tracker]
        fig, ax = _map_axes(plt, spec)
        _draw_boxes(ax, estimation)
        ax.plot(log.pose[:, 0], log.pose[:, 1], color="tab:green", lw=1.2, label="truth")
        ax.plot(ukf[:, 0], ukf[:, 1], color="tab:blue", lw=0.8, alpha=0.6, label="UKF only")
        fused = estimation.pose[FUSED]
        ax.plot(
            fused[:, 0], fused[:, 1], color="tab:orange", lw=1.0, label=f"fused ({tracker.upper()})"
        )
        ax.set_title(
            f"Fig. {number}: fused estimate, {tracker.upper()} boxes (every {BOX_EVERY}th epoch)"
        )
        _save(plt, fig, ax, folder / f"fig{number}_fused_{tracker}.png")
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for tracker, estimation in runs.items():
        ax.plot(estimation.epochs.t_s, estimation.epochs.area_m2, lw=1.0, label=tracker.upper())
    ax.set_xlabel("time (s)")
    ax.set_ylabel("(x, y) area of the set (m²)")
    ax.set_yscale("log")
    ax.set_title("Box area per epoch")
    _save(plt, fig, ax, folder / "fig10_box_area.png")


def _map_axes(plt, spec):
    fig, ax = plt.subplots(figsize=(8, 6.6))
    for (ax_, ay), (bx, by) in spec.map.segments:
        ax.plot([ax_, bx], [ay, by], color="black", lw=1.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    return fig, ax


def _draw_boxes(ax, estimation: Estimation) -> None:
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    epochs = estimation.epochs
    patches = [
        Rectangle((box[0, 0], box[1, 0]), box[0, 1] - box[0, 0], box[1, 1] - box[1, 0])
        for e in range(0, len(epochs.t_s), BOX_EVERY)
        for box in epochs.epoch_boxes(e)
    ]
    ax.add_collection(
        PatchCollection(
            patches, facecolor="tab:red", edgecolor="darkred", lw=0.8, alpha=0.7, zorder=3
        )
    )


def _save(plt, fig, ax, path: Path) -> None:
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
