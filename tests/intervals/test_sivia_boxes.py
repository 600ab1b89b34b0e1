"""Boxes, subpavings, SIVIA and IMAGESP checked against brute force."""

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from intervals import boxes as bx
from intervals import interval as ia
from intervals.bisection import split_rounds
from intervals.errors import IntervalError
from intervals.imagesp import imagesp, unique_rows
from intervals.sivia import INSIDE, OUTSIDE, UNDECIDED, cut_width, sivia


def range_only_test(landmarks: np.ndarray, ranges: np.ndarray):
    """Box test for ``|p - l_i| in ranges[i]`` for every landmark, by interval arithmetic."""

    def test(boxes):
        dx = ia.sub(boxes[:, None, 0, :], ia.interval(landmarks[None, :, 0]))
        dy = ia.sub(boxes[:, None, 1, :], ia.interval(landmarks[None, :, 1]))
        dist = ia.sqrt(ia.add(ia.sqr(dx), ia.sqr(dy)))  # (N, n, 2)
        out = np.any((dist[..., 1] < ranges[:, 0]) | (dist[..., 0] > ranges[:, 1]), axis=1)
        inside = np.all((dist[..., 0] >= ranges[:, 0]) & (dist[..., 1] <= ranges[:, 1]), axis=1)
        return np.where(out, OUTSIDE, np.where(inside, INSIDE, UNDECIDED)).astype(np.int8)

    return test


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_sivia_range_only_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    landmarks = rng.uniform(-5, 5, size=(rng.integers(2, 4), 2))
    truth = rng.uniform(-3, 3, size=2)
    d = np.linalg.norm(landmarks - truth, axis=1)
    half = rng.uniform(0.1, 0.6, size=d.size)
    ranges = np.stack([d - half, d + half], axis=1)
    box = np.array([[-6.0, 6.0], [-6.0, 6.0]])
    paving = sivia(range_only_test(landmarks, ranges), box, eps=0.1)

    g = np.linspace(-6, 6, 241)
    grid = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    dist = np.linalg.norm(grid[:, None, :] - landmarks[None], axis=-1)
    ok = np.all((dist >= ranges[:, 0]) & (dist <= ranges[:, 1]), axis=1)
    assert ok.any()
    assert np.all(paving.contains(grid[ok])), "a feasible grid point is outside the outer set"
    if paving.inner.shape[0]:
        in_inner = np.any(bx.contains_points(paving.inner, grid[~ok]), axis=0)
        assert not in_inner.any(), "an inner box holds an infeasible grid point"
    assert paving.contains(truth[None])[0]
    assert np.all(bx.max_width(paving.boundary) <= 0.1)


def test_sivia_min_level_boxes_keeps_every_feasible_point_with_fewer_calls():
    """Extra bisections of small levels skip tests but never a feasible point (brute force)."""
    landmarks = np.array([[0.0, 0.0], [4.0, 0.0], [1.0, 3.5]])
    truth = np.array([1.5, 1.0])
    d = np.linalg.norm(landmarks - truth, axis=1)
    ranges = np.stack([d - 0.3, d + 0.3], axis=1)
    test = range_only_test(landmarks, ranges)
    sizes = {1: [], 64: []}
    pavings = {}
    for minimum, calls in sizes.items():
        counted = lambda b, calls=calls: calls.append(b.shape[0]) or test(b)  # noqa: E731
        pavings[minimum] = sivia(
            counted, np.array([[-6.0, 6.0], [-6.0, 6.0]]), eps=0.05, min_level_boxes=minimum
        )
    assert sizes[1][0] == 1 and sizes[64][0] == 64  # the initial box is bisected 6 times first
    assert len(sizes[64]) < len(sizes[1]) and min(sizes[64][:-1]) >= 64 // 2
    g = np.linspace(-6, 6, 241)
    grid = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    dist = np.linalg.norm(grid[:, None, :] - landmarks[None], axis=-1)
    ok = np.all((dist >= ranges[:, 0]) & (dist <= ranges[:, 1]), axis=1)
    for paving in pavings.values():
        assert np.all(paving.contains(grid[ok]))
        assert np.all(bx.max_width(paving.boundary) <= 0.05)
    with pytest.raises(IntervalError, match="min_level_boxes"):
        sivia(test, np.array([[-6.0, 6.0], [-6.0, 6.0]]), eps=0.05, min_level_boxes=0)


