"""Shared machinery of the filter-family reproductions (papers 000 and 004): Monte Carlo runs
of several filters on the same noise draws, batched over runs, and their error tables."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from localization.models import MeasurementModel, ProcessModel
from localization.mukf import ModifiedBelief
from scenarios.errors import ScenarioError

#: Line styles of the four filters of a figure: filters that coincide stay visible.
LINE_STYLES = ("-", "--", "-.", ":")


def add_common_arguments(parser: argparse.ArgumentParser, name: str, steps: int) -> None:
    """``--runs``, ``--steps``, ``--out`` and ``--seed`` with the paper's defaults."""
    parser.add_argument(
        "--runs", type=int, default=100, help="Monte Carlo runs (default: 100, as the paper)"
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=steps,
        help=f"time steps per run (default: {steps}, as the paper)",
    )
    parser.add_argument(
        "--out", default=f"runs/reproduce/{name}", help="output folder (replaced atomically)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise draws (default: 0)")


def run_filter(
    kf: Any,
    belief: Any,
    process: ProcessModel,
    measurement: MeasurementModel,
    measurements: np.ndarray,
    step_args: Callable[[int], tuple],
) -> np.ndarray:
    """Estimates ``(N, R, n)`` of one filter over ``N`` steps, all ``R`` runs in each call.

    Step ``k`` (0-based) predicts with ``step_args(k)`` and updates with ``measurements[k]``
    ``(R, m)``. ``belief`` is a batched :class:`Gaussian` or :class:`ModifiedBelief`.
    """
    estimates = []
    for k, z in enumerate(measurements):
        belief = kf.update(kf.predict(belief, process, *step_args(k)), z, measurement)
        estimates.append(belief.estimate if isinstance(belief, ModifiedBelief) else belief.mean)
    return np.stack(estimates)


def rmse_over_time(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``(N, n)`` root mean square over runs of ``estimates - truth`` (both ``(N, R, n)``)."""
    return np.sqrt(np.mean((estimates - truth) ** 2, axis=1))


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def check_counts(args: argparse.Namespace, reason_source: str) -> None:
    """Refuse non-positive ``--runs`` / ``--steps`` and a negative ``--seed`` with a one-line user error."""
    for key in ("runs", "steps"):
        if getattr(args, key) < 1:
            raise ScenarioError(
                reason_source, f"--{key}", f"must be >= 1, got {getattr(args, key)}"
            )
    if args.seed < 0:
        raise ScenarioError(reason_source, "--seed", f"must be >= 0, got {args.seed}")


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    """``max |a - b| / |b|`` over the entries: how far two filters' error figures are apart."""
    return float(np.max(np.abs(np.asarray(a) - b) / np.abs(b)))


#: Two error figures closer than this (relative) are a tie: the claim is not decided.
TIE_TOLERANCE = 0.01


def judge(pairs: Sequence[tuple[float, float]]) -> str:
    """Verdict on a claim "each ``better`` is below its ``worse``", given ``(better, worse)`` pairs.

    ``"reproduced"`` if every pair differs by more than :data:`TIE_TOLERANCE` the right way,
    ``"NOT reproduced"`` if some pair differs by more than that the wrong way, otherwise
    ``"tie (within 1 %)"``.
    """
    if all(better < (1.0 - TIE_TOLERANCE) * worse for better, worse in pairs):
        return "reproduced"
    if any(better > (1.0 + TIE_TOLERANCE) * worse for better, worse in pairs):
        return "NOT reproduced"
    return f"tie (within {TIE_TOLERANCE:.0%})"


def best_of(values: dict[str, float], name: str) -> list[tuple[float, float]]:
    """The pairs of the claim "``name`` is best": ``(values[name], values[other])`` for every other."""
    return [(values[name], v) for other, v in values.items() if other != name]


def verdict_lines(near: Mapping[str, float], claims: Mapping[str, str], what: str) -> list[str]:
    """``table.md`` lines: how close filter pairs are, then the verdict on each of the paper's claims."""
    lines = [
        f"Largest relative {what} difference, {pair}: {value:.2e}" for pair, value in near.items()
    ]
    return (
        lines
        + ["", "Paper's orderings:", ""]
        + [f"- {verdict}: {claim}" for claim, verdict in claims.items()]
        + [""]
    )


def choices_lines(choices: Mapping[str, str]) -> list[str]:
    """The ``table.md`` section listing the choices where the paper is silent."""
    return (
        ["## Choices where the paper is silent", ""]
        + [f"- {key}: {value}" for key, value in choices.items()]
        + [""]
    )


def save_figure(
    path: Path,
    series: Mapping[str, np.ndarray],
    *,
    ylabel: str,
    title: str,
    log_scale: bool = False,
    reference: np.ndarray | None = None,
) -> None:
    """One PNG of curves over the time steps ``1..N`` (``series`` by filter; ``reference``: truth)."""
    from matplotlib import pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    steps = np.arange(1, len(next(iter(series.values()))) + 1)
    if reference is not None:
        ax.plot(steps, reference, "k", linewidth=0.8, label="truth")
    for (name, values), style in zip(series.items(), LINE_STYLES, strict=True):
        ax.plot(steps, values, style, label=name)
    if log_scale:
        ax.set_yscale("log")
    ax.set_xlabel("time step k")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
