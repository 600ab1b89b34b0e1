"""The fusion of the belief with the interval boxes: the paper's clamp against brute force and
shapely, the nearest component, the heading clamp across +-pi, the truncated-Gaussian option
against scipy and Monte Carlo, and the refusals (never an empty set)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.stats import truncnorm

from localization.errors import EstimationError
from localization.fusion import (
    FusionRule,
    box_distance,
    clamp_heading,
    fuse,
    nearest_component,
    truncated_standard_normal,
)
from localization.gaussian import Gaussian

N = 8


def belief_at(positions, heading=0.0, std=0.2, rng=None):
    """A batched belief ``(B, 8)`` at ``positions (B, 2)``, a random correlated covariance."""
    positions = np.asarray(positions, dtype=float)
    batch = len(positions)
    mean = np.zeros((batch, N))
    mean[:, :2] = positions
    mean[:, 2] = heading
    rng = rng or np.random.default_rng(0)
    mixing = rng.standard_normal((batch, N, N)) * std / 3
    return Gaussian(mean, mixing @ mixing.mT + std**2 * np.eye(N), (2,))


def random_boxes(rng, count):
    lower = rng.uniform(-5, 5, (count, 3))
    lower[:, 2] = rng.uniform(-4, 3, count)
    width = rng.uniform(0.05, 2.0, (count, 3))
    return np.stack([lower, lower + width], axis=-1)


def test_clamp_is_the_nearest_point_of_the_box_by_brute_force_and_shapely():
    rng = np.random.default_rng(1)
    for _ in range(100):
        box = random_boxes(rng, 1)
        point = rng.uniform(-8, 8, 2)
        fused, report = fuse(belief_at([point, point]), box, rows=[1])
        clamped = fused.mean[1, :2]
        (xl, xu), (yl, yu) = box[0, 0], box[0, 1]
        assert xl <= clamped[0] <= xu and yl <= clamped[1] <= yu
        rectangle = shapely.box(xl, yl, xu, yu)
        gap = np.hypot(*(clamped - point))
        assert gap == pytest.approx(rectangle.distance(shapely.Point(point)), abs=1e-12)
        grid = np.stack(
            np.meshgrid(np.linspace(xl, xu, 201), np.linspace(yl, yu, 201)), axis=-1
        ).reshape(-1, 2)
        brute = grid[np.argmin(np.hypot(*(grid - point).T))]
        assert np.hypot(*(clamped - brute)) <= 0.01 * max(xu - xl, yu - yl) + 1e-12
        assert report.moved[0] == (gap > 0)
        assert np.array_equal(
            fused.mean[0], belief_at([point, point]).mean[0]
        )  # UKF-only row untouched


def test_a_position_inside_the_box_is_left_alone():
    box = np.array([[[0.0, 2.0], [1.0, 3.0], [-0.5, 0.5]]])
    before = belief_at([[1.2, 2.9], [0.5, 1.5]])
    after, report = fuse(before, box, rows=[0, 1])
    assert np.array_equal(after.mean, before.mean) and np.array_equal(after.cov, before.cov)
    assert not report.moved.any() and (report.distance_m == 0).all()


def test_the_nearest_component_is_used_and_reported():
    rng = np.random.default_rng(2)
    for _ in range(50):
        boxes = random_boxes(rng, 9)
        labels = rng.integers(0, 3, 9)
        point = rng.uniform(-8, 8, 2)
        fused, report = fuse(belief_at([point, point]), boxes, labels, rows=[1])
        names = np.unique(labels)
        unions = [
            shapely.union_all(
                [shapely.box(b[0, 0], b[1, 0], b[0, 1], b[1, 1]) for b in boxes[labels == name]]
            )
            for name in names
        ]
        distances = [union.distance(shapely.Point(point)) for union in unions]
        best = names[int(np.argmin(distances))]
        assert report.component[0] == best
        assert report.distance_m[0] == pytest.approx(min(distances), abs=1e-12)
        members = boxes[labels == best]
        hull_lower, hull_upper = members[:, :2, 0].min(axis=0), members[:, :2, 1].max(axis=0)
        assert (fused.mean[1, :2] >= hull_lower).all() and (fused.mean[1, :2] <= hull_upper).all()
        assert np.allclose(fused.mean[1, :2], np.clip(point, hull_lower, hull_upper))


def test_nearest_component_breaks_ties_to_the_smallest_label():
    boxes = np.array([[[0.0, 1.0], [0.0, 1.0], [0, 1]], [[0.5, 2.0], [0.5, 2.0], [0, 1]]])
    label, distance, _ = nearest_component(np.array([[0.7, 0.7]]), boxes, np.array([4, 2]))
    assert label[0] == 2 and distance[0] == 0.0


def angular_gap(a, b):
    return np.abs((a - b + math.pi) % (2 * math.pi) - math.pi)


@settings(max_examples=150, deadline=None)
# theta at the arc's upper end, where the width the interval holds ((lower + width) - lower)
# rounds below the drawn width (found by hypothesis)
@example(lower=2.2831853071795862, width=6.028650425541252, theta=2.028650425541252)
@given(
    lower=st.floats(-2 * math.pi, 2 * math.pi),
    width=st.floats(0.0, 7.0),
    theta=st.floats(-math.pi, math.pi, exclude_max=True),
)
def test_heading_clamp_is_the_nearest_point_of_the_arc(lower, width, theta):
    clamped = clamp_heading(np.array([theta]), np.array([[lower, lower + width]]))[0]
    assert -math.pi <= clamped < math.pi
    arc = lower + np.linspace(0.0, min(width, 2 * math.pi), 4001)
    gaps = angular_gap(arc, theta)
    assert angular_gap(clamped, arc).min() < 1e-9 + 2 * math.pi / 4000  # on the arc
    assert angular_gap(clamped, theta) <= gaps.min() + 1e-9  # and nearest to theta
    span = (lower + width) - lower  # the width of the interval as the floats hold it
    inside = (theta - lower) % (2 * math.pi) <= span or span >= 2 * math.pi
    if inside:
        assert clamped == theta  # untouched, bit for bit


def test_heading_clamp_across_pi_in_the_fusion():
    box = np.array([[[0.0, 1.0], [0.0, 1.0], [3.0, 3.4]]])  # crosses +pi
    positions = [[0.5, 0.5]] * 4
    before = belief_at(positions)
    mean = np.array(before.mean)
    mean[:, 2] = [
        -3.1,
        -2.5,
        2.5,
        0.0,
    ]  # inside (3.183), near 3.4, near 3.0, opposite: 3.0 and 3.4 tie-ish
    fused, report = fuse(
        Gaussian(mean, before.cov, (2,)), box, rows=[0, 1, 2, 3], rule="clamp_heading"
    )
    expected = [-3.1, 3.4 - 2 * math.pi, 3.0]
    assert np.allclose(fused.mean[:3, 2], expected)
    assert list(report.heading_moved[:3]) == [False, True, True]
    assert angular_gap(fused.mean[3, 2], 0.0) == pytest.approx(
        min(angular_gap(3.0, 0.0), angular_gap(3.4, 0.0))
    )
    plain, _ = fuse(Gaussian(mean, before.cov, (2,)), box, rows=[0, 1, 2, 3], rule="clamp")
    assert np.array_equal(plain.mean[:, 2], mean[:, 2])  # the paper's rule leaves the heading


def test_truncated_normal_moments_match_scipy():
    rng = np.random.default_rng(3)
    lower = rng.uniform(-4, 4, 200)
    upper = lower + rng.uniform(0.01, 5, 200)
    mean, ratio = truncated_standard_normal(lower, upper)
    reference_mean, reference_var = truncnorm.stats(lower, upper, moments="mv")
    assert np.allclose(mean, reference_mean, atol=1e-9) and np.allclose(
        ratio, reference_var, rtol=1e-7
    )
    far_mean, far_ratio = truncated_standard_normal(
        np.array([1e3, -1e3 - 1]), np.array([1e3 + 1, -1e3])
    )
    assert np.allclose(far_mean, [1e3 + 1e-3, -1e3 - 1e-3], atol=1e-6) and (far_ratio > 0).all()


def test_truncated_update_moves_inside_and_shrinks_the_covariance():
    rng = np.random.default_rng(4)
    box = np.array([[[1.0, 1.5], [-0.5, 0.5], [-1.0, 1.0]]])
    before = belief_at([[2.0, 0.8], [1.2, 0.0]], rng=rng)
    after, report = fuse(before, box, rows=[0, 1], rule="truncated")
    assert (after.mean[:, 0] >= 1.0).all() and (after.mean[:, 0] <= 1.5).all()
    assert (after.mean[:, 1] >= -0.5).all() and (after.mean[:, 1] <= 0.5).all()
    for row in range(2):
        assert np.linalg.eigvalsh(before.cov[row] - after.cov[row]).min() > -1e-12  # P' <= P
        assert np.linalg.eigvalsh(after.cov[row]).min() > 0
    assert list(report.moved) == [True, False]


def test_truncation_on_one_coordinate_matches_monte_carlo():
    # a single constraint (only x binds): the update is exact, the other states follow
    rng = np.random.default_rng(5)
    before = belief_at([[0.3, 0.0]], std=0.3, rng=rng)
    box = np.array([[[0.0, 0.4], [-1e3, 1e3], [-10.0, 10.0]]])
    after, _ = fuse(before, box, rows=[0], rule="truncated")
    samples = rng.multivariate_normal(before.mean[0], before.cov[0], size=400_000)
    kept = samples[(samples[:, 0] >= 0.0) & (samples[:, 0] <= 0.4)]
    std = np.sqrt(np.diag(before.cov[0]))
    assert np.allclose(after.mean[0], kept.mean(axis=0), atol=0.02 * std.max())
    assert np.allclose(after.cov[0], np.cov(kept.T), atol=0.03 * std.max() ** 2)


def test_truncated_heading_stays_in_the_interval_across_pi():
    box = np.array([[[0.0, 1.0], [0.0, 1.0], [3.0, 3.4]]])
    before = belief_at([[0.5, 0.5]], heading=-2.0)
    after, _ = fuse(before, box, rows=[0], rule="truncated_heading")
    assert angular_gap(after.mean[0, 2], 3.2) <= 0.2 + 1e-12
    assert after.cov[0, 2, 2] < before.cov[0, 2, 2]


def test_never_clamps_to_an_empty_set():
    before = belief_at([[0.0, 0.0], [1.0, 1.0]])
    with pytest.raises(EstimationError, match="empty set"):
        fuse(before, np.zeros((0, 3, 2)), np.zeros(0, dtype=int))
    after, report = fuse(before, np.zeros((0, 3, 2)), np.zeros(0, dtype=int), on_empty="skip")
    assert after is before and report.skipped and (report.component == -1).all()


@pytest.mark.parametrize(
    ("boxes", "kwargs", "message"),
    [
        (np.zeros((2, 2, 2)), {}, "shape"),
        (np.array([[[1.0, 0.0], [0, 1], [0, 1]]]), {}, "lower bound above"),
        (np.array([[[np.nan, 0.0], [0, 1], [0, 1]]]), {}, "not finite"),
        (np.array([[[0.0, 1.0], [0, 1], [0, 1]]]), {"rule": "average"}, "rule must be one of"),
        (np.array([[[0.0, 1.0], [0, 1], [0, 1]]]), {"rows": [2]}, "rows must be"),
        (np.array([[[0.0, 1.0], [0, 1], [0, 1]]]), {"labels": [0.5]}, "labels"),
    ],
)
def test_bad_fusion_inputs_are_refused(boxes, kwargs, message):
    with pytest.raises(EstimationError, match=message):
        fuse(belief_at([[0.0, 0.0], [1.0, 1.0]]), boxes, **kwargs)


def test_every_rule_keeps_the_fused_position_in_the_box():
    rng = np.random.default_rng(6)
    for rule in FusionRule:
        for _ in range(20):
            box = random_boxes(rng, 1)
            point = rng.uniform(-8, 8, (3, 2))
            after, _ = fuse(belief_at(point, rng=rng), box, rows=[0, 1, 2], rule=rule)
            assert (after.mean[:, :2] >= box[0, :2, 0]).all() and (
                after.mean[:, :2] <= box[0, :2, 1]
            ).all()


def test_nearest_component_equals_the_per_component_definition():
    """Random boxes with unsorted, non-contiguous labels and several points: the label, the
    distance to the nearest box of that component and its hull, as computed component by
    component (ties to the smallest label)."""
    rng = np.random.default_rng(4)
    for _ in range(100):
        k = int(rng.integers(1, 40))
        lo = rng.integers(0, 10, size=(k, 3)).astype(float)
        boxes = np.stack([lo, lo + rng.integers(0, 3, size=(k, 3))], axis=-1)
        labels = rng.choice([7, 3, 11, 0, 5], size=k)
        points = rng.uniform(-2.0, 12.0, size=(5, 2))
        label, distance, hull = nearest_component(points, boxes, labels)
        names = np.unique(labels)
        per = np.array([box_distance(points, boxes[labels == c]).min(axis=1) for c in names]).T
        best = np.argmin(per, axis=1)
        np.testing.assert_array_equal(label, names[best])
        np.testing.assert_array_equal(distance, per[np.arange(5), best])
        for p, c in enumerate(names[best]):
            mine = boxes[labels == c]
            expected = np.stack([mine[..., 0].min(axis=0), mine[..., 1].max(axis=0)], axis=-1)
            np.testing.assert_array_equal(hull[p], expected)
