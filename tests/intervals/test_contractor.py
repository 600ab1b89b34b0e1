"""The sonar contractor (intervals/sonar/contractor.py) against brute force, and its SIVIA hook.

Soundness is checked with the simulator's own cone model (``tests.helpers.cone_ranges``) and
the readings' error bounds stated independently of the interval code: a pose explains an echo
``m`` when its exact cone distance ``d`` is at most ``d_max`` and ``|m - d| <= e_abs + e_rel
d``. Every sampled pose of a box that explains all but at most ``q`` echoes must lie in the
contracted box (no-echo readings are not counted: the contractor does not use them, so the
poses to keep are a superset of those the pipeline keeps).
"""

from __future__ import annotations

import numpy as np
import pytest

from intervals import localize as localize_module
from intervals.boxes import clip_to_boxes, meets_any_box, volume
from intervals.errors import IntervalError
from intervals.localize import box_test, gomne, localize
from intervals.sivia import INSIDE, OUTSIDE, UNDECIDED, sivia
from intervals.sonar.cone import sensor_verdicts
from intervals.sonar.contractor import HEADING_SLOTS, contract, shave
from intervals.sonar.scan import SonarBelt, SonarScan
from robotsim.maps import builtin_map
from tests.helpers import (
    DEFAULT_BELT,
    boxes_around,
    random_scan_case,
    sample_in_boxes,
    with_outliers,
    wrong_echoes,
    wrong_readings,
)

GAMMAS_RAD = (0.003, 0.05, np.deg2rad(12.5), 0.6)


def _inside(poses, boxes):
    """``(N, P)``: pose ``p`` of row ``n`` lies in box ``n`` (NaN boxes hold nothing)."""
    return np.all((boxes[:, None, :, 0] <= poses) & (poses <= boxes[:, None, :, 1]), axis=-1)


@pytest.mark.slow
@pytest.mark.parametrize("gamma", GAMMAS_RAD)
def test_every_pose_with_at_most_q_wrong_echoes_stays_in_the_contracted_box(gamma):
    """Random rooms, belts (default and random off-centre mounts), noise on the error bounds,
    outliers, q in 0..2: boxes round the truth of all sizes, poses sampled in them."""
    rng = np.random.default_rng(int(gamma * 1e6) + 7)
    kept = 0
    for case in range(30):
        scan, params, truth = random_scan_case(rng, gamma, echoes_never_lost=bool(case % 2))
        q = case % 3
        scan = with_outliers(scan, rng, int(rng.integers(0, q + 1)))
        boxes = boxes_around(truth, rng, 60)
        out = contract(boxes, scan, q)
        full = ~np.isnan(out).any(axis=(1, 2))
        assert np.all(out[full, :, 0] >= boxes[full, :, 0])
        assert np.all(out[full, :, 1] <= boxes[full, :, 1])
        assert np.array_equal(out[full, 2], boxes[full, 2])  # the heading is left alone
        poses = sample_in_boxes(boxes, truth, rng, 40)
        fits = wrong_echoes(poses, scan, params) <= q
        assert not np.any(fits & ~_inside(poses, out)), f"case {case}: a consistent pose lost"
        kept += int(np.count_nonzero(fits))
    assert kept > 1000  # the check saw many consistent poses


def test_truth_kept_and_boxes_contracted_on_the_default_belt():
    """Quick version of the brute force (the truth and poses near it), and the contractor is
    no no-op: boxes of 0.2 to 1 m round the truth shrink to well under their area on average."""
    rng = np.random.default_rng(3)
    ratios = []
    for _ in range(20):
        scan, params, truth = random_scan_case(rng, np.deg2rad(12.5), echoes_never_lost=False)
        half = rng.uniform(0.1, 0.5, (40, 3)) * np.array([1.0, 1.0, 0.3])
        offset = rng.uniform(-1, 1, (40, 3)) * half
        boxes = np.stack([truth + offset - half, truth + offset + half], axis=-1)
        out = contract(boxes, scan, 0)
        assert _inside(truth[None, None].repeat(40, 0), out).all()
        poses = sample_in_boxes(boxes, truth, rng, 8)
        fits = wrong_echoes(poses, scan, params) == 0
        assert not np.any(fits & ~_inside(poses, out))
        area = np.prod(boxes[:, :2, 1] - boxes[:, :2, 0], axis=1)
        ratios.append(np.prod(out[:, :2, 1] - out[:, :2, 0], axis=1) / area)
    assert np.mean(ratios) < 0.7


