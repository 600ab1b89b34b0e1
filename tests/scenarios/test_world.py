"""A world that differs from the map, declared in the scenario file: ``[world] obstacles``
and ``sonar_failure`` events, validated like every key; the run reports where the data
contradict the map, never clamps to an empty set, and times the recovery."""

from __future__ import annotations

import numpy as np
import pytest

from robotsim.maps import point_segment_distance
from robotsim.sensors.sonar import cone_distances
from scenarios.commands import guarantee_failure
from scenarios.errors import ScenarioError
from scenarios.metrics import set_wall_distance_m
from scenarios.pipeline import FUSED, RECOVERY_DISTANCE_M, RECOVERY_HOLD_S, localizer_for
from scenarios.runner import run_scenario
from scenarios.spec import BUILTIN_FOLDER, parse_scenario

#: A sofa the map lacks along the hall's south wall, beside the route's first leg (y = 1):
#: the sonars facing south read it, 0.35 m short of the wall, and a pose 0.35 m further
#: north explains most of the scan.
SOFA = """
[[world.obstacles]]
polygon_m = [[3.0, 0.05], [7.0, 0.05], [7.0, 0.4], [3.0, 0.4]]
"""


def hall_with(extra: str, duration_s: float = 60.0) -> str:
    text = (BUILTIN_FOLDER / "hall.toml").read_text()
    return text.replace("duration_s = 600.0", f"duration_s = {duration_s}") + extra


def refused(extra: str) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(hall_with(extra), source="w.toml")
    assert info.value.source == "w.toml"
    return info.value


BAD_WORLD = {
    "self-intersecting": (
        "polygon_m = [[4, 4], [5, 5], [5, 4], [4, 5]]",
        "world.obstacles[0].polygon_m",
        "not simple",
    ),
    "degenerate": (
        "polygon_m = [[4, 4], [5, 4], [5, 4], [4, 5]]",
        "world.obstacles[0].polygon_m",
        "degenerate",
    ),
    "two vertices": ("polygon_m = [[4, 4], [5, 4]]", "world.obstacles[0].polygon_m", "3 vertices"),
    "non-finite": (
        "polygon_m = [[4, 4], [nan, 4], [4, 5]]",
        "world.obstacles[0].polygon_m[1][0]",
        "finite",
    ),
    "zero-length segment": (
        "segment_m = [[4, 4], [4, 4]]",
        "world.obstacles[0].segment_m",
        "zero length",
    ),
    "outside the hall": (
        "polygon_m = [[9.5, 4], [10.5, 4], [10.5, 5], [9.5, 5]]",
        "world.obstacles[0].polygon_m",
        "outside",
    ),
    "on the start": (
        "polygon_m = [[0.8, 0.9], [1.2, 0.9], [1.2, 1.3], [0.8, 1.3]]",
        "world.obstacles[0].polygon_m",
        "start footprint",
    ),
    "walks out of the hall": (
        "polygon_m = [[8, 4], [8.4, 4], [8.4, 4.4], [8, 4.4]]\npath_m = [[11, 4.2]]",
        "world.obstacles[0].path_m",
        "moves outside",
    ),
    "walks through a landmark": (
        "polygon_m = [[5, 5.8], [5.4, 5.8], [5.4, 6.2], [5, 6.2]]\npath_m = [[7, 6.0]]",
        "world.obstacles[0].path_m",
        "crosses wall segment",
    ),
    "loops without a path": (
        "polygon_m = [[4, 4], [5, 4], [5, 5]]\nloop = true",
        "world.obstacles[0].loop",
        "needs a path",
    ),
    "both shapes": (
        "polygon_m = [[4, 4], [5, 4], [5, 5]]\nsegment_m = [[4, 4], [5, 5]]",
        "world.obstacles[0].segment_m",
        "exactly one",
    ),
    "no shape": ("speed_m_s = 1.0", "world.obstacles[0].polygon_m", "exactly one"),
    "speed zero": (
        "polygon_m = [[4, 4], [5, 4], [5, 5]]\npath_m = [[6, 5]]\nspeed_m_s = 0",
        "world.obstacles[0].speed_m_s",
        "> 0",
    ),
    "unknown key": (
        "polygon_m = [[4, 4], [5, 4], [5, 5]]\nheight_m = 1",
        "world.obstacles[0].height_m",
        "unknown key",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_WORLD))
def test_bad_obstacles_are_refused_naming_file_and_key(case):
    body, key, reason = BAD_WORLD[case]
    error = refused(f"\n[[world.obstacles]]\n{body}\n")
    assert error.key == key and reason in error.reason


