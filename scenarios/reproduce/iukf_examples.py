"""Paper 000 (iterated UKF), examples 1 and 2: EKF, IEKF, UKF and IUKF on the same draws.

    robotsim reproduce iukf-examples [--runs N] [--steps K] [--out DIR] [--seed S]

Example 1 (eq. 13): ``x(k+1) = [[1, T], [0, 1]] x(k) + w``, ``z = x1 x2^2 + v``,
``T = 0.05 s``, ``C_w = 0.01 I``, ``C_v = 100``. Example 2 (eq. 14):
``x1(k+1) = -k x2(k) + w1``, ``x2(k+1) = -exp(1e-3 x2(k)) + w2``, ``z = x1 x2 + v``,
``C_w = diag(300, 0.1)``, ``C_v = 3``. 100 Monte Carlo runs of 100 steps; every filter sees
the same truth and measurement draws, all runs of a filter in one batched call per step.

Writes ``DIR/table.json`` (time-averaged RMSE per state and filter, per example, and the
paper's orderings checked), ``DIR/table.md`` and ``DIR/fig1_example1_x1.png``,
``DIR/fig2_example1_x2.png``, ``DIR/fig3_example2_x1.png``, ``DIR/fig4_example2_x2.png``
(RMSE over time, like the paper's figures 1-4).

Choices where the paper is silent (also written to ``table.md``): see ``CHOICES``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from localization.ekf import ExtendedKalmanFilter, IteratedExtendedKalmanFilter, IterationSettings
from localization.gaussian import Gaussian
from localization.iukf import IteratedUnscentedKalmanFilter
from localization.models import MeasurementModel, ProcessModel
from localization.sigma_points import KappaSigmaPoints
from localization.ukf import UnscentedKalmanFilter
from scenarios.outputs import atomic_directory, write_json, write_text
from scenarios.reproduce._filter_runs import (
    add_common_arguments,
    best_of,
    check_counts,
    choices_lines,
    judge,
    markdown_table,
    relative_difference,
    rmse_over_time,
    run_filter,
    save_figure,
    verdict_lines,
)

HELP = "paper 000: EKF, IEKF, UKF and IUKF on examples 1 and 2 (RMSE tables and figures 1-4)"

#: Sampling time of example 1 (s).
T_S = 0.05
#: Newton / Gauss-Newton iterations of IEKF and IUKF: a fixed count, as the paper does.
ITERATIONS = IterationSettings(max_iterations=5, tolerance=None)
#: Paper 000 eq. 1 with n + kappa = 3 (Julier's choice; the paper gives no kappa).
POINTS = KappaSigmaPoints(kappa=1.0)
FILTER_NAMES = ("EKF", "IEKF", "UKF", "IUKF")

CHOICES = {
    "initial state (example 1)": "truth x(0) ~ N([10, 5], I); every filter starts from mean [10, 5], P(0) = I "
    "(the paper gives none; a measurement x1 x2^2 ~ 250 against noise std 10 makes the measurement informative; "
    "in development the ordering UKF < EKF < IEKF = IUKF was the same from [1, 1] and from [0, 0])",
    "initial state (example 2)": "truth x(0) ~ N([0, -1], diag(300, 0.1)); filters start from that mean and covariance",
    "k in -k x2(k)": "read as the time index k = 0, 1, ..., 99 of the step from x(k) to x(k+1)",
    "sigma points": "paper 000 eq. 1 with kappa = 1 (n + kappa = 3) for UKF and IUKF",
    "iterations": "IEKF and IUKF: a fixed count of L = 5 Gauss-Newton/Newton iterations (eq. 11), no tolerance",
    "measurement timing": "z(k+1) = h(x(k+1)) + v(k+1): each step predicts to k+1 and updates with its measurement",
}


@dataclass(frozen=True)
class Example:
    """One of the paper's two problems, with its initial belief."""

    name: str
    process: ProcessModel
    measurement: MeasurementModel
    initial_mean: np.ndarray
    initial_cov: np.ndarray


