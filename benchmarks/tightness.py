"""Benchmark: how tight the interval sets are, with and without the sonar contractor (issue 13).

    python benchmarks/tightness.py [PLAN ...] [--duration S] [--samples N] [--seed S]
                                   [--tighten-levels L ...] [--shave-rounds R] [--no-off]
                                   [--write]

For each built-in plan (default: all), the scenario is simulated for ``--duration`` seconds
(default 30) and the interval tracker steps through its scans at ``eps_m = 0.05`` with the
scenario's other ``[estimation]`` settings, twice, interleaved scan by scan: with the contractor
(:mod:`intervals.sonar.contractor`, the default) and without it (not with ``--no-off``); with
``--tighten-levels L ...`` once more for each L > 0, the contractor on and the kept boxes
tightened ``L`` levels below eps (:mod:`intervals.tighten`) then shaved ``--shave-rounds``
rounds (default 1), at most ``--tighten-max-tested`` pieces tested an epoch (default: the
scenario's ``tighten_max_tested``). For each tracking epoch the
outer set's volume (x, y, heading; m² rad) is compared with the volume of the consistent poses
in it, estimated by sampling: ``--samples`` poses drawn uniformly in the outer boxes (a box
chosen with probability proportional to its volume), each judged by the simulator's own sonar
model, independently of the interval code: the exact cone distances of
``robotsim.sensors.sonar.cone_distances``, an echo ``m`` explained when the distance ``d`` is at
most ``d_max`` and ``|m - d| <= e_abs + e_rel d``, a no-echo reading (when the run uses free
space) when ``d > d_max``; a pose is consistent when at most ``q`` readings are unexplained
(``q`` = ``q_max`` for the guaranteed set, GOMNE's ``q`` otherwise) and it lies inside the
map's boundary (each variant and scan draws from a stream of its own, seeded by ``--seed``, the
variant and the scan, so a variant's figures do not depend on the others measured with it).
The outer set holds every consistent pose of the predicted region (it is
sound), so the fraction of consistent samples ``f`` estimates consistent volume / outer volume,
and the tightness ratio is ``1 / f`` (the issue's target: at most 3). Reported per plan and
contractor setting: the median and 90th percentile of the ratio over the tracking epochs, the
pooled ratio (all outer volume over all consistent volume), the mean (x, y) area, the median
and 95th percentile of the epoch's CPU time (``time.process_time``), the median wall time,
and the epochs that lost the truth (must be 0). An epoch without a consistent
sample counts as ``--samples`` (a lower bound of its ratio).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import zlib

import numpy as np
import shapely
from _common import machine_line, markdown_table, write_section

from intervals.sonar.scan import SonarBelt, SonarScan
from intervals.tracker import EpochStatus, IntervalTracker
from robotsim.sensors.sonar import cone_distances
from scenarios.runner import simulate_spec
from scenarios.spec import builtin_names, load_scenario

EPS_M = 0.05
"""The SIVIA precision of the issue's target."""

SECTION = "Tightness: outer volume over the consistent poses' volume (issue 13)"


def consistent_fraction(boxes, readings, spec, q, rng, samples) -> float:
    """Fraction of ``samples`` poses drawn uniformly in the union of ``boxes (N, 3, 2)`` that
    the simulator's model finds consistent with ``readings (k,)`` (module doc)."""
    lo, hi = boxes[:, :, 0], boxes[:, :, 1]
    vol = np.prod(hi - lo, axis=1)
    pick = rng.choice(boxes.shape[0], size=samples, p=vol / vol.sum())
    poses = lo[pick] + rng.random((samples, 3)) * (hi - lo)[pick]
    sonar, est = spec.sensors.sonar, spec.estimation
    d = cone_distances(
        poses, spec.map.segments, sonar.mount_xy, sonar.mount_angle_rad, sonar.half_aperture_rad
    )
    bound = sonar.error_abs_bound_m + sonar.error_rel_bound * np.where(np.isfinite(d), d, 0.0)
    echo = np.isfinite(readings)
    with np.errstate(invalid="ignore"):
        explained = (d <= sonar.d_max_m) & (np.abs(readings - d) <= bound)
    wrong = echo & ~explained
    if est.free_space:
        wrong |= ~echo & (d <= sonar.d_max_m)
    ok = np.count_nonzero(wrong, axis=1) <= q
    if spec.map.boundary is not None:
        ok &= shapely.contains_xy(shapely.Polygon(spec.map.boundary), poses[:, 0], poses[:, 1])
    return float(np.mean(ok))