def test_boxes_sharing_headings_contract_as_each_box_alone():
    """The offset and polar boxes kept per heading interval (``HEADING_SLOTS`` of them) are
    those each box computes alone: many boxes over more distinct headings than slots, in a
    random order (slots evicted and met again), pairs of headings with the same lower bound
    and bounds at -0.0 and 0.0 among them, give the bytes of one call per box; and the scans
    contract some boxes and empty others."""
    rng = np.random.default_rng(11)
    moved = emptied = 0
    for case in range(6):
        scan, _, truth = random_scan_case(rng, np.deg2rad(12.5), echoes_never_lost=bool(case % 2))
        boxes = boxes_around(truth, rng, 400)
        starts = truth[2] + rng.uniform(-0.3, 0.05, HEADING_SLOTS)
        headings = [[s, s + w] for s in starts for w in rng.uniform(0.01, 0.3, 2)]  # lo shared
        headings += [[-0.0, 0.1], [0.0, 0.1], [-0.1, -0.0], [-0.1, 0.0]]
        boxes[:, 2] = np.array(headings)[rng.integers(0, len(headings), boxes.shape[0])]
        q = case % 2
        together = contract(boxes, scan, q)
        alone = np.concatenate([contract(boxes[n : n + 1], scan, q) for n in range(len(boxes))])
        assert together.tobytes() == alone.tobytes()
        full = ~np.isnan(together).any(axis=(1, 2))
        emptied += int(np.count_nonzero(~full))
        moved += int(np.count_nonzero(np.any(together[full] != boxes[full], axis=(1, 2))))
    assert moved > 100 and emptied > 100


def test_a_heading_slot_is_reused_only_for_the_same_cosines_and_sines(monkeypatch):
    """Boxes with the same heading bounds but other cosines and sines of them (here nudged by
    1e-6 for the boxes centred on one side of the truth, as another evaluation of ``cos`` and
    ``sin`` might differ by ulps) contract with their own: the bytes of one call per box,
    and not those of the unnudged values."""
    from intervals.sonar import contractor as contractor_module

    rng = np.random.default_rng(5)
    scan, _, truth = random_scan_case(rng, np.deg2rad(12.5), echoes_never_lost=False)
    boxes = boxes_around(truth, rng, 300)
    boxes[:, 2] = [truth[2] - 0.1, truth[2] + 0.05]
    plain = contract(boxes, scan, 1)

    def nudged(b):
        cos, sin = np.cos(b[:, 2]), np.sin(b[:, 2])
        far = b[:, 0].mean(axis=1) > truth[0]
        return cos + 1e-6 * far[:, None], sin - 1e-6 * far[:, None]

    monkeypatch.setattr(contractor_module, "heading_trig", nudged)
    together = contract(boxes, scan, 1)
    alone = np.concatenate([contract(boxes[n : n + 1], scan, 1) for n in range(len(boxes))])
    assert together.tobytes() == alone.tobytes()
    assert together.tobytes() != plain.tobytes()  # the nudge reaches the output


def test_impossible_reading_empties_and_no_echo_leaves_the_box():
    """An echo whose interval is empty (no fault-free reading gives it) empties every box at
    q = 0 and not at q = 1; a scan without echoes contracts nothing."""
    segments = builtin_map("hall").segments
    belt = SonarBelt.from_params(DEFAULT_BELT, echoes_never_lost=False)
    box = np.array([[[4.0, 5.0], [3.0, 4.0], [0.0, 0.2]]])
    none = SonarScan(segments, belt, np.full(belt.count, np.inf))
    assert np.array_equal(contract(box, none, 0), box)
    readings = np.full(belt.count, np.inf)
    readings[0] = DEFAULT_BELT.d_max_m + 0.5  # an echo beyond d_max: no fault-free sensor
    scan = SonarScan(segments, belt, readings)
    assert scan.ranges[0, 0] > scan.ranges[0, 1]  # the reading's interval is empty
    assert np.isnan(contract(box, scan, 0)).all()
    assert not np.isnan(contract(box, scan, 1)).any()


