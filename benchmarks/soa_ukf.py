"""The batched UKF's compiled entries: structure of arrays against the per-run loop (issue 17).

    python benchmarks/soa_ukf.py [--runs 1000] [--calls 50] [--repeats 15]

For the CTRV model (additive and augmented noise) and the pose update, on the same random
beliefs of ``--runs`` runs (``dt = 0.1 s``, scaled sigma points ``alpha = 1e-3``): the entries
the batched filter path calls (:mod:`localization.compiled.soa`) against the loop of
:mod:`localization.compiled.batch` over the per-run functions of
:mod:`localization.compiled.ukf` (the batched entries of the built-in kernels until issue 17).
Before timing, each pair is checked equal bit for bit (exits 1 otherwise). Timing: each entry
``--calls`` times per repetition, the entries in turn (A B C .. A B C ..), after a warm-up
call (no compile time counted); medians over ``--repeats`` of wall (``time.perf_counter``) and
CPU (``time.process_time``) microseconds per run; the load average before and after. Prints a
markdown table for ``BENCHMARKS.md``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

from localization.compiled import soa
from localization.compiled.glue import OK, angle_array
from localization.motion_models import CTRV
from localization.reference.per_run_ukf import (
    per_run_augmented,
    per_run_predict,
    per_run_update,
)
from localization.sigma_points import ScaledSigmaPoints

CTRV_NUMBER = 1
HEADING = angle_array((2,))
POINTS = ScaledSigmaPoints(alpha=1e-3, beta=2.0, kappa=0.0)


def _read_only(values) -> np.ndarray:
    values = np.array(values, dtype=np.float64, order="C")
    values.flags.writeable = False
    return values


def cases(runs: int) -> dict[str, tuple]:
    """``{label: (per-run entry, SoA entry, arguments without the outputs, n)}``."""
    rng = np.random.default_rng(17)
    mean = rng.normal(size=(runs, 5)) * np.array([5.0, 5.0, 2.0, 1.0, 0.5]) + [0, 0, 0, 2.0, 0]
    spread = rng.normal(size=(runs, 5, 5)) * 0.1
    mean = _read_only(mean)
    cov = _read_only(spread @ spread.transpose(0, 2, 1) + 0.01 * np.eye(5))
    dt = _read_only([[0.1]])
    additive = CTRV.process_model(np.diag([0.01, 0.01, 0.001, 0.1, 0.01]))
    q_sqrt = _read_only(np.linalg.cholesky(np.diag([0.1, 0.01]))[None])
    z = mean[:, :3] + rng.normal(size=(runs, 3)) * 0.1
    r_cov = _read_only(np.diag([0.05, 0.05, 0.01])[None])
    weights, augmented_weights = POINTS.weights(5).packed, POINTS.weights(7).packed
    predict = (CTRV_NUMBER, mean, cov, dt, _read_only(additive.Q[None]), weights, HEADING)
    augmented = (CTRV_NUMBER, mean, cov, dt, q_sqrt, augmented_weights, HEADING)
    update = (mean, cov, z, _read_only(np.empty((1, 0))), r_cov, weights, HEADING, HEADING)
    return {
        "CTRV predict, additive noise": (per_run_predict, soa.predict_builtin, predict),
        "CTRV predict, augmented noise": (per_run_augmented, soa.noisy_predict_builtin, augmented),
        "pose update": (per_run_update, soa.update_leading_entries, update),
    }


def outputs(runs: int) -> tuple[np.ndarray, np.ndarray]:
    return np.empty((runs, 5)), np.empty((runs, 5, 5))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--calls", type=int, default=50)
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args(argv)
    runs = args.runs
    table = cases(runs)
    for label, (reference, entry, arguments) in table.items():
        ref_out, soa_out = outputs(runs), outputs(runs)
        statuses = reference(*arguments, *ref_out), entry(*arguments, *soa_out)
        same = all(np.array_equal(a, b) for a, b in zip(ref_out, soa_out, strict=True))
        if statuses != (OK, OK) or not same:
            print(f"{label}: the SoA entry differs from the per-run loop", file=sys.stderr)
            return 1
    timed = {
        (label, kind): (function, arguments, outputs(runs))
        for label, (reference, entry, arguments) in table.items()
        for kind, function in (("per-run loop", reference), ("SoA", entry))
    }
    samples: dict[tuple[str, str], list[tuple[float, float]]] = {key: [] for key in timed}
    load_before = os.getloadavg()[0]
    for _ in range(args.repeats):
        for key, (function, arguments, outs) in timed.items():
            wall, cpu = time.perf_counter(), time.process_time()
            for _ in range(args.calls):
                function(*arguments, *outs)
            scale = 1e6 / (args.calls * runs)
            samples[key].append(
                ((time.perf_counter() - wall) * scale, (time.process_time() - cpu) * scale)
            )
    load_after = os.getloadavg()[0]
    print(f"load average (1 min) {load_before:.1f} before, {load_after:.1f} after; {runs} runs\n")
    print("| entry, us per run (wall / CPU) | per-run loop | SoA | ratio (wall) |")
    print("|---|---|---|---|")
    for label in table:
        loop = [statistics.median(v) for v in zip(*samples[(label, "per-run loop")], strict=True)]
        fast = [statistics.median(v) for v in zip(*samples[(label, "SoA")], strict=True)]
        print(
            f"| {label} | {loop[0]:.3f} / {loop[1]:.3f} | {fast[0]:.3f} / {fast[1]:.3f} "
            f"| {loop[0] / fast[0]:.2f}x |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
