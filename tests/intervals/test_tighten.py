"""The tightening of kept boxes below eps (intervals/tighten.py) against brute force.

Soundness is checked as in ``tests/intervals/test_contractor.py``
(:func:`tests.helpers.wrong_readings`): with the simulator's own cone model and the readings'
error bounds, independently of the interval code, every sampled pose that explains all but at
most ``q`` readings (no-echo readings counted where they prove free space, poses outside the
room explaining none) must lie in the tightened set. The poses are sampled in the untightened
set's boxes, where the consistent poses are, and near the truth.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from intervals.boxes import bisect, contains_points, volume
from intervals.errors import IntervalError
from intervals.localize import gomne, localize
from intervals.sonar.scan import SonarBelt, SonarScan
from intervals.tighten import MAX_LEVELS, MIN_REMOVED_SHARE, _clamped, _pieces, tighten
from intervals.tracker import IntervalTracker, TrackerSettings
from tests.helpers import (
    BIG_HALL_SEGMENTS,
    DEFAULT_BELT,
    big_hall_scan,
    big_hall_truth,
    bounded_readings,
    cone_ranges,
    random_scan_case,
    with_outliers,
    wrong_readings,
)

GAMMAS_RAD = (0.05, np.deg2rad(12.5), 0.6)


def _poses_in(boxes, truth, rng, count):
    """Poses ``(count + 400, 3)``: uniform in the union of ``boxes`` (a box picked by
    volume), and near the truth."""
    vol = np.prod(boxes[:, :, 1] - boxes[:, :, 0], axis=1)
    pick = rng.choice(boxes.shape[0], size=count, p=vol / vol.sum())
    lo, hi = boxes[pick, :, 0], boxes[pick, :, 1]
    uniform = np.clip(lo + rng.random((count, 3)) * (hi - lo), lo, hi)
    near = truth + rng.normal(0, 1, (400, 3)) * np.array([0.02, 0.02, 0.01])
    return np.concatenate([uniform, near])


def _outlier_case(rng, case, half_widths):
    """``(scan, params, truth, q, prior (3, 2))``: a random room scan at 12.5 degrees' half
    aperture (echoes never lost when ``case`` is odd), ``q = case % 2`` readings replaced by
    outliers, the prior ``truth -+ half_widths (3,)`` (m, m, rad)."""
    scan, params, truth = random_scan_case(rng, np.deg2rad(12.5), bool(case % 2))
    q = case % 2
    scan = with_outliers(scan, rng, q)
    return scan, params, truth, q, np.stack([truth - half_widths, truth + half_widths], axis=-1)


def _plain_cases(seed, half_widths, count=4):
    """``count`` cases of :func:`_outlier_case` from ``default_rng(seed)``, each with its plain
    paving (not empty): ``(rng, scan, params, truth, q, prior, plain)`` (``rng`` for the case's
    own samples, drawn before the next case)."""
    rng = np.random.default_rng(seed)
    for case in range(count):
        scan, params, truth, q, prior = _outlier_case(rng, case, half_widths)
        plain = localize(scan, prior, 0.05, q=q)
        assert not plain.is_empty
        yield rng, scan, params, truth, q, prior, plain


@pytest.mark.slow
@pytest.mark.parametrize("gamma", GAMMAS_RAD)
def test_every_consistent_pose_stays_in_the_tightened_set(gamma):
    """Random rooms, belts and noise (errors on their bounds), outliers, q in 0..2, with and
    without free space: no sampled consistent pose of the paved set leaves the tightened set,
    which is smaller."""
    rng = np.random.default_rng(int(gamma * 1e6) + 13)
    kept, ratios = 0, []
    for case in range(9):  # every pair of q in 0..2 and levels 3, 6, 9
        scan, params, truth = random_scan_case(rng, gamma, echoes_never_lost=bool(case % 2))
        q = case % 3
        scan = with_outliers(scan, rng, int(rng.integers(0, q + 1)))
        centre = truth + rng.uniform(-1, 1, 3) * np.array([0.2, 0.2, 0.1])
        prior = np.stack([centre - [0.4, 0.4, 0.2], centre + [0.4, 0.4, 0.2]], axis=-1)
        prior[:, 0] = np.minimum(prior[:, 0], truth)
        prior[:, 1] = np.maximum(prior[:, 1], truth)
        plain = localize(scan, prior, 0.05, q=q)
        if plain.is_empty:
            continue
        levels = (3, 6, 9)[case // 3]
        tight = localize(scan, prior, 0.05, q=q, tighten_levels=levels)
        poses = _poses_in(plain.outer, truth, rng, 2000)
        fits = wrong_readings(poses, scan, params) <= q
        inside = contains_points(tight.outer, poses).any(axis=0)
        assert not np.any(fits & ~inside), f"case {case}: a consistent pose lost"
        kept += int(np.count_nonzero(fits))
        ratios.append(tight.volume() / plain.volume())
    assert kept > 500  # the check saw many consistent poses
    assert max(ratios) <= 1.0 and np.median(ratios) < 0.5  # it tightens, never widens


@pytest.mark.slow
def test_gomne_sets_stay_sound_and_the_counts_follow_the_pieces():
    """GOMNE with tightening: the guaranteed set holds every consistent pose at q_max, and its
    minimal set (read off the pieces' counts) every pose with at most q wrong readings."""
    rng = np.random.default_rng(29)
    for case in range(6):
        scan, params, truth, _, prior = _outlier_case(rng, case, [0.3, 0.3, 0.15])
        plain = gomne(scan, prior, 0.05, q_max=2, guaranteed=True)
        wide = gomne(scan, prior, 0.05, q_max=2, guaranteed=True, tighten_levels=6)
        small = gomne(scan, prior, 0.05, q_max=2, guaranteed=False, tighten_levels=6)
        assert wide.consistent and small.consistent and small.q <= 2
        poses = _poses_in(plain.paving.outer, truth, rng, 3000)
        wrong = wrong_readings(poses, scan, params)
        assert not np.any((wrong <= 2) & ~contains_points(wide.paving.outer, poses).any(axis=0))
        assert not np.any(
            (wrong <= small.q) & ~contains_points(small.paving.outer, poses).any(axis=0)
        )
        assert wide.paving.volume() <= plain.paving.volume()


def _disk(boxes, parents=None):
    """``(keep, counts, proof None)`` for the unit disk: the exact interval bound of ``x^2 + y^2``."""
    lo, hi = boxes[:, :, 0], boxes[:, :, 1]
    near = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(lo**2, hi**2)).sum(axis=1)
    return near <= 1.0, (near > 0.5).astype(np.int64), None


