"""Soundness of the sonar box tests against robotsim's exact cone model.

A box that contains the true pose must never be rejected when the readings obey their error
bounds (q = 0), nor with k outliers at q = k; an inner box must hold only consistent poses.
"""

import numpy as np
import pytest

from intervals.boxes import contains_points
from intervals.errors import IntervalError
from intervals.localize import box_test, gomne, localize
from intervals.sivia import OUTSIDE
from intervals.sonar.reference.cone import sensor_boxes
from intervals.sonar.scan import SonarBelt, SonarScan, reading_intervals
from robotsim.maps import builtin_map
from robotsim.sensors.sonar import SonarBeltParams
from tests.helpers import bounded_readings, boxes_around, cone_ranges, random_room

PARAMS = SonarBeltParams.default_belt()


@pytest.mark.parametrize("echoes_never_lost", [True, False])
def test_boxes_holding_the_truth_are_never_rejected(echoes_never_lost):
    """150 maps x poses, 60 boxes each, at q = 0; and the test is not vacuous."""
    rng = np.random.default_rng(11 if echoes_never_lost else 12)
    belt = SonarBelt.from_params(PARAMS, echoes_never_lost=echoes_never_lost)
    kept = rejected_far = tested_far = 0
    for _ in range(150):
        segments, outer = random_room(rng)
        truth = np.array([*rng.uniform(0.3, 9.7, 2), rng.uniform(-np.pi, np.pi)])
        readings = bounded_readings(cone_ranges(truth, segments), PARAMS, rng)
        scan = SonarScan(segments, belt, readings, outer)
        boxes = boxes_around(truth, rng, 60)
        verdict = box_test(boxes, scan, q=0)
        assert np.all(verdict != OUTSIDE), boxes[verdict == OUTSIDE][:3]
        kept += boxes.shape[0]
        far = boxes.copy()
        far[:, :2] += rng.choice([-1.0, 1.0], size=(60, 2, 1)) * 1.0
        far_small = far[np.max(far[:, :2, 1] - far[:, :2, 0], axis=1) < 0.1]
        far_small = far_small[far_small[:, 2, 1] - far_small[:, 2, 0] < 0.1]
        tested_far += far_small.shape[0]
        rejected_far += np.count_nonzero(box_test(far_small, scan, q=0) == OUTSIDE)
    assert kept == 9000
    assert rejected_far > 0.5 * tested_far  # small boxes 1.4 m away are mostly rejected


def test_q_relaxation_keeps_the_truth_with_k_outliers():
    """k outliers (random value in [0, d_max] or a lost echo) at q = k: never rejected."""
    rng = np.random.default_rng(5)
    belt = SonarBelt.from_params(PARAMS, echoes_never_lost=True)
    for trial in range(120):
        segments, outer = random_room(rng)
        truth = np.array([*rng.uniform(0.3, 9.7, 2), rng.uniform(-np.pi, np.pi)])
        readings = bounded_readings(cone_ranges(truth, segments), PARAMS, rng)
        k = 1 + trial % 3
        bad = rng.choice(PARAMS.count, size=k, replace=False)
        readings[bad] = np.where(rng.random(k) < 0.3, np.inf, rng.uniform(0, PARAMS.d_max_m, k))
        scan = SonarScan(segments, belt, readings, outer)
        boxes = boxes_around(truth, rng, 40)
        assert np.all(box_test(boxes, scan, q=k) != OUTSIDE)