def test_echoes_beyond_the_grid_read_no_cell_past_its_end(monkeypatch):
    """Regression (a segfault in CI, test_physical_bounds): an echo whose hit points all lie
    beyond the segment grid's last row made the contractor read ``grid_starts`` past its
    end (in the last column). The kernel compiled with bounds checks, on a box just outside
    the hall's north-east corner (a predicted box may reach out of the map) with one echo
    straight up: no index error, and the box emptied (no wall there explains it)."""
    import numba

    from intervals.sonar import contractor as contractor_module

    checked = numba.njit(boundscheck=True)(contractor_module.contract_into.py_func)
    monkeypatch.setattr(contractor_module, "contract_into", checked)
    segments = builtin_map("hall").segments
    belt = SonarBelt.from_params(DEFAULT_BELT, echoes_never_lost=False)
    right, top = float(segments[..., 0].max()), float(segments[..., 1].max())
    heading = np.pi / 2 - DEFAULT_BELT.mount_angle_rad[0]  # sensor 0 points north
    box = np.array(
        [[[right - 0.3, right - 0.1], [top + 0.5, top + 0.6], [heading - 0.01, heading + 0.01]]]
    )
    readings = np.full(belt.count, np.inf)
    readings[0] = DEFAULT_BELT.d_max_m - 0.1  # hits 3.2 m and more above the north wall
    scan = SonarScan(segments, belt, readings)
    assert scan.scene is not None
    grid = scan.scene.grid
    assert top + 3.2 > grid.origin[1] + (grid.shape[1] + 2) * grid.cell_m  # two rows past
    assert np.isnan(contract(box, scan, 0)).all()
    assert not np.isnan(contract(box, scan, 1)).any()


@pytest.mark.slow
@pytest.mark.parametrize("gamma", GAMMAS_RAD[1:3])
def test_shaving_keeps_every_consistent_pose_and_narrows_the_heading(gamma):
    """Shaving with the box test (cone and room tests at q) against brute force: no sampled
    pose explaining all but q readings leaves its box; the headings get narrower."""
    rng = np.random.default_rng(int(gamma * 1e6) + 5)
    kept, widths = 0, []
    for case in range(16):
        scan, params, truth = random_scan_case(rng, gamma, echoes_never_lost=bool(case % 2))
        q = case % 2
        scan = with_outliers(scan, rng, q)
        centre = truth + rng.normal(0, 1, (40, 3)) * np.array([0.03, 0.03, 0.02])
        half = rng.uniform(0.01, 0.05, (40, 3))
        boxes = np.stack([centre - half, centre + half], axis=-1)
        local = scan.restricted_to(boxes)
        shaved, rows = shave(
            boxes, lambda b, s=local, r=q: box_test(b, s, r, inner=False) == OUTSIDE, local, q
        )
        assert np.all(shaved[:, :, 0] >= boxes[rows, :, 0])
        assert np.all(shaved[:, :, 1] <= boxes[rows, :, 1])
        poses = sample_in_boxes(boxes, truth, rng, 40)
        fits = wrong_readings(poses, scan, params) <= q
        placed = np.zeros(fits.shape, dtype=bool)
        placed[rows] = _inside(poses[rows], shaved)
        assert not np.any(fits & ~placed), f"case {case}: a consistent pose lost"
        kept += int(np.count_nonzero(fits))
        widths.append(np.mean(shaved[:, 2, 1] - shaved[:, 2, 0]) / np.mean(2 * half[rows, 2]))
    assert kept > 50 and np.mean(widths) < 0.9


def test_bad_arguments_raise_interval_error():
    rng = np.random.default_rng(0)
    scan, _, truth = random_scan_case(rng, 0.2, False)
    box = np.stack([truth - 0.1, truth + 0.1], axis=-1)
    for kwargs in ({"q": -1}, {"q": 1.5}, {"passes": 0}):
        with pytest.raises(IntervalError):
            contract(box, scan, **kwargs)
    with pytest.raises(IntervalError, match="pose boxes"):
        contract(box[:2], scan)
    assert contract(np.zeros((0, 3, 2)), scan).shape == (0, 3, 2)
    # the box test checks its boxes once, where they enter (its inner calls skip the checks)
    with pytest.raises(IntervalError, match="box test boxes must be"):
        box_test(box[:2], scan)
    with pytest.raises(IntervalError, match="NaN"):
        box_test(np.full((3, 2), np.nan), scan)
    boxes = boxes_around(truth, rng, 40)
    assert np.array_equal(
        contract(boxes, scan, validated=True), contract(boxes, scan), equal_nan=True
    )