def test_sivia_accepts_initial_subpaving_and_checks_preconditions():
    landmarks = np.array([[0.0, 0.0], [4.0, 0.0]])
    ranges = np.array([[2.0, 2.2], [2.8, 3.0]])
    test = range_only_test(landmarks, ranges)
    whole = sivia(test, np.array([[-5.0, 5.0], [-5.0, 5.0]]), eps=0.05)
    halves = np.array([[[-5.0, 0.0], [-5.0, 5.0]], [[0.0, 5.0], [-5.0, 5.0]]])
    split = sivia(test, halves, eps=0.05)
    assert split.volume() == pytest.approx(whole.volume())
    assert whole.components()[0] == 2  # two circle intersections, mirror images about y = 0
    for eps in (0.0, -1.0, np.nan):
        with pytest.raises(IntervalError, match="eps"):
            sivia(test, halves, eps=eps)
    with pytest.raises(IntervalError, match="lower bound above"):
        sivia(test, np.array([[1.0, 0.0], [0.0, 1.0]]), eps=0.1)
    with pytest.raises(IntervalError, match="bounded"):
        sivia(test, np.array([[0.0, np.inf], [0.0, 1.0]]), eps=0.1)
    with pytest.raises(IntervalError, match="max_boxes"):
        sivia(test, halves, eps=0.1, max_boxes=0)
    with pytest.raises(IntervalError, match="max_tested"):
        sivia(test, halves, eps=0.1, max_tested=-1)
    with pytest.raises(IntervalError, match="test returned"):
        sivia(lambda b: np.full(b.shape[0], 7, np.int8), halves, eps=0.1)


def test_sivia_never_cuts_across_the_idle_axes_its_test_reports():
    """A test reporting ``y`` idle (here ``y`` does not enter the constraints, the set is a
    band along ``y``): no box is cut across ``y``, the boundary boxes are as tall as the
    initial box and narrow along ``x``, the set holds every feasible point and only idle
    axes of the right shape are accepted."""

    def band(boxes):  # 1 <= x <= 1.5, any y
        v = np.where((boxes[:, 0, 1] < 1.0) | (boxes[:, 0, 0] > 1.5), OUTSIDE, UNDECIDED)
        v[(boxes[:, 0, 0] >= 1.0) & (boxes[:, 0, 1] <= 1.5)] = INSIDE
        idle = np.zeros(boxes.shape[:2], dtype=bool)
        idle[:, 1] = True
        return v.astype(np.int8), np.zeros(boxes.shape[0]), idle

    box = np.array([[-3.0, 3.0], [-2.0, 2.0]])
    paving = sivia(band, box, eps=0.05)
    outer = paving.outer
    np.testing.assert_array_equal(outer[:, 1], np.broadcast_to(box[1], (outer.shape[0], 2)))
    assert np.all(bx.widths(paving.boundary)[:, 0] <= 0.05)
    g = np.linspace(-3, 3, 601)
    points = np.stack(np.meshgrid(g, np.linspace(-2, 2, 41), indexing="ij"), -1).reshape(-1, 2)
    assert paving.contains(points[(points[:, 0] >= 1.0) & (points[:, 0] <= 1.5)]).all()
    with pytest.raises(IntervalError, match="idle axes"):
        sivia(lambda b: band(b)[:2] + (np.zeros(b.shape[0], bool),), box, eps=0.05)