@pytest.mark.slow
def test_inner_boxes_hold_only_consistent_poses():
    """Inner boxes from SIVIA (inner test on): 200 poses sampled in each are consistent."""
    rng = np.random.default_rng(8)
    belt = SonarBelt.from_params(PARAMS, echoes_never_lost=True)
    wide = SonarBelt(
        belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad, 3.0, 0.15, 0.02, True
    )
    inner_total = 0
    for _ in range(4):
        segments, outer = random_room(rng)
        truth = np.array([*rng.uniform(1, 9, 2), rng.uniform(-np.pi, np.pi)])
        readings = bounded_readings(cone_ranges(truth, segments), PARAMS, rng, extreme=False)
        scan = SonarScan(segments, wide, readings, outer)
        prior = np.stack([truth - [0.2, 0.2, 0.05], truth + [0.2, 0.2, 0.05]], axis=-1)
        paving = localize(scan, prior, eps=0.03, inner=True)
        assert paving.contains(truth[None])[0]
        inner = paving.inner
        inner_total += inner.shape[0]
        if not inner.shape[0]:
            continue
        u = rng.uniform(size=(inner.shape[0], 200, 3))
        poses = inner[:, None, :, 0] + u * (inner[:, None, :, 1] - inner[:, None, :, 0])
        d = cone_ranges(poses, segments)
        lo, hi = scan.ranges[:, 0], scan.ranges[:, 1]
        ok = np.where(np.isfinite(readings), (d >= lo) & (d <= hi), d > wide.d_max_m)
        assert np.all(ok)
    assert inner_total > 20, inner_total


def test_reading_intervals_follow_the_bounds():
    belt = SonarBelt.from_params(PARAMS, echoes_never_lost=True)
    d = np.linspace(0.0, 3.0, 16)
    e = PARAMS.error_abs_bound_m + PARAMS.error_rel_bound * d
    for sign in (-1.0, 1.0):
        ranges, kind = reading_intervals(np.maximum(d + sign * e, 0.0), belt)
        assert np.all(kind == 1)
        assert np.all((ranges[:, 0] <= d) & (d <= ranges[:, 1]))
    ranges, kind = reading_intervals(np.full(16, np.inf), belt)
    assert np.all(kind == 2) and np.all(ranges[:, 0] == 3.0)
    lossy = SonarBelt.from_params(PARAMS, echoes_never_lost=False)
    assert np.all(reading_intervals(np.full(16, np.inf), lossy)[1] == 0)
    with pytest.raises(IntervalError, match="NaN or negative"):
        reading_intervals(np.full(16, np.nan), belt)
    with pytest.raises(IntervalError, match="shape"):
        reading_intervals(np.ones(3), belt)


def _global_box(segment_map):
    b = segment_map.bounds
    return np.array([b[0], b[1], [-np.pi, np.pi]])


def test_global_localisation_in_hall_keeps_the_truth_and_narrows():
    hall = builtin_map("hall")
    belt = SonarBelt.from_params(PARAMS)
    rng = np.random.default_rng(2)
    for truth in ([3.1, 2.7, 0.4], [6.8, 5.2, -2.0], [8.5, 1.0, 2.5]):
        truth = np.array(truth)
        readings = bounded_readings(cone_ranges(truth, hall.segments), PARAMS, rng)
        scan = SonarScan(hall.segments, belt, readings, hall.boundary)
        paving = localize(scan, _global_box(hall), eps=0.05)
        assert paving.contains(truth[None])[0]
        assert paving.area_xy() < 0.5, paving.area_xy()  # of an 80 m^2 hall


def test_global_localisation_in_symmetric_keeps_the_twin():
    """In the plain rectangle the pose turned by pi about the centre gives the same readings
    (the belt is symmetric under a half turn): both survive, in separate components. The
    mirror images survive whenever their readings are consistent too."""
    room = builtin_map("symmetric")
    belt = SonarBelt.from_params(PARAMS)
    rng = np.random.default_rng(4)
    centre = room.bounds.mean(axis=1)
    for _ in range(2):
        truth = np.array([*centre, 0.0])
        while np.linalg.norm(truth[:2] - centre) < 1.0:
            truth = np.array(
                [
                    *rng.uniform(room.bounds[:, 0] + 1.0, room.bounds[:, 1] - 1.0),
                    rng.uniform(-np.pi, np.pi),
                ]
            )
        x, y, th = truth
        cx, cy = 2 * centre
        images = np.array(
            [
                [cx - x, cy - y, th + np.pi],  # half turn about the centre
                [cx - x, y, np.pi - th],  # mirror x
                [x, cy - y, -th],  # mirror y
            ]
        )
        images[:, 2] = np.mod(images[:, 2] + np.pi, 2 * np.pi) - np.pi
        readings = bounded_readings(cone_ranges(truth, room.segments), PARAMS, rng)
        scan = SonarScan(room.segments, belt, readings, room.boundary)
        d_images = cone_ranges(images, room.segments)
        np.testing.assert_allclose(d_images[0], cone_ranges(truth, room.segments), atol=1e-9)
        lo, hi = scan.ranges[:, 0], scan.ranges[:, 1]
        consistent = np.all(
            np.where(np.isfinite(readings), (d_images >= lo) & (d_images <= hi), d_images > 3.0),
            axis=1,
        )
        paving = localize(scan, _global_box(room), eps=0.05)
        must_keep = np.concatenate([truth[None], images[consistent]])
        assert np.all(paving.contains(must_keep))
        count, labels = paving.components()
        inside = contains_points(paving.outer, np.stack([truth, images[0]]))
        assert count >= 2
        assert set(labels[inside[:, 0]]).isdisjoint(labels[inside[:, 1]])


