"""Speed of one UKF step (predict + update) on the CTRV model, single and batched, beside filterpy.

    python benchmarks/ukf_step.py [--batch 1000] [--repeats 9]

Model: ``localization.motion_models.CTRV`` (5 states, additive process noise, ``dt = 0.01 s``),
measurement ``(x_m, y_m, theta_rad)`` with the heading declared an angle (3 measurements),
scaled sigma points ``alpha = 1e-3``. Targets (issue 3): at most 30 us per step for one
filter, at most 2.5 us per run-step for a batch of 1000 runs. Two paths of the same
``UnscentedKalmanFilter``, side by side: the compiled one (the models built with their
per-point kernels, ``CTRV.process_model(Q)`` and ``pose_model(R)``; ``localization.compiled_ukf``)
and the numpy one (the same functions without kernels). Before timing, the script checks
that both paths give the same step (to the rounding that ``alpha = 1e-3`` amplifies, see
``localization.sigma_points``) and that the compiled batch gives its runs' one-run numbers bit
for bit; it exits 1 otherwise. Prints a markdown table for ``BENCHMARKS.md``: the figures,
the share of the model itself (the numpy filter with a free model), the numpy batch stepped
in one piece beside the default slices of ``localization.ukf.SLICE_RUNS`` runs (with the minor
page faults per step of each), filterpy's UKF on the same model side by side (its ratios),
and the numpy call overhead of the machine for scale.
"""

from __future__ import annotations

import argparse
import math
import resource
import sys
import timeit

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints
from filterpy.kalman import UnscentedKalmanFilter as FilterpyUKF
from scipy.linalg import lapack

import localization.ukf as ukf_module
from localization.gaussian import Gaussian
from localization.models import MeasurementModel, ProcessModel
from localization.motion_models import CTRV, pose_model
from localization.sigma_points import ScaledSigmaPoints
from localization.ukf import UnscentedKalmanFilter

DT_S = 0.01
Q = np.diag([1e-6, 1e-6, 1e-6, 2.5e-3, 6e-4])
R = np.diag([1.0, 1.0, 0.01])
MEAN = np.array([3.0, -2.0, 0.4, 8.0, 0.2])
COV = np.diag([1.0, 1.0, 0.05, 0.5, 0.01])
Z = np.array([3.1, -1.9, 0.41])
AGREEMENT = 1e-8
"""Largest accepted difference between the compiled and the numpy step (state units). The
mean's second-order term at ``alpha = 1e-3`` is a finite difference that turns the rounding of
the images (1e-15 of ``|x| = 8``) into about ``1e-15 * 8 / gamma^2 = 2e-9``, rounded
differently by the two paths."""


def measure_xy_heading(x):
    """``(..., 5) -> (..., 3)``: position and heading."""
    return x[..., :3]


def numpy_models(transition=CTRV.transition) -> tuple[ProcessModel, MeasurementModel]:
    """The models without kernels: our UKF's numpy path (CTRV or a free model)."""
    return ProcessModel(transition, Q), MeasurementModel(measure_xy_heading, R, angle_indices=(2,))


def compiled_models() -> tuple[ProcessModel, MeasurementModel]:
    """The same models with their per-point kernels: our UKF's compiled path."""
    return CTRV.process_model(Q), pose_model(R)


def ukf_step(models: tuple[ProcessModel, MeasurementModel], batch: int | None):
    """One predict + update of our UKF with ``models``, one filter or ``batch`` runs; returns
    the step (a function returning the updated belief)."""
    ukf = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=1e-3, beta=2.0, kappa=0.0))
    process, measurement = models
    shape = () if batch is None else (batch,)
    belief = Gaussian(
        np.broadcast_to(MEAN, shape + (5,)),
        np.broadcast_to(COV, shape + (5, 5)),
        angle_indices=(2,),
    )
    z = np.array(np.broadcast_to(Z, shape + (3,)))

    def step():
        return ukf.update(ukf.predict(belief, process, DT_S), z, measurement)

    return step


def check_paths(batch: int) -> list[str]:
    """The failed checks (empty when all pass): compiled vs numpy step, compiled batch vs one run."""
    failures = []
    compiled, reference = ukf_step(compiled_models(), None)(), ukf_step(numpy_models(), None)()
    difference = max(
        np.abs(compiled.mean - reference.mean).max(), np.abs(compiled.cov - reference.cov).max()
    )
    print(f"compiled vs numpy step: largest difference {difference:.2g} (accepted {AGREEMENT:g})")
    if not difference <= AGREEMENT:
        failures.append("the compiled step differs from the numpy step")
    batched = ukf_step(compiled_models(), batch)()
    if not (
        np.array_equal(batched.mean[-1], compiled.mean)
        and np.array_equal(batched.cov[-1], compiled.cov)
    ):
        failures.append("the compiled batch differs from its one-run step")
    return failures


def in_one_piece(step):
    """``step`` with a batch stepped in one piece (slicing switched off for the call)."""

    def whole():
        sliced = ukf_module.SLICE_RUNS
        ukf_module.SLICE_RUNS = 10**9
        try:
            step()
        finally:
            ukf_module.SLICE_RUNS = sliced

    return whole


def page_faults(step, steps: int = 20) -> float:
    """Minor page faults per call of ``step`` (after a first call)."""
    step()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(steps):
        step()
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / steps


def best_us_round_robin(figures: dict, repeats: int) -> dict[str, float]:
    """Best microseconds per unit of each figure ``name: (fn, calls per round, units per call)``.

    The figures are timed in turn, round after round, so that a burst of load from other
    processes on the shared machine slows all of them alike; the best round of each counts.
    """
    best = dict.fromkeys(figures, math.inf)
    for _ in range(repeats):
        for name, (fn, number, units) in figures.items():
            best[name] = min(best[name], timeit.timeit(fn, number=number) / number / units * 1e6)
    return best