def test_sivia_in_chunks_and_under_a_test_budget():
    """A frontier larger than ``max_boxes`` is tested in chunks (no call sees more, same
    set); with ``max_tested`` the paving stops, is marked coarse, and still covers the set
    (every point of the fine outer set, which holds the set, is in the coarse one); an
    everywhere-undecided test at a tiny eps (10^8 boxes at the end) stops in bounded work."""
    rng = np.random.default_rng(2)
    landmarks = np.array([[0.0, 0.0], [4.0, 0.0]])
    ranges = np.array([[2.0, 2.2], [2.8, 3.0]])  # two lenses, mirror images about y = 0
    seen = []

    def test(boxes):
        seen.append(boxes.shape[0])
        return range_only_test(landmarks, ranges)(boxes)

    box = np.array([[-5.0, 5.0], [-5.0, 5.0]])
    whole = sivia(test, box, eps=0.01)
    assert not whole.coarse and max(seen) > 200
    seen.clear()
    chunked = sivia(test, box, eps=0.01, max_boxes=60)
    assert max(seen) <= 60 and not chunked.coarse
    order = np.lexsort(whole.boundary.reshape(-1, 4).T)
    np.testing.assert_array_equal(
        np.sort(chunked.boundary.reshape(-1, 4), axis=0),
        np.sort(whole.boundary.reshape(-1, 4), axis=0),
    )
    assert order.size == chunked.boundary.shape[0]
    points = np.concatenate(
        [rng.uniform(b[:, 0], b[:, 1], size=(20, 2)) for b in whole.outer]
    )  # points of the fine outer set
    for budget in (0, 10, 200, 1000):  # the whole paving tests 1169 boxes
        seen.clear()
        coarse = sivia(test, box, eps=0.01, max_boxes=60, max_tested=budget)
        assert sum(seen) <= budget and coarse.coarse
        assert coarse.contains(points).all()
    seen.clear()
    undecided = sivia(
        lambda b: (seen.append(b.shape[0]), np.full(b.shape[0], UNDECIDED, np.int8))[1],
        box,
        eps=1e-4,
        max_boxes=1000,
        max_tested=20_000,
    )
    assert undecided.coarse and sum(seen) <= 20_000 and undecided.boundary.shape[0] < 30_000
    assert undecided.contains(rng.uniform(-5, 5, size=(1000, 2))).all()


def test_bisect_scaled_axis_and_union():
    box = np.array([[[0.0, 1.0], [0.0, 0.8], [-0.5, 0.5]]])
    left, right = bx.bisect(box, bx.pose_scale(2.0))  # heading width 1 rad -> 2 m: widest
    assert left[0, 2, 1] == right[0, 2, 0] == 0.0
    left, right = bx.bisect(box, bx.pose_scale(0.5))
    assert left[0, 0, 1] == 0.5
    assert bx.volume(np.concatenate([left, right])) == pytest.approx(bx.volume(box))


def test_compiled_bisect_gives_the_numpy_expressions_bit_for_bit():
    """``bisect`` against its numpy expressions (widths times the scale, ``-1`` on idle axes
    unless all are idle, ``np.argmax``, ``centres``) on random boxes of 1 to 4 dimensions with
    tied widths, zero and subnormal widths, whole lines (``inf`` width: a NaN cut) and none:
    the same halves, bit for bit."""
    rng = np.random.default_rng(23)
    for trial in range(300):
        n, d = int(rng.integers(0, 40)), int(rng.integers(1, 5))
        lo = rng.normal(0.0, 10.0, (n, d))
        width = rng.choice([0.0, 5e-324, 1e-9, 0.5, 1.0, 3.0], (n, d))
        boxes = np.stack([lo, lo + width], axis=-1)
        if n and trial % 5 == 0:
            boxes[0, int(rng.integers(d))] = [-np.inf, np.inf]
        scale = None if trial % 2 else rng.choice([0.5, 1.0, 2.0], d)
        idle = None if trial % 3 == 0 else rng.random((n, d)) < 0.5
        with np.errstate(invalid="ignore"):  # inf - inf in a whole line's centre
            w = bx.widths(boxes, scale)
            if idle is not None:
                w = np.where(idle & ~np.all(idle, axis=1, keepdims=True), -1.0, w)
            axis, rows = np.argmax(w, axis=-1), np.arange(n)
            cut = bx.centres(boxes)[rows, axis]
            left, right = bx.bisect(boxes, scale, idle)
        expected_left, expected_right = boxes.copy(), boxes.copy()
        expected_left[rows, axis, 1] = cut
        expected_right[rows, axis, 0] = cut
        np.testing.assert_array_equal(left, expected_left)
        np.testing.assert_array_equal(right, expected_right)


