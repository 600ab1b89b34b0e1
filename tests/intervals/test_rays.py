"""The ray test against robotsim's exact cone model: sound for every half-aperture, not vacuous.

Soundness: a box holding the true pose is never rejected when the readings obey their error
bounds (errors often exactly at the bounds), for thin (1e-6 rad) and wide (0.2 rad) cones, on
random maps, random belts (mounts off the radial direction too) and boxes from 1e-6 m to 2 m
wide. Brute force: every pose sampled in a rejected box is inconsistent with the rejecting
sensor. Not vacuous: most boxes shifted away from the truth are rejected, and on thin cones
it rejects boxes that :mod:`intervals.sonar.cone` keeps.
"""

import numpy as np
import pytest

from intervals.boxes import contains_points, volume
from intervals.errors import IntervalError
from intervals.localize import gomne, localize, uses_ray_test
from intervals.sonar.cone import sensor_verdicts
from intervals.sonar.rays import (
    joint_rejection_counts,
    joint_rejections,
    piece_rejections,
    ray_rejections,
    sub_boxes,
)
from intervals.sonar.reference import rays as reference_rays
from intervals.sonar.scan import SonarBelt, SonarScan
from robotsim.maps import builtin_map
from robotsim.sensors.sonar import SonarBeltParams
from tests.helpers import (
    bounded_readings,
    boxes_around,
    cone_ranges,
    random_scan_case,
)

GAMMAS_RAD = (1e-6, 0.02, 0.2)


@pytest.mark.slow
@pytest.mark.parametrize("gamma", GAMMAS_RAD)
def test_boxes_holding_the_truth_are_never_rejected(gamma):
    """3 x 200 cases x 40 boxes, no-echo readings used as free space in half of them; whole
    boxes (also against the segments within reach only, as SIVIA passes them) and pieces
    (4 heading pieces, 2 x 2 in x and y): no piece holding the truth is rejected."""
    rng = np.random.default_rng(int(gamma * 1e6) + 7)
    for case in range(200):
        scan, _, truth = random_scan_case(rng, gamma, echoes_never_lost=case % 2 == 0)
        boxes = boxes_around(truth, rng, 40)
        if case % 3 == 0:
            assert not ray_rejections(boxes, scan).any()
            assert not ray_rejections(boxes, scan.restricted_to(boxes)).any()
            continue
        pieces = (1, 1, 4) if case % 3 == 1 else (2, 2, 1)
        subs = sub_boxes(boxes, pieces)
        held = np.all((subs[..., 0] <= truth) & (subs[..., 1] >= truth), axis=-1)  # (N, P)
        rejected = piece_rejections(boxes, scan, pieces)
        assert not np.any(rejected.any(axis=2) & held), (
            case,
            np.argwhere(rejected & held[..., None])[:4],
        )


@pytest.mark.slow
@pytest.mark.parametrize("gamma", GAMMAS_RAD)
def test_every_pose_of_a_rejected_box_disagrees_with_the_rejecting_sensor(gamma):
    """Brute force on boxes near the truth: 64 poses (corners and random) per rejected box."""
    rng = np.random.default_rng(int(gamma * 1e6) + 99)
    checked = 0
    for _ in range(40):
        scan, params, truth = random_scan_case(rng, gamma, echoes_never_lost=True)
        centre = truth + rng.normal(0, 1, (30, 3)) * np.array([0.15, 0.15, 0.08])
        half = rng.uniform(0.005, 0.05, (30, 3))
        boxes = np.stack([centre - half, centre + half], axis=-1)
        reject = ray_rejections(boxes, scan)
        rows = np.flatnonzero(reject.any(axis=1))
        if rows.size == 0:
            continue
        corners = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
        frac = np.concatenate([corners, rng.uniform(0, 1, (56, 3))])  # (64, 3)
        lo, hi = boxes[rows, :, 0], boxes[rows, :, 1]
        poses = lo[:, None] + frac[None] * (hi - lo)[:, None]  # (R, 64, 3)
        d = cone_ranges(poses, scan.segments, params)  # (R, 64, k)
        fits = (d >= scan.ranges[:, 0]) & (d <= scan.ranges[:, 1])
        assert not np.any(fits & reject[rows][:, None, :])
        checked += rows.size
    assert checked > 100


