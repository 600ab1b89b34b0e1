"""``robotsim reproduce ia-fusion``'s figures and its comparison with paper 002, on a few
seconds of ``hall`` (both trackers on the same simulated data)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from matplotlib import pyplot as plt

from intervals.boxes import contains_points
from scenarios.commands import with_run_options
from scenarios.reproduce import ia_fusion as ia
from scenarios.reproduce.figure_style import legend_labels, unlabelled_artists
from scenarios.spec import load_scenario


@pytest.fixture(scope="module")
def short_hall():
    spec = with_run_options(load_scenario("hall"), 1, 6.0)
    log, runs, rows = ia.experiment(spec)
    return spec, log, runs, rows


@pytest.fixture(scope="module")
def figures(short_hall):
    spec, log, runs, _ = short_hall
    built = ia.figures(spec, log, runs)
    yield built
    for fig in built.values():
        plt.close(fig)


def test_every_figure_is_written_with_a_legend_entry_for_every_drawn_element(figures):
    assert set(figures) == {
        "fig7_ukf_only.png",
        "fig8_fused_sivia.png",
        "fig9_fused_imagesp.png",
        "fig10_box_area.png",
        "fig11_error_over_time.png",
        "fig12_epoch_time.png",
        "fig13_zoomed_epoch.png",
    }
    for name, fig in figures.items():
        assert unlabelled_artists(fig) == [], name
        # one unit style: "quantity (unit)", never "[unit]"
        for ax in fig.axes:
            for label in (ax.get_xlabel(), ax.get_ylabel()):
                assert "[" not in label, (name, label)
            assert ax.get_xlabel() in ("", "time (s)", "x (m)"), (name, ax.get_xlabel())


def test_the_sets_are_outlined_patches_named_in_the_legend(figures):
    from matplotlib.collections import PatchCollection

    for name, tracker in (("fig8_fused_sivia.png", "SIVIA"), ("fig9_fused_imagesp.png", "IMAGESP")):
        fig = figures[name]
        assert legend_labels(fig) == [
            "walls, landmarks",
            f"{tracker} set, every {ia.BOX_EVERY}th epoch",
            "truth",
            "UKF only",
            f"fused ({tracker})",
        ]
        (sets,) = [c for c in fig.axes[0].collections if isinstance(c, PatchCollection)]
        assert len(sets.get_paths()) > 0 and np.asarray(sets.get_linewidth())[0] > 0


def test_the_new_figures_name_what_they_draw(figures):
    errors = legend_labels(figures["fig11_error_over_time.png"])
    assert errors[:3] == ["UKF only", "fused (SIVIA)", "fused (IMAGESP)"]
    assert errors.count("SIVIA box") == 3 and errors.count("IMAGESP box") == 3
    assert any(label.startswith("UKF only = fused") for label in errors)
    times = legend_labels(figures["fig12_epoch_time.png"])
    assert times[0] == "SIVIA" and times[2] == "IMAGESP"
    assert times[1].startswith("SIVIA median") and times[3].startswith("IMAGESP median")
    zoom = legend_labels(figures["fig13_zoomed_epoch.png"])
    for label in ("truth", "box the clamp used (SIVIA)", "box the clamp used (IMAGESP)"):
        assert label in zoom
    assert any(label.startswith("clamped to IMAGESP") for label in zoom)
    # plain tick labels on the log axes
    area = figures["fig10_box_area.png"].axes[0]
    area.figure.canvas.draw()
    assert area.get_yscale() == "log"
    assert all("^" not in t.get_text() for t in area.get_yticklabels())


def test_the_band_holds_zero_exactly_where_the_truth_is_in_the_clamp_box(short_hall):
    """The band of figure 11 is the box the clamp used minus the truth: checked against the
    containment of the truth in that box, computed on the boxes themselves."""
    _, log, runs, _ = short_hall
    for estimation in runs.values():
        errors = ia.epoch_errors(log, estimation)
        band = errors["band"]
        clamped = np.isfinite(band[:, 0, 0])
        assert clamped.any()
        in_band = (band[clamped, :2, 0] <= 0).all(axis=1) & (band[clamped, :2, 1] >= 0).all(axis=1)
        truth = log.pose[estimation.epoch_index][clamped]
        boxes = estimation.fused_box[clamped]
        inside = np.array(
            [
                contains_points(b[None, :2], p[None, :2])[0, 0]
                for b, p in zip(boxes, truth, strict=True)
            ]
        )
        np.testing.assert_array_equal(in_band, inside)
        # the fused estimate is in the box: its error lies in the band
        fused = errors["fused"][clamped]
        assert (
            (band[clamped, :2, 0] <= fused[:, :2] + 1e-12)
            & (fused[:, :2] <= band[clamped, :2, 1] + 1e-12)
        ).all()
        # headings: the band is within one turn and narrower than a turn on this run
        width = band[clamped, 2, 1] - band[clamped, 2, 0]
        assert (width > 0).all() and (width < np.pi).all()


def test_the_comparison_with_the_paper_has_its_settings_and_directions(short_hall):
    spec, _, _, rows = short_hall
    against = ia.against_paper(spec, rows)
    settings = [r for r in against if r["paper"] is not None]
    assert [r["quantity"] for r in settings] == [q for q, _, _ in ia.PAPER_SETTINGS]
    for r in settings:
        assert (
            r["ratio"] == pytest.approx(r["ours"] / r["paper"]) and r["verdict"] == "as the paper"
        )
    results = [r for r in against if r["paper"] is None]
    assert len(results) == len(ia.PAPER_RESULTS)
    for r in results:
        assert np.isfinite(r["ours"]) and r["ratio"] is None
        assert r["verdict"].endswith("no paper value")
    area = next(r for r in results if r["quantity"].startswith("IMAGESP / SIVIA mean set area"))
    assert area["ours"] == pytest.approx(
        rows["imagesp"]["box"]["mean_area_m2"] / rows["sivia"]["box"]["mean_area_m2"]
    )
