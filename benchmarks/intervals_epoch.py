"""Benchmark: one interval tracking epoch and one global localisation on the ``hall`` map.

Tracking epoch: prior box truth-centred up to 0.25 m / 0.1 rad, half-widths 0.5 m and 0.2 rad,
``eps`` 0.05 m, default 16-sonar belt, bounded errors, echoes never lost. Global localisation:
the whole hall, heading in [-pi, pi]. Random poses at least 0.3 m from every wall; the median
wall time over many epochs is reported, with the set sizes. Each epoch is timed as the best of
``--repeat`` identical runs (as ``timeit`` does) so that other processes on a shared machine
do not inflate the figure; ``--repeat 1`` gives single-shot times. Exits 1 if a set loses the
truth. Then both trackers (SIVIA on the inflated hull, IMAGESP) on the same 60 scans of a
circuit, side by side, and the tracker in the pipeline's setting: the scans of the ``hall``
scenario's run (``--pipeline-s`` simulated seconds, 0 to skip) with its ``[estimation]``
settings (SIVIA, ``q_max`` 1, guaranteed, the robot's physical limits), as ``robotsim run``
steps it (only the interval epochs are timed).

Every case runs both implementations of the sonar box tests (the numpy references of
:mod:`intervals.sonar.reference`, through :func:`~intervals.sonar.reference.reference_box_tests`,
and the compiled kernels) on the same scans, interleaved scan by scan, and reports their times
side by side with the median per-epoch speed-up; it exits 1 as well if their sets differ. The
compiled kernel is loaded (compiled, on a fresh checkout) by one warm-up epoch before any
timing.

    python benchmarks/intervals_epoch.py [--epochs 200] [--global-runs 20] [--repeat 3] [--seed 0]
                                         [--pipeline-s 600]
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from functools import partial

import numpy as np

from intervals.localize import localize
from intervals.sonar.reference import reference_box_tests
from intervals.sonar.scan import SonarBelt, SonarScan
from intervals.tracker import IntervalTracker, Tracker, TrackerSettings
from robotsim.maps import builtin_map, point_segment_distance
from robotsim.sensors.sonar import SonarBeltParams, cone_distances

IMPLEMENTATIONS = ("numpy", "compiled")
"""The box tests timed side by side: the numpy references and the kernels."""


def _running(impl: str):
    """The context in which the pipeline runs the implementation ``impl``."""
    return reference_box_tests() if impl == "numpy" else contextlib.nullcontext()


def _random_poses(segment_map, count: int, rng: np.random.Generator) -> np.ndarray:
    b = segment_map.bounds
    poses = []
    while len(poses) < count:
        p = np.array([*rng.uniform(b[:, 0], b[:, 1]), rng.uniform(-np.pi, np.pi)])
        starts, ends = segment_map.segments[:, 0], segment_map.segments[:, 1]
        d = point_segment_distance(p[None, :2], starts, ends)
        if np.min(d) >= 0.3:
            poses.append(p)
    return np.array(poses)


def _scan(segment_map, params, belt, truth, rng) -> SonarScan:
    d = cone_distances(
        truth,
        segment_map.segments,
        params.mount_xy,
        params.mount_angle_rad,
        params.half_aperture_rad,
    )
    bound = params.error_abs_bound_m + params.error_rel_bound * np.where(np.isfinite(d), d, 0.0)
    m = np.maximum(d + rng.uniform(-1, 1, d.shape) * bound, 0.0)
    return SonarScan(
        segment_map.segments, belt, np.where(d > params.d_max_m, np.inf, m), segment_map.boundary
    )


def _step_both(trackers, previous, scan, dt_s, repeat):
    """One tracker epoch per implementation on the same scan, interleaved: ``(results, best_s)``
    dicts keyed by implementation (the best of ``repeat`` identical runs each)."""
    results, best = {}, {}
    for impl in IMPLEMENTATIONS:
        results[impl], best[impl] = _best_of(
            lambda i=impl: trackers[i].step(previous[i], scan, dt_s), repeat, impl
        )
    return results, best


def _same_sets(results) -> bool:
    """Every implementation returned the same status and the same boxes."""
    first = results["compiled"]
    return all(
        r.status == first.status and np.array_equal(r.outer, first.outer) for r in results.values()
    )


def _circuit_rows(hall, params, belt, rng, epochs: int, repeat: int) -> list[str]:
    """Both trackers on the same scans of a 2 m-radius circle at 0.3 m/s (1 Hz), side by side.
    Limits 0.5 m/s and 0.5 rad/s; q_max 0 (the scans have no outliers)."""
    omega = 0.15
    t = np.arange(epochs, dtype=float)
    heading = np.mod(omega * t + 1.5 * np.pi, 2 * np.pi) - np.pi
    poses = np.stack([4.5 + 2 * np.cos(omega * t), 3.8 + 2 * np.sin(omega * t), heading], 1)
    scans = [_scan(hall, params, belt, p, rng) for p in poses]
    rows = []
    for kind in Tracker:
        settings = TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=0.5, q_max=0, tracker=kind)
        trackers = {impl: IntervalTracker(settings, hall.bounds) for impl in IMPLEMENTATIONS}
        previous = dict.fromkeys(IMPLEMENTATIONS)
        times, boxes, areas, kept, differ = {i: [] for i in IMPLEMENTATIONS}, [], [], 0, 0
        for truth, scan in zip(poses, scans, strict=True):
            results, best = _step_both(trackers, previous, scan, 1.0, repeat)
            result = results["compiled"]
            if result.status == "tracking":
                for impl in IMPLEMENTATIONS:
                    times[impl].append(best[impl])
                boxes.append(result.paving.outer.shape[0])
                areas.append(result.paving.area_xy())
            kept += int(result.consistent and result.paving.contains(truth[None])[0])
            differ += int(not _same_sets(results))
            previous = {e: r.paving for e, r in results.items()}
        rows.append(
            _row(f"{kind} tracker epoch (circuit, limits 0.5 m/s, 0.5 rad/s)", times, boxes, areas)
        )
        if kept != epochs:
            rows.append(f"| FAILED: {kind} kept the truth in {kept} of {epochs} epochs |")
        if differ:
            rows.append(f"| FAILED: {kind}: the implementations' sets differ in {differ} epochs |")
    return rows


def _pipeline_rows(duration_s: float, repeat: int) -> list[str]:
    """The tracker on the scans of the ``hall`` scenario, with the scenario's settings."""
    from scenarios.runner import simulate_spec
    from scenarios.spec import load_scenario

    spec = load_scenario("hall").with_run(duration_s=duration_s)
    log = simulate_spec(spec)
    est = spec.estimation
    belt = SonarBelt.from_params(spec.sensors.sonar, echoes_never_lost=est.free_space)
    settings = spec.estimation.intervals
    trackers = {impl: IntervalTracker(settings, spec.map.bounds) for impl in IMPLEMENTATIONS}
    scans = np.arange(0, len(log.sonar_t_s), est.scan_stride(spec.sensors.sonar.rate_hz))
    previous, last_t = dict.fromkeys(IMPLEMENTATIONS), log.sonar_t_s[scans[0]]
    times, boxes, areas, kept, differ = {i: [] for i in IMPLEMENTATIONS}, [], [], 0, 0
    for index in scans:
        scan = SonarScan(spec.map.segments, belt, log.sonar_range_m[index], spec.map.boundary)
        results, best = _step_both(
            trackers, previous, scan, float(log.sonar_t_s[index] - last_t), repeat
        )
        result = results["compiled"]
        previous, last_t = {e: r.paving for e, r in results.items()}, log.sonar_t_s[index]
        for impl in IMPLEMENTATIONS:
            times[impl].append(best[impl])
        differ += int(not _same_sets(results))
        if result.consistent:
            boxes.append(result.paving.outer.shape[0])
            areas.append(result.paving.area_xy())
            kept += int(result.paving.contains(log.sonar_pose[index][None])[0])
    rows = [
        _row(
            f"sivia tracker epoch (pipeline: hall {duration_s:g} s, q_max {settings.q_max}, "
            "guaranteed; all epochs)",
            times,
            boxes,
            areas,
        )
    ]
    if kept != len(scans):
        rows.append(f"| FAILED: pipeline tracker kept the truth in {kept} of {len(scans)} epochs |")
    if differ:
        rows.append(f"| FAILED: pipeline: the implementations' sets differ in {differ} epochs |")
    return rows