def test_a_kidnap_into_an_obstacle_is_refused_at_its_time():
    walker = "\n[[world.obstacles]]\npolygon_m = [[4, 4], [4.4, 4], [4.4, 4.4], [4, 4.4]]\npath_m = [[8, 4.2]]\n"
    kidnap = '\n[[events]]\nkind = "kidnap"\nt_s = {t}\nxy_m = [6.2, 4.2]\n'
    parse_scenario(hall_with(walker + kidnap.format(t=1.0)), source="w.toml")  # not there yet
    error = refused(walker + kidnap.format(t=2.0))  # the walker is at x = 6.2 at 2 s
    assert error.key == "events[0].xy_m" and "overlaps an obstacle at t = 2" in error.reason


BAD_FAILURES = {
    "sensor off the belt": (
        "sensors = [3, 16]",
        "events[0].sensors",
        "sensor 16 is not on the belt",
    ),
    "sensor named twice": ("sensors = [3, 3]", "events[0].sensors", "twice"),
    "sensors not integers": ('sensors = "front"', "events[0].sensors", '"all" or'),
    "empty sensors": ("sensors = []", "events[0].sensors", '"all" or'),
    "no duration": ("", "events[0].duration_s", "required"),
    "zero duration": ("duration_s = 0.0", "events[0].duration_s", "> 0"),
    "reading beyond the range": ("reading_m = 3.5", "events[0].reading_m", "<= 3"),
    "a kidnap's key": ("xy_m = [5, 5]", "events[0].xy_m", "unknown key"),
}


@pytest.mark.parametrize("case", sorted(BAD_FAILURES))
def test_bad_sonar_failures_are_refused_naming_file_and_key(case):
    body, key, reason = BAD_FAILURES[case]
    if "duration" not in body and case != "no duration":
        body += "\nduration_s = 5.0"
    error = refused(f'\n[[events]]\nkind = "sonar_failure"\nt_s = 10.0\n{body}\n')
    assert error.key == key and reason in error.reason


def direct_recovery_s(error_m: np.ndarray, start: int, rate_hz: float) -> float | None:
    """The first sample from ``start`` after which the error stays within the distance for
    the hold time, one candidate at a time (test_events.py's reading)."""
    hold = round(RECOVERY_HOLD_S * rate_hz)
    for k in range(start, len(error_m) - hold + 1):
        if np.all(error_m[k : k + hold] <= RECOVERY_DISTANCE_M):
            return (k - start) / rate_hz
    return None


def check_never_clamped_without_a_set(estimation) -> None:
    """Every epoch without a set left the fused branch alone; every clamp used a real box."""
    epochs = estimation.epochs
    clamped = estimation.component >= 0
    np.testing.assert_array_equal(clamped, epochs.has_set)
    np.testing.assert_array_equal(estimation.after[~clamped], estimation.before[~clamped])
    box = estimation.fused_box[clamped]
    assert np.isfinite(box).all() and (box[:, :, 0] <= box[:, :, 1]).all()
    assert np.isfinite(estimation.pose).all()


@pytest.mark.slow
def test_an_unmapped_sofa_fools_the_sonar_and_the_run_says_so():
    spec = parse_scenario(hall_with(SOFA), source="sofa.toml")
    # the estimator's map is the hall's alone
    localizer = localizer_for(spec)
    np.testing.assert_array_equal(localizer.map_segments, spec.map.segments)
    run = run_scenario(spec)
    summary, estimation, log = run.summary, run.estimation, run.log
    # the sonar saw the sofa: shorter true ranges than the map alone gives, never longer
    belt = spec.sensors.sonar
    bare = cone_distances(
        log.sonar_pose,
        spec.map.segments,
        belt.mount_xy,
        belt.mount_angle_rad,
        belt.half_aperture_rad,
    )
    seen = log.sonar_true_range_m
    assert (seen <= bare).all() and (seen < bare - 0.3).sum() >= 10
    check_never_clamped_without_a_set(estimation)
    epochs = estimation.epochs
    # the data contradict the map: outliers used, epochs with no set at all
    assert summary["q_used_epochs"] == int((epochs.q_used > 0).sum()) >= 3
    assert summary["inconsistent_epochs"] >= 1
    # and where the sofa fits a wrong pose, the set misses the truth: containment broken,
    # computed from the boxes and the true poses here
    held = [
        bool(np.all((b[:, :, 0] <= p) & (p <= b[:, :, 1]), axis=1).any())
        for b, p in (
            (epochs.epoch_boxes(e), log.pose[estimation.epoch_index[e]])
            for e in np.flatnonzero(epochs.has_set)
        )
    ]
    assert summary["containment"] == pytest.approx(np.mean(held)) and summary["containment"] < 1.0
    assert summary["walls"]["obstacle_contact_steps"] == 0