def test_sensor_boxes_hold_every_sensor_position_and_cone_direction():
    """The sensor-position boxes and wedge half-planes (angle addition, arc extrema) against
    sampled poses: headings across the axis directions, near-pi and near-2-pi widths, tiny and
    degenerate boxes, headings beyond +-pi."""
    rng = np.random.default_rng(4)
    belt = SonarBelt.from_params(PARAMS)
    n = 400
    centre = np.column_stack([rng.uniform(-900, 900, (n, 2)), rng.uniform(-8, 8, n)])
    quarter = np.round(centre[:, 2] / (np.pi / 2)) * (np.pi / 2)
    centre[: n // 4, 2] = quarter[: n // 4]  # heading centred on an axis direction
    half = np.column_stack([rng.uniform(0, 0.5, (n, 2)), np.exp(rng.uniform(-30, 1.9, n))])
    half[n // 4 : n // 2, 2] = np.pi / 2 + rng.uniform(-1e-9, 1e-9, n // 4)  # width near pi
    half[n // 2 : n // 2 + 20, 2] = np.pi + rng.uniform(-1e-9, 1e-9, 20)  # near 2 pi
    half[-20:] = 0.0  # degenerate boxes: one pose
    boxes = np.stack([centre - half, centre + half], axis=-1)
    sb = sensor_boxes(boxes, belt)
    m = 64
    t = rng.uniform(0, 1, (n, m, 3))
    t[:, :8] = np.round(t[:, :8])  # corners
    poses = boxes[None, :, :, 0].transpose(1, 0, 2) + t * (
        boxes[:, None, :, 1] - boxes[:, None, :, 0]
    )
    c, s_ = np.cos(poses[..., 2]), np.sin(poses[..., 2])
    mx, my = belt.mount_xy[:, 0], belt.mount_xy[:, 1]
    sx = poses[..., 0, None] + c[..., None] * mx - s_[..., None] * my  # (n, m, k)
    sy = poses[..., 1, None] + s_[..., None] * mx + c[..., None] * my
    assert np.all(np.abs(sx - sb.cx[:, None]) <= sb.hx[:, None])
    assert np.all(np.abs(sy - sb.cy[:, None]) <= sb.hy[:, None])
    # cone points at 0.05 to 5 m along a direction of the cone: in the union half-planes
    gamma = belt.half_aperture_rad
    phi = poses[..., 2, None] + belt.mount_angle_rad + rng.uniform(-gamma, gamma, (n, m, 16))
    rho = rng.uniform(0.05, 5.0, (n, m, 16))
    qx, qy = sx + rho * np.cos(phi), sy + rho * np.sin(phi)
    for nx, ny, k in sb.union:
        assert np.all(nx[:, None] * qx + ny[:, None] * qy >= k[:, None])
    # a point in the intersection half-planes is in the cone of every sampled pose
    inter_in = np.ones(qx.shape, bool)
    px, py = rng.uniform(-5, 5, qx.shape) + sx.mean(1, keepdims=True), sy.mean(1, keepdims=True)
    py = py + rng.uniform(-5, 5, qx.shape)
    for nx, ny, k in sb.inter:
        inter_in &= nx[:, None] * px + ny[:, None] * py >= k[:, None]
    inter_in &= sb.sure[:, None]
    seen = np.arctan2(py - sy, px - sx) - (poses[..., 2, None] + belt.mount_angle_rad)
    off_axis = np.abs(np.mod(seen + np.pi, 2 * np.pi) - np.pi)
    assert inter_in.any() and np.all(off_axis[inter_in] <= gamma)


def _hall_scan_with_outliers(truth, seed, outliers, shift_m):
    """A scan in ``hall`` at ``truth`` whose first ``outliers`` echoes are moved by
    ``shift_m``, and the prior box ``truth +- (0.5 m, 0.5 m, 0.2 rad)``."""
    hall = builtin_map("hall")
    readings = bounded_readings(
        cone_ranges(truth, hall.segments), PARAMS, np.random.default_rng(seed)
    )
    moved = np.flatnonzero(np.isfinite(readings))[:outliers]
    readings[moved] += shift_m
    scan = SonarScan(hall.segments, SonarBelt.from_params(PARAMS), readings, hall.boundary)
    return scan, np.stack([truth - [0.5, 0.5, 0.2], truth + [0.5, 0.5, 0.2]], axis=-1)


def test_gomne_finds_the_outlier_count_or_reports_inconsistency():
    truth = np.array([2.0, 3.0, 1.0])
    scan, prior = _hall_scan_with_outliers(truth, seed=9, outliers=2, shift_m=1.0)
    result = gomne(scan, prior, eps=0.05, q_max=4)
    assert result.consistent and result.q <= 2
    assert result.paving.contains(truth[None])[0]
    absurd = SonarScan(scan.segments, scan.belt, np.full(16, 0.1), scan.boundary)
    bad = gomne(absurd, prior, eps=0.05, q_max=3)
    assert not bad.consistent and bad.q is None and bad.paving.is_empty
    with pytest.raises(IntervalError, match="q_max"):
        gomne(scan, prior, eps=0.05, q_max=-1)
    with pytest.raises(IntervalError, match="eps"):
        localize(scan, prior, eps=0.0)


def test_gomne_guaranteed_set_contains_the_minimal_one():
    """S_q is nested in S_qmax; the guaranteed result keeps S_qmax, the other S_q."""
    truth = np.array([7.5, 2.5, 0.3])
    scan, prior = _hall_scan_with_outliers(truth, seed=13, outliers=1, shift_m=0.8)
    sure = gomne(scan, prior, eps=0.05, q_max=2)
    minimal = gomne(scan, prior, eps=0.05, q_max=2, guaranteed=False)
    assert sure.q == minimal.q and sure.q_set == 2 and minimal.q_set == minimal.q
    assert sure.paving.contains(truth[None])[0]
    inside = np.all(np.any(contains_points(sure.paving.outer, _centres(minimal.paving.outer)), 0))
    assert inside and sure.paving.volume() >= minimal.paving.volume()


def test_gomne_minimal_set_equals_a_fresh_sivia_pass_at_its_q():
    """GOMNE reads S_q off the reject counts of the q_max pass; a separate SIVIA pass at q on
    S_qmax's boxes (the definition) must give the very same boxes. Without the contractor:
    it contracts by the relaxation of the pass, so a pass at q keeps smaller boxes (a
    tighter set, not the same boxes)."""
    for seed, outliers in ((3, 1), (21, 2), (5, 0)):
        truth = np.array([4.0 + seed / 10.0, 3.0, -2.0 + seed / 7.0])
        scan, prior = _hall_scan_with_outliers(truth, seed=seed, outliers=outliers, shift_m=0.7)
        sure = gomne(scan, prior, eps=0.05, q_max=3, contract=False)
        minimal = gomne(scan, prior, eps=0.05, q_max=3, guaranteed=False, contract=False)
        assert sure.consistent and minimal.q == sure.q <= outliers
        fresh = localize(scan, sure.paving.outer, eps=0.05, q=minimal.q, contract=False)
        assert np.array_equal(fresh.outer, minimal.paving.outer)
        if minimal.q > 0:
            below = localize(scan, sure.paving.outer, eps=0.05, q=minimal.q - 1)
            assert below.is_empty


def _centres(boxes):
    """Centres ``(N, 3)`` of the boxes (each lies in any box that contains the box)."""
    return (boxes[..., 0] + boxes[..., 1]) / 2.0