def _numpy_split_rounds(boxes, eps, scale, times, idle):
    """The bisection rounds as numpy passes (what SIVIA ran before the compiled call): each
    round every left child, then every right child, cut along the first widest scaled axis not
    ``idle (N, d)`` of its box; the narrow ones (along their axes not idle) set aside in round
    order, the still wide ones last; with the row of the parent of each."""
    done, parents, todo, owners = [], [], boxes, np.arange(boxes.shape[0])
    for _ in range(times):
        rows = np.arange(todo.shape[0])
        axis = np.argmax(np.where(idle[owners], -1.0, bx.widths(todo, scale)), axis=-1)
        cut = bx.centres(todo)[rows, axis]
        left, right = todo.copy(), todo.copy()
        left[rows, axis, 1] = cut
        right[rows, axis, 0] = cut
        children, owners = np.concatenate([left, right]), np.concatenate([owners, owners])
        wide = cut_width(children, scale, idle[owners]) > eps
        done.append(children[~wide])
        parents.append(owners[~wide])
        todo, owners = children[wide], owners[wide]
    return np.concatenate([*done, todo]), np.concatenate([*parents, owners])


def test_compiled_bisection_rounds_give_the_numpy_rounds_children_in_order():
    """``split_rounds`` against the numpy rounds on random boxes of 1 to 4 dimensions whose
    widths tie often (the first widest axis is cut), without idle axes and with random ones: the
    same children bit for bit, in the same order, with the same parents; no child is cut across
    an idle axis of its parent; each child lies in its parent and the children of a parent fill
    it (volumes add up)."""
    rng = np.random.default_rng(8)
    checked = 0
    for trial in range(400):
        n, d = int(rng.integers(1, 120)), int(rng.integers(1, 5))
        lo = rng.uniform(-5, 5, (n, d))
        width = rng.choice([0.05, 0.1, 0.2, 0.7, 1.3], (n, d)) * rng.choice([1.0, 0.5], (n, d))
        boxes = np.stack([lo, lo + width], axis=-1)
        scale = rng.choice([0.5, 1.0, 2.0], d)
        eps = float(rng.choice([0.049, 0.1, 0.3]))
        idle = (rng.random((n, d)) < 0.4) if trial % 2 else np.zeros((n, d), dtype=bool)
        wide = cut_width(boxes, scale, idle) > eps
        boxes, idle = boxes[wide], idle[wide]
        if boxes.shape[0] == 0:
            continue
        for times in (1, 3, 6):
            children, parents = split_rounds(boxes, eps, scale, times, idle)
            expected, expected_parents = _numpy_split_rounds(boxes, eps, scale, times, idle)
            np.testing.assert_array_equal(children, expected)
            np.testing.assert_array_equal(parents, expected_parents)
            assert bx.contains_boxes(boxes[parents], children).all()
            kept = np.where(idle[parents][..., None], boxes[parents], children)
            np.testing.assert_array_equal(kept, children)  # idle axes: the parent's interval
            sums = np.bincount(parents, np.prod(bx.widths(children), axis=1), boxes.shape[0])
            np.testing.assert_allclose(sums, np.prod(bx.widths(boxes), axis=1), rtol=1e-12)
            checked += children.shape[0]
    assert checked > 20_000


def test_area_xy_matches_shapely_union():
    rng = np.random.default_rng(3)
    lo = rng.uniform(0, 10, size=(200, 3))
    boxes = np.stack([lo, lo + rng.uniform(0.1, 2, size=(200, 3))], axis=-1)
    union = shapely.union_all([shapely.box(b[0, 0], b[1, 0], b[0, 1], b[1, 1]) for b in boxes])
    assert bx.area_xy(boxes) == pytest.approx(union.area, rel=1e-12)


