"""The look shared by every reproduction figure: one unit style, plain tick labels, legends
that name every drawn element, and a check of those legends for the tests.

Units are written in round brackets after the quantity, ``"position error (m)"``
(:func:`axis_label`), in the figures and in the tables alike. Tick labels are plain
numbers, also on logarithmic axes (:func:`plain_ticks`). A line that would hide another is
shown with a difference panel or named in its legend entry with how far the two are apart.

Matplotlib is imported inside the functions, so that importing the reproductions stays
cheap.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: Dots per inch of every saved figure: small files, readable at screen size.
DPI = 100


def axis_label(quantity: str, unit: str | None = None) -> str:
    """``"quantity (unit)"``, or the quantity alone for a number without unit."""
    return quantity if unit is None else f"{quantity} ({unit})"


def plain_ticks(ax: Any, axis: str = "y") -> None:
    """Plain number tick labels (``0.01``, ``0.1``, no ``10^-2``) on ``axis`` of ``ax``,
    logarithmic (ticks at 1, 2 and 5 per decade) or linear; minor ticks of a log axis keep no
    labels."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter, ScalarFormatter

    target = ax.yaxis if axis == "y" else ax.xaxis
    if target.get_scale() == "log":
        # 1, 2, 5 in every decade: a curve spanning less than a decade still gets labels
        target.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
        target.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        target.set_minor_formatter(NullFormatter())
    else:
        formatter = ScalarFormatter(useOffset=False)
        formatter.set_scientific(False)
        target.set_major_formatter(formatter)


def legend_labels(fig: Any) -> list[str]:
    """The legend entries of every axes of ``fig``, in drawing order (axes by axes)."""
    labels = []
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is not None:
            labels += [text.get_text() for text in legend.get_texts()]
    return labels


def unlabelled_artists(fig: Any) -> list[str]:
    """Descriptions of drawn lines, collections and patches that have no legend entry.

    An artist counts as drawn data when it is visible and not an axes' own patch; its label
    must appear in its axes' legend. An empty list means every drawn element is explained.
    """
    missing = []
    for number, ax in enumerate(fig.axes):
        legend = ax.get_legend()
        shown = {text.get_text() for text in legend.get_texts()} if legend is not None else set()
        for artist in [*ax.lines, *ax.collections, *ax.patches]:
            label = artist.get_label()
            if not artist.get_visible() or label in shown:
                continue
            missing.append(f"axes {number}: {type(artist).__name__} {label!r}")
    return missing


def save(fig: Any, path: Path) -> None:
    """Write ``fig`` as a PNG at :data:`DPI`, grown to hold legends placed outside the axes,
    and release it."""
    from matplotlib import pyplot as plt

    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