def _ex1_f(x, k):
    return np.stack([x[..., 0] + T_S * x[..., 1], x[..., 1]], axis=-1)


def _ex1_f_jac(x, k):
    return np.broadcast_to(np.array([[1.0, T_S], [0.0, 1.0]]), x.shape[:-1] + (2, 2))


def _ex1_h(x):
    return (x[..., 0] * x[..., 1] ** 2)[..., None]


def _ex1_h_jac(x):
    return np.stack([x[..., 1] ** 2, 2.0 * x[..., 0] * x[..., 1]], axis=-1)[..., None, :]


def _ex2_f(x, k):
    return np.stack([-k * x[..., 1], -np.exp(1e-3 * x[..., 1])], axis=-1)


def _ex2_f_jac(x, k):
    jac = np.zeros(x.shape[:-1] + (2, 2))
    jac[..., 0, 1] = -k
    jac[..., 1, 1] = -1e-3 * np.exp(1e-3 * x[..., 1])
    return jac


def _ex2_h(x):
    return (x[..., 0] * x[..., 1])[..., None]


def _ex2_h_jac(x):
    return np.stack([x[..., 1], x[..., 0]], axis=-1)[..., None, :]


EXAMPLES = (
    Example(
        "example_1",
        ProcessModel(_ex1_f, 0.01 * np.eye(2), jacobian=_ex1_f_jac),
        MeasurementModel(_ex1_h, np.array([[100.0]]), jacobian=_ex1_h_jac),
        np.array([10.0, 5.0]),
        np.eye(2),
    ),
    Example(
        "example_2",
        ProcessModel(_ex2_f, np.diag([300.0, 0.1]), jacobian=_ex2_f_jac),
        MeasurementModel(_ex2_h, np.array([[3.0]]), jacobian=_ex2_h_jac),
        np.array([0.0, -1.0]),
        np.diag([300.0, 0.1]),
    ),
)


def filters() -> dict[str, object]:
    """The four filters of the comparison."""
    return {
        "EKF": ExtendedKalmanFilter(),
        "IEKF": IteratedExtendedKalmanFilter(ITERATIONS),
        "UKF": UnscentedKalmanFilter(POINTS),
        "IUKF": IteratedUnscentedKalmanFilter(POINTS, ITERATIONS),
    }