def plan_rows(
    name: str,
    duration_s: float,
    samples: int,
    seed: int,
    levels: tuple[int, ...] = (),
    rounds: int = 1,
    off: bool = True,
    max_tested: int | None = None,
) -> list[list[str]]:
    """Table rows for one plan: with the contractor, without it (``off``), and tightened
    ``L`` levels for each ``L > 0`` of ``levels`` (at most ``max_tested`` pieces tested an
    epoch; None: the scenario's budget)."""
    spec = load_scenario(name).with_run(duration_s=duration_s)
    spec = spec.with_estimation(eps_m=EPS_M)
    log = simulate_spec(spec)
    est = spec.estimation
    belt = SonarBelt.from_params(spec.sensors.sonar, echoes_never_lost=est.free_space)
    variants = {"on": {"contractor": True}}
    if off:
        variants["off"] = {"contractor": False}
    for level in (level for level in levels if level > 0):
        variants[f"on, tighten {level}, shave {rounds}"] = {
            "contractor": True,
            "tighten_levels": level,
            "shave_rounds": rounds,
        }
        if max_tested is not None:
            variants[f"on, tighten {level}, shave {rounds}"]["tighten_max_tested"] = max_tested
    trackers = {
        key: IntervalTracker(dataclasses.replace(est.intervals, **change), spec.map.bounds)
        for key, change in variants.items()
    }
    scans = np.arange(0, len(log.sonar_t_s), est.scan_stride(spec.sensors.sonar.rate_hz))
    previous = dict.fromkeys(variants)
    last_t = log.sonar_t_s[scans[0]]
    stats = {
        key: {"ratio": [], "outer": [], "consistent": [], "area": [], "s": [], "cpu": []}
        for key in variants
    }
    lost = dict.fromkeys(variants, 0)
    for index in scans:
        scan = SonarScan(spec.map.segments, belt, log.sonar_range_m[index], spec.map.boundary)
        dt_s = float(log.sonar_t_s[index] - last_t)
        truth = log.sonar_pose[index]
        for key, tracker in trackers.items():  # interleaved: same scan, one after the other
            start, cpu = time.perf_counter(), time.process_time()
            result = tracker.step(previous[key], scan, dt_s)
            elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
            previous[key] = result.paving
            if not result.consistent:
                continue
            lost[key] += int(not result.paving.contains(truth[None])[0])
            if result.status != EpochStatus.TRACKING:
                continue
            outer = result.paving.outer
            q = est.intervals.q_max if est.intervals.guaranteed else result.q
            # a stream of its own for each variant and scan: a variant's samples are the same
            # whichever other variants the run measures
            rng = np.random.default_rng([seed, zlib.crc32(key.encode()), int(index)])
            f = consistent_fraction(outer, log.sonar_range_m[index], spec, q, rng, samples)
            volume = float(np.sum(np.prod(outer[:, :, 1] - outer[:, :, 0], axis=1)))
            s = stats[key]
            f = max(f, 1.0 / samples)  # no consistent sample: the ratio is at least `samples`
            s["ratio"].append(1.0 / f)
            s["outer"].append(volume)
            s["consistent"].append(volume * f)
            s["area"].append(result.paving.area_xy())
            s["s"].append(elapsed)
            s["cpu"].append(cpu)
        last_t = log.sonar_t_s[index]
    rows = []
    for key in variants:
        s = stats[key]
        if not s["ratio"]:
            rows.append([name, key, "0", "-", "-", "-", "-", "-", "-", str(lost[key])])
            continue
        ratio = np.array(s["ratio"])
        pooled = np.sum(s["outer"]) / np.sum(s["consistent"])
        rows.append(
            [
                name,
                key,
                str(ratio.size),
                f"{np.median(ratio):.1f}",
                f"{np.percentile(ratio, 90):.1f}",
                f"{pooled:.1f}",
                f"{np.mean(s['area']):.4f}",
                f"{1e3 * np.median(s['cpu']):.1f} / {1e3 * np.percentile(s['cpu'], 95):.1f}",
                f"{1e3 * np.median(s['s']):.1f}",
                str(lost[key]),
            ]
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("plans", nargs="*", help="built-in scenarios (default: all)")
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds")
    parser.add_argument("--samples", type=int, default=4000, help="poses sampled per epoch")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sampling")
    parser.add_argument(
        "--tighten-levels", type=int, nargs="*", default=[], help="also run tightened, each L"
    )
    parser.add_argument("--shave-rounds", type=int, default=1, help="shaving of that run")
    parser.add_argument(
        "--tighten-max-tested", type=int, help="pieces the tightening may test an epoch"
    )
    parser.add_argument("--no-off", action="store_true", help="not without the contractor")
    parser.add_argument("--write", action="store_true", help="update BENCHMARKS.md")
    args = parser.parse_args(argv)
    plans = args.plans or list(builtin_names())
    header = [
        "plan",
        "contractor",
        "tracking epochs",
        "ratio median",
        "ratio p90",
        "ratio pooled",
        "mean set area (m²)",
        "epoch CPU median / p95 (ms)",
        "epoch wall median (ms)",
        "truth lost",
    ]
    before = machine_line()
    rows = []
    for name in plans:
        new = plan_rows(
            name,
            args.duration,
            args.samples,
            args.seed,
            tuple(args.tighten_levels),
            args.shave_rounds,
            not args.no_off,
            args.tighten_max_tested,
        )
        rows += new
        print(markdown_table(header, new).split("\n", 2)[2], flush=True)
    command = "python benchmarks/tightness.py" + (" " + " ".join(args.plans) if args.plans else "")
    command += f" --duration {args.duration:g} --samples {args.samples} --seed {args.seed}"
    levels = " ".join(str(level) for level in args.tighten_levels if level > 0)
    if levels:
        command += f" --tighten-levels {levels} --shave-rounds {args.shave_rounds}"
        if args.tighten_max_tested is not None:
            command += f" --tighten-max-tested {args.tighten_max_tested}"
    if args.no_off:
        command += " --no-off"
    body = (
        f"`{command}`: per built-in plan, {args.duration:g} s simulated, eps_m = {EPS_M}, the "
        "scenario's other settings; the tracker with the sonar contractor (`on`, the default)"
        + ("" if args.no_off else " and without (`off`)")
        + (
            f", and with it and the kept boxes tightened {levels} levels below eps "
            f"then shaved {args.shave_rounds} round(s)"
            if levels
            else ""
        )
        + ", interleaved scan by scan. Ratio: outer volume over the volume of "
        f"the consistent poses in it, per tracking epoch, from {args.samples} poses sampled "
        "uniformly in the outer boxes and judged by the simulator's own cone model and error "
        "bounds (see the script's docstring); target <= 3. Pooled: all outer volume over all "
        "consistent volume.\n\n"
        + markdown_table(header, rows)
        + f"\n\nMachine: {before} (before); {machine_line()} (after)."
    )
    print(body)
    if args.write:
        write_section(SECTION, body)
    return 1 if any(row[-1] != "0" for row in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
