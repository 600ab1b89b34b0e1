"""The budget (``max_boxes``): a paving that would exceed it stays under it, is reported
coarse, and keeps every consistent pose (checked against poses sampled and tested with the
simulator's exact cone model, independent of the interval tests)."""

import numpy as np
import pytest

from intervals import localize as localize_module
from intervals.imagesp import coarsen
from intervals.localize import TESTS_PER_BOX, gomne
from intervals.sonar.scan import ECHO, FREE, SonarBelt, SonarScan
from intervals.tracker import IntervalTracker, TrackerSettings
from robotsim.maps import builtin_map
from tests.helpers import (
    DEFAULT_BELT,
    bounded_readings,
    circuit_poses,
    cone_ranges,
    random_room,
    random_scan_case,
)

pytestmark = pytest.mark.slow  # global searches under a budget, checked by brute-force sampling


def _consistent_poses(scan: SonarScan, segments, centre, half, q, rng, count=1500):
    """Poses of the box ``centre -+ half`` that leave at most ``q`` readings unexplained by the
    exact cone model (``robotsim.sensors.sonar.cone_distances``), sampled uniformly."""
    poses = rng.uniform(centre - half, centre + half, size=(count, 3))
    poses[:, 2] = np.mod(poses[:, 2] + np.pi, 2 * np.pi) - np.pi  # headings as the sets hold them
    d = cone_ranges(poses, segments)  # (count, k)
    lo, hi = scan.ranges[:, 0], scan.ranges[:, 1]
    echo_bad = (scan.kind == ECHO) & ~((d >= lo) & (d <= hi))
    free_bad = (scan.kind == FREE) & ~(d > scan.belt.d_max_m)
    return poses[np.count_nonzero(echo_bad | free_bad, axis=1) <= q]


class _CountingTest:
    """Wraps ``intervals.localize.sensor_verdicts`` to record the boxes of each call."""

    def __init__(self, monkeypatch):
        self.calls: list[int] = []
        real = localize_module.sensor_verdicts

        def counted(boxes, *args, **kwargs):
            self.calls.append(len(boxes))
            return real(boxes, *args, **kwargs)

        monkeypatch.setattr(localize_module, "sensor_verdicts", counted)


@pytest.mark.parametrize("echoes_never_lost", [True, False])
def test_a_global_search_over_budget_stays_under_it_and_keeps_the_consistent_poses(
    monkeypatch, echoes_never_lost
):
    """30 random rooms, poses and bounded noise (often at the bounds), a global search at
    eps 0.05 m with q_max 1 under budgets of 16 to 400 boxes (an unbudgeted search tests
    thousands): the set holds at most ``max_boxes`` boxes, no test call sees more, at most
    ``TESTS_PER_BOX * max_boxes`` boxes are tested by SIVIA, as many again when the boxes it
    left are retested and ``max_boxes`` when they are merged, the set is coarse, and every
    consistent pose sampled near the truth, the truth included, is in it."""
    rng = np.random.default_rng(21 if echoes_never_lost else 22)
    belt = SonarBelt.from_params(DEFAULT_BELT, echoes_never_lost=echoes_never_lost)
    counting = _CountingTest(monkeypatch)
    checked, coarse = 0, 0
    for trial in range(30):
        segments, outer = random_room(rng)
        truth = np.array([*rng.uniform(1.0, 9.0, size=2), rng.uniform(-np.pi, np.pi)])
        readings = bounded_readings(cone_ranges(truth[None], segments)[0], DEFAULT_BELT, rng)
        scan = SonarScan(segments, belt, readings, outer)
        max_boxes = int((16, 50, 400)[trial % 3])
        counting.calls.clear()
        result = gomne(  # without the contractor, whose smaller sets seldom reach the budget
            scan,
            np.array([[0, 10], [0, 10], [-np.pi, np.pi]]),
            0.05,
            1,
            max_boxes=max_boxes,
            contract=False,
        )
        assert result.consistent  # the truth leaves no reading unexplained
        paving = result.paving
        assert paving.outer.shape[0] <= max_boxes
        assert max(counting.calls) <= max_boxes
        assert sum(counting.calls) <= 2 * TESTS_PER_BOX * max_boxes + max_boxes
        coarse += paving.coarse
        poses = _consistent_poses(scan, segments, truth, np.array([0.1, 0.1, 0.05]), 1, rng)
        poses = np.concatenate([truth[None], poses])
        assert paving.contains(poses).all()
        checked += len(poses)
    assert coarse >= 20 and checked > 30 * 20  # the budget bit, and the check is not vacuous


