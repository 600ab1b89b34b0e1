"""The compiled glue of the paver (boxes, SIVIA's levels, the tracker's cover count) against
the numpy formulas it replaced, kept here as oracles: the same arrays, bit for bit (signed
zeros included), on random inputs with periodic headings and the edge cases (no box, one box,
flat boxes, NaN rows from a contractor)."""

import itertools

import numpy as np
import pytest

from intervals import boxes as bx
from intervals import localize as lz
from intervals import sivia as sv
from intervals.sonar.idle import probes
from intervals.tracker import covered_volume


def _same(actual: np.ndarray, expected: np.ndarray) -> None:
    """Equal shapes, equal values (NaN where NaN) and equal sign bits."""
    assert actual.shape == expected.shape
    np.testing.assert_array_equal(actual, expected)
    np.testing.assert_array_equal(np.signbit(actual), np.signbit(expected))


def _oracle_nudge(x, direction: int, ulps: int = 2):
    for _ in range(ulps):
        x = np.nextafter(x, direction * np.inf)
    return x


def _oracle_shift_turns(boxes, turns, axis):
    out = boxes.copy()
    moved = turns != 0
    shift = turns * (2.0 * np.pi)
    out[:, axis, 0] = np.where(moved, _oracle_nudge(boxes[:, axis, 0] - shift, -1), out[:, axis, 0])
    out[:, axis, 1] = np.where(moved, _oracle_nudge(boxes[:, axis, 1] - shift, 1), out[:, axis, 1])
    return out


def _oracle_wrap_headings(boxes, axis=2):
    full = boxes[:, axis, 1] - boxes[:, axis, 0] >= 2.0 * np.pi
    out = _oracle_shift_turns(boxes, np.floor((boxes[:, axis, 0] + np.pi) / (2.0 * np.pi)), axis)
    pi_up, pi_down = _oracle_nudge(np.pi, 1), _oracle_nudge(-np.pi, -1)
    hi = out[:, axis, 1].copy()
    out[:, axis, 0] = np.where(full, pi_down, np.maximum(out[:, axis, 0], pi_down))
    out[:, axis, 1] = np.where(full, pi_up, np.minimum(hi, pi_up))
    crossing = ~full & (hi > pi_up)
    extra = out[crossing].copy()
    extra[:, axis, 0] = pi_down
    extra[:, axis, 1] = _oracle_nudge(hi[crossing] - 2.0 * np.pi, 1)
    return np.concatenate([out, extra], axis=0)


def _oracle_merge_pass(boxes, axis):
    """One pass of the numpy ``merge_adjacent`` along ``axis`` (two boxes or more)."""
    others = [a for a in range(boxes.shape[1]) if a != axis]
    keys = [boxes[:, axis, 0]] + [boxes[:, a, k] for a in others for k in (0, 1)]
    b = boxes[np.lexsort(keys)]
    joined = np.all(b[1:, others] == b[:-1, others], axis=(1, 2))
    joined &= b[1:, axis, 0] == b[:-1, axis, 1]
    first = np.flatnonzero(np.concatenate([[True], ~joined]))
    last = np.append(first[1:] - 1, b.shape[0] - 1)
    out = b[first].copy()
    out[:, axis, 1] = b[last, axis, 1]
    return out


def _oracle_merge_adjacent(boxes, rounds):
    """``rounds`` rounds of passes over the axes, the last one a round that merged nothing;
    fewer than two boxes are left as they are."""
    if rounds == 0 or boxes.shape[0] < 2:
        return boxes
    merged = boxes
    for axis in range(boxes.shape[1]):
        merged = _oracle_merge_pass(merged, axis) if merged.shape[0] > 1 else merged
    return (
        merged if merged.shape[0] == boxes.shape[0] else _oracle_merge_adjacent(merged, rounds - 1)
    )


