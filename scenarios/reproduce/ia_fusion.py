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
epoch, containment of the truth; the run beside the paper's stated setting and results; the
paper's qualitative claims checked) and the figures: like the paper's, ``fig7_ukf_only.png``
(truth and UKF-only estimate), ``fig8_fused_sivia.png`` and ``fig9_fused_imagesp.png``
(truth, UKF-only, fused estimate and the sets); of our own, ``fig10_box_area.png`` (set area
per epoch, both trackers), ``fig11_error_over_time.png`` (errors at the epochs inside the
band of the box the clamp used), ``fig12_epoch_time.png`` (time per epoch, both trackers)
and ``fig13_zoomed_epoch.png`` (one epoch on the map, close up).

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
from scenarios.reproduce._filter_runs import format_ratio, magnitude_verdict, ratio
from scenarios.reproduce.figure_style import axis_label, plain_ticks, save
from scenarios.runner import simulate_spec
from scenarios.spec import Follow, load_scenario

HELP = "paper 002: UKF dead reckoning clamped to interval boxes, SIVIA vs IMAGESP on hall (table, figures 7-13)"

TRACKERS = tuple(Tracker)
SCENARIO = "hall"

#: Boxes are drawn at every this many epochs in the figures (all of them would hide the paths);
#: a prime, so that on the laps of ``hall`` they fall at new places instead of piling up.
BOX_EVERY = 7


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
    # the paper's setting: the robot on its route (the true pose steers), the clamp
    loaded = with_run_options(load_scenario(SCENARIO), args.seed, args.duration)
    spec = dataclasses.replace(loaded, follow=Follow.TRUTH).with_estimation(fusion="clamp")
    log, runs, rows = experiment(spec)
    claims = check_claims(rows)
    table = {
        "scenario": spec.name,
        "seed": spec.run.seed,
        "duration_s": spec.run.duration_s,
        "estimation": {k: v for k, v in spec.estimation.as_keys().items() if k != "tracker"},
        "trackers": rows,
        "claims": claims,
        "against_paper": against_paper(spec, rows),
    }
    with atomic_directory(args.out) as folder:
        write_json(folder / "table.json", table)
        write_text(folder / "table.md", markdown(table))
        for name, fig in figures(spec, log, runs).items():
            save(fig, folder / name)
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


def experiment(spec) -> tuple[Any, dict[str, Estimation], dict[str, dict[str, Any]]]:
    """Simulate ``spec`` once and run the pipeline with each tracker on the same data: the
    log, the estimations and the table rows, by tracker (no I/O)."""
    log = simulate_spec(spec)
    rows: dict[str, dict[str, Any]] = {}
    runs: dict[str, Estimation] = {}
    for tracker in TRACKERS:
        variant = dataclasses.replace(spec, estimation=spec.estimation.with_keys(tracker=tracker))
        estimation, _ = estimate(variant, log)
        runs[tracker] = estimation
        rows[tracker] = table_row(estimation_summary(log, estimation), estimation)
    return log, runs, rows


#: What paper 002 states in numbers: its setting (section, wording), beside the run's.
PAPER_SETTINGS = (
    ("dead-reckoning rate (Hz)", 100.0, "sec. 4: sampling time of 0.01 s"),
    ("interval epochs per second (Hz)", 1.0, "sec. 4: updated once every second"),
    ("sonar range limit (m)", 3.0, "sec. 3: range limited to 3 m"),
)
#: What it states in words only (section), with the ratio ours that decides it.
PAPER_RESULTS = (
    (
        "fused / UKF-only position RMSE, SIVIA",
        "below 1: 'significantly improved' (sec. 4, figs. 7-8)",
    ),
    (
        "fused / UKF-only position RMSE, IMAGESP",
        "below 1: 'significantly improved' (sec. 4, fig. 9)",
    ),
    ("IMAGESP / SIVIA mean set area", "below 1: SIVIA's uncertainty 'is more' (sec. 4, figs. 8-9)"),
    ("IMAGESP / SIVIA median time per epoch", "above 1: IMAGESP's complexity 'is more' (sec. 4)"),
)


