"""Paper 004 (modified UKF), section 4: EKF, MEKF, UKF and MUKF identifying ``x3``.

    robotsim reproduce mukf-example [--runs N] [--steps K] [--out DIR] [--seed S]

Model (eq. 22)::

    x(k+1) = [[1 - 0.1 x3(k), 0.1, 0], [-0.1, 1, 0], [0, 0, 1]] x(k) + xi(k),   z(k) = x1(k) + v(k)

with ``Var xi = 1e-6 I3``, ``Var v = 1e-5``; the true parameter follows case a)
``x3(k) = 1`` or case b) ``x3(k) = 1 + 0.01 k`` (eq. 23), ``k = 1..200``. Every filter starts
from ``[0.9, 0.9, 0.9]`` with ``P(0) = 1e-5 I3`` (table 1) and uses the model above with
``x3`` a random walk of variance ``1e-6``; UKF and MUKF use paper 004's sigma points with
``a = 0.1`` (eq. 3, 7). The linear subsystem of the modified filters is ``(x1, x2)`` with
``F(x3)`` and ``H = [1, 0]`` (eq. 17). 100 runs on the same draws for the four filters.

Writes ``DIR/table.json`` (MSE per state and filter, per case, beside the paper's tables 2
and 3 with ours / paper and a verdict, the MSE of an oracle on ``x3`` (:func:`oracle_x3`) and
the paper's orderings checked), ``DIR/table.md`` and ``DIR/fig1_x3_case_a.png``,
``DIR/fig2_x3_case_b.png`` (the run-averaged ``x3`` estimates against the truth and the
oracle, like figures 1 and 2, and below the differences of the filters that coincide).

Choices where the paper is silent (also written to ``table.md``): see ``CHOICES``.
"""

from __future__ import annotations

import argparse
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from localization.ekf import ExtendedKalmanFilter
from localization.gaussian import Gaussian
from localization.linalg import CovarianceRepairWarning, PDPolicy
from localization.models import MeasurementModel, ProcessModel
from localization.mukf import LinearSubsystem, ModifiedKalmanFilter
from localization.sigma_points import SpreadSigmaPoints
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
    relative_difference,
    run_filter,
    verdict_lines,
    with_magnitude,
)
from scenarios.reproduce.figure_style import save

HELP = (
    "paper 004: EKF, MEKF, UKF and MUKF identifying x3 in cases a and b (MSE tables, figures 1-2)"
)

FILTER_NAMES = ("EKF", "MEKF", "UKF", "MUKF")
STATES = ("x1", "x2", "x3")
CASES = ("case_a", "case_b")
#: The figures by file name: the case each shows (the paper's figures 1 and 2).
FIGURES = {"fig1_x3_case_a.png": "case_a", "fig2_x3_case_b.png": "case_b"}
INITIAL_ESTIMATE = np.array([0.9, 0.9, 0.9])
INITIAL_COV = 1e-5 * np.eye(3)
TRUE_INITIAL_STATE = np.array([1.0, 1.0, 1.0])
Q = 1e-6 * np.eye(3)
R = np.array([[1e-5]])
#: Paper 004 eq. 3, 7; the centre weight is 1 - 1/a^2 = -99.
POINTS = SpreadSigmaPoints(a=0.1)
#: Paper 004 tables 2 and 3 (MSE), for the side-by-side table.
PAPER_MSE = {
    "case_a": {
        "EKF": (0.0001702, 0.0025883, 0.004326),
        "MEKF": (0.0001752, 0.0025893, 0.004019),
        "UKF": (0.0001822, 0.0026913, 0.004229),
        "MUKF": (0.0001752, 0.0025633, 0.003973),
    },
    "case_b": {
        "EKF": (0.0001852, 0.0028743, 0.0057051),
        "MEKF": (0.000189, 0.002924, 0.005453),
        "UKF": (0.000205, 0.003013, 0.005513),
        "MUKF": (0.0001882, 0.0028963, 0.005344),
    },
}

CHOICES = {
    "true initial state": "x(0) = [1, 1, 1] for every run (the paper gives only the filters' initial estimate "
    "[0.9, 0.9, 0.9]; x3(0) = 1 continues eq. 23)",
    "true x3": "deterministic as eq. 23 (no process noise on the true parameter); x1, x2 get xi ~ N(0, 1e-6)",
    "filter model of x3": "a random walk x3(k+1) = x3(k) + xi3, Var xi3 = 1e-6 (eq. 22 with Var xi = 1e-6 I3)",
    "MSE": "mean over runs and over k = 1..200 of the squared estimation error",
    "modified filters' estimate": "(x^1, x^2) from Algorithm II (the linear KF), x~3 from Algorithm I",
    "covariance policy": "UKF and MUKF repair a covariance that is not positive definite (centre weight -99) "
    "with a reported jitter; counted in table.json",
}