@pytest.mark.slow
def test_a_silent_sonar_belt_is_reported_and_its_recovery_timed():
    failure = '\n[[events]]\nkind = "sonar_failure"\nt_s = 20.0\nduration_s = 10.0\n'
    spec = parse_scenario(hall_with(failure), source="f.toml")
    (declared,) = spec.sonar_failures
    assert (declared.start_s, declared.end_s, declared.sensors) == (20.0, 30.0, tuple(range(16)))
    run = run_scenario(spec)
    summary, estimation, log = run.summary, run.estimation, run.log
    window = (log.sonar_t_s >= 20.0) & (log.sonar_t_s < 30.0)
    assert np.isinf(log.sonar_range_m[window]).all() and window.sum() == 10
    assert log.sonar_fault[window].all() and not log.sonar_fault[~window].any()
    # no echo anywhere claims free space to 3 m (free_space is on): the tracked set is
    # contradicted at once, and the global search then finds the hall's open middle, which
    # is not where the robot is; the run reports both, and clamps to no empty set
    epochs = estimation.epochs
    first = int(np.argmax(window))
    assert not epochs.has_set[first] and summary["inconsistent_epochs"] >= 1
    assert not epochs.contains_truth[window].all() and summary["containment"] < 1.0
    check_never_clamped_without_a_set(estimation)
    (reported,) = summary["sonar_failures"]
    assert reported["start_s"] == 20.0 and reported["end_s"] == 30.0
    error = np.linalg.norm(estimation.pose[FUSED, :, :2] - log.pose[:, :2], axis=1)
    assert error[2000:3000].max() > 1.0  # the estimate was led away
    assert reported["recovery_s"] == direct_recovery_s(error, 2000, log.rate_hz) > 0.0
    # told that a missing echo proves nothing, the localiser keeps the truth throughout
    cautious = run_scenario(
        parse_scenario(hall_with(failure + "\n[estimation]\nfree_space = false\n"), source="f.toml")
    )
    assert cautious.summary["containment"] == 1.0
    assert cautious.summary["sonar_failures"][0]["recovery_s"] == 0.0


def test_a_few_stuck_sonars_within_q_max_keep_the_guarantee():
    # one sonar stuck at 0.3 m for 20 s: one outlier a scan, within q_max = 1
    failure = '\n[[events]]\nkind = "sonar_failure"\nt_s = 10.0\nduration_s = 20.0\nsensors = [4]\nreading_m = 0.3\n'
    run = run_scenario(parse_scenario(hall_with(failure, duration_s=40.0), source="f.toml"))
    window = (run.log.sonar_t_s >= 10.0) & (run.log.sonar_t_s < 30.0)
    assert (run.log.sonar_range_m[window, 4] == 0.3).all()
    assert run.summary["containment"] == 1.0 and run.summary["empty_epochs"] == 0
    assert (run.estimation.epochs.q_used[window] >= 1).all()  # the stuck reading was used up
    (reported,) = run.summary["sonar_failures"]
    assert reported["recovery_s"] == 0.0  # the estimate never left the truth


def box_segment_distance(box: np.ndarray, segments: np.ndarray) -> float:
    """Distance from the rectangle ``box (2, 2)`` to the segments ``(m, 2, 2)``: 0 when one
    crosses or enters it, else the least of the corner-to-segment and end-to-rectangle
    distances (the nearest pair of points has one at a corner or at an end point)."""
    lo, hi = box[:, 0], box[:, 1]
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    a, b = segments[:, 0], segments[:, 1]
    t = np.linspace(0.0, 1.0, 2001)[:, None, None]
    dense = a + t * (b - a)  # points along each segment, for the crossing test
    inside = np.all((lo <= dense) & (dense <= hi), axis=-1).any()
    if inside:
        return 0.0
    to_corner = point_segment_distance(corners[:, None, :], a, b).min()
    ends = np.concatenate([a, b])
    to_end = np.linalg.norm(np.maximum(np.maximum(lo - ends, ends - hi), 0.0), axis=1).min()
    return float(min(to_corner, to_end))