def _oracle_covered_volume(boxes, cells):
    whole = bx.hull(boxes)
    width = whole[:, 1] - whole[:, 0]
    if not np.all(width > 0):
        return bx.volume(boxes)
    d = boxes.shape[1]
    first = np.clip(np.floor((boxes[..., 0] - whole[:, 0]) / width * cells), 0, cells - 1)
    last = np.clip(np.ceil((boxes[..., 1] - whole[:, 0]) / width * cells), 1, cells)
    ends = (first.astype(np.int64), np.maximum(last, first + 1).astype(np.int64))
    shape = (cells + 1,) * d
    counts = np.zeros(int(np.prod(shape)), dtype=np.int64)
    for corner in np.ndindex(*(2,) * d):
        index = np.ravel_multi_index(tuple(ends[c][:, a] for a, c in enumerate(corner)), shape)
        counts += (-1) ** sum(corner) * np.bincount(index, minlength=counts.size)
    counts = counts.reshape(shape)
    for axis in range(d):
        counts = np.cumsum(counts, axis=axis)
    covered = np.count_nonzero(counts[(slice(0, cells),) * d] > 0)
    return float(covered * np.prod(width / cells))


def _grid_boxes(rng, n, d, flat_share=0.2):
    """``n`` boxes ``(n, d, 2)`` on a grid of quarter units (neighbours share bounds, runs to
    merge), some flat (zero width) along an axis, some bounds ``-0.0``."""
    lo = rng.integers(-6, 6, size=(n, d)) * 0.25
    width = rng.integers(1, 3, size=(n, d)) * 0.25 * (rng.random((n, d)) >= flat_share)
    boxes = np.stack([lo, lo + width], axis=-1)
    boxes[boxes == 0.0] = np.where(rng.random(np.count_nonzero(boxes == 0.0)) < 0.5, -0.0, 0.0)
    return boxes


def _pose_boxes(rng, n):
    """``n`` pose boxes with headings anywhere over several turns, some wider than a turn,
    some flat, some with a bound at exactly ``-+pi``."""
    lo = rng.uniform(-5, 5, size=(n, 3))
    lo[:, 2] = rng.uniform(-15, 15, size=n)
    width = rng.exponential(0.5, size=(n, 3)) * (rng.random((n, 3)) >= 0.1)
    width[rng.random(n) < 0.1, 2] = rng.uniform(6.0, 7.0)
    boxes = np.stack([lo, lo + width], axis=-1)
    at_pi = rng.random(n) < 0.1
    boxes[at_pi, 2] = rng.choice([-np.pi, np.pi]), np.pi
    boxes[at_pi, 2, 0] = np.minimum(boxes[at_pi, 2, 0], np.pi)
    at_bound = rng.random(n) < 0.1  # reaching exactly the wrapped bound above pi: not split
    boxes[at_bound, 2] = 3.0, _oracle_nudge(np.pi, 1)
    return boxes


@pytest.mark.parametrize("n", [0, 1, 2, 7, 300])
def test_wrap_headings_equals_the_numpy_formula(n):
    rng = np.random.default_rng(n)
    boxes = _pose_boxes(rng, n)
    wrapped = bx.wrap_headings(boxes)
    _same(wrapped, _oracle_wrap_headings(boxes))
    # every heading within [-pi, pi] up to the outward rounding
    assert np.all(wrapped[:, 2, 0] >= -np.pi - 1e-15) and np.all(wrapped[:, 2, 1] <= np.pi + 1e-15)
    reference = rng.uniform(-4, 4, size=n)
    _same(
        bx.unwrap_headings(boxes, reference),
        _oracle_shift_turns(
            boxes,
            np.round(((boxes[:, 2, 0] + boxes[:, 2, 1]) / 2.0 - reference) / (2.0 * np.pi)),
            2,
        ),
    )
    if n:  # another periodic axis, on a non-contiguous view
        view = boxes[:, ::-1]
        _same(bx.wrap_headings(view, axis=0), _oracle_wrap_headings(view, axis=0))