def test_tighten_covers_the_disk_counts_each_piece_and_stops_at_its_caps():
    """On a 2-D disk test (exact bounds): the pieces cover the disk's sampled points and hold
    less area; each piece carries its own test count; the caps stop it with a set as sound."""
    edges = list(itertools.pairwise(np.linspace(-1.2, 1.2, 7)))
    cells = np.array([[x, y] for x in edges for y in edges])
    keep, counts, _ = _disk(cells)
    cells, counts = cells[keep], counts[keep]
    n = cells.shape[0]
    points = np.random.default_rng(2).uniform(-1, 1, (3000, 2))
    points = points[np.hypot(*points.T) <= 1]
    out, out_counts, tested = tighten(cells, counts, _disk, None, None, 6)
    assert contains_points(out, points).any(axis=0).all()
    assert volume(out) < 0.8 * volume(cells) and tested > cells.shape[0]
    assert np.array_equal(out_counts, _disk(out)[1])
    # caps: the next call would exceed them, so the set comes back as it was
    same, same_counts, none = tighten(cells, counts, _disk, None, None, 6, max_boxes=8)
    assert np.array_equal(same, cells) and np.array_equal(same_counts, counts) and none == 0
    part, _, seen = tighten(cells, counts, _disk, None, None, 6, max_tested=cells.shape[0] * 8)
    assert seen == cells.shape[0] * 8 and contains_points(part, points).any(axis=0).all()
    assert volume(out) <= volume(part) <= volume(cells)
    room = 3 * cells.shape[0]  # room for a third of the boxes' children: the largest refined
    some, some_counts, _ = tighten(cells, counts, _disk, None, None, 6, max_boxes=room)
    assert some.shape[0] <= room and contains_points(some, points).any(axis=0).all()
    assert volume(out) < volume(some) < volume(cells)
    assert np.array_equal(some_counts, _disk(some)[1])
    # room for two boxes a box: each bisected once at least (fewer cuts a call), never looser
    halved, halved_counts, _ = tighten(cells, counts, _disk, None, None, 6, max_boxes=2 * n)
    assert halved.shape[0] <= 2 * n and contains_points(halved, points).any(axis=0).all()
    assert volume(halved) <= volume(tighten(cells, counts, _disk, None, None, 1)[0])
    assert np.array_equal(halved_counts, _disk(halved)[1])

    # a contractor that empties a row drops it; one that widens a row is clipped to it
    def widening(b, proof):
        c = b.copy()
        c[:, :, 0] -= 1.0
        c[0] = np.nan
        return c

    children = np.concatenate(bisect(cells))
    clipped, _, _ = tighten(cells, counts, _disk, widening, None, 1)
    assert np.array_equal(clipped, children[_disk(children)[0]][1:])


