"""Paper 000 (iterated UKF), examples 1 and 2: EKF, IEKF, UKF and IUKF on the same draws.

    robotsim reproduce iukf-examples [--runs N] [--steps K] [--out DIR] [--seed S]

Example 1 (eq. 13): ``x(k+1) = [[1, T], [0, 1]] x(k) + w``, ``z = x1 x2^2 + v``,
``T = 0.05 s``, ``C_w = 0.01 I``, ``C_v = 100``. Example 2 (eq. 14):
``x1(k+1) = -k x2(k) + w1``, ``x2(k+1) = -exp(1e-3 x2(k)) + w2``, ``z = x1 x2 + v``,
``C_w = diag(300, 0.1)``, ``C_v = 3``. 100 Monte Carlo runs of 100 steps; every filter sees
the same truth and measurement draws, all runs of a filter in one batched call per step.

Writes ``DIR/table.json`` (time-averaged RMSE per state and filter, per example, the
posterior Cramer-Rao bound on the same draws, the paper's magnitude with ours / paper and a
verdict, and the paper's orderings checked), ``DIR/table.md`` and ``DIR/fig1_example1_x1.png``,
``DIR/fig2_example1_x2.png``, ``DIR/fig3_example2_x1.png``, ``DIR/fig4_example2_x2.png``
(RMSE over time with the bound, like the paper's figures 1-4, and below the differences of
the filters that coincide).

Choices where the paper is silent (also written to ``table.md``): see ``CHOICES``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from localization.ekf import ExtendedKalmanFilter, IteratedExtendedKalmanFilter, IterationSettings
from localization.gaussian import Gaussian
from localization.iukf import IteratedUnscentedKalmanFilter
from localization.models import MeasurementModel, ProcessModel
from localization.sigma_points import KappaSigmaPoints
from localization.ukf import UnscentedKalmanFilter
from scenarios.outputs import atomic_directory, write_json, write_text
from scenarios.reproduce._filter_runs import (
    MAGNITUDE_FACTOR,
    add_common_arguments,
    best_of,
    check_counts,
    choices_lines,
    curve_figure,
    format_ratio,
    judge,
    magnitude_verdict,
    markdown_table,
    plain_number,
    ratio,
    relative_difference,
    rmse_over_time,
    run_filter,
    verdict_lines,
    with_magnitude,
)
from scenarios.reproduce.figure_style import save

HELP = "paper 000: EKF, IEKF, UKF and IUKF on examples 1 and 2 (RMSE tables and figures 1-4)"

#: Sampling time of example 1 (s).
T_S = 0.05
#: Newton / Gauss-Newton iterations of IEKF and IUKF: a fixed count, as the paper does.
ITERATIONS = IterationSettings(max_iterations=5, tolerance=None)
#: Paper 000 eq. 1 with n + kappa = 3 (Julier's choice; the paper gives no kappa).
POINTS = KappaSigmaPoints(kappa=1.0)
FILTER_NAMES = ("EKF", "IEKF", "UKF", "IUKF")
STATES = ("x1", "x2")
#: The paper's magnitudes, by example: RMSE "all around 10^-3" in example 1 (section IV, the
#: text after fig. 1, for every filter and state); example 2's are in figures 3-4 only.
PAPER_RMSE: dict[str, float | None] = {"example_1": 1e-3, "example_2": None}
PAPER_SOURCE = {"example_1": "sec. IV text on figs. 1-2", "example_2": "figs. 3-4 only, no value"}
#: The figures by file name: (example, state index), like the paper's figures 1-4.
FIGURES = {
    "fig1_example1_x1.png": ("example_1", 0),
    "fig2_example1_x2.png": ("example_1", 1),
    "fig3_example2_x1.png": ("example_2", 0),
    "fig4_example2_x2.png": ("example_2", 1),
}

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


def posterior_crb(example: Example, truth: np.ndarray) -> np.ndarray:
    """The posterior Cramer-Rao bound on the RMSE of each state, ``(steps, 2)``, given the
    true trajectories ``truth (steps + 1, runs, 2)``.

    The recursion of Tichavsky, Muravchik and Nehorai (1998) for additive Gaussian noise:
    ``J(k+1) = D22 - D21 (J(k) + D11)^-1 D12`` with ``D11 = E[F' Q^-1 F]``,
    ``D12 = D21' = -E[F]' Q^-1``, ``D22 = Q^-1 + E[H' R^-1 H]`` (``F``, ``H`` the Jacobians
    at the true states), from ``J(0) = P(0)^-1``; the expectations are means over the runs.
    No filter's RMSE over many runs can be below ``sqrt(diag J^-1)``.
    """
    q_inv = np.linalg.inv(example.process.Q)
    r_inv = np.linalg.inv(example.measurement.R)
    info = np.linalg.inv(example.initial_cov)
    f_jac, h_jac = example.process.jacobian, example.measurement.jacobian
    assert f_jac is not None and h_jac is not None, "the bound needs both Jacobians"
    bound = np.empty((truth.shape[0] - 1, 2))
    for k in range(truth.shape[0] - 1):
        f = f_jac(truth[k], float(k))  # (runs, 2, 2)
        h = h_jac(truth[k + 1])  # (runs, 1, 2)
        d11 = np.mean(np.swapaxes(f, -1, -2) @ q_inv @ f, axis=0)
        d12 = -np.mean(np.swapaxes(f, -1, -2), axis=0) @ q_inv
        d22 = q_inv + np.mean(np.swapaxes(h, -1, -2) @ r_inv @ h, axis=0)
        info = d22 - d12.T @ np.linalg.solve(info + d11, d12)
        bound[k] = np.sqrt(np.diag(np.linalg.inv(info)))
    return bound


def evaluate(
    example: Example, runs: int, steps: int, rng: np.random.Generator
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """RMSE over time ``(steps, 2)`` of every filter on one example, and the posterior
    Cramer-Rao bound ``(steps, 2)`` on the same draws (:func:`posterior_crb`)."""
    truth, measurements = simulate(example, runs, steps, rng)
    start = Gaussian(
        np.broadcast_to(example.initial_mean, (runs, 2)),
        np.broadcast_to(example.initial_cov, (runs, 2, 2)),
    )
    rmse = {
        name: rmse_over_time(
            run_filter(
                kf, start, example.process, example.measurement, measurements, lambda k: (float(k),)
            ),
            truth[1:],
        )
        for name, kf in filters().items()
    }
    return rmse, posterior_crb(example, truth)


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


def example_table(name: str, average: dict, bound: np.ndarray) -> str:
    """The ``table.md`` table of one example: time-averaged RMSE, the bound, the paper's
    magnitude, the ratios and the verdict."""
    paper = PAPER_RMSE[name]
    rows = []
    for i, state in enumerate(STATES):
        for f in FILTER_NAMES:
            r = ratio(average[f][i], paper)
            rows.append(
                [
                    state,
                    f,
                    f"{average[f][i]:.4g}",
                    f"{average[f][i] / bound[i]:.3g}",
                    "-" if paper is None else f"~{paper:g}",
                    format_ratio(r),
                    magnitude_verdict(r),
                ]
            )
        rows.append([state, "bound (PCRB)", f"{bound[i]:.4g}", "1", "", "", ""])
    return markdown_table(
        ["state", "filter", "RMSE", "RMSE / bound", "paper", "ours / paper", "magnitude"], rows
    )


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
        "Time-averaged RMSE; bound: the posterior Cramer-Rao bound on the same draws "
        "(no filter can be below it); paper: the magnitude the paper states; 'same magnitude' "
        f"within a factor {MAGNITUDE_FACTOR:g} of it.",
        "",
    ]
    curves, bounds = {}, {}
    for example in EXAMPLES:
        rmse, bound = evaluate(example, args.runs, args.steps, rng)
        curves[example.name], bounds[example.name] = rmse, bound
        average = {name: r.mean(axis=0) for name, r in rmse.items()}
        average_bound = bound.mean(axis=0)
        final = {name: r[-max(1, args.steps // 4) :].mean(axis=0) for name, r in rmse.items()}
        paper = PAPER_RMSE[example.name]
        ratios = {
            name: {s: ratio(a[i], paper) for i, s in enumerate(STATES)}
            for name, a in average.items()
        }
        claims = {
            claim: with_magnitude(
                verdict, [r for by_state in ratios.values() for r in by_state.values()]
            )
            for claim, verdict in paper_claims(average, final)[example.name].items()
        }
        near = {
            "UKF vs EKF": relative_difference(average["UKF"], average["EKF"]),
            "IUKF vs IEKF": relative_difference(average["IUKF"], average["IEKF"]),
        }
        table[example.name] = {
            "rmse_time_average": {
                name: dict(zip(STATES, map(float, a), strict=True)) for name, a in average.items()
            },
            "rmse_last_quarter": {
                name: dict(zip(STATES, map(float, a), strict=True)) for name, a in final.items()
            },
            "posterior_crb_time_average": dict(zip(STATES, map(float, average_bound), strict=True)),
            "paper_rmse": paper,
            "paper_source": PAPER_SOURCE[example.name],
            "ratio_to_paper": ratios,
            "magnitude_verdict": {
                name: {s: magnitude_verdict(r) for s, r in by_state.items()}
                for name, by_state in ratios.items()
            },
            "max_relative_rmse_difference": near,
            "paper_orderings_verdict": claims,
        }
        md += [
            f"## {example.name.replace('_', ' ').capitalize()}",
            "",
            f"Paper's magnitude: {PAPER_SOURCE[example.name]}"
            + (
                "."
                if paper is None
                else f"; it is {plain_number(paper / average_bound.max())} to "
                f"{plain_number(paper / average_bound.min())} of the bound, out of any filter's reach "
                "under the stated noise."
            ),
            "",
            example_table(example.name, average, average_bound),
            "",
            "Last quarter of the run: "
            + "; ".join(
                f"{f} " + ", ".join(f"{s} {final[f][i]:.4g}" for i, s in enumerate(STATES))
                for f in FILTER_NAMES
            ),
            "",
        ]
        md += verdict_lines(near, claims, "RMSE")
    md += choices_lines(CHOICES)
    with atomic_directory(args.out) as out:
        write_json(out / "table.json", table)
        write_text(out / "table.md", "\n".join(md))
        for filename, fig in figures(curves, bounds, args.runs).items():
            save(fig, Path(out) / filename)
    print(f"iukf-examples: wrote {args.out}/table.json, table.md and {len(FIGURES)} figures")
    return 0


def figures(
    curves: dict[str, dict[str, np.ndarray]], bounds: dict[str, np.ndarray], runs: int
) -> dict[str, Any]:
    """Figures 1-4 of the paper by file name (unsaved): RMSE over time of the four filters
    with the bound, and the differences of the pairs that coincide (UKF and EKF, IUKF and
    IEKF)."""
    out = {}
    for filename, (name, state) in FIGURES.items():
        number = list(FIGURES).index(filename) + 1
        out[filename] = curve_figure(
            {f: curves[name][f][:, state] for f in FILTER_NAMES},
            extra={"posterior Cramer-Rao bound": bounds[name][:, state]},
            differences=(("UKF", "EKF"), ("IUKF", "IEKF")),
            difference_label=f"RMSE difference of x{state + 1}",
            log_scale=True,
            ylabel=f"RMSE of x{state + 1}",
            title=f"paper 000 fig. {number}, {name.replace('_', ' ')}: "
            f"RMSE of x{state + 1} over {runs} runs",
        )
    return out