def _shifted(truth, rng, count, half):
    """Boxes of half-widths ``half`` whose centres lie 0.3 to 1 m or 0.3 to 1 rad off."""
    offset = rng.normal(0, 1, (count, 3))
    offset *= rng.uniform(0.3, 1.0, (count, 1)) / np.linalg.norm(offset, axis=1, keepdims=True)
    centre = truth + offset
    return np.stack([centre - half, centre + half], axis=-1)


@pytest.mark.slow
def test_most_boxes_away_from_the_truth_are_rejected_by_a_thin_cone():
    rng = np.random.default_rng(3)
    rejected = total = 0
    for _ in range(40):
        scan, _, truth = random_scan_case(rng, 1e-6, echoes_never_lost=True)
        boxes = _shifted(truth, rng, 50, np.array([0.02, 0.02, 0.02]))
        rejected += np.count_nonzero(ray_rejections(boxes, scan).any(axis=1))
        total += boxes.shape[0]
    assert rejected > 0.9 * total


@pytest.mark.parametrize("gamma", [1e-6, np.deg2rad(12.5)])
def test_rejects_boxes_the_sonar_test_keeps(gamma):
    """Boxes near the truth in the hall: the ray test rejects boxes that
    :func:`intervals.sonar.cone.sensor_verdicts` keeps; on a thin cone (1e-6 rad) far more than
    the other way round, on the real belt (12.5 deg) some (its cone-edge free-space rays)."""
    rng = np.random.default_rng(5)
    hall = builtin_map("hall")
    params = SonarBeltParams.default_belt(
        half_aperture_rad=gamma, d_max_m=100.0 if gamma < 0.1 else 3.0
    )
    belt = SonarBelt.from_params(params, echoes_never_lost=True)
    only_rays = only_sonar = 0
    for truth in ([2.0, 6.0, 0.3], [5.0, 3.0, -2.0], [8.5, 6.5, 1.4], [4.0, 1.0, 3.0]):
        truth = np.array(truth)
        scan = SonarScan(
            hall.segments,
            belt,
            bounded_readings(cone_ranges(truth, hall.segments, params), params, rng),
        )
        centre = truth + rng.uniform(-1, 1, (300, 3)) * np.array([0.05, 0.05, 0.03])
        boxes = np.stack([centre - 0.02, centre + 0.02], axis=-1)
        by_rays = ray_rejections(boxes, scan).any(axis=1)
        by_sonar = sensor_verdicts(boxes, scan, inner=False)[0].any(axis=1)
        only_rays += np.count_nonzero(by_rays & ~by_sonar)
        only_sonar += np.count_nonzero(by_sonar & ~by_rays)
    if gamma < 0.1:
        assert only_rays > 100
        assert only_rays > 10 * only_sonar
    else:
        assert only_rays > 50


def test_free_space_ray_fires_on_a_no_echo_reading():
    """A sensor facing a wall 1 m away reports no echo (d_max 3 m, echoes never lost): the
    box is rejected by that sensor alone, through the free-space test."""
    params = SonarBeltParams(
        mount_xy=np.zeros((1, 2)), mount_angle_rad=np.zeros(1), half_aperture_rad=1e-6
    )
    belt = SonarBelt.from_params(params, echoes_never_lost=True)
    wall = np.array([[[1.0, -1.0], [1.0, 1.0]]])
    box = np.array([[-0.05, 0.05], [-0.05, 0.05], [-0.1, 0.1]])
    assert ray_rejections(box, SonarScan(wall, belt, np.array([np.inf]))).all()
    # an echo at the right distance is consistent, one at 2 m is not
    assert not ray_rejections(box, SonarScan(wall, belt, np.array([1.0]))).any()
    assert ray_rejections(box, SonarScan(wall, belt, np.array([2.0]))).all()
    # with lost echoes possible the no-echo reading says nothing
    lossy = SonarBelt.from_params(params, echoes_never_lost=False)
    assert not ray_rejections(box, SonarScan(wall, lossy, np.array([np.inf]))).any()


def test_sine_terms_enclose_sampled_values():
    rng = np.random.default_rng(8)
    lo = rng.uniform(-10, 10, 2000)
    hi = lo + np.exp(rng.uniform(np.log(1e-9), np.log(3.5), 2000))
    one_sign, inv, cot, sin, sin_max = reference_rays.sine_terms(lo, hi)
    assert 0.3 < one_sign.mean() < 0.99
    b = lo[:, None] + (hi - lo)[:, None] * np.linspace(0, 1, 201)
    assert np.all(np.abs(np.sin(b)) <= sin_max[:, None])
    s = np.sin(b[one_sign])
    assert np.all(np.sign(s) == np.sign(s[:, :1]))
    for (low, high), values in ((inv, 1 / s), (cot, np.cos(b[one_sign]) / s), (sin, s)):
        assert np.all((values >= low[one_sign, None]) & (values <= high[one_sign, None]))