def test_components_join_across_the_heading_cut():
    boxes = np.array(
        [
            [[0, 1], [0, 1], [3.0, np.pi]],
            [[0.5, 1.5], [0, 1], [-np.pi, -3.0]],  # same place, heading across +-pi
            [[5, 6], [5, 6], [0, 1]],
        ],
        dtype=float,
    )
    count, labels = bx.connected_components(boxes, periodic_axis=2)
    assert count == 2 and labels[0] == labels[1] != labels[2]
    assert bx.connected_components(boxes)[0] == 3


@pytest.mark.slow
def test_imagesp_encloses_image_of_random_points():
    """Rotation by an uncertain angle plus translation, checked on 20 000 random points."""
    rng = np.random.default_rng(7)
    angle = ia.interval(0.3, 0.35)

    def f(b):
        c, s = ia.cos(angle), ia.sin(angle)
        x, y = b[:, 0], b[:, 1]
        nx = ia.add(ia.sub(ia.mul(c, x), ia.mul(s, y)), ia.interval(1.0))
        ny = ia.add(ia.mul(s, x), ia.mul(c, y))
        return np.stack([nx, ny], axis=1)

    src = np.array([[[0.0, 1.0], [0.0, 0.5]], [[2.0, 2.3], [1.0, 2.0]]])
    cells = imagesp(f, src, eps=0.05)
    pitch = 0.05
    np.testing.assert_allclose(cells[..., 1] - cells[..., 0], pitch, atol=1e-12)
    k = rng.integers(0, 2, 20_000)
    u = rng.uniform(size=(20_000, 2))
    pts = src[k, :, 0] + u * (src[k, :, 1] - src[k, :, 0])
    a = rng.uniform(0.3, 0.35, 20_000)
    img = np.stack(
        [
            np.cos(a) * pts[:, 0] - np.sin(a) * pts[:, 1] + 1.0,
            np.sin(a) * pts[:, 0] + np.cos(a) * pts[:, 1],
        ],
        axis=1,
    )
    assert np.all(np.any(bx.contains_points(cells, img), axis=0))
    assert bx.area_xy(cells) < 1.5 * (0.5 + 0.3) + 0.5  # regular, not the hull of everything
    with pytest.raises(IntervalError, match="max_cells"):
        imagesp(f, src, eps=0.001, max_cells=1000)


def test_inflate_grows_every_side_and_refuses_negative_margins():
    box = np.array([[[0.0, 1.0], [2.0, 3.0], [-0.1, 0.1]]])
    grown = bx.inflate(box, [0.5, 0.5, 0.2])
    assert np.all(grown[..., 0] <= box[..., 0] - [0.5, 0.5, 0.2])
    assert np.all(grown[..., 1] >= box[..., 1] + [0.5, 0.5, 0.2])
    assert bx.contains_boxes(grown, box).all()
    with pytest.raises(IntervalError, match="margins"):
        bx.inflate(box, [-1.0, 0.0, 0.0])


def test_wrap_headings_keeps_every_pose():
    rng = np.random.default_rng(9)
    lo = rng.uniform(-12, 12, size=(500, 3))
    w = rng.uniform(0, 1.5, size=(500, 3))
    w[:20, 2] = 7.0  # wider than a turn
    boxes = np.stack([lo, lo + w], axis=-1)
    wrapped = bx.wrap_headings(boxes)
    assert np.all(wrapped[:, 2, 0] >= -np.pi - 1e-15) and np.all(wrapped[:, 2, 1] <= np.pi + 1e-15)
    u = rng.uniform(size=(500, 20, 3))
    pts = (boxes[:, None, :, 0] + u * w[:, None, :]).reshape(-1, 3)
    pts[:, 2] = np.mod(pts[:, 2] + np.pi, 2 * np.pi) - np.pi
    assert np.all(np.any(bx.contains_points(wrapped, pts), axis=0))


def test_imagesp_unique_rows_equals_numpy_unique():
    """IMAGESP's cell deduplication returns exactly ``np.unique(idx, axis=0)`` (rows and order)."""
    rng = np.random.default_rng(7)
    for rows, cols, spread in [(1, 3, 2), (50, 3, 3), (400, 3, 5), (300, 2, 1000), (200, 1, 4)]:
        idx = rng.integers(-spread, spread, size=(rows, cols), dtype=np.int64)
        np.testing.assert_array_equal(unique_rows(idx), np.unique(idx, axis=0))


