"""Speed of one UKF step (predict + update) on the CTRV model: the lean entry against a bare numba step.

    python benchmarks/ukf_step.py [--steps 2000] [--batch 1000] [--repeats 15]

Model: ``localization.motion_models.CTRV`` (5 states, additive process noise, ``dt = 0.01 s``),
measurement ``(x_m, y_m, theta_rad)`` with the heading declared an angle (``pose_model``),
scaled sigma points ``alpha = 1e-3``. Figures, all microseconds per step of one filter unless
said otherwise:

- lean: :class:`localization.compiled.lean.LeanUKF`, ``lean.step(z)`` from a Python loop;
- bare: the floor of any Python-called compiled step, a ``numba.njit`` function of three
  arrays ``(mean, cov, z)`` with everything else compiled in as constants, calling the same
  per-run functions (``localization.compiled.ukf.predict_run`` and ``update_run`` with the
  CTRV and pose kernels; their scratch allocated in the call) and returning no status, from
  the same kind of loop; target (issue 17): lean at most 5 us and at most 1.5 times bare;
- lean run: ``lean.run(zs)``, the whole sequence in one call, per step;
- filter step: ``UnscentedKalmanFilter.predict`` + ``update`` on immutable beliefs (its
  compiled path), one filter and a batch of ``--batch`` runs (per run-step);
- numpy: the same filter on its numpy path (the models without kernels), one filter.

Before timing, the script checks that lean and lean run give the filter step's beliefs bit for
bit over the ``--steps`` measurements, and bare over 1 and 10 of them to :data:`BARE_AGREEMENT`
(exits 1 otherwise). Timing: every
figure is timed once per repetition, in turn (A B C .. A B C ..), after a warm-up call (no
compile time counted); wall (``time.perf_counter``) and CPU (``time.process_time``) medians
over ``--repeats``; the load average before and after is printed. Prints a markdown table
for ``BENCHMARKS.md``. The peers (filterpy, Stone Soup) are in ``benchmarks/filters.py``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable

import numba
import numpy as np
from _common import machine_line, markdown_table

from localization.compiled import motion
from localization.compiled.lean import LeanUKF
from localization.compiled.ukf import (
    predict_run,
    predict_scratch_length,
    update_run,
    update_scratch_length,
)
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
BARE_AGREEMENT = 1e-9
"""Accepted difference of the bare step from the filter's (state units): the bare step is
compiled with the models and settings as constants, which lets the compiler fold them and
round a few operations differently; ``alpha = 1e-3`` turns such rounding of the images
(1e-15 of ``|x| = 8``) into about 1e-9 of the mean (``localization.sigma_points``), and the
difference grows along a run (2e-8 after 2000 steps), so it is checked over the first steps."""
UKF = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=1e-3, beta=2.0, kappa=0.0))

# the bare step's constants, compiled in (numba freezes global arrays)
_ARGS = np.array([DT_S])
_Q = Q.copy()
_R = R.copy()
_WEIGHTS = np.array(UKF.points.weights(5).packed)
_ANGLES = np.array([2], dtype=np.int64)


@numba.njit
def bare_step(mean, cov, z) -> None:
    """One CTRV UKF step of ``mean (5,)``, ``cov (5, 5)`` (overwritten) by ``z (3,)``: the
    compiled per-run cores with constant models and settings, no status, its scratch
    allocated per call."""
    prior_mean, prior_cov = np.empty(5), np.empty((5, 5))
    predict_run(
        motion.ctrv_point,
        mean,
        cov,
        _ARGS,
        _Q,
        _WEIGHTS,
        _ANGLES,
        prior_mean,
        prior_cov,
        np.empty(predict_scratch_length(5, 5)),
    )
    update_run(
        motion.leading_entries_point,
        prior_mean,
        prior_cov,
        z,
        _ARGS,
        _R,
        _WEIGHTS,
        _ANGLES,
        _ANGLES,
        mean,
        cov,
        np.empty(update_scratch_length(5, 3)),
    )


def measurements(steps: int, seed: int = 0) -> np.ndarray:
    """``(steps, 3)`` pose measurements of a CTRV truth from ``MEAN``."""
    rng = np.random.default_rng(seed)
    truth, zs = MEAN.copy(), np.empty((steps, 3))
    for t in range(steps):
        truth = CTRV.transition(truth, DT_S)
        zs[t] = truth[:3] + rng.normal(size=3) * np.sqrt(np.diag(R))
    return zs


def belief(batch: int | None = None) -> Gaussian:
    shape = () if batch is None else (batch,)
    return Gaussian(np.broadcast_to(MEAN, shape + (5,)), np.broadcast_to(COV, shape + (5, 5)), (2,))


def compiled_models() -> tuple[ProcessModel, MeasurementModel]:
    return CTRV.process_model(Q), pose_model(R)


def numpy_models() -> tuple[ProcessModel, MeasurementModel]:
    return ProcessModel(CTRV.transition, Q), MeasurementModel(
        lambda x: x[..., :3], R, angle_indices=(2,)
    )


# ------------------------------------------------------------------------- the runs timed


def lean_loop(zs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lean = LeanUKF(UKF, *compiled_models(), belief(), DT_S)
    for z in zs:
        lean.step(z)
    return lean.mean.copy(), lean.cov.copy()


def lean_run(zs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lean = LeanUKF(UKF, *compiled_models(), belief(), DT_S)
    lean.run(zs)
    return lean.mean.copy(), lean.cov.copy()


def bare_loop(zs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean, cov = MEAN.copy(), COV.copy()
    for z in zs:
        bare_step(mean, cov, z)
    return mean, cov


def filter_loop(zs: np.ndarray, models=None, batch: int | None = None):
    process, measurement = models or compiled_models()
    b = belief(batch)
    if batch is not None:
        zs = np.ascontiguousarray(np.broadcast_to(zs[:, None, :], (zs.shape[0], batch, 3)))
    for z in zs:
        b = UKF.update(UKF.predict(b, process, DT_S), z, measurement)
    return b.mean, b.cov


def check(zs: np.ndarray) -> list[str]:
    """The failed checks: every way of stepping gives the filter step's beliefs bit for bit."""
    reference = filter_loop(zs)
    failures = []
    for name, fn in (("lean", lean_loop), ("lean run", lean_run)):
        mean, cov = fn(zs)
        if not (np.array_equal(mean, reference[0]) and np.array_equal(cov, reference[1])):
            failures.append(f"{name} differs from the filter step")
    for steps in (1, 10):
        mean, cov = bare_loop(zs[:steps])
        expected = filter_loop(zs[:steps])
        difference = max(np.abs(mean - expected[0]).max(), np.abs(cov - expected[1]).max())
        print(f"bare vs the filter step after {steps} steps: largest difference {difference:.2g}")
        if not difference <= BARE_AGREEMENT:
            failures.append(f"bare differs from the filter step after {steps} steps")
    batched = filter_loop(zs[:20], batch=4)
    one = filter_loop(zs[:20])
    if not (np.array_equal(batched[0][-1], one[0]) and np.array_equal(batched[1][-1], one[1])):
        failures.append("the filter's batch differs from its one-run step")
    return failures