def test_tracker_over_budget_reports_coarse_epochs_and_keeps_the_truth():
    """The hall circuit with half the echoes lost (no free space then; unbudgeted, these sets
    reach millions of boxes and a minute an epoch) under budgets of 24 and 200 boxes: every
    epoch keeps the truth within the budget and coarse epochs are reported; with every echo
    kept and a budget of 100 000 boxes no epoch is coarse (the flag is not raised for
    nothing; the default 10 000 cuts one of these epochs, which tests 204 000 boxes)."""
    hall = builtin_map("hall")
    rng = np.random.default_rng(9)
    poses = circuit_poses(20)
    cases = []
    for lost in (0.5, 0.0):
        belt = SonarBelt.from_params(DEFAULT_BELT, echoes_never_lost=lost == 0.0)
        scans = []
        for truth in poses:
            m = bounded_readings(cone_ranges(truth[None], hall.segments)[0], DEFAULT_BELT, rng)
            m[rng.random(m.shape) < lost] = np.inf  # lost echoes
            scans.append(SonarScan(hall.segments, belt, m, hall.boundary))
        budgets = (24, 200) if lost else (100_000,)
        cases.extend((scans, max_boxes, lost > 0) for max_boxes in budgets)
    for kind in ("sivia", "imagesp"):
        for scans, max_boxes, expect_coarse in cases:
            settings = TrackerSettings(
                v_max_m_s=0.5, omega_max_rad_s=0.5, tracker=kind, max_boxes=max_boxes
            )
            tracker, previous, coarse = IntervalTracker(settings, hall.bounds), None, 0
            for truth, scan in zip(poses, scans, strict=True):
                result = tracker.step(previous, scan, 1.0)
                assert result.consistent and result.paving.contains(truth[None])[0]
                assert result.outer.shape[0] <= max_boxes
                assert result.coarse == result.paving.coarse
                coarse += result.coarse
                previous = result.paving
            assert (coarse > 0) == expect_coarse


def test_coarsen_covers_with_fewer_disjoint_boxes():
    """Random box sets merged into at most M boxes: points of the input boxes are covered, the
    cells do not overlap, and a set already small enough is returned as it is."""
    rng = np.random.default_rng(4)
    for _ in range(100):
        n = int(rng.integers(2, 3000))
        lo = rng.uniform(-5, 5, size=(n, 3))
        boxes = np.stack([lo, lo + rng.uniform(0, 0.2, size=(n, 3))], axis=-1)
        limit = int(rng.integers(1, 500))
        merged = coarsen(boxes, limit, np.array([1.0, 1.0, 2.0]))
        assert merged.shape[0] <= max(limit, 1)
        points = rng.uniform(boxes[..., 0], boxes[..., 1])
        inside = np.all(
            (merged[None, :, :, 0] <= points[:, None]) & (points[:, None] <= merged[None, :, :, 1]),
            axis=-1,
        )
        assert inside.any(axis=1).all()
        if merged.shape[0] > 1:  # regular cells: interiors disjoint
            centre = (merged[..., 0] + merged[..., 1]) / 2
            holding = np.all(
                (merged[None, :, :, 0] < centre[:, None])
                & (centre[:, None] < merged[None, :, :, 1]),
                axis=-1,
            )
            assert (holding.sum(axis=1) == 1).all()
    few = rng.uniform(0, 1, size=(5, 3, 2))
    assert coarsen(few, 5) is few