@pytest.mark.parametrize("d", [1, 2, 3])
def test_merge_adjacent_equals_the_numpy_formula(d):
    """The same boxes in the same order, whatever the rounds, on grid boxes (many runs to
    join, flat boxes, signed zeros), random real boxes (few shared bounds) and wrapped
    pose cells (periodic heading: split boxes next to the +-pi cut)."""
    rng = np.random.default_rng(d)
    cases = [np.zeros((0, d, 2)), _grid_boxes(rng, 1, d)]
    cases += [_grid_boxes(rng, n, d, flat) for n in (2, 30, 600) for flat in (0.0, 0.3)]
    real = np.sort(rng.normal(size=(200, d, 2)), axis=-1)
    cases += [real, np.concatenate([real, real])]  # duplicates: ties kept in row order
    if d == 3:
        cells = np.stack(np.meshgrid(*(np.arange(k) for k in (8, 4, 16)), indexing="ij"), -1)
        lo = cells.reshape(-1, 3) * [0.25, 0.25, 0.5] - [0.0, 0.0, 4.0]
        cut = np.stack([lo, lo + [0.25, 0.25, 0.5]], axis=-1)[rng.random(len(lo)) < 0.6]
        cases.append(bx.wrap_headings(cut))
    for boxes, rounds in itertools.product(cases, (1, 2, 3)):
        merged = bx.merge_adjacent(boxes, rounds)
        _same(merged, _oracle_merge_adjacent(boxes, rounds))
    for boxes, axis in itertools.product(cases[1:], range(d)):  # the compiled pass alone
        _same(bx._merge_along(np.ascontiguousarray(boxes), axis), _oracle_merge_pass(boxes, axis))
    grid = cases[-1] if d == 3 else cases[4]
    assert bx.merge_adjacent(grid).shape[0] < grid.shape[0]  # the cases do merge


@pytest.mark.parametrize("d", [1, 2, 3])
def test_covered_volume_equals_the_numpy_formula(d):
    rng = np.random.default_rng(10 + d)
    cases = [_grid_boxes(rng, 1, d, 0.0), _grid_boxes(rng, 40, d, 0.0)]
    cases += [_grid_boxes(rng, 40, d, 0.3)]  # flat boxes among others
    for n in (2, 50, 500):
        lo = rng.normal(size=(n, d)) * rng.uniform(0.1, 10)
        cases.append(np.stack([lo, lo + rng.exponential(size=(n, d))], axis=-1))
    cases.append(np.repeat(cases[-1][:1], 3, axis=0))  # one box three times over
    flat = cases[-2].copy()
    flat[:, 0] = 1.5  # every box flat on axis 0: the hull is flat, the plain volume sum
    cases.append(flat)
    for boxes, cells in itertools.product(cases, (1, 2, 7, 32)):
        assert covered_volume(boxes, cells) == _oracle_covered_volume(boxes, cells)
    assert covered_volume(flat) == bx.volume(flat)
    # overlaps count once: the same box twice covers its own volume
    box = np.array([[[0.0, 2.0]] * d])
    assert covered_volume(np.concatenate([box, box])) == pytest.approx(2.0**d)