def test_the_safety_share_against_a_direct_computation():
    margin = 0.6  # wide enough that the route's passes by the landmarks count
    text = hall_with("", duration_s=40.0).replace(
        "loop = true", f"loop = true\nsafety_margin_m = {margin}"
    )
    spec = parse_scenario(text, source="s.toml")
    run = run_scenario(spec)
    log, estimation, safety = run.log, run.estimation, run.summary["safety"]
    segments, reach = spec.map.segments, spec.robot.radius_m + log.world.wall_radius_m
    epochs = estimation.epochs
    clear = np.zeros(len(epochs.t_s), dtype=bool)
    for e in np.flatnonzero(epochs.has_set):  # the whole set beyond the margin
        boxes = epochs.epoch_boxes(e)[:, :2]
        clear[e] = min(box_segment_distance(box, segments) for box in boxes) - reach > margin
    inside = np.zeros(len(log.t_s), dtype=bool)
    said_clear = np.zeros(len(log.t_s), dtype=bool)
    for k, xy in enumerate(log.pose[:, :2]):
        inside[k] = (
            point_segment_distance(xy, segments[:, 0], segments[:, 1]).min() - reach < margin
        )
        earlier = np.flatnonzero(estimation.epoch_index <= k)
        said_clear[k] = bool(earlier.size) and clear[earlier[-1]]
    assert safety["margin_m"] == margin
    assert 0.0 < safety["inside_margin_share"] == pytest.approx(inside.mean())
    assert 0.0 < safety["set_clear_share"] == pytest.approx(said_clear.mean())
    assert safety["inside_margin_while_set_clear_share"] == pytest.approx(
        (inside & said_clear).mean()
    )
    # the sets held the truth at every epoch: at an epoch sample, never inside while clear
    at_epochs = estimation.epoch_index
    assert not (inside[at_epochs] & said_clear[at_epochs]).any()


def test_the_set_wall_distance_does_not_depend_on_its_block_size():
    spec = parse_scenario(hall_with("", duration_s=10.0), source="s.toml")
    epochs = run_scenario(spec).estimation.epochs
    segments = spec.map.segments
    whole = set_wall_distance_m(epochs, segments, block_boxes=len(epochs.boxes))
    assert len(epochs.boxes) > 50 and np.isfinite(whole).sum() > 5
    for block in (1, 7, 50):  # blocks that split epochs' sets, and a short last block
        np.testing.assert_array_equal(set_wall_distance_m(epochs, segments, block), whole)


def test_a_declared_fault_is_not_reported_as_a_broken_guarantee():
    broken = {
        "containment": 0.9,
        "empty_epochs": 2,
        "epoch_status": {"inconsistent": 2, "lost": 0},
    }
    plain = parse_scenario(hall_with(""), source="plain.toml")
    assert plain.injected_faults == ()
    assert "the guarantee failed" in guarantee_failure(plain, broken)
    sofa = parse_scenario(hall_with(SOFA), source="sofa.toml")
    assert sofa.injected_faults == ("world.obstacles",)
    assert guarantee_failure(sofa, broken) is None
    failure = '\n[[events]]\nkind = "sonar_failure"\nt_s = 5.0\nduration_s = 1.0\n'
    silent = parse_scenario(hall_with(failure), source="f.toml")
    assert silent.injected_faults == ("events sonar_failure",)
    assert guarantee_failure(silent, broken) is None


@pytest.mark.parametrize(
    ("line", "key", "reason"),
    [
        ("control_rate_hz = 30.0", "route.control_rate_hz", "whole number"),
        ("control_rate_hz = 200.0", "route.control_rate_hz", "whole number"),
        ("control_rate_hz = 0.0", "route.control_rate_hz", "> 0"),
        ("safety_margin_m = -0.1", "route.safety_margin_m", ">= 0"),
        ("follow = 'map'", "route.follow", "one of"),
    ],
)
def test_bad_closed_loop_keys_are_refused(line, key, reason):
    text = hall_with("").replace("loop = true", f"loop = true\n{line}")
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, source="r.toml")
    assert info.value.key == key and reason in info.value.reason


def test_the_closed_loop_defaults():
    spec = parse_scenario(hall_with(""), source="r.toml")
    assert spec.follow == "estimate" and spec.estimation.fusion == "truncated_heading"
    assert spec.control_rate_hz == 10.0 and spec.control_stride == 10
    truth = parse_scenario(
        hall_with("").replace("loop = true", "loop = true\nfollow = 'truth'"), source="r.toml"
    )
    assert truth.estimation.fusion == "clamp" and truth.control_stride == 1
