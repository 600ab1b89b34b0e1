"""The pipeline's guarantee (paper 002, docs/models.md sections 4-5), on short real runs.

- errors inside their bounds and at most ``q_max`` outliers per scan: the outer set holds the
  true pose at every epoch, no epoch is inconsistent, and the fused position lies in the box
  it was clamped to;
- more outliers than ``q_max``: the epoch is reported inconsistent (or lost), nothing is
  clamped, and the tracker relocalises and holds the truth again;
- a kidnapping (moved without odometry): inconsistent, then relocalised;
- bad ``[estimation]`` settings: one clear line, exit status 2, no output.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from robotsim.simulation import KidnapEvent
from scenarios.cli import main
from scenarios.epochs import GLOBAL, INCONSISTENT, LOST, TRACKING
from scenarios.pipeline import FUSED, estimate, estimation_summary
from scenarios.runner import run_scenario, simulate_spec
from scenarios.spec import Follow, builtin_names, load_scenario

pytestmark = pytest.mark.slow  # real runs over many seeds and maps

SHORT_S = 15.0

#: Built-in plans the interval stage cannot yet run within a test's time and memory (issue
#: 13: global localisation on big_hall asks for 32 GiB, corridor and office_floor run slower
#: than real time); benchmarks/buildings.py measures them. Drop names here as they scale.
TOO_LARGE_FOR_NOW = ("big_hall", "corridor", "office_floor")


def with_estimation(spec, **changes):
    return spec.with_estimation(**changes)


def with_outliers(log, per_scan: int, rng: np.random.Generator, scans=None):
    """The log with exactly ``per_scan`` readings of each chosen scan replaced by outliers:
    a uniform value in ``[0, d_max]`` or, one time in four, no echo."""
    ranges = np.array(log.sonar_range_m)
    k = ranges.shape[1]
    d_max = log.sensors.sonar.d_max_m
    for m in range(len(ranges)) if scans is None else scans:
        bad = rng.choice(k, size=per_scan, replace=False)
        values = rng.uniform(0.0, d_max, per_scan)
        ranges[m, bad] = np.where(rng.random(per_scan) < 0.25, np.inf, values)
    return dataclasses.replace(log, sonar_range_m=ranges)


def check_sound(estimation, expect_consistent=True):
    """Containment at every epoch with a set; the fusion only at clamping epochs, into its
    box; returns the epoch statuses."""
    epochs = estimation.epochs
    status = epochs.status
    has_set = np.isin(status, (GLOBAL, TRACKING))
    assert np.all(epochs.contains_truth[has_set]), np.flatnonzero(~epochs.contains_truth & has_set)
    check_sound_fusion(estimation)
    if expect_consistent:
        assert status[0] == GLOBAL and np.all(status[1:] == TRACKING), status
    return status


def check_sound_fusion(estimation):
    """The fusion clamps exactly at the epochs with a (non-empty) set, into its box, and
    leaves the estimate alone elsewhere; the estimates stay finite."""
    epochs = estimation.epochs
    has_set = np.isin(epochs.status, (GLOBAL, TRACKING))
    assert np.array_equal(has_set, epochs.box_counts > 0)  # no set at all when inconsistent or lost
    clamped = estimation.component >= 0
    assert np.array_equal(clamped, has_set)
    box = estimation.fused_box[clamped]
    assert np.all(np.isfinite(box)) and np.all(box[:, :, 0] <= box[:, :, 1])
    xy = estimation.after[clamped, :2]
    assert np.all((box[:, :2, 0] <= xy) & (xy <= box[:, :2, 1]))
    np.testing.assert_array_equal(estimation.after[~clamped], estimation.before[~clamped])
    assert np.all(np.isfinite(estimation.pose))


@pytest.mark.parametrize(
    "name",
    [
        name
        for name in builtin_names()
        if name not in TOO_LARGE_FOR_NOW and not load_scenario(name).injected_faults
    ],
)
@pytest.mark.parametrize(
    "seed", [1, 2, *(pytest.param(seed, marks=pytest.mark.slow) for seed in (3, 4, 5))]
)
def test_bounded_errors_and_at_most_q_outliers_keep_the_truth_in_the_set(name, seed):
    spec = load_scenario(name).with_run(seed=seed, duration_s=SHORT_S)
    # seeds 2 and 3 add the ray test (intervals.sonar.rays) to the box test, at q_max 1 and 2
    spec = with_estimation(spec, q_max=1 + seed % 2, ray_test=seed in (2, 3))
    log = simulate_spec(spec)
    bad = with_outliers(log, spec.estimation.intervals.q_max, np.random.default_rng(seed))
    estimation, _ = estimate(spec, bad)
    check_sound(estimation)
    assert estimation_summary(bad, estimation)["containment"] == 1.0
    # the outliers were really used up to the bound at some epochs
    assert estimation.epochs.q_used.max() >= 1


@pytest.mark.parametrize("tracker", ["sivia", "imagesp"])
def test_lost_echoes_without_free_space_stay_sound(tracker):
    spec = load_scenario("hall").with_run(seed=5, duration_s=10.0)
    spec = with_estimation(spec, tracker=tracker, free_space=False, q_max=0)
    sonar = dataclasses.replace(spec.sensors.sonar, lost_echo_prob=0.1)
    spec = dataclasses.replace(spec, sensors=dataclasses.replace(spec.sensors, sonar=sonar))
    log = simulate_spec(spec)
    assert log.sonar_fault.any()  # echoes were lost; as no-echo readings they are ignored
    estimation, _ = estimate(spec, log)
    check_sound(estimation)


def test_more_outliers_than_q_are_reported_never_clamped_and_recovered():
    spec = with_estimation(load_scenario("hall").with_run(seed=4, duration_s=14.0), q_max=1)
    log = simulate_spec(spec)
    # scans 5 and 6: every sensor "sees" a wall at 0.3 m, impossible anywhere in the hall;
    # scan 10: half the belt replaced by random values
    ranges = np.array(log.sonar_range_m)
    ranges[5:7] = 0.3
    bad = with_outliers(
        dataclasses.replace(log, sonar_range_m=ranges), 8, np.random.default_rng(0), scans=[10]
    )
    estimation, _ = estimate(spec, bad)
    status = estimation.epochs.status
    # tracked set empty: inconsistent; the next epoch searches globally and finds nothing
    # (the scan is absurd everywhere): lost; then a global relocalisation and tracking
    assert status[5] == INCONSISTENT and status[6] == LOST
    assert status[7] == GLOBAL and np.all(status[8:10] == TRACKING)
    assert np.all(estimation.component[5:7] == -1) and np.all(estimation.component[7:10] >= 0)
    assert np.all(estimation.epochs.contains_truth[7:10])
    # half the belt wrong at scan 10: more than q_max, so no guarantee there; whatever came
    # of it (detected here), the fusion never used an empty set and tracking resumed
    check_sound_fusion(estimation)
    assert status[10] == INCONSISTENT and status[11] == GLOBAL and np.all(status[12:] == TRACKING)
    assert np.all(estimation.epochs.contains_truth[11:])
    summary = estimation_summary(bad, estimation)
    assert summary["empty_epochs"] == 3 and summary["lost_epochs"] == 1


def test_many_random_outliers_never_crash_nor_clamp_to_nothing():
    spec = load_scenario("hall").with_run(seed=6, duration_s=10.0)
    sonar = dataclasses.replace(spec.sensors.sonar, outlier_prob=0.2)
    spec = with_estimation(
        dataclasses.replace(spec, sensors=dataclasses.replace(spec.sensors, sonar=sonar)), q_max=1
    )
    log = simulate_spec(spec)
    assert (log.sonar_fault.sum(axis=1) > 1).any()  # more outliers than q_max at some scans
    estimation, _ = estimate(spec, log)
    check_sound_fusion(estimation)
    epochs = estimation.epochs
    assert (epochs.status == INCONSISTENT).any()  # some were detected
    # a set that lost the truth can only come after a scan with more than q_max outliers
    # (the guarantee's hypothesis broken there or at an earlier epoch of the same track)
    first_excess = np.argmax(log.sonar_fault.sum(axis=1) > spec.estimation.intervals.q_max)
    assert np.all(epochs.contains_truth[:first_excess])


def test_kidnapping_is_detected_then_relocalised():
    # the estimator alone (steered on the truth, the paper's clamp): in the closed loop the
    # path differs a little, and at this seed the global set after the jump has a second
    # component nearer the stale estimate, so the fused branch lands one epoch later
    loaded = load_scenario("hall").with_run(seed=2, duration_s=16.0)
    spec = dataclasses.replace(loaded, follow=Follow.TRUTH).with_estimation(fusion="clamp")
    jump_s, there = 8.0, (5.0, 6.0, 2.5)
    result = run_scenario(spec, kidnaps=(KidnapEvent(jump_s, there),))
    estimation = result.estimation
    status = check_sound(estimation, expect_consistent=False)
    epoch_t = estimation.epochs.t_s
    at = int(np.searchsorted(epoch_t, jump_s))
    assert np.all(status[1:at] == TRACKING)
    assert status[at] == INCONSISTENT and estimation.component[at] == -1
    assert status[at + 1] == GLOBAL and np.all(status[at + 2 :] == TRACKING)
    assert np.all(estimation.epochs.contains_truth[at + 1 :])  # relocalised at the next scan
    # the fused branch is pulled to the new place at the next epochs; the UKF-only one is not
    truth = result.log.pose[estimation.epoch_index]
    fused_error = np.linalg.norm(estimation.after[at + 1 :, :2] - truth[at + 1 :, :2], axis=1)
    ukf_error = np.linalg.norm(
        estimation.pose[0, estimation.epoch_index[at + 1 :], :2] - truth[at + 1 :, :2], axis=1
    )
    assert fused_error.max() < 0.5 and ukf_error[0] > 4.0 and ukf_error.min() > 1.0
    assert result.summary["empty_epochs"] == 1 and result.summary["lost_epochs"] == 0
    assert result.summary["epoch_status"]["inconsistent"] == 1


def test_the_fused_heading_clamp_keeps_the_heading_in_its_interval():
    spec = with_estimation(
        load_scenario("hall").with_run(seed=3, duration_s=12.0), fusion="clamp_heading"
    )
    log = simulate_spec(spec)
    estimation, _ = estimate(spec, log)
    check_sound(estimation)
    heading = estimation.after[:, 2]
    box = estimation.fused_box[:, 2]
    turns = np.round((heading - 0.5 * (box[:, 0] + box[:, 1])) / (2 * np.pi))
    unwrapped = heading - 2 * np.pi * turns
    assert np.all((box[:, 0] - 1e-12 <= unwrapped) & (unwrapped <= box[:, 1] + 1e-12))
    assert np.array_equal(estimation.pose[FUSED].shape, log.pose.shape)


BAD_ESTIMATION = {
    "tracker": ("tracker = 'kalman'", "estimation.tracker"),
    "q_max": ("q_max = 40", "estimation.q_max"),
    "eps": ("eps_m = -0.1", "estimation.eps_m"),
    "filter": ("filter = 'particle'", "estimation.filter"),
}


@pytest.mark.parametrize("case", sorted(BAD_ESTIMATION))
def test_bad_estimation_settings_exit_2_with_one_line_and_no_output(tmp_path, capsys, case):
    line, key = BAD_ESTIMATION[case]
    scenario = tmp_path / "bad.toml"
    scenario.write_text(f"[robot]\nstart_xy_m = [1.0, 1.0]\n[estimation]\n{line}\n")
    out = tmp_path / "out"
    assert (
        main(["run", str(scenario), "--rrd", str(out / "x.rrd"), "--summary", str(out / "x.json")])
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith(f"robotsim: error: {scenario}: {key}: ") and err.count("\n") == 1
    assert not out.exists()


@pytest.mark.slow
def test_reproduce_ia_fusion_short_run(tmp_path):
    out = tmp_path / "ia"
    assert (
        main(["reproduce", "ia-fusion", "--duration", "25", "--seed", "1", "--out", str(out)]) == 0
    )
    table = json.loads((out / "table.json").read_text())
    for name in (
        "fig7_ukf_only.png",
        "fig8_fused_sivia.png",
        "fig9_fused_imagesp.png",
        "fig10_box_area.png",
        "fig11_error_over_time.png",
        "fig12_epoch_time.png",
        "fig13_zoomed_epoch.png",
    ):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    text = (out / "table.md").read_text()
    assert "| sivia |" in text and "| imagesp |" in text
    rows = table["trackers"]
    for row in rows.values():
        assert row["containment"] == 1.0 and row["fused_in_box"]
        assert row["rmse_position_m"]["fused"] < row["rmse_position_m"]["ukf_only"]
    assert rows["imagesp"]["box"]["mean_area_m2"] < rows["sivia"]["box"]["mean_area_m2"]
    # the paper's claims as the reproduction judged them (timing left out: a shared machine)
    claims = {k: v for k, v in table["claims"].items() if "slower" not in k}
    assert all(claims.values()), claims
    assert "## Against the paper" in text and "| sonar range limit (m) | 3 | 3 |" in text


def test_a_broken_guarantee_is_named_only_when_the_sonar_has_no_faults():
    from scenarios.commands import guarantee_failure
    from scenarios.reproduce.ia_fusion import missed_guarantee

    spec = load_scenario("hall")
    assert spec.sensors.sonar.outlier_prob == 0.0 and spec.sensors.sonar.lost_echo_prob == 0.0

    def summary(containment):  # the figures guarantee_failure reads, no empty epoch
        status = {"inconsistent": 0, "lost": 0}
        return {"containment": containment, "empty_epochs": 0, "epoch_status": status}

    failure = guarantee_failure(spec, summary(0.96))
    assert "containment 0.96" in failure and spec.source in failure
    assert guarantee_failure(spec, summary(1.0)) is None
    assert guarantee_failure(spec, summary(None)) is None  # no epoch at all: nothing to judge
    without_free_space = spec.with_estimation(free_space=False)  # unsound with lost echoes
    for fault in ("outlier_prob", "lost_echo_prob"):
        faulty = dataclasses.replace(
            without_free_space,
            sensors=dataclasses.replace(
                spec.sensors, sonar=dataclasses.replace(spec.sensors.sonar, **{fault: 0.1})
            ),
        )
        assert guarantee_failure(faulty, summary(0.96)) is None, fault
    rows = {"sivia": {"containment": 1.0}, "imagesp": {"containment": 0.5}}
    assert missed_guarantee(rows) == "imagesp containment 0.5"
    assert missed_guarantee({"sivia": {"containment": 1.0}}) == ""


@pytest.mark.parametrize(
    "experiment", ["iukf-examples", "mukf-example", "motion-models", "ia-fusion"]
)
def test_every_reproduction_refuses_a_negative_seed_in_one_line(tmp_path, capsys, experiment):
    out = tmp_path / "out"
    assert main(["reproduce", experiment, "--seed", "-1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith("robotsim: error: ")
        and "--seed: must be >= 0, got -1" in err
        and err.count("\n") == 1
    )
    assert not out.exists()


def test_every_reproduction_writes_under_runs_reproduce_by_default():
    import argparse
    from pathlib import Path

    from scenarios.reproduce import experiments

    found = experiments()
    assert set(found) == {
        "iukf-examples",
        "mukf-example",
        "motion-models",
        "ia-fusion",
        "estimators",
    }
    for name, module in found.items():
        parser = argparse.ArgumentParser()
        module.add_arguments(parser)
        assert Path(parser.parse_args([]).out) == Path("runs/reproduce") / name, name