def test_budget_with_the_ray_test_keeps_the_truth():
    """Thin cones (the ray test joins the cone test) under budgets of 16 and 100 boxes: the
    coarse sets, retested with both tests, hold the truth and stay under the budget."""
    rng = np.random.default_rng(13)
    for trial in range(16):
        scan, _, truth = random_scan_case(rng, 0.02, echoes_never_lost=trial % 2 == 0)
        half = np.array([0.8, 0.8, 0.4])
        prior = np.stack([truth - half, truth + half], axis=-1)
        max_boxes = (16, 100)[trial % 2]
        result = gomne(scan, prior, 0.02, 1, ray_test=True, max_boxes=max_boxes)
        assert result.consistent and result.paving.contains(truth[None])[0]
        assert result.paving.outer.shape[0] <= max_boxes


def test_a_coarse_epoch_is_refined_back_to_eps_on_a_repetitive_plan():
    """The office floor of twin rooms (``office``) under a budget of 200 boxes (4000 tests an
    epoch; its global search needs about 20 000): the first epoch is coarse, its set spanning
    most of the floor; the next epochs refine it on its own scan (:class:`Refinement`) until
    the set is fine again, as small as without a budget, and every epoch keeps the truth
    within the budget (the regression of office_floor, where every epoch stayed coarse)."""
    import dataclasses

    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario("office").with_run(duration_s=16.0)
    # without the contractor: with it the global search of office fits in 200 boxes and
    # the epoch is not coarse, so the refinement would go untested
    budget = dataclasses.replace(spec.estimation.intervals, max_boxes=200, contractor=False)
    spec = dataclasses.replace(
        spec, estimation=dataclasses.replace(spec.estimation, intervals=budget)
    )
    epochs = run_scenario(spec).estimation.epochs
    assert epochs.contains_truth.all()
    assert (epochs.box_counts <= 200).all()
    assert epochs.coarse[0] and epochs.area_m2[0] > 50.0  # cut short: most of the 96 m^2 floor
    fine = np.flatnonzero(~epochs.coarse)
    assert fine.size and fine[0] <= 12  # refined back within a dozen epochs
    assert not epochs.coarse[fine[0] :].any()  # and it stays fine
    assert epochs.area_m2[fine[0] :].max() < 0.5  # as tight as unbudgeted tracking (0.01-0.05)


@pytest.mark.parametrize("contractor", [False, True])
def test_corridor_epochs_hold_a_sound_strip_in_few_boxes(contractor):
    """The 30 m corridor, ambiguous along its axis: every epoch of a 30 s run keeps the
    truth, and its set is reported in at most 400 boxes, never coarse. Without the
    contractor the set is a strip of up to about 1.5 m^2 (hundreds of ``eps`` cells) held in
    fewer boxes than cells (adjacent boxes joined exactly: 3300 before); the contractor
    shrinks the strip itself (0.2 m^2 at most)."""
    import dataclasses

    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario("corridor").with_run(duration_s=30.0)
    intervals = dataclasses.replace(spec.estimation.intervals, contractor=contractor)
    spec = dataclasses.replace(
        spec, estimation=dataclasses.replace(spec.estimation, intervals=intervals)
    )
    epochs = run_scenario(spec).estimation.epochs
    assert epochs.contains_truth.all() and not epochs.coarse.any()
    assert epochs.box_counts.max() <= 400
    if contractor:
        return
    assert epochs.area_m2.max() > 0.5  # a strip, not a point
    assert epochs.box_counts.max() <= 400
    cells = epochs.area_m2 / 0.05**2  # the eps cells the strip's area holds, at least
    assert (epochs.box_counts < cells).sum() > len(cells) / 2