def against_paper(spec, rows: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """The run beside paper 002: its settings with ours / paper, then its results, which it
    gives as figures and words only (no paper value, no ratio; the verdict on the direction).
    """
    ours = (
        spec.run.rate_hz,
        spec.estimation.interval_rate_hz,
        spec.sensors.sonar.d_max_m,
    )
    out: list[dict[str, Any]] = [
        {
            "quantity": quantity,
            "ours": float(value),
            "paper": paper,
            "source": source,
            "ratio": ratio(value, paper),
            "verdict": "as the paper" if value == paper else magnitude_verdict(ratio(value, paper)),
        }
        for (quantity, paper, source), value in zip(PAPER_SETTINGS, ours, strict=True)
    ]
    sivia, imagesp = rows["sivia"], rows["imagesp"]
    values = (
        sivia["fused_to_ukf_only_position_rmse"],
        imagesp["fused_to_ukf_only_position_rmse"],
        imagesp["box"]["mean_area_m2"] / sivia["box"]["mean_area_m2"],
        imagesp["epoch_ms_median"] / sivia["epoch_ms_median"],
    )
    for (quantity, claim), value in zip(PAPER_RESULTS, values, strict=True):
        holds = value > 1.0 if claim.startswith("above") else value < 1.0
        out.append(
            {
                "quantity": quantity,
                "ours": float(value),
                "paper": None,
                "source": claim,
                "ratio": None,
                "verdict": ("direction holds" if holds else "direction DOES NOT HOLD")
                + "; no paper value",
            }
        )
    return out


def _value(paper: float | None) -> str:
    return "-" if paper is None else f"{paper:g}"


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
    lines += [
        "## Against the paper",
        "",
        "Paper 002 states its setting in numbers and its results in figures and words only: "
        "the results have no paper value to divide by, only a direction to check.",
        "",
        "| quantity | ours | paper | source | ours / paper | verdict |",
        "|---|---|---|---|---|---|",
        *(
            f"| {r['quantity']} | {r['ours']:.3g} | {_value(r['paper'])} "
            f"| {r['source']} | {format_ratio(r['ratio'])} | {r['verdict']} |"
            for r in table["against_paper"]
        ),
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


#: Colours of the elements, the same in every figure.
COLOURS = {
    "truth": "tab:green",
    "ukf_only": "tab:blue",
    "sivia": "tab:red",
    "imagesp": "tab:purple",
    "walls": "black",
}
#: Line styles of the fused estimates, so the two trackers stay apart where they coincide.
FUSED_STYLE = {"sivia": "-", "imagesp": "--"}


def figures(spec, log, runs: dict[str, Estimation]) -> dict[str, Any]:
    """Every figure by file name (unsaved): figures 7-9 of the paper (trajectories and sets on
    the map), the set's area per epoch (10), the errors over time with the band of the box the
    clamp used (11), the time per epoch (12) and one epoch zoomed in (13)."""
    out = {"fig7_ukf_only.png": _trajectories(spec, log, runs, None)}
    out |= {
        f"fig{number}_fused_{tracker}.png": _trajectories(spec, log, runs, tracker)
        for number, tracker in ((8, "sivia"), (9, "imagesp"))
    }
    out["fig10_box_area.png"] = _box_area(runs)
    out["fig11_error_over_time.png"] = _errors_over_time(log, runs)
    out["fig12_epoch_time.png"] = _epoch_times(runs)
    out["fig13_zoomed_epoch.png"] = _zoomed_epoch(spec, log, runs, zoom_epoch(runs))
    return out


def _trajectories(spec, log, runs: dict[str, Estimation], tracker: str | None):
    """Figure 7 (``tracker`` None: truth and UKF-only) or 8/9 (the fused estimate and the
    tracker's sets of every :data:`BOX_EVERY`-th epoch)."""
    from matplotlib import pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 6.6))
    _walls(ax, spec)
    ukf = runs[TRACKERS[0]].pose[UKF_ONLY]
    if tracker is None:
        ax.plot(*log.pose[:, :2].T, color=COLOURS["truth"], lw=1.2, label="truth")
        ax.plot(*ukf[:, :2].T, color=COLOURS["ukf_only"], lw=1.0, label="UKF only")
        ax.set_title("Fig. 7: UKF-only estimate (encoders, gyro, accelerometer)")
    else:
        estimation = runs[tracker]
        epochs = range(0, len(estimation.epochs.t_s), BOX_EVERY)
        _boxes(ax, estimation, epochs, tracker, f"{tracker.upper()} set, every {BOX_EVERY}th epoch")
        ax.plot(*log.pose[:, :2].T, color=COLOURS["truth"], lw=1.2, label="truth")
        ax.plot(*ukf[:, :2].T, color=COLOURS["ukf_only"], lw=0.8, alpha=0.6, label="UKF only")
        ax.plot(
            *estimation.pose[FUSED][:, :2].T,
            color="tab:orange",
            lw=1.0,
            label=f"fused ({tracker.upper()})",
        )
        number = 8 if tracker == "sivia" else 9
        ax.set_title(f"Fig. {number}: fused estimate and the {tracker.upper()} sets")
    _map_labels(ax)
    _legend(ax, loc="center", fontsize=8)
    fig.tight_layout()
    return fig


