"""Boxes, subpavings, SIVIA and IMAGESP checked against brute force."""

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from intervals import boxes as bx
from intervals import interval as ia
from intervals.errors import IntervalError
from intervals.imagesp import _unique_rows, imagesp
from intervals.sivia import INSIDE, OUTSIDE, UNDECIDED, sivia


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
        sivia(lambda b: np.full(b.shape[0], UNDECIDED, np.int8), halves, eps=1e-3, max_boxes=100)
    with pytest.raises(IntervalError, match="test returned"):
        sivia(lambda b: np.full(b.shape[0], 7, np.int8), halves, eps=0.1)


def test_bisect_scaled_axis_and_union():
    box = np.array([[[0.0, 1.0], [0.0, 0.8], [-0.5, 0.5]]])
    left, right = bx.bisect(box, bx.pose_scale(2.0))  # heading width 1 rad -> 2 m: widest
    assert left[0, 2, 1] == right[0, 2, 0] == 0.0
    left, right = bx.bisect(box, bx.pose_scale(0.5))
    assert left[0, 0, 1] == 0.5
    assert bx.volume(np.concatenate([left, right])) == pytest.approx(bx.volume(box))


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
        np.testing.assert_array_equal(_unique_rows(idx), np.unique(idx, axis=0))