def _best_of(call, repeat: int, impl: str = "compiled"):
    """``(call(), best wall time s)`` over ``repeat`` identical calls (at least one), run on
    the implementation ``impl`` of the box tests."""
    best, result = np.inf, None
    with _running(impl):
        for _ in range(max(1, repeat)):
            start = time.perf_counter()
            result = call()
            best = min(best, time.perf_counter() - start)
    return result, best


def _row(label: str, times: dict, boxes: list, areas: list) -> str:
    """A table row: per implementation the median and p95 epoch ms, the median per-epoch
    speed-up of the kernels, the median set size and (x, y) area."""
    t = {e: np.array(v) * 1e3 for e, v in times.items()}
    speedup = np.median(t["numpy"] / t["compiled"])
    return (
        f"| {label} | {len(t['compiled'])} | {np.median(t['numpy']):.1f} | "
        f"{np.percentile(t['numpy'], 95):.1f} | {np.median(t['compiled']):.1f} | "
        f"{np.percentile(t['compiled'], 95):.1f} | {speedup:.1f}x | {np.median(boxes):.0f} | "
        f"{np.median(areas):.4f} |"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=200)
    parser.add_argument("--global-runs", type=int, default=20)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pipeline-s", type=float, default=600.0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    hall = builtin_map("hall")
    params = SonarBeltParams.default_belt()
    belt = SonarBelt.from_params(params)
    eps = 0.05
    half = np.array([0.5, 0.5, 0.2])
    b = hall.bounds
    whole = np.array([b[0], b[1], [-np.pi, np.pi]])

    warm_up = _scan(hall, params, belt, np.array([3.0, 3.0, 0.0]), np.random.default_rng(0))
    for impl in IMPLEMENTATIONS:  # load (or compile) the kernels before timing; rng untouched
        _best_of(partial(localize, warm_up, whole, 0.5), 1, impl)
    rows, lost = [], 0
    for label, runs in (
        ("tracking epoch (prior +-0.5 m, +-0.2 rad)", args.epochs),
        ("global localisation (whole hall)", args.global_runs),
    ):
        times, boxes, areas, differ = {i: [] for i in IMPLEMENTATIONS}, [], [], 0
        for truth in _random_poses(hall, runs, rng):
            scan = _scan(hall, params, belt, truth, rng)
            if label.startswith("tracking"):
                centre = truth + rng.uniform(-1, 1, 3) * np.array([0.25, 0.25, 0.1])
                prior = np.stack([centre - half, centre + half], axis=-1)
            else:
                prior = whole
            pavings = {}
            for impl in IMPLEMENTATIONS:  # interleaved: both on each scan in turn
                pavings[impl], best = _best_of(
                    partial(localize, scan, prior, eps), args.repeat, impl
                )
                times[impl].append(best)
            paving = pavings["compiled"]
            differ += int(not np.array_equal(paving.outer, pavings["numpy"].outer))
            boxes.append(paving.outer.shape[0])
            areas.append(paving.area_xy())
            lost += int(not paving.contains(truth[None])[0])
        rows.append(_row(label, times, boxes, areas))
        if differ:
            rows.append(f"| FAILED: {label}: the implementations' sets differ in {differ} runs |")
    rows += _circuit_rows(hall, params, belt, rng, 60, args.repeat)
    if args.pipeline_s > 0:
        rows += _pipeline_rows(args.pipeline_s, args.repeat)
    lost += sum("FAILED" in row for row in rows)
    print(
        "| case (hall, eps 0.05 m, 16 sonars) | runs | numpy median ms | numpy p95 ms "
        "| compiled median ms | compiled p95 ms | speed-up (median) | median boxes "
        "| median (x, y) area m^2 |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    if lost:
        print(
            f"FAILED: the truth left a set, or the implementations differ ({lost})", file=sys.stderr
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