def test_lost_echo_tracking_epochs_stay_within_their_budget_and_keep_the_reachable_poses(
    monkeypatch,
):
    """big_hall (60 x 60 m, the sonar's 3 m out of reach of most of it) with half the echoes
    lost, 6 random walks of 8 epochs from random poses 1.5 to 2.5 m from the south or the west
    wall, readings at their error bounds, each epoch handed the previous one's refinement as
    the pipeline does: no tracking epoch hands one on (the global search's, continued by the
    first tracking epoch under the full budget, is the only one); every later
    tracking search tests at most ``LOST_ECHO_TRACKING_TESTS`` boxes in SIVIA and as many again
    in the retest of the boxes it left (with the 40 000 of a belt that never loses its
    echoes, tens of thousands), an epoch whose search was cut short is reported coarse, and every
    pose reachable from the previous true pose within the robot's limits that the exact cone
    model finds consistent with the scan (at most ``q_max`` readings unexplained), the truth
    among them, is in the set."""
    from intervals import tracker as tracker_module
    from intervals.tracker import LOST_ECHO_TRACKING_TESTS
    from scenarios.spec import load_scenario

    hall = load_scenario("big_hall").map
    rng = np.random.default_rng(30)
    belt = SonarBelt.from_params(DEFAULT_BELT, echoes_never_lost=False)
    counting = _CountingTest(monkeypatch)
    searches: list[tuple[int, bool]] = []  # (boxes tested, cut short) of each search
    real_gomne = tracker_module.gomne

    def counted_gomne(*args, **kwargs):
        before = sum(counting.calls)
        found = real_gomne(*args, **kwargs)
        searches.append((sum(counting.calls) - before, found.paving.coarse))
        return found

    monkeypatch.setattr(tracker_module, "gomne", counted_gomne)
    settings = TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=0.5)
    reach = np.array([0.5, 0.5, 0.5])
    tracker = IntervalTracker(settings, hall.bounds)
    coarse, checked = 0, 0
    for _ in range(6):
        # within the sonar's reach of one wall (along which the sets are strips and shells)
        truth = np.array(
            [rng.uniform(2.0, 58.0), rng.uniform(1.5, 2.5), rng.uniform(-np.pi, np.pi)]
        )
        if rng.random() < 0.5:
            truth[:2] = truth[1::-1]
        previous, refinement = None, None
        for _ in range(8):
            last = truth
            if previous is not None:  # a move within the limits, inside the hall
                truth = last + rng.uniform(-0.9, 0.9, size=3) * reach
                truth[:2] = np.clip(truth[:2], 1.0, 59.0)
                truth[2] = np.mod(truth[2] + np.pi, 2 * np.pi) - np.pi
            m = bounded_readings(cone_ranges(truth[None], hall.segments)[0], DEFAULT_BELT, rng)
            m[rng.random(m.shape) < 0.5] = np.inf  # lost echoes
            scan = SonarScan(hall.segments, belt, m, hall.boundary)
            searches.clear()
            result = tracker.step(previous, scan, 1.0, refinement)
            assert result.consistent and result.paving.contains(truth[None])[0]
            if previous is not None:
                assert result.status == "tracking" and result.refinement is None
                if refinement is None:
                    assert all(tests <= 2 * LOST_ECHO_TRACKING_TESTS for tests, _ in searches)
                assert result.coarse or not searches[-1][1]
                coarse += result.coarse
                poses = _consistent_poses(scan, hall.segments, last, reach, 1, rng, count=400)
                poses = poses[(poses[:, :2] > 0.5).all(axis=1) & (poses[:, :2] < 59.5).all(axis=1)]
                assert result.paving.contains(poses).all()
                checked += len(poses)
            previous, refinement = result.paving, result.refinement
    assert coarse >= 10 and checked > 1000  # the budget bit, and the check is not vacuous