def test_bad_arguments_raise_interval_error():
    scan = SonarScan(
        builtin_map("hall").segments,
        SonarBelt.from_params(SonarBeltParams.default_belt()),
        np.full(16, 1.0),
    )
    box = np.array([[1.0, 2.0], [1.0, 2.0], [0.0, 0.1]])
    with pytest.raises(IntervalError, match="SonarScan"):
        ray_rejections(box, object())
    with pytest.raises(IntervalError, match="pieces"):
        ray_rejections(box, scan, (1, 1, 0))
    with pytest.raises(IntervalError, match="pieces"):
        ray_rejections(box, scan, (2, 2))
    with pytest.raises(IntervalError, match="pose boxes"):
        ray_rejections(box[:2], scan)
    assert ray_rejections(np.zeros((0, 3, 2)), scan).shape == (0, 16)


def test_sonar_verdicts_and_rays_agree_on_the_truth_box_of_the_real_belt():
    """The real 16-sonar belt (12.5 deg): the truth box is kept by both tests, and a box shifted
    0.5 m is rejected by at least one (the combination the benchmark uses)."""
    rng = np.random.default_rng(2)
    params = SonarBeltParams.default_belt()
    hall = builtin_map("hall")
    belt = SonarBelt.from_params(params, echoes_never_lost=True)
    truth = np.array([5.0, 4.0, 0.7])
    scan = SonarScan(
        hall.segments,
        belt,
        bounded_readings(cone_ranges(truth, hall.segments, params), params, rng),
    )
    boxes = np.stack([truth - 0.02, truth + 0.02], axis=-1)[None]
    assert not ray_rejections(boxes, scan).any() and not sensor_verdicts(boxes, scan)[0].any()
    moved = boxes + np.array([0.5, 0.0, 0.0])[:, None]
    assert (ray_rejections(moved, scan) | sensor_verdicts(moved, scan)[0]).any()


def test_sub_boxes_cover_the_box_exactly():
    rng = np.random.default_rng(4)
    lo = rng.uniform(-5, 5, (50, 3))
    boxes = np.stack([lo, lo + rng.uniform(0, 1, (50, 3)) ** 3], axis=-1)
    subs = sub_boxes(boxes, (3, 2, 5))
    assert subs.shape == (50, 30, 3, 2)
    assert np.all(subs[..., 0] <= subs[..., 1])
    # along each axis the pieces' ends chain from the box's lower to its upper bound
    grid = subs.reshape(50, 3, 2, 5, 3, 2)
    for axis in range(3):
        ends = np.moveaxis(grid[..., axis, :], axis + 1, 1)[:, :, 0, 0]  # (50, count, 2)
        assert np.array_equal(ends[:, 0, 0], boxes[:, axis, 0])
        assert np.array_equal(ends[:, -1, 1], boxes[:, axis, 1])
        assert np.array_equal(ends[:, 1:, 0], ends[:, :-1, 1])


@pytest.mark.slow
def test_joint_test_rejects_what_no_single_sensor_can():
    """Heading pieces each rejected by a different sensor: the joint test rejects the box,
    the per-sensor test cannot; and ``other`` rejections count in every piece."""
    rng = np.random.default_rng(6)
    params = SonarBeltParams.default_belt(half_aperture_rad=1e-6, d_max_m=100.0)
    belt = SonarBelt.from_params(params, echoes_never_lost=True)
    hall = builtin_map("hall")
    joint_only = 0
    for _ in range(8):
        truth = np.array([*rng.uniform([1, 1], [9, 7]), rng.uniform(-np.pi, np.pi)])
        scan = SonarScan(
            hall.segments,
            belt,
            bounded_readings(cone_ranges(truth, hall.segments, params), params, rng),
        )
        centre = truth + rng.uniform(-1, 1, (150, 3)) * np.array([0.1, 0.1, 0.1])
        boxes = np.stack([centre - 0.03, centre + 0.03], axis=-1)
        single = ray_rejections(boxes, scan, (1, 1, 4)).any(axis=1)
        joint = joint_rejections(boxes, scan, 0, (1, 1, 4))
        assert np.all(joint | ~single)  # a single sensor rejecting every piece is joint too
        joint_only += np.count_nonzero(joint & ~single)
    assert joint_only > 20
    counts = joint_rejection_counts(boxes, scan, (1, 1, 4))
    assert np.array_equal(counts > 0, joint_rejections(boxes, scan, 0, (1, 1, 4)))
    assert np.all(counts >= ray_rejections(boxes, scan, (1, 1, 4)).sum(axis=1))
    some = rng.random((150, 16)) < 0.3  # another test's rejections count in every piece
    assert np.all(joint_rejection_counts(boxes, scan, (1, 1, 4), other=some) >= some.sum(axis=1))
    everything = np.ones((10, 16), dtype=bool)
    assert joint_rejections(boxes[:10], scan, 15, (1, 1, 4), other=everything).all()
    assert not joint_rejections(boxes[:10], scan, 16, (1, 1, 4), other=everything).any()