def filterpy_step():
    """filterpy's UKF, same model, points, noise and angle handling (residuals and means)."""

    def wrap(a):
        return (a + math.pi) % (2 * math.pi) - math.pi

    def residual(a, b, index):
        d = a - b
        d[index] = wrap(d[index])
        return d

    def circular_mean(sigmas, weights, index):
        mean = weights @ sigmas
        mean[index] = math.atan2(
            weights @ np.sin(sigmas[:, index]), weights @ np.cos(sigmas[:, index])
        )
        return mean

    ukf = FilterpyUKF(
        dim_x=5,
        dim_z=3,
        dt=DT_S,
        hx=measure_xy_heading,
        fx=CTRV.transition,
        points=MerweScaledSigmaPoints(5, alpha=1e-3, beta=2.0, kappa=0.0),
        x_mean_fn=lambda s, w: circular_mean(s, w, 2),
        z_mean_fn=lambda s, w: circular_mean(s, w, 2),
        residual_x=lambda a, b: residual(a, b, 2),
        residual_z=lambda a, b: residual(a, b, 2),
    )
    ukf.Q, ukf.R = Q.copy(), R.copy()

    def step():
        ukf.x, ukf.P = MEAN.copy(), COV.copy()
        ukf.predict()
        ukf.update(Z)

    return step


def free_transition(x, dt_s):
    """A model that costs nothing: the share of the filter itself."""
    return x


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args(argv)
    five = np.eye(5)
    runs = args.batch
    failures = check_paths(runs)
    if failures:
        print("FAILED: " + "; ".join(failures), file=sys.stderr)
        return 1
    sliced, whole = ukf_step(numpy_models(), runs), in_one_piece(ukf_step(numpy_models(), runs))
    us = best_us_round_robin(
        {
            "compiled_single": (ukf_step(compiled_models(), None), 2000, 1),
            "compiled_batched": (ukf_step(compiled_models(), runs), 20, runs),
            "single": (ukf_step(numpy_models(), None), 200, 1),
            "single_free": (ukf_step(numpy_models(free_transition), None), 200, 1),
            "ctrv_single": (lambda: CTRV.transition(np.zeros((11, 5)), DT_S), 1000, 1),
            "batched": (sliced, 3, runs),
            "batched_free": (ukf_step(numpy_models(free_transition), runs), 3, runs),
            "whole": (whole, 3, runs),
            "ctrv_batched": (lambda: CTRV.transition(np.zeros((runs, 11, 5)), DT_S), 3, runs),
            "theirs": (filterpy_step(), 50, 1),
            "add": (lambda: five + five, 3000, 1),
            "chol": (lambda: np.linalg.cholesky(five), 3000, 1),
            "potrf": (lambda: lapack.dpotrf(five, lower=1), 3000, 1),
        },
        args.repeats,
    )
    compiled_single, compiled_batched = us["compiled_single"], us["compiled_batched"]
    single, single_free, ctrv_single, theirs = (
        us["single"],
        us["single_free"],
        us["ctrv_single"],
        us["theirs"],
    )
    batched, batched_free, whole_us, ctrv_batched = (
        us["batched"],
        us["batched_free"],
        us["whole"],
        us["ctrv_batched"],
    )
    add_us, chol_us, potrf_us = us["add"], us["chol"], us["potrf"]
    faults, whole_faults = page_faults(sliced), page_faults(whole)
    slices = ukf_module.SLICE_RUNS
    print("| figure | us | target |")
    print("|---|---|---|")
    print(
        f"| compiled: one filter, predict + update (CTRV, 3 measurements) | {compiled_single:.1f} | 30 |"
    )
    print(f"| compiled: batch of {args.batch}, per run-step | {compiled_batched:.2f} | 2.5 |")
    print(f"| numpy: one filter, predict + update | {single:.1f} | |")
    print(f"| numpy: one filter, same with a free model (filter share) | {single_free:.1f} | |")
    print(f"| CTRV transition of 11 sigma points, one call | {ctrv_single:.1f} | |")
    print(
        f"| numpy: batch of {args.batch} in slices of <= {slices} runs, per run-step "
        f"({faults:.0f} page faults/step) | {batched:.2f} | |"
    )
    print(
        f"| numpy: batch of {args.batch} in slices, free model, per run-step | {batched_free:.2f} | |"
    )
    print(
        f"| numpy: batch of {args.batch} in one piece, per run-step "
        f"({whole_faults:.0f} page faults/step) | {whole_us:.2f} | |"
    )
    print(f"| batch of {args.batch}, CTRV transition per run (11 points) | {ctrv_batched:.2f} | |")
    print(f"| filterpy UKF, one filter, same model (sigma-point loop) | {theirs:.1f} | |")
    print(f"| ratio filterpy / ours, one filter, compiled | {theirs / compiled_single:.1f}x | 8x |")
    print(f"| ratio filterpy / ours, one filter, numpy | {theirs / single:.1f}x | |")
    print(
        f"| ratio filterpy (one filter) / ours batched per run, compiled | {theirs / compiled_batched:.0f}x | |"
    )
    print(
        f"| ratio filterpy (one filter) / ours batched per run, numpy | {theirs / batched:.0f}x | |"
    )
    print(f"| numpy overhead: `a + a` on 5x5 | {add_us:.2f} | |")
    print(f"| numpy overhead: `np.linalg.cholesky` on 5x5 | {chol_us:.2f} | |")
    print(
        f"| the same factor by LAPACK `dpotrf` directly (`scipy.linalg.lapack`) | {potrf_us:.2f} | |"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