def _slab(boxes, parents=None):
    """``(keep, counts, proof None)`` for the slabs ``|y - 0.1 k| <= 0.15`` over ``k <= x < k + 1`` (a box
    within one such strip, x idle in it): exact interval bounds."""
    centre = 0.1 * np.floor(boxes[:, 0, 0])
    gap = np.maximum(boxes[:, 1, 0] - centre, centre - boxes[:, 1, 1])
    return gap <= 0.15, np.zeros(boxes.shape[0], dtype=np.int64), None


def test_tighten_never_cuts_an_idle_axis_and_keeps_boxes_idle_on_every_axis():
    """``idle``: x idle in every box (the slab test cannot change along a box's x), every axis
    idle in the boxes right of x = 2. No piece is cut across x, the boxes idle on every axis
    come back as they were and untested, the slab's sampled points stay covered, and the set
    is smaller than with the same cuts spent partly across x."""
    edges = list(itertools.pairwise(np.linspace(0.0, 3.0, 4)))
    cells = np.array([[x, y] for x in edges for y in itertools.pairwise(np.linspace(-1, 1, 9))])
    keep, counts, _ = _slab(cells)
    cells, counts = cells[keep], counts[keep]

    def idle(b):
        return np.stack([np.ones(b.shape[0], bool), b[:, 0, 0] >= 2.0], axis=1)

    out, _, tested = tighten(cells, counts, _slab, None, None, 6, idle=idle)
    stuck = cells[:, 0, 0] >= 2.0
    assert stuck.any() and not stuck.all()
    parent = np.argmax(contains_points(cells, out.mean(axis=2)), axis=0)  # each piece's cell
    assert np.array_equal(out[:, 0], cells[parent, 0])  # x bounds: never cut
    assert all((out == cell).all(axis=(1, 2)).any() for cell in cells[stuck])
    alone, _, alone_tested = tighten(cells[~stuck], counts[~stuck], _slab, None, None, 6, idle=idle)
    assert tested == alone_tested  # the stuck boxes cost no test
    assert np.array_equal(np.sort(out[: alone.shape[0]], axis=0), np.sort(alone, axis=0))
    points = np.random.default_rng(3).uniform([0, -1], [3, 1], (20000, 2))
    x0 = np.floor(points[:, 0])
    points = points[np.abs(points[:, 1] - 0.1 * x0) <= 0.15]
    assert contains_points(out, points).any(axis=0).all()
    spread, _, _ = tighten(cells[~stuck], counts[~stuck], _slab, None, None, 6)  # across x too
    assert volume(alone) < volume(spread) < volume(cells[~stuck])


def test_whole_boxes_tightened_keep_every_consistent_pose_and_their_idle_length():
    """GOMNE with whole boxes (idle axes) and tightening, along a wall of a 60 m hall, in a
    corner and in the open, q in 0..2: every sampled pose explaining all but q readings lies in
    the tightened set, no larger than the untightened one; a box whole along the wall (x idle)
    stays as long: no cut across x."""
    rng = np.random.default_rng(31)
    params, kept, long_kept = DEFAULT_BELT, 0, 0
    for case in range(6):
        where = case % 3
        truth = big_hall_truth(rng, where)
        readings = bounded_readings(cone_ranges(truth, BIG_HALL_SEGMENTS, params), params, rng)
        scan = big_hall_scan(readings, bool(case % 2), params)
        q = case % 3
        initial = np.stack([truth - [2.0, 0.4, 0.15], truth + [2.0, 0.4, 0.15]], axis=1)
        plain = gomne(scan, initial, 0.05, q, whole_boxes=True)
        tight = gomne(scan, initial, 0.05, q, whole_boxes=True, tighten_levels=6)
        assert plain.consistent and tight.consistent and tight.q == plain.q
        count = 4000  # poses along the strip: any x of the box, y and heading near the truth's
        poses = truth + np.column_stack(
            [rng.uniform(-2.0, 2.0, count), rng.normal(0, 0.05, count), rng.normal(0, 0.03, count)]
        )
        poses = poses[contains_points(initial[None], poses)[0]]
        fits = wrong_readings(poses, scan, params) <= tight.q
        held = contains_points(tight.paving.outer, poses).any(axis=0)
        assert not np.any(fits & ~held), f"case {case}: a consistent pose lost"
        kept += int(np.count_nonzero(fits))
        assert tight.paving.volume() <= plain.paving.volume()
        x_width = np.max(plain.paving.outer[:, 0, 1] - plain.paving.outer[:, 0, 0])
        if where == 0 and x_width > 1.0:
            assert np.max(tight.paving.outer[:, 0, 1] - tight.paving.outer[:, 0, 0]) == x_width
            long_kept += 1
    assert kept > 1000 and long_kept >= 1  # the check saw consistent poses and a long box