@pytest.mark.slow
def test_the_kernel_matches_the_numpy_reference():
    """Same verdicts on random cases, thin and wide cones, with edge cases: degenerate and
    unbounded boxes, headings at +-pi and far beyond, boxes wider than the room."""
    rng = np.random.default_rng(9)
    for case in range(45):
        scan, _, truth = random_scan_case(
            rng, GAMMAS_RAD[case % 3], echoes_never_lost=case % 2 == 0
        )
        centre = truth + rng.normal(0, 1, (40, 3)) * np.array([0.2, 0.2, 0.1])
        half = np.exp(rng.uniform(np.log(1e-4), np.log(0.3), (40, 3)))
        half[:4] = 0.0  # points
        boxes = np.stack([centre - half, centre + half], axis=-1)
        boxes[4, 2] = [np.pi - 0.01, np.pi]
        boxes[5, 2] = [-np.pi, -np.pi + 0.01]
        boxes[6, 2] += 1e7
        boxes[7, 0] = [-np.inf, np.inf]
        boxes[8] = [[-5.0, 15.0], [-5.0, 15.0], [-4.0, 4.0]]
        pieces = ((1, 1, 1), (1, 1, 4), (2, 2, 1))[case % 3]
        compiled = piece_rejections(boxes, scan, pieces)
        assert np.array_equal(compiled, reference_rays.piece_rejections(boxes, scan, pieces))
        assert not compiled[7].any() and not compiled[8].any()


def test_localize_and_gomne_with_the_ray_test_keep_the_truth_in_smaller_sets():
    """The hook in :mod:`intervals.sonar.cone`: with ``ray_test`` the sets still hold the truth (also
    with ``q`` outliers under GOMNE) and are never larger, and strictly smaller on thin cones."""
    rng = np.random.default_rng(11)
    smaller = 0
    for trial in range(12):
        scan, params, truth = random_scan_case(rng, GAMMAS_RAD[trial % 2], echoes_never_lost=True)
        prior = np.stack([truth - [0.4, 0.4, 0.15], truth + [0.4, 0.4, 0.15]], axis=-1)
        # the ray test's own effect: without the contractor, which takes part of its gain
        plain = localize(scan, prior, 0.05, ray_test=False, contract=False)
        joint = localize(scan, prior, 0.05, ray_test=True, contract=False)
        assert contains_points(joint.outer, truth[None]).any()
        assert volume(joint.outer) <= volume(plain.outer)
        smaller += volume(joint.outer) < volume(plain.outer)
        # two readings replaced by outliers: GOMNE's guaranteed set at q_max = 2 keeps the truth
        readings = scan.readings_m.copy()
        readings[rng.choice(len(readings), 2, replace=False)] = rng.uniform(0.0, params.d_max_m, 2)
        noisy = SonarScan(scan.segments, scan.belt, readings, scan.boundary)
        result = gomne(noisy, prior, 0.05, q_max=2, ray_test=True)
        assert result.consistent and contains_points(result.paving.outer, truth[None]).any()
    assert smaller >= 9


def test_ray_test_setting():
    """``None`` follows the aperture; anything but a bool or ``None`` is refused."""
    thin = SonarBelt.from_params(SonarBeltParams.default_belt(half_aperture_rad=0.05))
    wide = SonarBelt.from_params(SonarBeltParams.default_belt())
    assert uses_ray_test(None, thin) and not uses_ray_test(None, wide)
    assert uses_ray_test(True, wide) and not uses_ray_test(False, thin)
    with pytest.raises(IntervalError, match="ray_test"):
        uses_ray_test("yes", thin)