def _disk_test(boxes):
    """SIVIA test of the unit disk (exact interval bounds of x^2 + y^2)."""
    lo, hi = boxes[:, :, 0], boxes[:, :, 1]
    near = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(lo**2, hi**2)).sum(axis=1)
    far = np.maximum(lo**2, hi**2).sum(axis=1)
    return np.where(near > 1, OUTSIDE, np.where(far <= 1, INSIDE, UNDECIDED)).astype(np.int8)


def test_sivia_drops_emptied_rows_clips_to_the_input_and_stays_sound():
    """A contractor of the unit disk (its box [-1, 1]^2, NaN beyond it; one that also widens
    its rows, which SIVIA must clip): fewer tests, and the disk's sampled points covered."""
    seen = {"plain": 0, "contracted": 0}

    def counting(name):
        def test(boxes):
            seen[name] += boxes.shape[0]
            return _disk_test(boxes)

        return test

    def disk_box(boxes):
        lo = np.maximum(boxes[:, :, 0], -1.0)
        hi = np.minimum(boxes[:, :, 1], 1.0)
        out = np.stack([lo - 0.5 * (lo > hi), hi + 0.5], axis=-1)  # widened: SIVIA clips
        out[np.any(lo > hi, axis=1)] = np.nan
        return out

    initial = np.array([[-3.0, 2.0], [-1.5, 4.0]])
    plain = sivia(counting("plain"), initial, 0.05)
    contracted = sivia(counting("contracted"), initial, 0.05, contract=disk_box)
    assert seen["contracted"] < seen["plain"]
    outer = contracted.outer
    assert np.all(outer[:, :, 0] >= initial[:, 0]) and np.all(outer[:, :, 1] <= initial[:, 1])
    rng = np.random.default_rng(1)
    points = rng.uniform(-1, 1, (5000, 2))
    points = points[np.hypot(*points.T) <= 1]
    assert contracted.contains(points).all() and plain.contains(points).all()
    assert volume(outer) <= volume(plain.outer) * 1.01
    with pytest.raises(IntervalError, match="contractor returned shape"):
        sivia(_disk_test, initial, 0.05, contract=lambda b: b[:1])


@pytest.mark.slow
def test_localize_and_gomne_with_the_contractor_keep_the_truth_in_smaller_sets():
    """Default belt and a thin cone, random rooms: the paved set with the contractor holds the
    truth whenever the set without it does (always here: no outliers), and is smaller on
    average; shaving (2 rounds) keeps the truth in a set no larger than the contracted one."""
    rng = np.random.default_rng(11)
    ratios, shaved_ratios = [], []
    for case in range(12):
        gamma = np.deg2rad(12.5) if case % 2 else 0.05
        scan, _, truth = random_scan_case(rng, gamma, echoes_never_lost=bool(case % 3 == 0))
        prior = np.stack([truth - [0.6, 0.6, 0.2], truth + [0.6, 0.6, 0.2]], axis=-1)
        plain = localize(scan, prior, 0.05, q=1, contract=False)
        tight = localize(scan, prior, 0.05, q=1)
        assert plain.contains(truth[None])[0] and tight.contains(truth[None])[0]
        shaved = localize(scan, prior, 0.05, q=1, shave_rounds=2)
        assert shaved.contains(truth[None])[0] and shaved.volume() <= tight.volume()
        found = gomne(scan, prior, 0.05, q_max=1)
        assert found.consistent and found.paving.contains(truth[None])[0]
        found = gomne(scan, prior, 0.05, q_max=1, shave_rounds=2)
        assert found.consistent and found.paving.contains(truth[None])[0]
        ratios.append(tight.volume() / plain.volume())
        shaved_ratios.append(shaved.volume() / tight.volume())
    assert np.mean(ratios) < 1.0 and np.mean(shaved_ratios) < 1.0
    with pytest.raises(IntervalError, match="contract must be"):
        localize(scan, prior, 0.05, contract=1)  # type: ignore[arg-type]
    with pytest.raises(IntervalError, match="shave_rounds must be"):
        localize(scan, prior, 0.05, shave_rounds=-1)


