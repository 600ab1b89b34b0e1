"""Speed of the 100 Hz dead reckoning: 60,000 steps (600 s) of the 2-branch batch.

    python benchmarks/dead_reckoning.py [--steps 60000] [--repeats 3] [--runs 100] [--generic-steps 2000]

Data: the sensor log of 600 s on ``hall`` (the default route of the simulator's tests, seed
0). Figures, side by side in one run (best of ``--repeats``):

- the compiled step (``localization.compiled.dead_reckoning``, one numba call per ``run()``
  stretch) for ``ukf``, ``iukf`` and ``ekf`` (``iekf`` runs the ``ekf`` code), the batch
  ``(2, 8)`` = the UKF-only and the fused branch on the same data, without fusion (one call
  for the whole run) and with the paper's clamp once a second (600 epochs, 601 calls: the
  pipeline's pattern);
- the library's generic filter classes (``localization.reference.dead_reckoning``:
  ``UnscentedKalmanFilter`` and its siblings in ``localization.ukf``/``iukf``/``ekf``, the
  reference) on the first
  ``--generic-steps`` samples, per step, and the ratio generic / compiled;
- a Monte Carlo batch of ``--runs`` runs x 2 branches, per run-step.
The compiled kernels are loaded (or compiled) before the timings.
Target (issue 5, after the compiled step): dead reckoning well under 10 us a step, so that
the pipeline reaches 100x real time.
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import numpy as np
from _common import best_seconds

from localization.dead_reckoning import (
    DeadReckoning,
    DeadReckoningSettings,
    Filter,
    NominalRobot,
    initial_belief,
    odometry_data,
    run_dead_reckoning,
)
from localization.fusion import fuse
from localization.reference.dead_reckoning import GenericDeadReckoning
from robotsim.control import Route
from robotsim.maps import builtin_map
from robotsim.simulation import simulate

ROUTE = Route([[8.5, 1.0], [8.8, 4.0], [5.0, 4.3], [4.5, 7.0], [1.0, 7.0]], loop=True)
START = (1.0, 1.0, 0.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=60_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--runs", type=int, default=100)
    parser.add_argument("--generic-steps", type=int, default=2_000)
    args = parser.parse_args(argv)

    log = simulate(
        builtin_map("hall"),
        ROUTE,
        start_pose=START,
        duration_s=args.steps / 100.0,
        rng=np.random.default_rng(0),
    )
    robot = NominalRobot(log.robot.wheel_radius_m, log.robot.wheel_base_m, log.robot.ticks_per_rev)
    started = time.perf_counter()
    data = odometry_data(log.wheel_ticks, log.gyro_rad_s, log.accel_m_s2, 1.0 / log.rate_hz, robot)
    prepare_s = time.perf_counter() - started
    initial = initial_belief(START, [0.01, 0.01, 0.01])
    steps = data.count - 1
    truth = log.pose

    def clamp(index, belief):  # a 0.4 m box around the truth, once a second
        box = np.array(
            [
                [
                    [truth[index, 0] - 0.2, truth[index, 0] + 0.2],
                    [truth[index, 1] - 0.2, truth[index, 1] + 0.2],
                    [-np.pi, np.pi],
                ]
            ]
        )
        return fuse(belief, box, rows=[1])[0]

    def run_generic(settings: DeadReckoningSettings, count: int) -> None:
        """A fresh generic filter over samples ``1..count`` (its construction timed too)."""
        GenericDeadReckoning(data, initial, settings).run(count)

    epochs = range(100, data.count, 100)
    DeadReckoning(data, initial).run(1)  # load (or compile) the kernels before any timing
    rows = []
    for name in (Filter.UKF, Filter.IUKF, Filter.EKF):
        settings = DeadReckoningSettings(filter=name)
        plain = best_seconds(partial(run_dead_reckoning, data, initial, settings), args.repeats)
        fused = best_seconds(
            partial(run_dead_reckoning, data, initial, settings, epochs, clamp), args.repeats
        )
        short = min(args.generic_steps, steps)
        generic_s = best_seconds(partial(run_generic, settings, short), 1) / short * steps
        rows.append((name, plain, fused, generic_s))

    ticks = np.repeat(log.wheel_ticks[:, None, :], 2 * args.runs, axis=1)
    gyro = np.repeat(log.gyro_rad_s[:, None], 2 * args.runs, axis=1)
    accel = np.repeat(log.accel_m_s2[:, None, :], 2 * args.runs, axis=1)
    mc_steps = min(steps, 6_000)
    mc_data = odometry_data(
        ticks[: mc_steps + 1], gyro[: mc_steps + 1], accel[: mc_steps + 1], 0.01, robot
    )
    mc_initial = initial_belief(START, [0.01, 0.01, 0.01], batch=2 * args.runs)
    mc_s = best_seconds(lambda: run_dead_reckoning(mc_data, mc_initial), args.repeats)

    print(f"| figure ({steps} steps, batch of 2 branches) | wall s | us per step | ratio |")
    print("|---|---|---|---|")
    print(f"| sensor arrays to filter inputs (`odometry_data`, vectorised) | {prepare_s:.3f} | | |")
    for name, plain, fused, generic_s in rows:
        print(
            f"| compiled `{name}`, no fusion (1 call) | {plain:.3f} | {plain / steps * 1e6:.2f} | |"
        )
        print(
            f"| compiled `{name}`, clamp of row 1 once a second ({len(epochs) + 1} calls, "
            f"`fuse` included) | {fused:.3f} | {fused / steps * 1e6:.2f} | |"
        )
        print(
            f"| generic `{name}` (filter classes, step by step), first {min(args.generic_steps, steps)} steps "
            f"| {generic_s:.1f} (projected) | {generic_s / steps * 1e6:.0f} "
            f"| generic / compiled {generic_s / plain:.0f}x |"
        )
    print(
        f"| compiled `ukf`, Monte Carlo {args.runs} runs x 2 branches, {mc_steps} steps | {mc_s:.3f} "
        f"| {mc_s / mc_steps / (2 * args.runs) * 1e6:.2f} per run-step | |"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