def _brute_components(boxes, periodic_axis=None, period=2.0 * np.pi):
    """The all-pairs definition: boxes ``i, j`` touch when their closed intervals meet on every
    axis (the periodic one also shifted by -+period); components by a depth-first search."""
    lo, hi = boxes[:, None, :, 0], boxes[:, None, :, 1]
    lo_t, hi_t = boxes[None, :, :, 0], boxes[None, :, :, 1]
    touch = (lo <= hi_t) & (lo_t <= hi)
    if periodic_axis is not None:
        a = periodic_axis
        for shift in (-period, period):
            touch[..., a] |= (lo[..., a] + shift <= hi_t[..., a]) & (
                lo_t[..., a] <= hi[..., a] + shift
            )
    adjacent = np.all(touch, axis=-1)
    labels = np.full(boxes.shape[0], -1)
    count = 0
    for start in range(boxes.shape[0]):
        if labels[start] >= 0:
            continue
        stack, labels[start] = [start], count
        while stack:
            node = stack.pop()
            for other in np.flatnonzero(adjacent[node] & (labels < 0)):
                labels[other] = count
                stack.append(other)
        count += 1
    return count, labels


def _random_grid_boxes(rng, n, d, cells):
    """Boxes with integer bounds on a small grid: shared faces, edges and corners are common."""
    lo = rng.integers(0, cells, size=(n, d))
    width = rng.integers(0, 3, size=(n, d))
    return np.stack([lo, lo + width], axis=-1).astype(float)


def _components_every_sweep_axis(boxes, periodic_axis=None, period=2.0 * np.pi):
    """``[(count, labels)]``: :func:`bx.connected_components`, then its sweep along each axis
    in turn (the periodic one included: the sweep over shifted copies), without slabs and with
    1, 3 and ``N`` slabs of each other non-periodic axis."""
    found = [bx.connected_components(boxes, periodic_axis, period)]
    lo = np.ascontiguousarray(boxes[..., 0])
    hi = np.ascontiguousarray(boxes[..., 1])
    periodic = -1 if periodic_axis is None else periodic_axis
    d = boxes.shape[1]
    for axis in range(d):
        slabbed = [(-1, 1)] + [
            (slab_axis, slabs)
            for slab_axis in range(d)
            if slab_axis not in (axis, periodic_axis)
            for slabs in (1, 3, boxes.shape[0])
        ]
        for slab_axis, slabs in slabbed:
            labels = bx._sweep_components(lo, hi, axis, slab_axis, slabs, periodic, period)
            found.append((int(labels.max()) + 1, labels))
    return found


def test_components_equal_the_all_pairs_partition():
    """Random box sets (1, 2 and 3 axes, with and without a periodic heading; flat boxes, shared
    faces, edges and corners common) give the partition and the labels of the all-pairs
    definition, with the sweep along every axis."""
    rng = np.random.default_rng(5)
    corner = np.array([[[0, 1], [0, 1]], [[1, 2], [1, 2]], [[2.5, 3], [0, 1]]], dtype=float)
    count, labels = bx.connected_components(corner)  # a shared corner connects
    assert count == 2 and tuple(labels) == (0, 0, 1)
    for trial in range(400):
        d = 1 + trial % 3
        boxes = _random_grid_boxes(rng, int(rng.integers(1, 80)), d, int(rng.integers(3, 15)))
        periodic = None
        if trial % 4 == 1:  # headings on a turn of 8 units near the cut
            periodic = d - 1
            boxes[:, periodic] = boxes[:, periodic] % 8 - 4
            boxes[:, periodic, 1] = np.maximum(boxes[:, periodic, 1], boxes[:, periodic, 0])
        period = 8.0 if periodic is not None else 2.0 * np.pi
        expected_count, expected = _brute_components(boxes, periodic, period)
        for count, labels in _components_every_sweep_axis(boxes, periodic, period):
            assert count == expected_count
            np.testing.assert_array_equal(labels, expected)  # same partition, same numbering