def interleaved_medians(
    figures: dict[str, tuple[Callable[[], object], int]], repeats: int
) -> dict[str, tuple[float, float]]:
    """``name: (fn, steps per call)`` -> ``name: (wall us, CPU us)`` per step, medians over
    ``repeats`` repetitions that time every figure once, in turn, after one warm-up call each."""
    for fn, _ in figures.values():
        fn()
    wall: dict[str, list[float]] = {name: [] for name in figures}
    cpu: dict[str, list[float]] = {name: [] for name in figures}
    for _ in range(repeats):
        for name, (fn, units) in figures.items():
            w0, c0 = time.perf_counter(), time.process_time()
            fn()
            c1, w1 = time.process_time(), time.perf_counter()
            wall[name].append((w1 - w0) / units * 1e6)
            cpu[name].append((c1 - c0) / units * 1e6)
    return {name: (statistics.median(wall[name]), statistics.median(cpu[name])) for name in figures}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--batch", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args(argv)
    zs = measurements(args.steps)
    failures = check(zs)
    if failures:
        print("FAILED: " + "; ".join(failures), file=sys.stderr)
        return 1
    print(f"checked: lean and lean run equal the filter step bit for bit ({args.steps} steps)")
    short = zs[: max(1, args.steps // 20)]
    batch_steps = zs[:5]
    numpy = numpy_models()
    figures = {
        "lean": (lambda: lean_loop(zs), args.steps),
        "bare": (lambda: bare_loop(zs), args.steps),
        "lean run": (lambda: lean_run(zs), args.steps),
        "filter": (lambda: filter_loop(zs), args.steps),
        "filter batched": (
            lambda: filter_loop(batch_steps, batch=args.batch),
            len(batch_steps) * args.batch,
        ),
        "numpy": (lambda: filter_loop(short, numpy), len(short)),
    }
    before = os.getloadavg()[0]
    us = interleaved_medians(figures, args.repeats)
    after = os.getloadavg()[0]
    lean, bare = us["lean"], us["bare"]
    labels = {
        "lean": "lean entry: `LeanUKF.step(z)` from a Python loop, one filter",
        "bare": "bare numba step `bare_step(mean, cov, z)` from the same loop (the floor)",
        "lean run": "lean multi-step entry: `LeanUKF.run(zs)`, one call, per step",
        "filter": "`UnscentedKalmanFilter` predict + update, compiled path, one filter",
        "filter batched": f"the same, batch of {args.batch} runs, per run-step",
        "numpy": "the same, numpy path (models without kernels), one filter",
    }
    targets = {"lean": "<= 5", "bare": ""}
    rows = [
        [labels[name], f"{w:.2f}", f"{c:.2f}", targets.get(name, "")] for name, (w, c) in us.items()
    ]
    rows.append(
        [
            "ratio lean / bare",
            f"{lean[0] / bare[0]:.2f}",
            f"{lean[1] / bare[1]:.2f}",
            "<= 1.5",
        ]
    )
    rows.append(
        [
            "ratio filter step / lean",
            f"{us['filter'][0] / lean[0]:.1f}",
            f"{us['filter'][1] / lean[1]:.1f}",
            "",
        ]
    )
    print(machine_line("numba"))
    print(f"load average before {before:.2f}, after {after:.2f}; medians of {args.repeats}")
    print(markdown_table(["figure (CTRV, 3 measurements)", "wall us", "CPU us", "target"], rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