def _box_area(runs: dict[str, Estimation]):
    """Figure 10: the (x, y) area of each tracker's set per epoch, log scale, plain ticks."""
    from matplotlib import pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.5))
    for tracker, estimation in runs.items():
        area = estimation.epochs.area_m2
        ax.plot(
            estimation.epochs.t_s,
            area,
            lw=1.0,
            color=COLOURS[tracker],
            label=f"{tracker.upper()} (mean {np.nanmean(area):.3g} m²)",
        )
    ax.set_yscale("log")
    plain_ticks(ax)
    ax.set_xlabel(axis_label("time", "s"))
    ax.set_ylabel(axis_label("(x, y) area of the set", "m²"))
    ax.set_title("Fig. 10: area of the interval set per epoch")
    _legend(ax, loc="upper right", fontsize=8)
    fig.tight_layout()
    return fig


def epoch_errors(log, estimation: Estimation) -> dict[str, np.ndarray]:
    """Errors at the epochs ``(E, 3)`` (x, y in metres, heading in radians wrapped to
    ``(-pi, pi]``) of the UKF-only and the fused (after the clamp) estimates, and the box the
    clamp used relative to the truth, ``band (E, 3, 2)`` (NaN where the epoch did not clamp).
    The truth is in that box exactly where the band holds 0.

    The heading of the band is the hull of the headings of that component's boxes, each box
    shifted by whole turns to lie nearest the true heading: the box the fusion keeps is a hull
    in ``[-pi, pi]`` and spans the whole turn when the set straddles ``+-pi``.
    """
    truth = log.pose[estimation.epoch_index]
    band = estimation.fused_box - truth[:, :, None]
    epochs = estimation.epochs
    owner = np.repeat(np.arange(len(epochs.t_s)), epochs.box_counts)  # (B,) epoch of each box
    chosen = epochs.labels == estimation.component[owner]
    heading = epochs.boxes[:, 2, :] - truth[owner, 2, None]  # (B, 2)
    heading -= 2.0 * np.pi * np.round(heading.mean(axis=1) / (2.0 * np.pi))[:, None]
    low = np.full(len(epochs.t_s), np.inf)
    high = np.full(len(epochs.t_s), -np.inf)
    np.minimum.at(low, owner[chosen], heading[chosen, 0])
    np.maximum.at(high, owner[chosen], heading[chosen, 1])
    clamped = np.isfinite(band[:, 2, 0]) & np.isfinite(low)
    band[:, 2, 0] = np.where(clamped, low, np.nan)
    band[:, 2, 1] = np.where(clamped, high, np.nan)

    def wrapped(pose: np.ndarray) -> np.ndarray:
        error = pose - truth
        error[:, 2] = np.angle(np.exp(1j * error[:, 2]))
        return error

    return {
        "ukf_only": wrapped(estimation.pose[UKF_ONLY][estimation.epoch_index]),
        "fused": wrapped(estimation.after),
        "band": band,
    }