def _corridor(rng):
    """A random corridor ``(boundary (m, 2), segments (m, 2, 2))``: 12 to 20 m long, 1.5 to
    2.2 m wide, closed door niches (0.1 m deep, 0.9 m wide) along both walls at random
    places, as the built-in ``corridor``."""
    length, width = rng.uniform(12, 20), rng.uniform(1.5, 2.2)
    south = [[0.0, 0.0]]
    for x in np.sort(rng.choice(np.arange(1.0, length - 2.0, 1.5), 4, replace=False)):
        south += [[x, 0.0], [x, -0.1], [x + 0.9, -0.1], [x + 0.9, 0.0]]
    north = [[length, width]]
    for x in np.sort(rng.choice(np.arange(1.0, length - 2.0, 1.5), 4, replace=False))[::-1]:
        north += [[x + 0.9, width], [x + 0.9, width + 0.1], [x, width + 0.1], [x, width]]
    boundary = np.array(south + [[length, 0.0]] + north + [[0.0, width]])
    return boundary, np.stack([boundary, np.roll(boundary, -1, axis=0)], axis=1)


@pytest.mark.slow
def test_tightened_corridor_strips_keep_every_consistent_pose():
    """GOMNE on strips along random corridors with door niches (the prior 3 m long along the
    axis, as a tracking prediction there), whole boxes, heading scales of 1 and 2 m/rad, q in
    0..1, 12 levels within the default 4000 tests: every sampled pose of the untightened set
    explaining all but q readings lies in the tightened set, which is smaller. Fails if a piece
    holding a consistent pose is dropped."""
    rng = np.random.default_rng(29)
    params, kept = DEFAULT_BELT, 0
    for case in range(4):
        boundary, segments = _corridor(rng)
        length, width = boundary[:, 0].max(), boundary[:, 1].max()
        truth = np.array(
            [
                rng.uniform(3.0, length - 3.0),
                width / 2 + rng.uniform(-0.2, 0.2),
                rng.uniform(-0.1, 0.1),
            ]
        )
        truth[2] += np.pi * (case % 2)  # either way along the corridor
        readings = bounded_readings(cone_ranges(truth, segments, params), params, rng, False)
        scan = SonarScan(
            segments, SonarBelt.from_params(params, echoes_never_lost=True), readings, boundary
        )
        q = case % 2
        initial = np.stack([truth - [1.5, 0.1, 0.1], truth + [1.5, 0.1, 0.1]], axis=1)
        scaled = {"heading_scale_m_per_rad": 1.0 + case // 2, "whole_boxes": True}
        plain = gomne(scan, initial, 0.05, q, **scaled)
        tight = gomne(scan, initial, 0.05, q, **scaled, tighten_levels=12, tighten_max_tested=4000)
        assert plain.consistent and tight.consistent and tight.q == plain.q
        along = truth + np.column_stack(  # the strip's axis: any x, y and heading near the truth's
            [rng.uniform(-1.5, 1.5, 3000), rng.normal(0, 0.005, 3000), rng.normal(0, 0.002, 3000)]
        )
        near = truth + rng.normal(0, 1, (1000, 3)) * np.array([0.003, 0.003, 0.001])
        poses = np.concatenate([_poses_in(plain.paving.outer, truth, rng, 6000), along, near])
        fits = wrong_readings(poses, scan, params) <= tight.q
        held = contains_points(tight.paving.outer, poses).any(axis=0)
        assert not np.any(fits & ~held), f"case {case}: a consistent pose lost"
        kept += int(np.count_nonzero(fits))
        assert tight.paving.volume() < 0.5 * plain.paving.volume()
    assert kept > 500  # the check saw many consistent poses


def test_a_test_budget_bounds_the_pieces_and_keeps_every_consistent_pose():
    """``tighten_max_tested``: with none the set is the plain paving's; with a few tests it
    holds at most that many boxes more than the plain set (each tested piece is at most one
    box), lies between the fully tightened set and the plain one in volume, and keeps every
    sampled pose that explains all but ``q`` readings."""
    kept = 0
    for rng, scan, params, truth, q, prior, plain in _plain_cases(41, [0.3, 0.3, 0.15]):
        full = localize(scan, prior, 0.05, q=q, tighten_levels=9)
        none = localize(scan, prior, 0.05, q=q, tighten_levels=9, tighten_max_tested=0)
        assert np.array_equal(none.outer, plain.outer)
        budget = 8 * plain.outer.shape[0] + 16  # every box refined once, a few twice
        part = localize(scan, prior, 0.05, q=q, tighten_levels=9, tighten_max_tested=budget)
        assert part.outer.shape[0] <= plain.outer.shape[0] + budget
        assert full.volume() <= part.volume() <= plain.volume()
        poses = _poses_in(plain.outer, truth, rng, 2000)
        fits = wrong_readings(poses, scan, params) <= q
        assert not np.any(fits & ~contains_points(part.outer, poses).any(axis=0))
        kept += int(np.count_nonzero(fits))
    assert kept > 200  # the check saw consistent poses


def test_sivia_s_tests_are_taken_off_the_pass_s_pieces(monkeypatch):
    """``tighten_max_tested`` is shared with SIVIA: the pass may test that many pieces minus
    :data:`intervals.localize.SIVIA_TEST_PIECES` per box SIVIA tested, floored at 0, and
    tests no more; with a budget SIVIA's tests exhaust the pass tests nothing and the set is
    the plain paving's. Every sampled pose that explains all but ``q`` readings stays."""
    import intervals.localize as loc

    calls = []  # per localize: [SIVIA's tests, the pass's max_tested, the pieces it tested]
    test_and_counts, tighten_pass = loc._test_and_counts, loc.tighten

    def counting(b, *args, **kwargs):
        if "parents" not in kwargs:  # SIVIA's test (the pass's pieces come with parents)
            calls[-1][0] += b.shape[0]
        return test_and_counts(b, *args, **kwargs)

    def passing(*args, **kwargs):
        boxes, counts, seen = tighten_pass(*args, **kwargs)
        calls[-1][1:] = [kwargs["max_tested"], seen]
        return boxes, counts, seen

    monkeypatch.setattr(loc, "_test_and_counts", counting)
    monkeypatch.setattr(loc, "tighten", passing)
    rng = np.random.default_rng(29)
    kept = 0
    for case in range(3):
        scan, params, truth, q, prior = _outlier_case(rng, case, [0.5, 0.5, 0.25])
        calls.append([0, None, None])
        plain = localize(scan, prior, 0.05, q=q)
        sivia_tests = calls[-1][0]
        assert sivia_tests > 100 and not plain.is_empty
        share = sivia_tests * loc.SIVIA_TEST_PIECES
        for budget in (share + 3000, share // 2):
            calls.append([0, None, None])
            tight = localize(scan, prior, 0.05, q=q, tighten_levels=12, tighten_max_tested=budget)
            tests, max_tested, seen = calls[-1]
            assert tests == sivia_tests
            assert max_tested == max(budget - share, 0) and 0 <= seen <= max_tested < budget
            if max_tested == 0:
                assert np.array_equal(tight.outer, plain.outer)
            else:
                assert seen > 0 and tight.volume() < plain.volume()
            poses = _poses_in(plain.outer, truth, rng, 2000)
            fits = wrong_readings(poses, scan, params) <= q
            assert not np.any(fits & ~contains_points(tight.outer, poses).any(axis=0))
            kept += int(np.count_nonzero(fits))
    assert kept > 200  # the check saw consistent poses


def _block_and_sheet(boxes, parents=None):
    """``(keep, counts, proof None)`` for the union of the cube ``[0, 1]^3`` and the sheet
    ``|z - 0.3 x - 0.2 y| <= 0.02`` over ``2 <= x <= 4``: exact interval bounds of each part."""
    lo, hi = boxes[:, :, 0], boxes[:, :, 1]
    cube = np.all((lo <= 1.0) & (hi >= 0.0), axis=1)
    g_lo = lo[:, 2] - 0.3 * hi[:, 0] - 0.2 * hi[:, 1]
    g_hi = hi[:, 2] - 0.3 * lo[:, 0] - 0.2 * lo[:, 1]
    sheet = (g_lo <= 0.02) & (g_hi >= -0.02) & (lo[:, 0] <= 4.0) & (hi[:, 0] >= 2.0)
    return cube | sheet, np.zeros(boxes.shape[0], dtype=np.int64), None


def _cube_and_sheet_cells():
    """``(cube (8, 3, 2), sheet (K, 3, 2))``: the cube's eight cells (inside the set of
    :func:`_block_and_sheet`) and the sheet's cells the test keeps."""
    cube = np.array(
        [
            [[x, x + 0.5], [y, y + 0.5], [z, z + 0.5]]
            for x, y, z in itertools.product((0.0, 0.5), repeat=3)
        ]
    )
    edges = [(a, a + 0.25) for a in np.arange(0.0, 2.0, 0.25)]
    sheet = np.array(
        [
            [(2.0 + x0, 2.0 + x1), y, (0.5 + z0, 0.5 + z1)]
            for (x0, x1), y, (z0, z1) in itertools.product(edges, edges, edges[:5])
        ]
    )
    return cube, sheet[_block_and_sheet(sheet)[0]]


def test_a_budget_goes_to_the_boxes_whose_cuts_remove_volume():
    """The cube's eight cells (inside the set: a cut removes nothing) are larger than the
    sheet's cells, and after one call their pieces are still the largest boxes. With tests
    left for 64 boxes in the second call (as many as the cube's pieces), the pass refines
    sheet pieces, not the cube's: the set ends smaller than after the first call (refining
    the largest boxes would leave it as large), the cube's 64 pieces come back as they were,
    every sampled point of the set stays covered, and the same inputs give the same set."""
    cells = np.concatenate(_cube_and_sheet_cells())
    counts = np.zeros(cells.shape[0], dtype=np.int64)
    budget = 8 * cells.shape[0] + 8 * 64
    out, _, tested = tighten(cells, counts, _block_and_sheet, None, None, 6, max_tested=budget)
    first, _, _ = tighten(cells, counts, _block_and_sheet, None, None, 3)
    assert tested == budget and volume(out) < volume(first) < volume(cells)
    cube_pieces = out[np.all(out[:, :, 1] <= 1.0, axis=1)]
    assert cube_pieces.shape[0] == 64
    assert np.allclose(cube_pieces[:, :, 1] - cube_pieces[:, :, 0], 0.25)
    rng = np.random.default_rng(5)
    points = rng.uniform([0.0, 0.0, 0.0], [4.0, 2.0, 1.75], (100000, 3))
    x, y = points[:20000, 0], points[:20000, 1]
    points[:20000, 2] = 0.3 * x + 0.2 * y + rng.uniform(-0.02, 0.02, 20000)
    in_cube = np.all(points <= 1.0, axis=1)
    on_sheet = np.abs(points[:, 2] - 0.3 * points[:, 0] - 0.2 * points[:, 1]) <= 0.02
    on_sheet &= points[:, 0] >= 2.0
    assert np.count_nonzero(in_cube) > 5000 and np.count_nonzero(on_sheet) > 5000
    points = points[in_cube | on_sheet]
    assert contains_points(cells, points).any(axis=0).all()
    assert contains_points(out, points).any(axis=0).all()
    again, _, _ = tighten(cells, counts, _block_and_sheet, None, None, 6, max_tested=budget)
    assert np.array_equal(again, out)


def test_the_pass_ends_after_a_call_that_removes_little():
    """``min_removed``: a cut of the cube's cells (inside the set) removes nothing, so with
    the rule their pass ends after its first call (8 pieces a cell tested, against 8 + 64
    without it) and keeps the cube whole; each call on the sheet's cells removes more than
    the share, so there the rule leaves the pass as it is (the same set, bit for bit); on both
    the pass ends after the first call that removed less than the share of all it refined (the
    second). Every sampled point of the set stays covered."""
    cube, sheet = _cube_and_sheet_cells()
    zeros = np.zeros(cube.shape[0], dtype=np.int64)
    short, _, tested = tighten(cube, zeros, _block_and_sheet, None, None, 6, min_removed=0.2)
    long, _, all_tested = tighten(cube, zeros, _block_and_sheet, None, None, 6)
    assert (tested, all_tested) == (8 * 8, 8 * 8 + 64 * 8)
    assert np.isclose(volume(short), 1.0) and np.isclose(volume(long), 1.0)
    counts = np.zeros(sheet.shape[0], dtype=np.int64)
    ruled, _, ruled_tested = tighten(
        sheet, counts, _block_and_sheet, None, None, 6, min_removed=0.2
    )
    plain, _, plain_tested = tighten(sheet, counts, _block_and_sheet, None, None, 6)
    assert np.array_equal(ruled, plain) and ruled_tested == plain_tested
    assert volume(plain) < 0.5 * volume(sheet)
    both = np.concatenate([cube, sheet])  # calls 1 and 2 remove 27 and 18 % of what they cut
    counts = np.zeros(both.shape[0], dtype=np.int64)
    mixed, _, mixed_tested = tighten(both, counts, _block_and_sheet, None, None, 9, min_removed=0.2)
    first = tighten(both, counts, _block_and_sheet, None, None, 3)[0]
    second, _, second_tested = tighten(both, counts, _block_and_sheet, None, None, 6)
    deep_tested = tighten(both, counts, _block_and_sheet, None, None, 9)[2]
    assert 1.0 - volume(first) / volume(both) > 0.2 > 1.0 - volume(second) / volume(first)
    assert np.array_equal(mixed, second) and mixed_tested == second_tested < deep_tested
    rng = np.random.default_rng(7)
    points = rng.uniform([0.0, 0.0, 0.0], [4.0, 2.0, 1.75], (100000, 3))
    x, y = points[:20000, 0], points[:20000, 1]
    points[:20000, 2] = 0.3 * x + 0.2 * y + rng.uniform(-0.02, 0.02, 20000)
    in_cube = np.all((points >= 0.0) & (points <= 1.0), axis=1)
    on_sheet = np.abs(points[:, 2] - 0.3 * points[:, 0] - 0.2 * points[:, 1]) <= 0.02
    on_sheet &= (points[:, 0] >= 2.0) & (points[:, 2] >= 0.5) & (points[:, 2] <= 1.75)
    assert np.count_nonzero(in_cube) > 5000 and np.count_nonzero(on_sheet) > 5000
    assert contains_points(short, points[in_cube]).any(axis=0).all()
    assert contains_points(ruled, points[on_sheet]).any(axis=0).all()
    assert contains_points(mixed, points[in_cube | on_sheet]).any(axis=0).all()


def test_the_pipeline_s_pass_ends_on_calls_that_remove_little_and_stays_sound(monkeypatch):
    """:func:`intervals.localize.localize` hands the pass
    :data:`intervals.tighten.MIN_REMOVED_SHARE`: for random rooms the pass tests at most as
    many pieces as without the rule, and every sampled pose that explains all but ``q``
    readings stays in the set."""
    import intervals.localize as loc

    seen, tighten_pass = [], loc.tighten

    def passing(*args, **kwargs):
        boxes, counts, tested = tighten_pass(*args, **kwargs)
        seen.append((kwargs["min_removed"], tested))
        return boxes, counts, tested

    monkeypatch.setattr(loc, "tighten", passing)
    kept = 0
    for rng, scan, params, truth, q, prior, plain in _plain_cases(34, [0.4, 0.4, 0.2]):
        ruled = localize(scan, prior, 0.05, q=q, tighten_levels=9)
        monkeypatch.setattr(loc, "MIN_REMOVED_SHARE", 0.0)
        full = localize(scan, prior, 0.05, q=q, tighten_levels=9)
        monkeypatch.setattr(loc, "MIN_REMOVED_SHARE", MIN_REMOVED_SHARE)
        (rule, ruled_tested), (none, full_tested) = seen[-2:]
        assert (rule, none) == (MIN_REMOVED_SHARE, 0.0) and 0 < ruled_tested <= full_tested
        assert full.volume() <= ruled.volume() < plain.volume()
        poses = _poses_in(plain.outer, truth, rng, 2000)
        fits = wrong_readings(poses, scan, params) <= q
        assert not np.any(fits & ~contains_points(ruled.outer, poses).any(axis=0))
        kept += int(np.count_nonzero(fits))
    assert kept > 200  # the check saw consistent poses


@pytest.mark.parametrize("scaled, with_idle", list(itertools.product((False, True), repeat=2)))
def test_the_compiled_cuts_and_clamp_give_the_numpy_pieces_bit_for_bit(scaled, with_idle):
    """:func:`_pieces` against ``cuts`` calls of :func:`bisect` (idle axes of piece ``n``
    those of parent ``n % P``): the same boxes in the same order, every sampled point of a
    parent in one of its pieces (they cover it: nothing is lost); :func:`_clamped` against
    the numpy clamp of the pass, a NaN (emptied) row and an empty clamp left out."""
    rng = np.random.default_rng(7)
    lo = rng.uniform(-3, 3, (40, 3, 1))
    parents = np.concatenate([lo, lo + rng.uniform(0.01, 2, (40, 3, 1))], axis=-1)
    parents[5, 1] = [0.0, 0.0]  # a zero width
    scale = np.array([1.0, 0.7, 1.5]) if scaled else None
    still = rng.random((40, 3)) < 0.3 if with_idle else None
    if still is not None:
        still[3] = True  # idle along every axis: cut along its widest axis, as bisect does
    for cuts in (1, 2, 3):
        expected = parents
        for _ in range(cuts):
            axes = None if still is None else np.resize(still, expected.shape[:2])
            expected = np.concatenate(bisect(expected, scale, axes))
        got = _pieces(parents, scale, still, cuts)
        assert got.tobytes() == expected.tobytes()
        points = (
            parents[:, None, :, 0]
            + rng.random((40, 50, 3)) * np.diff(parents, axis=-1)[..., 0][:, None]
        )
        for n in range(40):
            mine = got[n::40]
            assert np.all(contains_points(mine, points[n]).any(axis=0))
    pieces = _pieces(parents, scale, still, 3)
    contracted = pieces + rng.uniform(-0.05, 0.05, pieces.shape)
    contracted[10] = np.nan
    contracted[11, 0] = [pieces[11, 0, 1] + 1, pieces[11, 0, 1] + 2]  # beyond the piece: empty
    c = np.stack(
        [
            np.maximum(contracted[..., 0], pieces[..., 0]),
            np.minimum(contracted[..., 1], pieces[..., 1]),
        ],
        axis=-1,
    )
    full = np.all(c[..., 0] <= c[..., 1], axis=1)
    kept, got_full = _clamped(contracted, pieces)
    assert np.array_equal(got_full, full) and not full[10] and not full[11]
    assert kept.tobytes() == c[full].tobytes()


def test_bad_levels_are_refused():
    rng = np.random.default_rng(0)
    scan, _, truth = random_scan_case(rng, 0.2, False)
    prior = np.stack([truth - 0.1, truth + 0.1], axis=-1)
    for levels in (-1, MAX_LEVELS + 1, 1.5, True):
        with pytest.raises(IntervalError, match="tighten_levels must be"):
            localize(scan, prior, 0.05, tighten_levels=levels)  # type: ignore[arg-type]
    for tests in (-1, 2.5, True):
        with pytest.raises(IntervalError, match="tighten_max_tested must be"):
            localize(scan, prior, 0.05, tighten_levels=3, tighten_max_tested=tests)  # type: ignore[arg-type]
    with pytest.raises(IntervalError, match="tighten: levels must be"):
        tighten(prior[None], np.zeros(1), _disk, None, None, MAX_LEVELS + 1)
    with pytest.raises(IntervalError, match="counts"):
        tighten(prior[None], np.zeros(2), _disk, None, None, 1)
    with pytest.raises(IntervalError):
        TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=1.0, tighten_levels=MAX_LEVELS + 1)


def test_tracker_with_tightening_keeps_the_truth_in_smaller_sets():
    """The tracker, from a box round the truth over a few scans of a still robot: the
    tightened sets hold the truth and are smaller than the plain ones."""
    rng = np.random.default_rng(5)
    scan, _, truth = random_scan_case(rng, np.deg2rad(12.5), echoes_never_lost=True)
    bounds = np.array([[0.0, 10.0], [0.0, 10.0]])
    plain = IntervalTracker(TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=1.0), bounds)
    tight = IntervalTracker(
        TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=1.0, tighten_levels=9), bounds
    )
    previous = {"plain": None, "tight": None}
    for _ in range(3):
        for key, tracker in (("plain", plain), ("tight", tight)):
            result = tracker.step(previous[key], scan, 0.25)
            assert result.consistent and result.paving.contains(truth[None])[0]
            previous[key] = result.paving
    assert previous["tight"].volume() < 0.5 * previous["plain"].volume()
    # under the smallest budget (8 boxes, binding here) the report stays within it, fine, sound
    capped = IntervalTracker(
        TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=1.0, tighten_levels=9, max_boxes=8),
        bounds,
    )
    result = capped.step(previous["plain"], scan, 0.25)
    assert result.consistent and not result.coarse and result.paving.contains(truth[None])[0]
    assert result.paving.outer.shape[0] <= 8
    assert previous["tight"].volume() < result.paving.volume() < previous["plain"].volume()