@pytest.mark.parametrize("n", [0, 1, 9, 400])
def test_cut_width_equals_the_numpy_formula(n):
    rng = np.random.default_rng(20 + n)
    boxes = _grid_boxes(rng, n, 3)
    idle = rng.random((n, 3)) < 0.4
    idle[: n // 4] = True  # idle along every axis: width 0
    scale = np.array([1.0, 1.0, 0.7])
    for s, i in itertools.product((None, scale), (None, idle)):
        w = bx.widths(boxes, s)
        expected = np.max(np.where(i, 0.0, w), axis=-1) if i is not None else np.max(w, axis=-1)
        _same(sv.cut_width(boxes, s, i), expected.reshape(n))


@pytest.mark.parametrize("n", [0, 1, 9, 400])
def test_kept_within_equals_the_numpy_clamp_and_filter(n):
    """A contractor's rows clamped into the input rows, the empty and NaN rows dropped."""
    rng = np.random.default_rng(30 + n)
    boxes = _grid_boxes(rng, n, 3)
    contracted = boxes + rng.normal(scale=0.2, size=boxes.shape) * (rng.random(boxes.shape) < 0.5)
    contracted[rng.random(n) < 0.1, 1] = np.nan  # emptied by the contractor
    contracted[rng.random(n) < 0.1, 2] = [np.inf, -np.inf]
    same = rng.random(boxes.shape) < 0.3  # bounds equal up to the sign of zero
    contracted = np.where(same, boxes, contracted)
    contracted[contracted == 0.0] = -0.0
    lo = np.maximum(contracted[..., 0], boxes[..., 0])
    hi = np.minimum(contracted[..., 1], boxes[..., 1])
    clamped = np.stack([lo, hi], -1)
    expected = clamped[np.all(clamped[..., 0] <= clamped[..., 1], axis=1)]
    _same(sv._kept_within(contracted, boxes), expected)


@pytest.mark.parametrize("n", [0, 1, 9, 400])
def test_sorted_level_and_by_parent_equal_the_numpy_masks(n):
    rng = np.random.default_rng(40 + n)
    boxes = _grid_boxes(rng, n, 3)
    verdicts = rng.integers(0, 3, size=n).astype(np.int8)
    idle = rng.random((n, 3)) < 0.3
    scale, eps = np.array([1.0, 1.0, 0.5]), 0.3
    inner, small, wide, wide_idle, rows = sv._sorted_level(boxes, verdicts, scale, idle, eps)
    undecided = np.flatnonzero(verdicts == sv.UNDECIDED)
    narrow = sv.cut_width(boxes[undecided], scale, idle[undecided]) <= eps
    _same(inner, boxes[verdicts == sv.INSIDE])
    _same(small, boxes[undecided[narrow]])
    _same(wide, boxes[undecided[~narrow]])
    np.testing.assert_array_equal(wide_idle, idle[undecided[~narrow]])
    np.testing.assert_array_equal(rows, undecided[~narrow])
    parents = rng.integers(0, max(n, 1), size=3 * n)
    children = _grid_boxes(rng, 3 * n, 3)
    _same(sv._by_parent(children, parents, n), children[np.argsort(parents, kind="stable")])


@pytest.mark.parametrize("n", [0, 1, 9, 400])
def test_sensor_counts_and_codes_equal_the_numpy_formulas(n):
    """The box test's counts and verdicts from the sensor verdicts (:mod:`intervals.localize`)."""
    rng = np.random.default_rng(50 + n)
    reject, certain = rng.random((n, 16)) < 0.15, rng.random((n, 16)) < 0.8
    for q, inner in itertools.product((0, 1, 3), (False, True)):
        rejects, out, inside = lz._sensor_counts(reject, certain, q, inner)
        np.testing.assert_array_equal(rejects, np.count_nonzero(reject, axis=1))
        np.testing.assert_array_equal(out, np.count_nonzero(reject, axis=1) > q)
        unsure = np.count_nonzero(~certain, axis=1) <= q
        np.testing.assert_array_equal(inside, unsure if inner else np.zeros(n, bool))
        codes = lz._verdict_codes(out, inside)
        expected = np.where(out, sv.OUTSIDE, np.where(inside, sv.INSIDE, sv.UNDECIDED))
        assert codes.dtype == np.int8
        np.testing.assert_array_equal(codes, expected.astype(np.int8))


@pytest.mark.parametrize("n", [0, 1, 9, 400])
def test_probes_equal_the_numpy_formula(n):
    """Idle intervals collapsed to their midpoints (:func:`intervals.sonar.idle.probes`)."""
    rng = np.random.default_rng(60 + n)
    boxes = np.concatenate([_grid_boxes(rng, n, 3), _pose_boxes(rng, n)])
    idle = rng.random((2 * n, 3)) < 0.4
    mid = boxes[..., 0] + (boxes[..., 1] - boxes[..., 0]) / 2.0
    _same(probes(boxes, idle), np.where(idle[..., None], mid[..., None], boxes))
