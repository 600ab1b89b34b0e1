"""Speed of one UKF step (predict + update) on the CTRV model, single and batched, beside filterpy.

    python benchmarks/ukf_step.py [--batch 1000] [--repeats 7]

Model: ``localization.motion_models.CTRV`` (5 states, additive process noise, ``dt = 0.01 s``),
measurement ``(x_m, y_m, theta_rad)`` with the heading declared an angle (3 measurements).
Targets (issue 3): at most 30 us per step for one filter, at most 2.5 us per run-step for a
batch of 1000 runs. Prints a markdown section for ``BENCHMARKS.md``: the figures, the share
of the model itself (the same filter with a free model), filterpy's UKF on the same model
side by side (its ratio), and the numpy call overhead of the machine for scale.
"""

from __future__ import annotations

import argparse
import math
import timeit

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints
from filterpy.kalman import UnscentedKalmanFilter as FilterpyUKF

from localization.gaussian import Gaussian
from localization.models import MeasurementModel, ProcessModel
from localization.motion_models import CTRV
from localization.sigma_points import ScaledSigmaPoints
from localization.ukf import UnscentedKalmanFilter

DT_S = 0.01
Q = np.diag([1e-6, 1e-6, 1e-6, 2.5e-3, 6e-4])
R = np.diag([1.0, 1.0, 0.01])
MEAN = np.array([3.0, -2.0, 0.4, 8.0, 0.2])
COV = np.diag([1.0, 1.0, 0.05, 0.5, 0.01])
Z = np.array([3.1, -1.9, 0.41])


def measure_xy_heading(x):
    """``(..., 5) -> (..., 3)``: position and heading."""
    return x[..., :3]


def best_us(fn, number: int, repeats: int) -> float:
    """Best time of one call of ``fn`` in microseconds."""
    return min(timeit.repeat(fn, number=number, repeat=repeats)) / number * 1e6


def ours(transition, batch: int | None, number: int, repeats: int) -> float:
    """Microseconds per predict + update (per run-step when batched)."""
    ukf = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=1e-3, beta=2.0, kappa=0.0))
    process = ProcessModel(transition, Q)
    measurement = MeasurementModel(measure_xy_heading, R, angle_indices=(2,))
    shape = () if batch is None else (batch,)
    belief = Gaussian(np.broadcast_to(MEAN, shape + (5,)), np.broadcast_to(COV, shape + (5, 5)), angle_indices=(2,))
    z = np.broadcast_to(Z, shape + (3,))

    def step():
        ukf.update(ukf.predict(belief, process, DT_S), z, measurement)

    return best_us(step, number, repeats) / (1 if batch is None else batch)


def filterpy_step_us(number: int, repeats: int) -> float:
    """filterpy's UKF, same model, points, noise and angle handling (residuals and means)."""

    def wrap(a):
        return (a + math.pi) % (2 * math.pi) - math.pi

    def residual(a, b, index):
        d = a - b
        d[index] = wrap(d[index])
        return d

    def circular_mean(sigmas, weights, index):
        mean = weights @ sigmas
        mean[index] = math.atan2(weights @ np.sin(sigmas[:, index]), weights @ np.cos(sigmas[:, index]))
        return mean

    ukf = FilterpyUKF(
        dim_x=5, dim_z=3, dt=DT_S, hx=measure_xy_heading, fx=CTRV.transition,
        points=MerweScaledSigmaPoints(5, alpha=1e-3, beta=2.0, kappa=0.0),
        x_mean_fn=lambda s, w: circular_mean(s, w, 2), z_mean_fn=lambda s, w: circular_mean(s, w, 2),
        residual_x=lambda a, b: residual(a, b, 2), residual_z=lambda a, b: residual(a, b, 2),
    )
    ukf.Q, ukf.R = Q.copy(), R.copy()

    def step():
        ukf.x, ukf.P = MEAN.copy(), COV.copy()
        ukf.predict()
        ukf.update(Z)

    return best_us(step, number, repeats)


def free_transition(x, dt_s):
    """A model that costs nothing: the share of the filter itself."""
    return x


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)
    five = np.eye(5)
    single = ours(CTRV.transition, None, 300, args.repeats)
    single_free = ours(free_transition, None, 300, args.repeats)
    batched = ours(CTRV.transition, args.batch, 5, args.repeats)
    batched_free = ours(free_transition, args.batch, 5, args.repeats)
    ctrv_single = best_us(lambda: CTRV.transition(np.zeros((11, 5)), DT_S), 300, args.repeats)
    ctrv_batched = best_us(lambda: CTRV.transition(np.zeros((args.batch, 11, 5)), DT_S), 5, args.repeats) / args.batch
    theirs = filterpy_step_us(100, args.repeats)
    add_us = best_us(lambda: five + five, 5000, args.repeats)
    chol_us = best_us(lambda: np.linalg.cholesky(five), 5000, args.repeats)
    print("| figure | us | target |")
    print("|---|---|---|")
    print(f"| one filter, predict + update (CTRV, 3 measurements) | {single:.1f} | 30 |")
    print(f"| one filter, same with a free model (filter share) | {single_free:.1f} | |")
    print(f"| CTRV transition of 11 sigma points, one call | {ctrv_single:.1f} | |")
    print(f"| batch of {args.batch}, per run-step | {batched:.2f} | 2.5 |")
    print(f"| batch of {args.batch}, free model, per run-step | {batched_free:.2f} | |")
    print(f"| batch of {args.batch}, CTRV transition per run (11 points) | {ctrv_batched:.2f} | |")
    print(f"| filterpy UKF, one filter, same model (sigma-point loop) | {theirs:.1f} | |")
    print(f"| ratio filterpy / ours, one filter | {theirs / single:.1f}x | |")
    print(f"| ratio filterpy (one filter) / ours batched per run | {theirs / batched:.0f}x | |")
    print(f"| numpy overhead: `a + a` on 5x5 | {add_us:.2f} | |")
    print(f"| numpy overhead: `np.linalg.cholesky` on 5x5 | {chol_us:.2f} | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
