"""Shared machinery of the filter-family reproductions (papers 000 and 004): Monte Carlo runs
of several filters on the same noise draws, batched over runs, and their error tables."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping, Sequence
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
        + ["", "Paper's orderings (claim -> ordering verdict; magnitude against the paper):", ""]
        + [f"- {claim} -> {verdict}" for claim, verdict in claims.items()]
        + [""]
    )


def choices_lines(choices: Mapping[str, str]) -> list[str]:
    """The ``table.md`` section listing the choices where the paper is silent."""
    return (
        ["## Choices where the paper is silent", ""]
        + [f"- {key}: {value}" for key, value in choices.items()]
        + [""]
    )


def curve_figure(
    series: Mapping[str, np.ndarray],
    *,
    ylabel: str,
    title: str,
    log_scale: bool = False,
    reference: np.ndarray | None = None,
    differences: Sequence[tuple[str, str]] = (),
    difference_label: str = "difference",
    extra: Mapping[str, np.ndarray] | None = None,
) -> Any:
    """A figure of curves over the time steps ``1..N`` (``series`` by filter, each ``(N,)``).

    ``reference``: the truth, drawn in black; ``extra``: further labelled curves drawn thin
    and grey (a bound, an oracle). ``differences``: pairs ``(a, b)`` of ``series`` drawn as
    ``a - b`` in a second panel below, each labelled with its largest absolute value, so that
    filters whose curves coincide in the top panel are still told apart. Returns the
    matplotlib figure, unsaved (:func:`scenarios.reproduce.figure_style.save`).
    """
    from matplotlib import pyplot as plt

    from scenarios.reproduce.figure_style import plain_ticks

    rows = 2 if differences else 1
    fig, axes = plt.subplots(
        rows,
        1,
        figsize=(6.4, 4.0 + 1.8 * (rows - 1)),
        sharex=True,
        squeeze=False,
        gridspec_kw={"height_ratios": [2.2, 1.0][:rows]},
    )
    ax = axes[0, 0]
    steps = np.arange(1, len(next(iter(series.values()))) + 1)
    if reference is not None:
        ax.plot(steps, reference, "k", linewidth=0.8, label="truth")
    for (name, values), style in zip(series.items(), LINE_STYLES, strict=True):
        ax.plot(steps, values, style, label=name)
    for (name, values), style in zip((extra or {}).items(), LINE_STYLES, strict=False):
        ax.plot(steps, values, style, color="0.5", linewidth=0.9, label=name)
    if log_scale:
        ax.set_yscale("log")
    plain_ticks(ax)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    if differences:
        low = axes[1, 0]
        largest = 0.0
        for a, b in differences:
            gap = np.asarray(series[a]) - np.asarray(series[b])
            peak = float(np.max(np.abs(gap)))
            largest = max(largest, peak)
            low.plot(steps, gap, label=f"{a} - {b} (largest |difference| {peak:.2g})")
        low.axhline(0.0, color="k", linewidth=0.5, label="zero")
        # differences far below the curves' scale stay a flat line, not magnified rounding
        floor = 1e-3 * float(np.nanmax(np.abs(np.concatenate(list(series.values())))))
        if largest < floor:
            low.set_ylim(-floor, floor)
        plain_ticks(low)
        low.set_ylabel(difference_label)
        low.legend(fontsize=7)
    axes[-1, 0].set_xlabel("time step k")
    fig.tight_layout()
    return fig


#: Ours against the paper's within this factor (either way) is "the same magnitude".
MAGNITUDE_FACTOR = 2.0


def ratio(ours: float, paper: float | None) -> float | None:
    """``ours / paper``, None where the paper gives no value."""
    return None if paper is None else float(ours) / float(paper)


def magnitude_verdict(value: float | None) -> str:
    """Verdict on a ratio ours / paper: ``"same magnitude (x1.7)"`` within
    :data:`MAGNITUDE_FACTOR`, otherwise ``"FAR (960 x the paper's)"`` or ``"FAR (1/6.5 of the
    paper's)"``; ``"no paper value"`` for None."""
    if value is None:
        return "no paper value"
    if 1.0 / MAGNITUDE_FACTOR <= value <= MAGNITUDE_FACTOR:
        return f"same magnitude ({format_ratio(value)})"
    if value > 1.0:
        return f"FAR ({plain_number(value)} x the paper's)"
    return f"FAR (1/{plain_number(1.0 / value)} of the paper's)"


def with_magnitude(verdict: str, ratios: Sequence[float | None]) -> str:
    """An ordering verdict followed by the magnitude verdict of the ratio ours / paper
    farthest from 1 among ``ratios``, so that a tie between filters far from the paper's
    values does not read as agreement."""
    known = [r for r in ratios if r is not None]
    if not known:
        return f"{verdict}; no paper value"
    worst = max(known, key=lambda r: max(r, 1.0 / r))
    return f"{verdict}; {magnitude_verdict(worst)}"


def format_ratio(value: float | None) -> str:
    """A ratio cell: ``"x1.7"``, ``"x0.41"``; ``"-"`` without a paper value."""
    return "-" if value is None else f"x{plain_number(value)}"


def plain_number(value: float) -> str:
    """A positive number in plain digits, three significant ones (``1210``, ``1.7``, ``0.0057``)."""
    return f"{value:.0f}" if value >= 100 else f"{float(f'{value:.3g}'):g}"