def transition(s, *_):
    """Eq. 22: ``(..., 3) -> (..., 3)``."""
    return np.stack(
        [
            (1.0 - 0.1 * s[..., 2]) * s[..., 0] + 0.1 * s[..., 1],
            -0.1 * s[..., 0] + s[..., 1],
            s[..., 2],
        ],
        axis=-1,
    )


def transition_jacobian(s, *_):
    """``d f / d s`` ``(..., 3, 3)``."""
    jac = np.zeros(s.shape[:-1] + (3, 3))
    jac[..., 0, 0], jac[..., 0, 1], jac[..., 0, 2] = 1.0 - 0.1 * s[..., 2], 0.1, -0.1 * s[..., 0]
    jac[..., 1, 0], jac[..., 1, 1], jac[..., 2, 2] = -0.1, 1.0, 1.0
    return jac


def linear_transition(y, *_):
    """``F(x3)`` ``(..., 2, 2)`` of the linear subsystem ``(x1, x2)`` (eq. 17)."""
    f = np.empty(y.shape[:-1] + (2, 2))
    f[..., 0, 0], f[..., 0, 1], f[..., 1, 0], f[..., 1, 1] = 1.0 - 0.1 * y[..., 0], 0.1, -0.1, 1.0
    return f


def linear_observation(x, y, *_):
    """``H = [1, 0]`` ``(..., 1, 2)``."""
    return np.broadcast_to(np.array([[1.0, 0.0]]), x.shape[:-1] + (1, 2))


PROCESS = ProcessModel(transition, Q, jacobian=transition_jacobian)
MEASUREMENT = MeasurementModel(
    lambda s: s[..., :1],
    R,
    jacobian=lambda s: np.broadcast_to(np.array([[1.0, 0.0, 0.0]]), s.shape[:-1] + (1, 3)),
)
SUBSYSTEM = LinearSubsystem(2, linear_transition, linear_observation)


def true_parameter(case: str, k: np.ndarray) -> np.ndarray:
    """Eq. 23: the true ``x3(k)``."""
    return np.ones_like(k, dtype=float) if case == "case_a" else 1.0 + 0.01 * k