def test_boxes_outside_every_region_of_within_are_never_contracted(monkeypatch):
    """GOMNE with ``within`` (the tracker's predicted components): the contractor only ever
    sees boxes meeting some region (the others are OUTSIDE, dropped before it), the set holds
    the truth and lies in the regions, and fewer boxes are contracted than without them."""
    rng = np.random.default_rng(12)
    seen: list[np.ndarray] = []

    def recording(boxes, scan, q=0, passes=2, validated=False):
        seen.append(np.array(boxes))
        return contract(boxes, scan, q, passes, validated)

    monkeypatch.setattr(localize_module.contractor, "contract", recording)
    for case in range(6):
        scan, _, truth = random_scan_case(rng, np.deg2rad(12.5), echoes_never_lost=case % 2 == 0)
        prior = np.stack([truth - [1.0, 1.0, 0.4], truth + [1.0, 1.0, 0.4]], axis=-1)
        elsewhere = truth + rng.uniform(-0.7, 0.7, 3) * [1.0, 1.0, 0.3]
        regions = np.stack(
            [
                np.stack([c - [0.15, 0.15, 0.08], c + [0.15, 0.15, 0.08]], -1)
                for c in (truth, elsewhere)
            ]
        )
        seen.clear()
        found = gomne(scan, prior, 0.05, q_max=1, within=regions)
        assert found.consistent and found.paving.contains(truth[None])[0]
        assert meets_any_box(found.paving.outer, regions).all()
        contracted = np.concatenate(seen)
        assert meets_any_box(contracted, regions).all()
        seen.clear()
        gomne(scan, prior, 0.05, q_max=1)
        assert contracted.shape[0] < np.concatenate(seen).shape[0]


def test_clip_to_boxes_keeps_every_point_in_a_region_and_equals_the_numpy_broadcast():
    """The compiled clip against its numpy broadcast (the hull over the regions a box meets of
    the intersections, closed intervals; held: within one region) bit for bit, on random boxes
    and regions with shared bounds and signed zeros; every sampled point of a box lying in
    some region is in its clipped box, and ``meets_any_box`` is "the clipped box is not empty"."""
    rng = np.random.default_rng(21)
    for trial in range(300):
        n, m = int(rng.integers(0, 60)), int(rng.integers(0, 8))
        grid = np.array([-1.0, -0.0, 0.0, 0.5, 1.0])
        lo = rng.choice(grid, (n, 3)) if trial % 2 else rng.uniform(-1, 1, (n, 3))
        boxes = np.stack([lo, lo + rng.choice([0.0, 0.5, 1.0], (n, 3))], -1)
        r_lo = rng.choice(grid, (m, 3))
        regions = np.stack([r_lo, r_lo + rng.choice([0.0, 0.5, 1.5], (m, 3))], -1)
        clipped, held = clip_to_boxes(boxes, regions)
        b = boxes[:, None]
        lo_b = np.maximum(b[..., 0], regions[None, :, :, 0])
        hi_b = np.minimum(b[..., 1], regions[None, :, :, 1])
        met = np.all(lo_b <= hi_b, axis=2)[..., None]
        expected = np.stack(
            [
                np.where(met, lo_b, np.inf).min(axis=1, initial=np.inf),
                np.where(met, hi_b, -np.inf).max(axis=1, initial=-np.inf),
            ],
            -1,
        )
        within = (regions[None, :, :, 0] <= b[..., 0]) & (b[..., 1] <= regions[None, :, :, 1])
        assert clipped.tobytes() == expected.tobytes()
        np.testing.assert_array_equal(held, np.any(np.all(within, axis=2), axis=1))
        np.testing.assert_array_equal(
            meets_any_box(boxes, regions), np.all(clipped[..., 0] <= clipped[..., 1], axis=1)
        )
        if n and m:
            t = rng.random((n, 50, 3))
            points = boxes[:, None, :, 0] + t * (boxes[:, None, :, 1] - boxes[:, None, :, 0])
            in_region = np.any(
                np.all(
                    (regions[None, None, :, :, 0] <= points[:, :, None])
                    & (points[:, :, None] <= regions[None, None, :, :, 1]),
                    axis=3,
                ),
                axis=2,
            )
            in_clip = np.all(
                (clipped[:, None, :, 0] <= points) & (points <= clipped[:, None, :, 1]), axis=2
            )
            assert np.all(in_clip | ~in_region)


