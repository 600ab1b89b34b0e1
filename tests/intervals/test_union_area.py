"""The union area of boxes' (x, y) projections (``intervals.boxes.area_xy``, a sweep line with a
segment tree) against the raster it replaced, shapely's polygon union and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from shapely.ops import unary_union

from intervals.boxes import area_xy
from intervals.union_area import union_area


def raster_area(boxes: np.ndarray) -> float:
    """The previous ``area_xy`` (the oracle): the projections rasterised on the grid of their
    own edge coordinates with a 2-D difference array, covered cells summed. ``O(N^2)`` memory."""
    if boxes.shape[0] == 0:
        return 0.0
    xs = np.unique(boxes[:, 0, :])
    ys = np.unique(boxes[:, 1, :])
    i0, i1 = np.searchsorted(xs, boxes[:, 0, 0]), np.searchsorted(xs, boxes[:, 0, 1])
    j0, j1 = np.searchsorted(ys, boxes[:, 1, 0]), np.searchsorted(ys, boxes[:, 1, 1])
    cover = np.zeros((xs.size + 1, ys.size + 1), dtype=np.int64)
    np.add.at(cover, (i0, j0), 1)
    np.add.at(cover, (i1, j0), -1)
    np.add.at(cover, (i0, j1), -1)
    np.add.at(cover, (i1, j1), 1)
    covered = np.cumsum(np.cumsum(cover, axis=0), axis=1)[:-2, :-2] > 0
    cell_area = np.outer(np.diff(xs), np.diff(ys))
    return float(np.sum(cell_area[covered]))


def boxes_from(lo_x, hi_x, lo_y, hi_y, d: int = 2) -> np.ndarray:
    """Boxes ``(N, d, 2)`` with the given (x, y) bounds and, beyond y, the interval [0, 1]."""
    n = len(lo_x)
    b = np.zeros((n, d, 2))
    b[:, 0, 0], b[:, 0, 1], b[:, 1, 0], b[:, 1, 1] = lo_x, hi_x, lo_y, hi_y
    b[:, 2:, 1] = 1.0
    return b


def random_boxes(rng: np.random.Generator, n: int, kind: str, d: int = 3) -> np.ndarray:
    """``n`` random boxes of one of the families the tests sweep over."""
    if kind == "overlapping":  # wide boxes in a small square: most pairs overlap
        lo = rng.uniform(0.0, 1.0, (n, 2))
        hi = lo + rng.uniform(0.0, 0.6, (n, 2))
    elif kind == "grid":  # edges on a coarse lattice: shared edges, many equal coordinates
        lo = rng.integers(0, 12, (n, 2)) * 0.25
        hi = lo + rng.integers(0, 4, (n, 2)) * 0.25  # width 0: flat boxes, about 1 in 4 axes
    elif kind == "nested":  # boxes of shrinking size about a few centres
        centre = rng.uniform(-5.0, 5.0, (4, 2))[rng.integers(0, 4, n)]
        half = rng.uniform(0.01, 1.0, (n, 2))
        lo, hi = centre - half, centre + half
    elif kind == "sparse":  # small boxes over a large hall: few overlaps
        lo = rng.uniform(-50.0, 50.0, (n, 2))
        hi = lo + rng.exponential(0.3, (n, 2))
    else:
        raise ValueError(kind)
    return boxes_from(lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1], d)


KINDS = ["overlapping", "grid", "nested", "sparse"]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("n", [1, 2, 7, 60, 500, 2000])
def test_matches_the_raster(kind, n):
    rng = np.random.default_rng([n, KINDS.index(kind)])
    boxes = random_boxes(rng, n, kind)
    expected = raster_area(boxes)
    assert area_xy(boxes) == pytest.approx(expected, rel=1e-12, abs=1e-300)


@pytest.mark.parametrize("seed", range(20))
def test_matches_shapely_union(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    boxes = random_boxes(rng, n, KINDS[seed % len(KINDS)])
    b = boxes[:, :2]
    union = unary_union(shapely.box(b[:, 0, 0], b[:, 1, 0], b[:, 0, 1], b[:, 1, 1]))
    assert area_xy(boxes) == pytest.approx(union.area, rel=1e-12, abs=1e-300)


def test_disjoint_boxes_add_up():
    # a 30 x 30 checkerboard of unit cells, each shrunk to [i, i + 0.5] x [j, j + 0.25]
    i, j = np.meshgrid(np.arange(30.0), np.arange(30.0))
    boxes = boxes_from(i.ravel(), i.ravel() + 0.5, j.ravel(), j.ravel() + 0.25)
    assert area_xy(boxes) == 900 * 0.125


def test_boxes_touching_along_edges_add_up():
    x = np.arange(10.0)
    boxes = boxes_from(x, x + 1.0, x % 3, x % 3 + 2.0)  # neighbours share the edge x = k
    assert area_xy(boxes) == 20.0


def test_a_box_inside_another_counts_once():
    outer = boxes_from([0.0], [4.0], [-1.0], [1.0])
    inner = boxes_from([1.0, 1.5, 0.0], [2.0, 1.75, 4.0], [-0.5, 0.0, -1.0], [0.5, 1.0, 1.0])
    for order in (np.concatenate((outer, inner)), np.concatenate((inner, outer))):
        assert area_xy(order) == 8.0


def test_two_overlapping_boxes_inclusion_exclusion():
    rng = np.random.default_rng(3)
    for _ in range(200):
        lo = rng.uniform(0.0, 1.0, (2, 2))
        hi = lo + rng.uniform(0.0, 1.0, (2, 2))
        overlap = np.prod(np.clip(hi.min(axis=0) - lo.max(axis=0), 0.0, None))
        expected = np.prod(hi - lo, axis=1).sum() - overlap
        boxes = boxes_from(lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1])
        assert area_xy(boxes) == pytest.approx(expected, rel=1e-14)


def test_flat_and_empty_sets():
    assert area_xy(np.zeros((0, 3, 2))) == 0.0
    flat = boxes_from([0.0, 1.0, 2.0], [0.0, 3.0, 2.0], [0.0, 1.0, 5.0], [1.0, 1.0, 6.0])
    assert area_xy(flat) == 0.0  # a vertical segment, a horizontal one, a second vertical
    square = boxes_from([0.0], [1.0], [0.0], [1.0])
    assert area_xy(np.concatenate((flat, square))) == 1.0


def test_ignores_axes_beyond_y():
    rng = np.random.default_rng(5)
    boxes = random_boxes(rng, 100, "overlapping", d=3)
    shifted = boxes.copy()
    shifted[:, 2] = rng.uniform(-3.0, 3.0, (100, 1)) + np.array([0.0, 0.1])
    assert area_xy(shifted) == area_xy(boxes) == area_xy(np.ascontiguousarray(boxes[:, :2]))


def test_kernel_on_plain_arrays():
    # three unit squares in an L and one covering the corner twice: area 3
    x_lo, x_hi = np.array([0.0, 1.0, 0.0, 0.0]), np.array([1.0, 2.0, 1.0, 1.0])
    y_lo, y_hi = np.array([0.0, 0.0, 1.0, 0.0]), np.array([1.0, 1.0, 2.0, 1.0])
    assert union_area(x_lo, x_hi, y_lo, y_hi) == 3.0


def test_small_slabs_are_not_lost_beside_a_large_one():
    # a unit square, then 1000 disjoint slivers of area 1e-16 each, below half an ulp of 1:
    # added one by one to 1.0 each would vanish; the compensated sum keeps them (1 + 1e-13)
    k = np.arange(1000.0)
    boxes = boxes_from(
        np.r_[0.0, 2.0 + k], np.r_[1.0, 3.0 + k], np.zeros(1001), np.r_[1.0, 1e-16 * np.ones(1000)]
    )
    assert area_xy(boxes) == pytest.approx(1.0 + 1e-13, rel=0.0, abs=1e-15)


def test_a_box_with_a_nan_bound_is_skipped():
    # documented behaviour for input that as_boxes would have rejected
    boxes = boxes_from([0.0, np.nan, 5.0], [1.0, 2.0, 6.0], [0.0, 0.0, 0.0], [1.0, 1.0, np.nan])
    assert area_xy(boxes) == 1.0