def test_components_of_one_periodic_axis():
    """d = 1, the axis periodic: intervals joined across the wrap and only there."""
    rng = np.random.default_rng(8)
    for _ in range(100):
        lo = rng.uniform(-np.pi, np.pi, size=int(rng.integers(1, 30)))
        boxes = np.stack([lo, lo + rng.uniform(0, 0.5, size=lo.size)], axis=-1)[:, None, :]
        count, labels = bx.connected_components(boxes, 0)
        expected_count, expected = _brute_components(boxes, 0)
        assert count == expected_count
        np.testing.assert_array_equal(labels, expected)


@pytest.mark.slow
def test_components_of_a_large_paving():
    """200 000 boxes of a regular paving in three strips (x, y, heading): three components.
    The all-pairs definition would need 200 000^2 x 3 bytes (120 GB)."""
    nx, ny, nt = 500, 20, 20
    ix, iy, it = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nt), indexing="ij")
    keep = iy % 7 != 6  # strips of 6 rows of cells, 1 row apart
    cells = (
        np.stack([ix[keep], iy[keep], it[keep]], axis=-1).astype(float) * 0.0625
    )  # exact neighbours
    boxes = np.stack([cells, cells + 0.0625], axis=-1)
    count, labels = bx.connected_components(boxes)
    assert boxes.shape[0] > 150_000 and count == 3
    np.testing.assert_array_equal(labels, iy[keep] // 7)


@pytest.mark.slow
def test_components_of_mixed_sizes():
    """Float boxes of sizes spread over three orders of magnitude (a paving's boxes, some of
    them flat, and wide ones), with and without a periodic heading: the partition and labels
    of the all-pairs definition, with the sweep along every axis."""
    rng = np.random.default_rng(11)
    for trial in range(120):
        n = int(rng.integers(65, 1500))
        lo = rng.uniform(-3.0, 3.0, size=(n, 3))
        width = rng.uniform(0.05, 0.1, size=(n, 3))
        width[rng.uniform(size=n) < 0.05] = 0.0
        wide = rng.uniform(size=n) < (0.15, 0.6, 0.0)[trial % 3]
        width[wide] = 10.0 ** rng.uniform(-1, 0.5, size=(np.count_nonzero(wide), 3))
        boxes = np.stack([lo, lo + width], axis=-1)
        periodic = 2 if trial % 2 else None
        expected_count, expected = _brute_components(boxes, periodic)
        for count, labels in _components_every_sweep_axis(boxes, periodic):
            assert count == expected_count
            np.testing.assert_array_equal(labels, expected)


def test_clip_to_boxes_and_meets_any_box_equal_the_definitions():
    """Random boxes and regions on a small grid (touching faces and flat boxes common): the
    clipped boxes are the hulls of the intersections (empty rows ``+inf, -inf`` for a box
    meeting no region), ``held`` says a region contains the box, ``meets_any_box`` says a
    region meets it; every grid point of a box lying in a region stays in its clipped box."""
    rng = np.random.default_rng(12)
    for _ in range(300):
        boxes = _random_grid_boxes(rng, int(rng.integers(0, 60)), 3, 8)
        regions = _random_grid_boxes(rng, int(rng.integers(1, 20)), 3, 8)
        clipped, held = bx.clip_to_boxes(boxes, regions)
        lo = np.maximum(boxes[:, None, :, 0], regions[None, :, :, 0])  # (N, M, d)
        hi = np.minimum(boxes[:, None, :, 1], regions[None, :, :, 1])
        meets = np.all(lo <= hi, axis=2)
        np.testing.assert_array_equal(bx.meets_any_box(boxes, regions), meets.any(axis=1))
        expected_lo = np.where(meets[..., None], lo, np.inf).min(axis=1, initial=np.inf)
        expected_hi = np.where(meets[..., None], hi, -np.inf).max(axis=1, initial=-np.inf)
        np.testing.assert_array_equal(clipped[..., 0], expected_lo)
        np.testing.assert_array_equal(clipped[..., 1], expected_hi)
        inside = bx.contains_boxes(regions[None], boxes[:, None])  # (N, M)
        np.testing.assert_array_equal(held, inside.any(axis=1))
        points = rng.integers(0, 10, size=(200, 3)).astype(float)
        in_region = bx.contains_points(regions, points).any(axis=0)  # (P,)
        for box, clip in zip(boxes, clipped, strict=True):
            kept = bx.contains_points(box[None], points)[0] & in_region
            assert bx.contains_points(clip[None], points[kept]).all()


def test_merge_adjacent_keeps_the_union_exactly_in_fewer_boxes():
    """Random subsets of a regular grid of pose cells (exact binary bounds, so neighbours
    share bounds) and the boundary of a real SIVIA paving: the merged boxes hold every
    point of the input and no point outside it (checked on points of the merged boxes,
    against the input boxes), they do not overlap (volume equal to the input's), and a full
    row of cells becomes one box."""
    rng = np.random.default_rng(8)
    cells = np.stack(np.meshgrid(*(np.arange(n) for n in (16, 8, 4)), indexing="ij"), -1)
    cells = cells.reshape(-1, 3) * 0.125
    for share in (0.3, 0.7, 1.0):
        lo = cells[rng.random(len(cells)) < share]
        boxes = np.stack([lo, lo + 0.125], axis=-1)
        merged = bx.merge_adjacent(boxes)
        assert merged.shape[0] < boxes.shape[0]
        assert bx.volume(merged) == pytest.approx(bx.volume(boxes), rel=1e-12)
        inside = rng.uniform(boxes[..., 0], boxes[..., 1])
        assert bx.contains_points(merged, inside).any(axis=0).all()
        # points strictly inside merged boxes lie in some input box
        probe = rng.uniform(merged[..., 0], merged[..., 1])
        assert bx.contains_points(boxes, probe).any(axis=0).all()
    assert bx.merge_adjacent(np.stack([cells, cells + 0.125], axis=-1)).shape[0] == 1
    landmarks = np.array([[0.0, 0.0], [4.0, 0.0]])
    paving = sivia(
        range_only_test(landmarks, np.array([[2.0, 2.6], [2.4, 3.0]])),
        np.array([[-5.0, 5.0], [-5.0, 5.0]]),
        eps=0.02,
    )
    merged = bx.merge_adjacent(paving.boundary)
    assert merged.shape[0] < 0.75 * paving.boundary.shape[0]
    assert bx.volume(merged) == pytest.approx(bx.volume(paving.boundary), rel=1e-12)
    assert bx.area_xy(merged) == pytest.approx(bx.area_xy(paving.boundary), rel=1e-12)
    probe = rng.uniform(merged[..., 0], merged[..., 1])
    assert bx.contains_points(paving.boundary, probe).any(axis=0).all()


def test_sivia_under_a_budget_bisects_the_lowest_scores_first():
    """A test that scores every box by its distance to a target point: under a budget SIVIA
    reaches eps next to the target first (the boxes it left whole lie away from it), without
    a budget the scores change nothing (the same boxes, in the same order)."""
    target = np.array([3.0, -2.0])

    def scored(boxes):
        verdicts = np.full(boxes.shape[0], UNDECIDED, np.int8)
        return verdicts, np.linalg.norm(bx.centres(boxes) - target, axis=1)

    def plain(boxes):
        return scored(boxes)[0]

    box = np.array([[-5.0, 5.0], [-5.0, 5.0]])
    np.testing.assert_array_equal(
        sivia(scored, box, eps=0.3).boundary, sivia(plain, box, eps=0.3).boundary
    )
    cut = sivia(scored, box, eps=0.01, max_boxes=200, max_tested=3000)
    fine = bx.max_width(cut.boundary) <= 0.01
    assert cut.coarse and fine.any() and (~fine).any()
    assert cut.contains(target[None])[0]
    near = np.linalg.norm(bx.centres(cut.boundary[fine]) - target, axis=1).max()
    far = np.linalg.norm(bx.centres(cut.boundary[~fine]) - target, axis=1).min()
    assert near < far + 0.5  # the fine boxes cluster round the target
    assert near < 1.0