def test_the_relaxed_bound_is_the_sorted_rank():
    """``_largest`` (the contractor's ``(q + 1)``-th largest bound) against ``np.sort`` on
    random values with ties, infinities and signed zeros, for every rank."""
    from intervals.sonar.contractor import _largest

    rng = np.random.default_rng(4)
    pool = np.array([-np.inf, -1.0, -0.0, 0.0, 0.5, 2.0, np.inf])
    for trial in range(2000):
        k = int(rng.integers(1, 20))
        values = rng.choice(pool, k) if trial % 2 else rng.normal(size=k)
        q = int(rng.integers(0, k))
        got = _largest(values.copy(), q, np.empty(q + 1))
        assert got == np.sort(values)[k - 1 - q]


@pytest.mark.parametrize("gamma", GAMMAS_RAD[1:3])
def test_readings_known_wrong_keep_every_pose_with_at_most_qwrong_readings(gamma):
    """The rejection rows of the box test handed in as known wrong readings (``wrong``):
    random rooms, belts, outliers, q in 0..2, boxes round the truth; every sampled pose with at
    most ``q`` wrong readings (free space included where the scan uses it) stays in the
    contracted box, which is inside the plain contraction and, over the cases, smaller. A
    reading marked wrong that is not (the rows shifted to other sensors) loses poses: the
    check sees the rule."""
    rng = np.random.default_rng(int(gamma * 1e6) + 11)
    kept, narrower, lost_when_false = 0, 0.0, 0
    for case in range(30):
        scan, params, truth = random_scan_case(rng, gamma, echoes_never_lost=bool(case % 2))
        q = case % 3
        scan = with_outliers(scan, rng, int(rng.integers(0, q + 1)))
        boxes = boxes_around(truth, rng, 60)
        rows = sensor_verdicts(boxes, scan, False)[0]
        out = contract(boxes, scan, q, wrong=rows)
        plain = contract(boxes, scan, q)
        full = ~np.isnan(out).any(axis=(1, 2))
        assert np.all(out[full, :, 0] >= plain[full, :, 0])
        assert np.all(out[full, :, 1] <= plain[full, :, 1])
        poses = sample_in_boxes(boxes, truth, rng, 40)
        fits = wrong_readings(poses, scan, params) <= q
        assert not np.any(fits & ~_inside(poses, out)), f"case {case}: a consistent pose lost"
        kept += int(np.count_nonzero(fits))
        narrower += volume(np.where(np.isnan(plain), 0.0, plain)) - volume(
            np.where(np.isnan(out), 0.0, out)
        )
        false = contract(boxes, scan, q, wrong=np.roll(rows, 1, axis=1) & ~rows)
        lost_when_false += int(np.count_nonzero(fits & ~_inside(poses, false)))
    assert kept > 1000  # the check saw many consistent poses
    assert narrower > 0  # the known wrong readings narrowed some boxes
    assert lost_when_false > 0


def test_known_wrong_readings_are_checked_and_more_than_q_empty_the_box():
    scan, _, truth = random_scan_case(np.random.default_rng(3), 0.2, echoes_never_lost=False)
    box = np.stack([truth - 0.05, truth + 0.05], axis=-1)[None]
    wrong = np.zeros((1, scan.belt.count), dtype=bool)
    assert np.array_equal(contract(box, scan, 1, wrong=wrong), contract(box, scan, 1))
    wrong[0, :2] = True
    assert np.isnan(contract(box, scan, 1, wrong=wrong)).all()
    with pytest.raises(IntervalError, match="wrong must be"):
        contract(box, scan, 1, wrong=wrong[:, 1:])