def simulate(
    case: str, runs: int, steps: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Truth ``(steps + 1, runs, 3)`` and measurements ``(steps, runs, 1)`` of ``x(1..steps)``."""
    truth = np.empty((steps + 1, runs, 3))
    truth[0] = TRUE_INITIAL_STATE
    noise = 1e-3 * rng.standard_normal((steps, runs, 2))
    for k in range(steps):
        truth[k + 1] = transition(truth[k])
        truth[k + 1, :, :2] += noise[k]
        truth[k + 1, :, 2] = true_parameter(case, np.array(k + 1))
    measurements = truth[1:, :, :1] + np.sqrt(R[0, 0]) * rng.standard_normal((steps, runs, 1))
    return truth, measurements


def filters() -> dict[str, object]:
    """The four filters of the comparison."""
    ukf = UnscentedKalmanFilter(POINTS, PDPolicy(action="repair"))
    return {
        "EKF": ExtendedKalmanFilter(),
        "MEKF": ModifiedKalmanFilter(ExtendedKalmanFilter(), SUBSYSTEM),
        "UKF": ukf,
        "MUKF": ModifiedKalmanFilter(ukf, SUBSYSTEM),
    }


def oracle_x3(
    truth: np.ndarray,
    start: tuple[float, float] = (INITIAL_ESTIMATE[2], INITIAL_COV[2, 2]),
    walk_var: float = Q[2, 2],
) -> np.ndarray:
    """Estimates ``(steps, runs)`` of ``x3(1..steps)`` by a filter with the paper's model of
    ``x3`` (a random walk of variance ``walk_var`` from ``start``, mean and variance: table 1
    and eq. 22 by default) that sees ``x1`` and ``x2`` without noise (``truth (steps + 1,
    runs, 3)``).

    The first row of eq. 22, ``x1(k) - x1(k-1) - 0.1 x2(k-1) = -0.1 x1(k-1) x3(k-1) +
    xi1(k-1)``, is then a linear measurement of ``x3(k-1)`` with variance ``Q[0, 0]``, and a
    scalar Kalman filter on it is exact. It knows more than any filter given ``z``, so its
    MSE is what the paper's model of ``x3`` allows at best.
    """
    runs = truth.shape[1]
    x3 = np.full(runs, start[0])
    var = np.full(runs, start[1])
    out = np.empty((truth.shape[0] - 1, runs))
    for k in range(1, truth.shape[0]):
        h = -0.1 * truth[k - 1, :, 0]
        y = truth[k, :, 0] - truth[k - 1, :, 0] - 0.1 * truth[k - 1, :, 1]
        gain = var * h / (h * h * var + Q[0, 0])
        x3, var = x3 + gain * (y - h * x3), (1.0 - gain * h) * var + walk_var
        out[k - 1] = x3
    return out


@dataclass(frozen=True)
class CaseResult:
    """One case: MSE ``(3,)`` per filter, run-averaged ``x3`` estimates ``(steps,)`` per
    filter, the oracle's (:func:`oracle_x3`) MSE and mean ``x3`` estimates, the true ``x3``
    ``(steps,)`` and the covariance repairs per filter."""

    mse: dict[str, np.ndarray]
    x3_mean: dict[str, np.ndarray]
    oracle_mse: float
    oracle_x3_mean: np.ndarray
    x3_true: np.ndarray
    repairs: dict[str, int]


def evaluate(case: str, runs: int, steps: int, rng: np.random.Generator) -> CaseResult:
    """The four filters and the oracle on the same draws of one case."""
    truth, measurements = simulate(case, runs, steps, rng)
    start = Gaussian(
        np.broadcast_to(INITIAL_ESTIMATE, (runs, 3)), np.broadcast_to(INITIAL_COV, (runs, 3, 3))
    )
    mse, x3_mean, repairs = {}, {}, {}
    for name, kf in filters().items():
        belief = kf.initial(start) if isinstance(kf, ModifiedKalmanFilter) else start
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", CovarianceRepairWarning)
            estimates = run_filter(kf, belief, PROCESS, MEASUREMENT, measurements, lambda k: ())
        repairs[name] = sum(issubclass(w.category, CovarianceRepairWarning) for w in caught)
        mse[name] = np.mean((estimates - truth[1:]) ** 2, axis=(0, 1))
        x3_mean[name] = estimates[:, :, 2].mean(axis=1)
    oracle = oracle_x3(truth)
    return CaseResult(
        mse=mse,
        x3_mean=x3_mean,
        oracle_mse=float(np.mean((oracle - truth[1:, :, 2]) ** 2)),
        oracle_x3_mean=oracle.mean(axis=1),
        x3_true=truth[1:, 0, 2],
        repairs=repairs,
    )


#: The states and filters each of the paper's claims is about (for its magnitude verdict).
CLAIM_SCOPE = {
    "MUKF better than UKF for every state": (STATES, ("MUKF", "UKF")),
    "x3: MUKF best of the four": (("x3",), FILTER_NAMES),
    "x3: MEKF better than EKF and UKF": (("x3",), ("MEKF", "EKF", "UKF")),
    "x1, x2: EKF best of the four": (("x1", "x2"), FILTER_NAMES),
}


def paper_claims(mse: dict[str, np.ndarray]) -> dict[str, str]:
    """The orderings paper 004 states (section 4), judged on the MSE."""
    state = {s: {name: float(m[i]) for name, m in mse.items()} for i, s in enumerate(STATES)}
    return {
        "MUKF better than UKF for every state": judge(
            [(state[s]["MUKF"], state[s]["UKF"]) for s in STATES]
        ),
        "x3: MUKF best of the four": judge(best_of(state["x3"], "MUKF")),
        "x3: MEKF better than EKF and UKF": judge(
            [(state["x3"]["MEKF"], state["x3"][f]) for f in ("EKF", "UKF")]
        ),
        "x1, x2: EKF best of the four": judge(
            best_of(state["x1"], "EKF") + best_of(state["x2"], "EKF")
        ),
    }


def ratios_to_paper(case: str, mse: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Our MSE over the paper's (tables 2-3), by filter and state."""
    return {
        name: {s: float(mse[name][i]) / PAPER_MSE[case][name][i] for i, s in enumerate(STATES)}
        for name in FILTER_NAMES
    }


def judged_claims(claims: dict[str, str], ratios: dict[str, dict[str, float]]) -> dict[str, str]:
    """Each claim's ordering verdict with the magnitude verdict of the MSE it compares
    (:func:`with_magnitude` over the claim's states and filters, :data:`CLAIM_SCOPE`)."""
    return {
        claim: with_magnitude(
            verdict,
            [ratios[n][s] for n in CLAIM_SCOPE[claim][1] for s in CLAIM_SCOPE[claim][0]],
        )
        for claim, verdict in claims.items()
    }


def case_table(case: str, result: CaseResult, ratios: dict[str, dict[str, float]]) -> str:
    """The ``table.md`` table of one case: ours, the paper's, the ratio and the verdict."""
    table_no = {"EKF": 2, "MEKF": 2, "UKF": 3, "MUKF": 3}
    rows = [
        [
            s,
            name,
            f"{result.mse[name][i]:.4g}",
            f"{PAPER_MSE[case][name][i]:.4g} (table {table_no[name]})",
            format_ratio(ratios[name][s]),
            magnitude_verdict(ratios[name][s]),
        ]
        for i, s in enumerate(STATES)
        for name in FILTER_NAMES
    ]
    rows.append(
        ["x3", "oracle (sees x1, x2 without noise)", f"{result.oracle_mse:.4g}", "-", "-", "-"]
    )
    return markdown_table(["state", "filter", "MSE", "paper", "ours / paper", "magnitude"], rows)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``robotsim reproduce mukf-example``."""
    add_common_arguments(parser, "mukf-example", steps=200)


def main(args: argparse.Namespace) -> int:
    """Run both cases, write the table and the figures; returns 0."""
    import matplotlib

    matplotlib.use("Agg")
    check_counts(args, "mukf-example")
    rng = np.random.default_rng(args.seed)
    table: dict[str, object] = {
        "paper": "004 (Babacan, Doroslovacki and Ozbek, modified UKF)",
        "runs": args.runs,
        "steps": args.steps,
        "seed": args.seed,
        "choices": CHOICES,
    }
    md = [
        f"# Paper 004, cases a and b ({args.runs} runs, {args.steps} steps, seed {args.seed})",
        "",
        "MSE over runs and steps beside the paper's tables 2-3; magnitude: "
        f"'same magnitude' within a factor {MAGNITUDE_FACTOR:g} of the paper's value.",
        "",
    ]
    results = {}
    for case in CASES:
        result = evaluate(case, args.runs, args.steps, rng)
        results[case] = result
        ratios = ratios_to_paper(case, result.mse)
        claims = judged_claims(paper_claims(result.mse), ratios)
        near = {
            "UKF vs EKF": relative_difference(result.mse["UKF"], result.mse["EKF"]),
            "MUKF vs MEKF": relative_difference(result.mse["MUKF"], result.mse["MEKF"]),
        }
        table[case] = {
            "mse": {
                name: dict(zip(STATES, map(float, m), strict=True))
                for name, m in result.mse.items()
            },
            "paper_mse": {
                name: dict(zip(STATES, m, strict=True)) for name, m in PAPER_MSE[case].items()
            },
            "ratio_to_paper": ratios,
            "magnitude_verdict": {
                name: {s: magnitude_verdict(r) for s, r in by_state.items()}
                for name, by_state in ratios.items()
            },
            "oracle_x3_mse": result.oracle_mse,
            "covariance_repairs": result.repairs,
            "max_relative_mse_difference": near,
            "paper_orderings_verdict": claims,
        }
        md += [f"## Case {case[-1]}", "", case_table(case, result, ratios), ""]
        md += [f"Covariance repairs (steps with a jitter): {result.repairs}", ""]
        md += verdict_lines(near, claims, "MSE")
    md += choices_lines(CHOICES)
    with atomic_directory(args.out) as out:
        write_json(out / "table.json", table)
        write_text(out / "table.md", "\n".join(md))
        for filename, fig in figures(results, args.runs).items():
            save(fig, Path(out) / filename)
    print(f"mukf-example: wrote {args.out}/table.json, table.md and {len(FIGURES)} figures")
    return 0


def figures(results: dict[str, CaseResult], runs: int) -> dict[str, Any]:
    """Figures 1-2 of the paper by file name (unsaved): the run-averaged ``x3`` estimates
    against the truth and the oracle, and the differences of the filters that coincide."""
    return {
        filename: curve_figure(
            results[case].x3_mean,
            reference=results[case].x3_true,
            extra={"oracle (sees x1, x2 without noise)": results[case].oracle_x3_mean},
            differences=(("UKF", "EKF"), ("MUKF", "MEKF")),
            difference_label="x3 estimate difference",
            ylabel=f"x3 estimate (mean of {runs} runs)",
            title=f"paper 004 fig. {case_number}, {case.replace('_', ' ')}: estimation of x3",
        )
        for case_number, (filename, case) in enumerate(FIGURES.items(), start=1)
    }
