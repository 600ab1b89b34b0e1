"""Cost of one particle-filter update (localization.mcl) against the particle count.

    python benchmarks/mcl.py [--counts 500 2000 5000 20000] [--repeats 7] [--write]

Data: a hall scan (16 sonars, 3 m) and an odometry step of 0.3 m that passes the
``update_min_d`` gate; the particles spread uniformly over the hall (global localisation,
where every cone meets walls at every distance). Each particle count runs with
``min_particles = max_particles = N``, so every update keeps N particles. One update is the
whole step: the odometry motion model, the expected ranges (the simulator's exact cone
model, :func:`scenarios.mcl_ranges.cone_range_function`), the beam mixture, the weights and
the KLD-sized systematic resampling. The table gives, per update, the best and median wall
time over ``--repeats`` updates, the CPU time (``time.process_time``) of the best round,
the wall time per particle, and the share of the expected ranges. The kernels are compiled
(or loaded from numba's cache) before the timings; that time is printed apart. Single
threaded (no numba ``parallel``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import machine_line, markdown_table, write_section

from localization.mcl import MclSettings, MonteCarloLocalization
from scenarios.mcl_ranges import cone_range_function, free_space_sampler
from scenarios.runner import simulate_spec
from scenarios.spec import load_scenario

SECTION = "MCL update against the particle count"
STEP = np.array([0.3, 0.0, 0.05])
"""The odometry step between two timed updates (x_m, y_m, theta_rad)."""


def hall_inputs():
    """The spec, one scan of a hall run and the range function."""
    spec = load_scenario("hall").with_run(duration_s=5.0)
    log = simulate_spec(spec)
    ranges = cone_range_function(spec.map.segments, spec.sensors.sonar)
    return spec, np.array(log.sonar_range_m[-1]), ranges


def make_filter(spec, ranges, count: int, seed: int = 0) -> MonteCarloLocalization:
    """A filter of ``count`` particles over the hall, uniform prior."""
    settings = MclSettings(min_particles=count, max_particles=count)
    mcl = MonteCarloLocalization(
        settings,
        ranges,
        free_space_sampler(spec.map, spec.robot.radius_m),
        spec.map.bounds,
        spec.sensors.sonar.d_max_m,
        np.random.default_rng(seed),
    )
    mcl.global_localization()
    return mcl


def time_updates(mcl: MonteCarloLocalization, scan: np.ndarray, ranges, repeats: int) -> dict:
    """Wall and CPU seconds of ``repeats`` updates (each re-spreading the particles
    uniformly first, untimed, so that every update sees a global-localisation set), and the
    best wall time of the expected ranges alone."""
    odom = np.zeros(3)
    mcl.update(odom, scan)  # the first update (no motion)
    wall, cpu, range_s = [], [], []
    for _ in range(repeats):
        mcl.global_localization()
        odom = odom + STEP
        wall_0, cpu_0 = time.perf_counter(), time.process_time()
        updated = mcl.update(odom, scan)
        wall.append(time.perf_counter() - wall_0)
        cpu.append(time.process_time() - cpu_0)
        if not updated:
            raise RuntimeError("the odometry step did not pass the update gate")
        particles = mcl.particles
        start = time.perf_counter()
        ranges(particles)
        range_s.append(time.perf_counter() - start)
    best = int(np.argmin(wall))
    return {
        "best_s": wall[best],
        "median_s": float(np.median(wall)),
        "cpu_s": cpu[best],
        "ranges_s": min(range_s),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[500, 2000, 5000, 20000])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--write", action="store_true", help="update this section of BENCHMARKS.md")
    args = parser.parse_args()

    spec, scan, ranges = hall_inputs()
    start = time.perf_counter()
    warm = make_filter(spec, ranges, 200)
    warm.update(np.zeros(3), scan)
    warm.update(STEP, scan)
    warm.estimate()
    compile_s = time.perf_counter() - start
    print(f"compile or cache load of the kernels, and a 200-particle warm-up: {compile_s:.2f} s")

    rows = []
    for count in args.counts:
        figures = time_updates(make_filter(spec, ranges, count), scan, ranges, args.repeats)
        rows.append(
            [
                f"{count}",
                f"{figures['best_s'] * 1e3:.2f}",
                f"{figures['median_s'] * 1e3:.2f}",
                f"{figures['cpu_s'] * 1e3:.2f}",
                f"{figures['best_s'] / count * 1e6:.2f}",
                f"{100 * figures['ranges_s'] / figures['best_s']:.0f} %",
            ]
        )
    header = [
        "particles",
        "update, ms (best)",
        "update, ms (median)",
        "CPU, ms (best round)",
        "us / particle",
        "expected ranges",
    ]
    table = markdown_table(header, rows)
    segments = len(spec.map.segments)
    body = (
        f"`python benchmarks/mcl.py --repeats {args.repeats}`: one update (motion, expected "
        f"ranges of 16 sonars over {segments} segments, beam mixture, KLD-sized systematic "
        f"resampling) of a uniformly spread set on hall, best of {args.repeats}; "
        f"kernels compiled before timing ({compile_s:.1f} s with the cache state of this run). "
        f"{machine_line('numba')}.\n\n{table}"
    )
    print(body)
    if args.write:
        write_section(SECTION, body)


if __name__ == "__main__":
    main()
