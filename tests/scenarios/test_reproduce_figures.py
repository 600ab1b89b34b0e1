"""The figures' shared style (scenarios.reproduce.figure_style) and the magnitude verdicts
of the reproductions' tables (scenarios.reproduce._filter_runs)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from matplotlib import pyplot as plt

from scenarios.reproduce._filter_runs import (
    curve_figure,
    format_ratio,
    magnitude_verdict,
    ratio,
    with_magnitude,
)
from scenarios.reproduce.figure_style import (
    axis_label,
    legend_labels,
    plain_ticks,
    save,
    unlabelled_artists,
)


def _tick_texts(fig, ax) -> list[str]:
    fig.canvas.draw()
    return [t.get_text() for t in ax.get_yticklabels() if t.get_text()]


def test_log_ticks_are_plain_numbers_even_within_one_decade():
    fig, ax = plt.subplots()
    ax.plot([1, 2], [0.3, 0.9])
    ax.set_yscale("log")
    plain_ticks(ax)
    texts = _tick_texts(fig, ax)
    plt.close(fig)
    assert {"0.5"} <= set(texts), texts  # a label inside the one decade the curve spans
    assert all("10" not in t or t == "10" for t in texts)
    assert not any("$" in t or "e" in t for t in texts), texts


def test_linear_ticks_have_no_offset_or_exponent():
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1000.001, 1000.004])
    plain_ticks(ax)
    texts = _tick_texts(fig, ax)
    plt.close(fig)
    assert texts and all(t.replace(".", "").replace("−", "").isdigit() for t in texts), texts
    assert ax.yaxis.get_offset_text().get_text() == ""


def test_an_element_without_a_legend_entry_is_reported():
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="shown")
    ax.plot([0, 1], [1, 0])  # drawn, never explained
    ax.legend()
    assert legend_labels(fig) == ["shown"]
    assert unlabelled_artists(fig) == ["axes 0: Line2D '_child1'"]
    plt.close(fig)


def test_curve_figure_explains_every_curve_and_its_difference_panel(tmp_path):
    steps = 30
    base = np.linspace(1.0, 2.0, steps)
    fig = curve_figure(
        {"A": base, "B": base + 1e-12, "C": 2 * base, "D": 3 * base},
        reference=base,
        extra={"bound": 0.5 * base},
        differences=(("B", "A"), ("D", "C")),
        ylabel=axis_label("RMSE", "m"),
        title="t",
        log_scale=True,
    )
    labels = legend_labels(fig)
    assert labels[:6] == ["truth", "A", "B", "C", "D", "bound"]
    assert labels[6].startswith("B - A (largest |difference| 1e-12")
    assert labels[7].startswith("D - C (largest |difference| 2")
    assert unlabelled_artists(fig) == []
    # a difference of rounding size is drawn flat, not magnified to fill the panel
    low = fig.axes[1]
    assert low.get_ylim()[1] >= 1e-3
    save(fig, tmp_path / "f.png")
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("value", "verdict"),
    [
        (1.7, "same magnitude (x1.7)"),
        (0.55, "same magnitude (x0.55)"),
        (249.3, "FAR (249 x the paper's)"),
        (0.16, "FAR (1/6.25 of the paper's)"),
        (None, "no paper value"),
    ],
)
def test_magnitude_verdicts(value, verdict):
    assert magnitude_verdict(value) == verdict


def test_a_tie_far_from_the_paper_does_not_read_as_agreement():
    """Mukf case b: the four filters within 1 % of each other, 250 times the paper's MSE."""
    r = ratio(1.42, 0.0057)
    assert format_ratio(r) == "x249"
    verdict = with_magnitude("tie (within 1%)", [r, ratio(0.0072, 0.0043)])
    assert verdict == "tie (within 1%); FAR (249 x the paper's)"
    assert with_magnitude("reproduced", [None]) == "reproduced; no paper value"