def test_lost_echo_global_search_and_scans_without_constraint_keep_the_reachable_poses(
    monkeypatch,
):
    """big_hall with half the echoes lost, 8 random poses 1.5 to 2.5 m from a wall, readings
    at their error bounds: the global search paves at ``LOST_ECHO_GLOBAL_EPS_M`` (not
    ``eps_m``), holds the truth and every consistent pose sampled near it, and hands its
    report on as a refinement; then, on a scan left with at most ``q_max`` echoes (which
    rejects no pose), the tracking epoch handed that refinement paves at most
    ``LOST_ECHO_PREDICTED_BOXES`` boxes, tests at most ``LOST_ECHO_TRACKING_TESTS`` boxes and
    as many again in its retest (not the full budget of a refinement's chain: no budget splits
    what the sonar does not constrain), hands no refinement on, and every pose reachable from
    the set within the robot's limits (sampled in its boxes) that lies in the hall, the truth
    among them, is in its set."""
    from intervals import tracker as tracker_module
    from intervals.tracker import (
        LOST_ECHO_GLOBAL_EPS_M,
        LOST_ECHO_PREDICTED_BOXES,
        LOST_ECHO_TRACKING_TESTS,
    )
    from scenarios.spec import load_scenario

    hall = load_scenario("big_hall").map
    rng = np.random.default_rng(31)
    belt = SonarBelt.from_params(DEFAULT_BELT, echoes_never_lost=False)
    counting = _CountingTest(monkeypatch)
    searches: list[tuple[float, int]] = []  # (eps, initial boxes) of each search
    real_gomne = tracker_module.gomne

    def recorded_gomne(scan, initial, eps, *args, **kwargs):
        searches.append((eps, np.asarray(initial).reshape(-1, 3, 2).shape[0]))
        return real_gomne(scan, initial, eps, *args, **kwargs)

    monkeypatch.setattr(tracker_module, "gomne", recorded_gomne)
    settings = TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=0.5)
    reach = np.array([0.5, 0.5, 0.5])
    tracker = IntervalTracker(settings, hall.bounds)
    assert settings.eps_m < LOST_ECHO_GLOBAL_EPS_M  # else the first check is vacuous
    checked = 0
    for _ in range(8):
        truth = np.array(
            [rng.uniform(2.0, 58.0), rng.uniform(1.5, 2.5), rng.uniform(-np.pi, np.pi)]
        )
        if rng.random() < 0.5:
            truth[:2] = truth[1::-1]
        m = bounded_readings(cone_ranges(truth[None], hall.segments)[0], DEFAULT_BELT, rng)
        m[rng.random(m.shape) < 0.5] = np.inf  # lost echoes
        searches.clear()
        found = tracker.step(None, SonarScan(hall.segments, belt, m, hall.boundary), 1.0)
        assert found.status == "global" and searches[0][0] == LOST_ECHO_GLOBAL_EPS_M
        poses = _consistent_poses(
            SonarScan(hall.segments, belt, m, hall.boundary),
            hall.segments,
            truth,
            np.array([0.3, 0.3, 0.1]),
            1,
            rng,
            count=400,
        )
        assert found.paving.contains(np.concatenate([truth[None], poses])).all()
        if not found.coarse:
            assert found.refinement is not None
            assert np.array_equal(found.refinement.paving.outer, found.paving.outer)
        # a move within the limits, then a scan with one echo at most
        last = truth
        truth = last + rng.uniform(-0.9, 0.9, size=3) * reach
        truth[2] = np.mod(truth[2] + np.pi, 2 * np.pi) - np.pi
        m = bounded_readings(cone_ranges(truth[None], hall.segments)[0], DEFAULT_BELT, rng)
        echoes = np.flatnonzero(np.isfinite(m))
        m[echoes[1:]] = np.inf
        scan = SonarScan(hall.segments, belt, m, hall.boundary)
        assert tracker.rejects_nothing(scan)
        searches.clear()
        counting.calls.clear()
        result = tracker.step(found.paving, scan, 1.0, found.refinement)
        assert result.consistent and searches[0][1] <= LOST_ECHO_PREDICTED_BOXES
        assert sum(counting.calls) <= 2 * LOST_ECHO_TRACKING_TESTS
        assert result.refinement is None
        # poses reachable from the set: uniform in its boxes (by volume), then moved
        boxes = found.paving.outer
        widths = boxes[..., 1] - boxes[..., 0]
        volumes = widths.prod(axis=1)
        picked = boxes[rng.choice(len(boxes), size=800, p=volumes / volumes.sum())]
        reachable = rng.uniform(picked[..., 0], picked[..., 1])
        reachable += rng.uniform(-reach, reach, size=reachable.shape)
        reachable[:, 2] = np.mod(reachable[:, 2] + np.pi, 2 * np.pi) - np.pi
        inside = ((reachable[:, :2] > 0.5) & (reachable[:, :2] < 59.5)).all(axis=1)
        reachable = np.concatenate([truth[None], reachable[inside]])
        assert result.paving.contains(reachable).all()
        checked += len(reachable)
    assert checked > 8 * 400  # the check is not vacuous