def _errors_over_time(log, runs: dict[str, Estimation]):
    """Figure 11: position error of both branches, and x, y and heading errors of the fused
    estimates inside the band of the box the clamp used, per epoch."""
    from matplotlib import pyplot as plt

    fig, axes = plt.subplots(4, 1, figsize=(9, 9.5), sharex=True)
    errors = {tracker: epoch_errors(log, e) for tracker, e in runs.items()}
    t_s = runs[TRACKERS[0]].epochs.t_s
    ukf = errors[TRACKERS[0]]["ukf_only"]
    ax = axes[0]
    ax.plot(
        t_s, np.hypot(ukf[:, 0], ukf[:, 1]), color=COLOURS["ukf_only"], lw=1.0, label="UKF only"
    )
    for tracker, e in errors.items():
        ax.plot(
            t_s,
            np.hypot(e["fused"][:, 0], e["fused"][:, 1]),
            FUSED_STYLE[tracker],
            color=COLOURS[tracker],
            lw=0.9,
            label=f"fused ({tracker.upper()})",
        )
    ax.set_yscale("log")
    plain_ticks(ax)
    ax.set_ylabel(axis_label("position error", "m"))
    ax.set_title("Fig. 11: errors at the epochs; bands: the box the clamp used, minus the truth")
    _legend(ax, loc="upper left", fontsize=7, ncol=3)
    for ax, i, quantity, unit in (
        (axes[1], 0, "x error", "m"),
        (axes[2], 1, "y error", "m"),
        (axes[3], 2, "heading error", "rad"),
    ):
        for tracker, e in errors.items():
            ax.fill_between(
                t_s,
                e["band"][:, i, 0],
                e["band"][:, i, 1],
                color=COLOURS[tracker],
                alpha=0.25 if tracker == "sivia" else 0.35,
                lw=0,
                label=f"{tracker.upper()} box",
            )
        if i == 2:
            # the clamp moves the position only: the fused heading is the UKF-only heading
            ax.plot(
                t_s,
                ukf[:, 2],
                color=COLOURS["ukf_only"],
                lw=0.9,
                label="UKF only = fused, both trackers (the clamp keeps the heading)",
            )
        else:
            for tracker, e in errors.items():
                ax.plot(
                    t_s,
                    e["fused"][:, i],
                    FUSED_STYLE[tracker],
                    color=COLOURS[tracker],
                    lw=0.8,
                    label=f"fused ({tracker.upper()})",
                )
        ax.axhline(0.0, color="k", lw=0.5, label="zero (the truth)")
        plain_ticks(ax)
        ax.set_ylabel(axis_label(quantity, unit))
        _legend(ax, loc="upper left", fontsize=7, ncol=3)
    axes[-1].set_xlabel(axis_label("time", "s"))
    fig.tight_layout()
    return fig