def simulate(
    example: Example, runs: int, steps: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Truth ``(steps + 1, runs, 2)`` from ``x(0)`` and measurements ``(steps, runs, 1)`` of ``x(1..steps)``."""
    chol_w = np.linalg.cholesky(example.process.Q)
    chol_v = np.sqrt(example.measurement.R[0, 0])
    truth = np.empty((steps + 1, runs, 2))
    truth[0] = (
        example.initial_mean
        + rng.standard_normal((runs, 2)) @ np.linalg.cholesky(example.initial_cov).T
    )
    for k in range(steps):
        truth[k + 1] = (
            example.process.f(truth[k], float(k)) + rng.standard_normal((runs, 2)) @ chol_w.T
        )
    measurements = example.measurement.h(truth[1:]) + chol_v * rng.standard_normal((steps, runs, 1))
    return truth, measurements


def evaluate(
    example: Example, runs: int, steps: int, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """RMSE over time ``(steps, 2)`` of every filter on one example."""
    truth, measurements = simulate(example, runs, steps, rng)
    start = Gaussian(
        np.broadcast_to(example.initial_mean, (runs, 2)),
        np.broadcast_to(example.initial_cov, (runs, 2, 2)),
    )
    return {
        name: rmse_over_time(
            run_filter(
                kf, start, example.process, example.measurement, measurements, lambda k: (float(k),)
            ),
            truth[1:],
        )
        for name, kf in filters().items()
    }


def paper_claims(
    average: dict[str, np.ndarray], final: dict[str, np.ndarray]
) -> dict[str, dict[str, str]]:
    """The orderings the paper states, judged on time-averaged (and last-quarter) RMSE."""
    state = {f"x{i + 1}": {name: float(a[i]) for name, a in average.items()} for i in range(2)}
    return {
        "example_1": {
            "x1: IEKF best of the four (fig. 1)": judge(best_of(state["x1"], "IEKF")),
            "x2: IUKF best of the four (fig. 2)": judge(best_of(state["x2"], "IUKF")),
        },
        "example_2": {
            f"{x}: UKF and IUKF both better than IEKF and EKF (figs. 3-4)": judge(
                [(state[x][a], state[x][b]) for a in ("UKF", "IUKF") for b in ("IEKF", "EKF")]
            )
            for x in ("x1", "x2")
        }
        | {
            "x1: IUKF best of the four (fig. 3)": judge(best_of(state["x1"], "IUKF")),
            "x2: IUKF steady state (last quarter) better than UKF (fig. 4)": judge(
                [(float(final["IUKF"][1]), float(final["UKF"][1]))]
            ),
        },
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``robotsim reproduce iukf-examples``."""
    add_common_arguments(parser, "iukf-examples", steps=100)


def main(args: argparse.Namespace) -> int:
    """Run both examples, write the table and the figures; returns 0."""
    import matplotlib

    matplotlib.use("Agg")
    check_counts(args, "iukf-examples")
    rng = np.random.default_rng(args.seed)
    table: dict[str, object] = {
        "paper": "000 (Banani and Masnadi-Shirazi, iterated UKF)",
        "runs": args.runs,
        "steps": args.steps,
        "seed": args.seed,
        "choices": CHOICES,
    }
    md = [
        f"# Paper 000, examples 1 and 2 ({args.runs} runs, {args.steps} steps, seed {args.seed})",
        "",
    ]
    curves = {}
    for example in EXAMPLES:
        rmse = evaluate(example, args.runs, args.steps, rng)
        curves[example.name] = rmse
        average = {name: r.mean(axis=0) for name, r in rmse.items()}
        final = {name: r[-max(1, args.steps // 4) :].mean(axis=0) for name, r in rmse.items()}
        claims = paper_claims(average, final)[example.name]
        near = {
            "UKF vs EKF": relative_difference(average["UKF"], average["EKF"]),
            "IUKF vs IEKF": relative_difference(average["IUKF"], average["IEKF"]),
        }
        table[example.name] = {
            "rmse_time_average": {
                name: {"x1": float(a[0]), "x2": float(a[1])} for name, a in average.items()
            },
            "rmse_last_quarter": {
                name: {"x1": float(a[0]), "x2": float(a[1])} for name, a in final.items()
            },
            "max_relative_rmse_difference": near,
            "paper_orderings_verdict": claims,
        }
        md += [
            f"## {example.name.replace('_', ' ').capitalize()}",
            "",
            "Time-averaged RMSE (last quarter in brackets):",
            "",
        ]
        md.append(
            markdown_table(
                ["state", *FILTER_NAMES],
                [
                    [s] + [f"{average[f][i]:.4g} ({final[f][i]:.4g})" for f in FILTER_NAMES]
                    for i, s in enumerate(("x1", "x2"))
                ],
            )
        )
        md += [""] + verdict_lines(near, claims, "RMSE")
    md += choices_lines(CHOICES)
    with atomic_directory(args.out) as out:
        write_json(out / "table.json", table)
        write_text(out / "table.md", "\n".join(md))
        figures = [
            ("fig1_example1_x1.png", "example_1", 0),
            ("fig2_example1_x2.png", "example_1", 1),
            ("fig3_example2_x1.png", "example_2", 0),
            ("fig4_example2_x2.png", "example_2", 1),
        ]
        for filename, name, state in figures:
            save_figure(
                Path(out) / filename,
                {f: curves[name][f][:, state] for f in FILTER_NAMES},
                log_scale=True,
                ylabel=f"RMSE of x{state + 1}",
                title=f"{name.replace('_', ' ')}: RMSE of x{state + 1} over {args.runs} runs",
            )
    print(f"iukf-examples: wrote {args.out}/table.json, table.md and 4 figures")
    return 0
