"""Paper 001's reproduction: a short run keeps the robust orderings and writes its outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from localization.motion_models import MODELS
from localization.sigma_points import ScaledSigmaPoints
from robotsim.vehicle.drives import highway_drive
from robotsim.vehicle.sensors import VehicleSensorParams, measure
from scenarios.cli import main as cli_main
from scenarios.reproduce import motion_models as mm_repro


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """``robotsim reproduce motion-models`` on 60-s drives with 4 runs, through the CLI."""
    out = tmp_path_factory.mktemp("repro") / "motion-models"
    argv = [
        "reproduce",
        "motion-models",
        "--runs",
        "4",
        "--duration",
        "60",
        "--seed",
        "3",
        "--out",
        str(out),
    ]
    status = cli_main(argv)
    return status, out


@pytest.mark.slow
def test_outputs_are_written_and_parseable(short_run):
    status, out = short_run
    assert status == 0
    table = json.loads((out / "table.json").read_text())
    assert set(table["table"]) == {"urban", "highway"}
    for drive in table["table"].values():
        assert set(drive) == set(MODELS)
        for errors in drive.values():
            assert set(errors) == {"euclidean", "lateral", "longitudinal"}
            # the Euclidean RMS is the root of the sum of the lateral and longitudinal mean squares
            assert errors["euclidean"] == pytest.approx(
                np.hypot(errors["lateral"], errors["longitudinal"])
            )
    assert table["settings"]["sigma_points"]["alpha"] == 1e-5
    md = (out / "table.md").read_text()
    assert "| urban | euclidean |" in md and "| highway | euclidean |" in md
    for name in (
        "fig5_cv_ctrv_highway.png",
        "fig6_ctrv_ctra_highway.png",
        "fig7_ctra_cca_urban.png",
        "drives.png",
    ):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.parent.glob(".*.part"))


@pytest.mark.slow
def test_curvilinear_models_beat_cv_in_the_city(short_run):
    """The ordering that holds robustly (paper 001 table II and figure 5): yaw rate helps."""
    _, out = short_run
    table = json.loads((out / "table.json").read_text())
    urban = table["table"]["urban"]
    for model in ("CTRV", "CTRA", "CCA"):
        assert urban[model]["euclidean"] < 0.6 * urban["CV"]["euclidean"]
        assert urban[model]["lateral"] < urban["CV"]["lateral"]
    turns = table["restricted_euclidean"]["urban"]
    assert turns["epochs"]["high_yaw_rate"] > 0
    assert turns["CTRV"]["high_yaw_rate"] < 0.6 * turns["CV"]["high_yaw_rate"]
    assert table["findings"]["urban"]["curvilinear_beat_cv"] is True


@pytest.mark.slow
def test_same_seed_gives_the_same_table():
    a = mm_repro.experiment(runs=2, seed=5, duration_s=25.0)
    b = mm_repro.experiment(runs=2, seed=5, duration_s=25.0)
    assert a["table"] == b["table"]


@pytest.mark.slow
def test_tiny_alpha_agrees_with_a_moderate_alpha():
    """alpha = 1e-5 (centre weight about -2e10) gives the same estimates as alpha = 1e-3:
    the local frame and the moments about the centre point keep the rounding in check."""
    drive = highway_drive(np.random.default_rng(0), 60.0)
    meas = measure(drive, VehicleSensorParams(), np.random.default_rng(1), runs=3)
    draws = np.random.default_rng(2).standard_normal((3, 6))
    for name in ("CTRV", "CCA"):
        tiny = mm_repro.run_filter(MODELS[name], drive, meas, draws).position_m
        moderate = mm_repro.run_filter(
            MODELS[name], drive, meas, draws, ScaledSigmaPoints(alpha=1e-3, beta=2.0, kappa=None)
        ).position_m
        assert np.abs(tiny - moderate).max() < 0.02  # metres, on a 1.8 km drive
        errors = mm_repro.position_errors(tiny, drive, meas)["euclidean"]
        assert errors[:, meas.t_s > 10].max() < 15.0  # the filter tracks the reference


def test_bad_options_get_one_line_errors(tmp_path, capsys):
    assert (
        cli_main(["reproduce", "motion-models", "--runs", "0", "--out", str(tmp_path / "x")]) == 2
    )
    assert (
        cli_main(["reproduce", "motion-models", "--duration", "5", "--out", str(tmp_path / "x")])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "robotsim: error: --runs: must be >= 1, got 0",
        "robotsim: error: --duration: must be >= 20 s, got 5.0",
    ]
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_table_ii_is_judged_against_the_paper(short_run):
    _, out = short_run
    table = json.loads((out / "table.json").read_text())
    against = table["against_paper"]
    for drive, row in table["table"].items():
        for model, errors in row.items():
            for i, kind in enumerate(("euclidean", "lateral", "longitudinal")):
                paper = mm_repro.PAPER_TABLE_II[drive][model][i]
                assert against["paper_table_ii"][drive][model][kind] == paper
                r = against["ratio_to_paper"][drive][model][kind]
                assert np.isfinite(r) and r == pytest.approx(errors[kind] / paper)
                verdict = against["magnitude_verdict"][drive][model][kind]
                assert verdict.startswith("FAR") == (not 0.5 <= r <= 2.0)
    assert len(against["summary"]) == 2
    md = (out / "table.md").read_text()
    assert "| scenario | RMS (m) |" in md and "Magnitudes against table II:" in md
    assert "[m]" not in md


@pytest.mark.slow
def test_figures_5_to_7_show_the_difference_of_their_pair():
    from matplotlib import pyplot as plt

    from scenarios.reproduce.figure_style import legend_labels, unlabelled_artists

    results = mm_repro.experiment(runs=2, seed=5, duration_s=25.0)
    figures = mm_repro.figures(results)
    assert list(figures) == [f for f, *_ in mm_repro.FIGURES] + ["drives.png"]
    for filename, _, (first, second), subset in mm_repro.FIGURES:
        fig = figures[filename]
        labels = legend_labels(fig)
        assert [label.split(" ")[0] for label in labels if "RMS" in label] == [first, second]
        assert any(
            label.startswith(f"{second} - {first} (largest |difference|") for label in labels
        )
        if subset is not None:
            assert subset.replace("_", " ") in labels
        assert fig.axes[0].get_ylabel() == "Euclidean error, RMS over runs (m)"
    for fig in figures.values():
        assert unlabelled_artists(fig) == []
        plt.close(fig)
