"""Benchmark of the whole localisation pipeline with its recording, stage by stage.

    python benchmarks/pipeline.py [SCENARIO] [--duration S] [--tracker sivia|imagesp] [--repeat R]

Runs what ``robotsim run`` runs steering on the truth (``follow = "truth"``, the paper's
clamp; default: ``hall``, 600 s): the physics loop, the sensors,
the 100 Hz dead reckoning of both branches, the interval epochs, the fusion, the summary and
the rerun recording (to a temporary file). The physics/sensors split comes from the
simulator's progress callback (it reports 1.0 when the physics loop ends). Prints each
stage's wall time and share, the median dead-reckoning step, the median and 95th
percentile interval epoch, the estimation figures of the run, and the real-time factor, for
the first run and the best of ``R`` repeats (per stage). The target of issue 5: at least
100 times real time (600 s in at most 6 s). The estimation runs the online localiser fed the
samples in order (``scenarios.pipeline.estimate``); the same pipeline on the finished arrays
(``estimate_offline``, bit-for-bit the same results) is timed beside it.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from intervals.tracker import Tracker
from scenarios.metrics import summarize
from scenarios.pipeline import estimate, estimate_offline, estimation_summary
from scenarios.recording import write_recording
from scenarios.runner import simulate_spec
from scenarios.spec import Follow, load_scenario
from validated_records import choices

STAGES = (
    "physics",
    "sensors",
    "dead reckoning",
    "interval epochs",
    "fusion",
    "summary",
    "recording",
)


def one_run(spec) -> tuple[dict[str, float], dict]:
    """Stage wall times of one run, and the run's figures (``offline_s``: the wall time of
    the estimation on the finished arrays, beside the online stages)."""
    stages: dict[str, float] = {}
    start = time.perf_counter()
    physics_end = []
    log = simulate_spec(
        spec, progress=lambda f: physics_end.append(time.perf_counter()) if f == 1.0 else None
    )
    end = time.perf_counter()
    stages["physics"] = physics_end[-1] - start
    stages["sensors"] = end - physics_end[-1]
    estimation, times = estimate(spec, log)
    stages["dead reckoning"] = times.dead_reckoning_s
    stages["interval epochs"] = times.intervals_s
    stages["fusion"] = times.fusion_s
    clock = time.perf_counter()
    estimate_offline(spec, log)
    offline_s = time.perf_counter() - clock
    clock = time.perf_counter()
    summary = summarize(spec, log)
    summary.update(estimation_summary(log, estimation))
    stages["summary"] = time.perf_counter() - clock
    clock = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        write_recording(Path(folder) / "run.rrd", spec, log, estimation)
        stages["recording"] = time.perf_counter() - clock
    epoch_ms = estimation.epochs.elapsed_s * 1e3
    figures = {
        "dr_step_us_median": float(np.median(times.dr_step_us)),
        "epoch_ms_median": float(np.median(epoch_ms)),
        "epoch_ms_p95": float(np.percentile(epoch_ms, 95)),
        "summary": summary,
        "offline_s": offline_s,
        "online_s": times.dead_reckoning_s + times.intervals_s + times.fusion_s,
    }
    return stages, figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="hall")
    parser.add_argument(
        "--duration", type=float, default=600.0, help="simulated seconds (default: %(default)s)"
    )
    parser.add_argument(
        "--tracker", choices=choices(Tracker), help="override the scenario's tracker"
    )
    parser.add_argument(
        "--repeat", type=int, default=1, help="repeats, best kept per stage (default: %(default)s)"
    )
    args = parser.parse_args(argv)
    # the open-loop pipeline with the paper's clamp (the closed loop: closed_loop.py --timing)
    loaded = load_scenario(args.scenario).with_run(duration_s=args.duration)
    spec = dataclasses.replace(loaded, follow=Follow.TRUTH).with_estimation(fusion="clamp")
    if args.tracker:
        spec = dataclasses.replace(spec, estimation=spec.estimation.with_keys(tracker=args.tracker))

    runs = [one_run(spec) for _ in range(max(1, args.repeat))]
    first, figures = runs[0]
    best = {name: min(run[0][name] for run in runs) for name in STAGES}
    print(
        f"pipeline {args.scenario} ({spec.estimation.intervals.tracker}, {spec.estimation.dead_reckoning.filter}, "
        f"{spec.estimation.fusion}): {args.duration:g} s; first run and best of {len(runs)}"
    )
    print("| stage | first (s) | best (s) | share |\n|---|---|---|---|")
    for name in STAGES:
        print(
            f"| {name} | {first[name]:.3f} | {best[name]:.3f} | {best[name] / sum(best.values()):.1%} |"
        )
    print(f"| **total** | **{sum(first.values()):.3f}** | **{sum(best.values()):.3f}** | |")
    print(
        f"| real-time factor | {args.duration / sum(first.values()):.0f}x "
        f"| {args.duration / sum(best.values()):.0f}x | |"
    )
    online, offline = figures["online_s"], figures["offline_s"]
    print(
        f"estimation alone (first run): online {online:.3f} s ({args.duration / online:.0f}x real time), "
        f"offline on the finished arrays {offline:.3f} s ({args.duration / offline:.0f}x)"
    )
    s = figures["summary"]
    print(
        f"dead-reckoning step (2 branches) median {figures['dr_step_us_median']:.1f} us; interval epoch median "
        f"{figures['epoch_ms_median']:.1f} ms, p95 {figures['epoch_ms_p95']:.1f} ms"
    )
    print(
        f"containment {s['containment']}, position RMSE UKF-only {s['rmse_position_m']['ukf_only']:.3f} m, fused "
        f"{s['rmse_position_m']['fused']:.3f} m (ratio {s['fused_to_ukf_only_position_rmse']:.2f}), heading RMSE "
        f"{s['rmse_heading_rad']['ukf_only']:.4f} / {s['rmse_heading_rad']['fused']:.4f} rad, mean box area "
        f"{s['box']['mean_area_m2']:.4f} m2, width {s['box']['mean_width_m']:.3f} m, q max {s['q_used_max']}, "
        f"empty {s['empty_epochs']}, lost {s['lost_epochs']}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