def _epoch_times(runs: dict[str, Estimation]):
    """Figure 12: wall time of each tracker's epoch, with its median."""
    from matplotlib import pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.5))
    for tracker, estimation in runs.items():
        ms = estimation.epochs.elapsed_s * 1e3
        ax.plot(estimation.epochs.t_s, ms, lw=0.8, color=COLOURS[tracker], label=tracker.upper())
        ax.axhline(
            float(np.median(ms)),
            color=COLOURS[tracker],
            ls=":",
            lw=1.2,
            label=f"{tracker.upper()} median {np.median(ms):.3g} ms",
        )
    ax.set_yscale("log")
    plain_ticks(ax)
    ax.set_xlabel(axis_label("time", "s"))
    ax.set_ylabel(axis_label("time per epoch", "ms"))
    ax.set_title("Fig. 12: time per epoch (wall time, depends on the machine's load)")
    _legend(ax, loc="upper right", fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def zoom_epoch(runs: dict[str, Estimation]) -> int:
    """The epoch figure 13 shows: the one where the UKF-only estimate is farthest outside
    the SIVIA box, that is where the clamp moves the estimate most."""
    estimation = runs["sivia"]
    moved = np.hypot(*(estimation.after - estimation.before)[:, :2].T)
    return int(np.argmax(np.nan_to_num(moved, nan=-1.0)))


def _zoomed_epoch(spec, log, runs: dict[str, Estimation], epoch: int):
    """Figure 13: one epoch on the map. Left, the map within the sonar's reach of the truth
    and a frame round the close-up; right, the close-up: both trackers' sets, the boxes the
    clamp used, the truth with its heading, the estimate before the clamp and both clamped
    ones."""
    from matplotlib import pyplot as plt
    from matplotlib.patches import Rectangle

    fig, (wide, ax) = plt.subplots(1, 2, figsize=(11, 5.2))
    _epoch_on_map(wide, spec, log, runs, epoch, detail=False)
    _epoch_on_map(ax, spec, log, runs, epoch)
    first = runs[TRACKERS[0]]
    truth = log.pose[int(first.epoch_index[epoch])]
    middle, half = _close_up(log, runs, epoch)
    walls = np.asarray(spec.map.segments).reshape(-1, 2)  # the map's extent bounds the view
    low = np.maximum(truth[:2] - spec.sensors.sonar.d_max_m, walls.min(axis=0) - 0.2)
    high = np.minimum(truth[:2] + spec.sensors.sonar.d_max_m, walls.max(axis=0) + 0.2)
    wide.set_xlim(low[0], high[0])
    wide.set_ylim(low[1], high[1])
    ax.set_xlim(middle[0] - half, middle[0] + half)
    ax.set_ylim(middle[1] - half, middle[1] + half)
    for axes in (wide, ax):
        plain_ticks(axes, "x")
        plain_ticks(axes)
        _map_labels(axes)
    wide.add_patch(
        Rectangle(
            tuple(middle - half), 2 * half, 2 * half, fill=False, lw=1.0, label="close-up (right)"
        )
    )
    t_s = first.epochs.t_s[epoch]
    wide.set_title(f"Fig. 13: the epoch at t = {t_s:g} s, within the sonar range")
    ax.set_title("close up")
    _legend(wide, loc="best", fontsize=7)
    _legend(ax, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7)
    fig.tight_layout()
    return fig


def _close_up(log, runs: dict[str, Estimation], epoch: int) -> tuple[np.ndarray, float]:
    """Centre ``(2,)`` and half width (m) of a square holding the truth, the boxes the clamp
    used and the clamped estimates of ``epoch``."""
    first = runs[TRACKERS[0]]
    corners = [log.pose[int(first.epoch_index[epoch]), None, :2]]
    for estimation in runs.values():
        box = estimation.fused_box[epoch]
        if np.isfinite(box).all():
            corners.append(box[:2].T)
        corners.append(estimation.after[epoch][None, :2])
    low, high = np.concatenate(corners).min(axis=0), np.concatenate(corners).max(axis=0)
    return (low + high) / 2.0, max(0.25, 0.6 * float(np.max(high - low)))


def _epoch_on_map(
    ax, spec, log, runs: dict[str, Estimation], epoch: int, detail: bool = True
) -> None:
    """What figure 13 shows of ``epoch``, drawn on ``ax`` (limits left to the caller): the
    walls, the sets and the truth, and with ``detail`` the boxes the clamp used and the
    estimates."""
    _walls(ax, spec)
    first = runs[TRACKERS[0]]
    sample = int(first.epoch_index[epoch])
    truth = log.pose[sample]
    for tracker, estimation in runs.items():
        _boxes(ax, estimation, [epoch], tracker, f"{tracker.upper()} set")
        box = estimation.fused_box[epoch]
        if detail and np.isfinite(box).all():
            ax.add_patch(
                _rectangle(
                    box,
                    facecolor="none",
                    edgecolor=COLOURS[tracker],
                    lw=1.4,
                    ls="--",
                    label=f"box the clamp used ({tracker.upper()})",
                )
            )
    ax.plot(*truth[:2], "o", color=COLOURS["truth"], ms=7 if detail else 3, zorder=5, label="truth")
    if not detail:
        return
    before = first.before[epoch]
    ukf = first.pose[UKF_ONLY][sample]
    reach = 0.15  # m, length of the heading marks
    ax.plot(
        [truth[0], truth[0] + reach * np.cos(truth[2])],
        [truth[1], truth[1] + reach * np.sin(truth[2])],
        color=COLOURS["truth"],
        lw=2,
        zorder=5,
        label=f"truth heading ({reach} m mark)",
    )
    ax.plot(
        [truth[0], ukf[0]],
        [truth[1], ukf[1]],
        ":",
        color=COLOURS["ukf_only"],
        label=f"to the UKF-only estimate ({np.hypot(*(ukf - truth)[:2]):.2f} m away)",
    )
    ax.plot(
        *before[:2],
        "s",
        mfc="none",
        color="tab:orange",
        ms=7,
        zorder=5,
        label=f"fused branch before the clamp ({np.hypot(*(before - truth)[:2]):.2f} m off)",
    )
    ax.plot(
        [before[0], first.after[epoch][0]],
        [before[1], first.after[epoch][1]],
        ":",
        color="tab:orange",
        label=f"the clamp's move ({TRACKERS[0].upper()})",
    )
    for tracker, estimation in runs.items():
        after = estimation.after[epoch]
        ax.plot(
            *after[:2],
            "x" if tracker == "sivia" else "+",
            color=COLOURS[tracker],
            ms=9,
            mew=2,
            zorder=6,
            label=f"clamped to {tracker.upper()} ({np.hypot(*(after - truth)[:2]):.2f} m off)",
        )


def _walls(ax, spec) -> None:
    from matplotlib.collections import LineCollection

    ax.add_collection(
        LineCollection(
            list(np.asarray(spec.map.segments)),
            colors=COLOURS["walls"],
            lw=1.5,
            label="walls, landmarks",
        )
    )
    ax.autoscale_view()


def _map_labels(ax) -> None:
    ax.set_aspect("equal")
    ax.set_xlabel(axis_label("x", "m"))
    ax.set_ylabel(axis_label("y", "m"))


def _rectangle(box: np.ndarray, **style):
    """The (x, y) face of ``box (3, 2)`` as a matplotlib rectangle."""
    from matplotlib.patches import Rectangle

    return Rectangle((box[0, 0], box[1, 0]), box[0, 1] - box[0, 0], box[1, 1] - box[1, 0], **style)


def _boxes(ax, estimation: Estimation, epochs, tracker: str, label: str) -> None:
    """The outer boxes of ``epochs`` as outlined, lightly filled rectangles: one collection
    labelled ``label`` (:func:`_legend` gives it a legend entry)."""
    from matplotlib.collections import PatchCollection

    colour = COLOURS[tracker]
    patches = [_rectangle(box) for e in epochs for box in estimation.epochs.epoch_boxes(e)]
    ax.add_collection(
        PatchCollection(
            patches,
            facecolor=colour,
            edgecolor=colour,
            alpha=0.3,
            lw=0.5,
            zorder=3,
            label=label,
        )
    )


def _legend(ax, **options) -> None:
    """The legend of every labelled element of ``ax``. A patch collection (the sets) has no
    legend handle of its own: a rectangle of its colours stands in for it."""
    from matplotlib.collections import PatchCollection
    from matplotlib.colors import to_hex
    from matplotlib.patches import Patch

    handles, labels = ax.get_legend_handles_labels()
    handles = [
        Patch(
            facecolor=to_hex(np.asarray(h.get_facecolor())[0], keep_alpha=True),
            edgecolor=to_hex(np.asarray(h.get_edgecolor())[0], keep_alpha=True),
            lw=1.0,
        )
        if isinstance(h, PatchCollection)
        else h
        for h in handles
    ]
    ax.legend(handles, labels, **options)
