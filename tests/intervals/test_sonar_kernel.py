"""The compiled sonar box test (``intervals.sonar.cone_kernel``) against its numpy reference
(``intervals.sonar.reference``).

Random maps, poses, belts (the default one and random non-radial ones, apertures from 1e-3 to
1.2 rad), readings with errors at their bounds, outliers, lost echoes (ignored, or free space
when echoes are never lost) and impossible echoes beyond ``d_max``, and boxes around the truth,
away from it, across the +-pi cut, beyond +-pi, untrusted (``|theta| > 2^20``), full turns and
single poses: every per-sensor verdict, every sensor box and every box verdict (q = 0 to 3, with
and without the inner test) must be equal, bit for bit.
"""

import dataclasses

import numpy as np
import pytest

import intervals.localize as localize_module
from intervals.errors import IntervalError
from intervals.interval import TRIG_EXACT_LIMIT_RAD
from intervals.localize import box_test, gomne, localize
from intervals.sivia import INSIDE, OUTSIDE
from intervals.sonar import cone_kernel, rays
from intervals.sonar.cone import heading_trig, sensor_verdicts
from intervals.sonar.geometry import ANGLE_MARGIN_RAD, ARC_SLACK, GUARD_M
from intervals.sonar.reference import cone as reference_cone
from intervals.sonar.reference import rays as reference_rays
from intervals.sonar.reference import reference_box_tests
from intervals.sonar.reference import room as reference_room
from intervals.sonar.room import room_verdicts
from intervals.sonar.scan import ECHO, FREE, IGNORED, SonarBelt, SonarScan
from intervals.tracker import IntervalTracker, TrackerSettings
from robotsim.maps import builtin_map
from robotsim.sensors.sonar import SonarBeltParams
from tests.helpers import bounded_readings, boxes_around, cone_ranges, random_room

PARAMS = SonarBeltParams.default_belt()


def _random_belt(rng) -> tuple[SonarBelt, object]:
    """The default belt, or 8 sensors with random mounts, axes and aperture; ``(belt, params)``
    with random ``d_max`` and error bounds, echoes lost or not."""
    params = PARAMS
    if rng.random() < 0.5:
        k = 8
        params = dataclasses.replace(
            PARAMS,
            mount_xy=rng.uniform(-0.3, 0.3, (k, 2)),
            mount_angle_rad=rng.uniform(-np.pi, np.pi, k),
            half_aperture_rad=float(np.exp(rng.uniform(np.log(1e-3), np.log(1.2)))),
            d_max_m=float(rng.uniform(2.0, 6.0)),
            error_abs_bound_m=float(rng.uniform(0.0, 0.05)),
            error_rel_bound=float(rng.uniform(0.0, 0.03)),
        )
    return SonarBelt.from_params(params, echoes_never_lost=bool(rng.random() < 0.5)), params


def _faulty(readings, d_max_m, rng):
    """Outliers (uniform in [0, 1.3 d_max]: some beyond d_max, impossible echoes) and lost
    echoes, each on about 10 % of the sensors."""
    u = rng.random(readings.shape)
    out = np.where(u < 0.1, rng.uniform(0, 1.3 * d_max_m, readings.shape), readings)
    return np.where(u > 0.9, np.inf, out)


def _special_boxes(truth, rng) -> np.ndarray:
    """Boxes ``(60, 3, 2)`` near ``truth`` in x, y with awkward headings: across +-pi, beyond
    +-pi, untrusted, at least a full turn, with a bound on an axis direction, single poses."""
    n = 60
    centre = truth + np.column_stack([rng.uniform(-1, 1, (n, 2)), np.zeros(n)])
    half = np.column_stack([np.exp(rng.uniform(-12, -1, (n, 2))), np.exp(rng.uniform(-20, 1, n))])
    centre[:20, 2] = rng.choice([-np.pi, np.pi], 20) + rng.uniform(-0.05, 0.05, 20)  # the cut
    centre[20:30, 2] = rng.uniform(-4 * np.pi, 4 * np.pi, 10)  # beyond +-pi
    centre[30:35, 2] = rng.choice([-1, 1], 5) * rng.uniform(1.0, 2.0, 5) * TRIG_EXACT_LIMIT_RAD
    centre[35:40, 2] = rng.uniform(-np.pi, np.pi, 5)
    half[35:40, 2] = np.pi + rng.uniform(-1e-9, 0.5, 5)  # about a full turn or more
    centre[40:, 2] = truth[2] + rng.uniform(-0.5, 0.5, 20)
    # a heading bound on a multiple of pi/8: arc ends on the axis directions (default belt)
    centre[40:45, 2] = rng.integers(-8, 8, 5) * np.pi / 8 + rng.choice([-1, 1], 5) * half[40:45, 2]
    half[50:] = 0.0  # single poses
    return np.stack([centre - half, centre + half], axis=-1)


def _case(rng):
    """``(scan, boxes (180, 3, 2))`` for a random map, pose, belt and readings."""
    segments, outer = random_room(rng)
    belt, params = _random_belt(rng)
    truth = np.array([*rng.uniform(0.3, 9.7, 2), rng.uniform(-np.pi, np.pi)])
    readings = bounded_readings(cone_ranges(truth, segments, params), params, rng)
    if rng.random() < 0.5:
        readings = _faulty(readings, params.d_max_m, rng)
    scan = SonarScan(segments, belt, readings, outer)
    near = boxes_around(truth, rng, 60)
    away = near.copy()
    away[:, :, :] += (rng.uniform(-1, 1, (60, 3)) * [1.0, 1.0, 1.0])[:, :, None]
    return scan, np.concatenate([near, away, _special_boxes(truth, rng)])


@pytest.mark.slow
def test_compiled_verdicts_equal_the_numpy_reference():
    """200 random cases x 180 boxes: per-sensor reject / certain and the box verdicts at
    q = 0..3 agree everywhere; the cases reach every kind of reading and verdict."""
    rng = np.random.default_rng(31)
    seen = dict.fromkeys(
        (
            "reject",
            "keep",
            "certain",
            "free",
            "ignored",
            "impossible",
            "inside",
            "outside",
            "sensor_verdicts",
        ),
        0,
    )
    for _ in range(200):
        scan, boxes = _case(rng)
        for inner in (True, False):
            reference = reference_cone.sensor_verdicts(boxes, scan, inner)
            compiled = sensor_verdicts(boxes, scan, inner)
            np.testing.assert_array_equal(compiled[0], reference[0])
            np.testing.assert_array_equal(compiled[1], reference[1])
            seen["sensor_verdicts"] += 2 * reference[0].size
            seen["certain"] += np.count_nonzero(reference[1])
        for q in (0, 1, 3):
            with reference_box_tests():
                verdicts = box_test(boxes, scan, q, inner=q < 3)
            np.testing.assert_array_equal(box_test(boxes, scan, q, q < 3), verdicts)
            seen["inside"] += np.count_nonzero(verdicts == INSIDE)
            seen["outside"] += np.count_nonzero(verdicts == OUTSIDE)
        seen["reject"] += np.count_nonzero(reference[0])
        seen["keep"] += np.count_nonzero(~reference[0])
        seen["free"] += np.count_nonzero(scan.kind == FREE)
        seen["ignored"] += np.count_nonzero(scan.kind == IGNORED)
        seen["impossible"] += np.count_nonzero(
            (scan.kind == ECHO) & (scan.ranges[:, 0] > scan.ranges[:, 1])
        )
    assert seen["sensor_verdicts"] > 500_000
    assert min(seen.values()) > 0, seen
    assert seen["reject"] > 0.1 * seen["keep"], seen


def test_compiled_sensor_boxes_equal_the_numpy_ones():
    """The kernel's sensor boxes and wedge half-planes are the reference's bit for bit."""
    rng = np.random.default_rng(32)
    rows_checked = 0
    for _ in range(20):
        belt, _ = _random_belt(rng)
        truth = np.array([*rng.uniform(0.3, 9.7, 2), rng.uniform(-np.pi, np.pi)])
        boxes = np.ascontiguousarray(
            np.concatenate([boxes_around(truth, rng, 20), _special_boxes(truth, rng)])
        )
        reference = reference_cone.sensor_boxes(boxes, belt)
        cos_theta, sin_theta = heading_trig(boxes)
        rows = np.empty((belt.count, cone_kernel.SENSOR_COLUMNS))
        for n in range(boxes.shape[0]):
            sure = cone_kernel.sensor_rows(
                boxes[n],
                cos_theta[n],
                sin_theta[n],
                belt.kernel_table,
                belt.half_aperture_rad,
                belt.sensor_box_margin_m,
                GUARD_M,
                ARC_SLACK,
                ANGLE_MARGIN_RAD,
                TRIG_EXACT_LIMIT_RAD,
                rows,
            )
            assert sure == reference.sure[n, 0]
            expected = np.column_stack(
                [reference.cx[n], reference.cy[n], reference.hx[n], reference.hy[n]]
                + [v[n] for plane in reference.union for v in plane]
                + [v[n] for plane in reference.inter for v in plane]
            )
            np.testing.assert_array_equal(rows, expected)
            rows_checked += 1
    assert rows_checked == 20 * 80


def test_compiled_room_verdicts_equal_the_numpy_reference():
    """The in-room kernel against its reference on random star-shaped (non-convex) boundaries
    of 5 to 30 vertices, with boxes of every size inside, outside and across the edges: the
    same verdicts, and all three outcomes occur."""
    rng = np.random.default_rng(34)
    outcomes = np.zeros(3, dtype=int)  # outside, inside, neither
    for _ in range(20):
        count = int(rng.integers(5, 31))
        angle = np.sort(rng.uniform(-np.pi, np.pi, count))
        radius = rng.uniform(2.0, 6.0, count)
        boundary = 5.0 + radius[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
        centre = rng.uniform(-2.0, 12.0, (200, 2))
        half = np.exp(rng.uniform(np.log(1e-4), np.log(3.0), (200, 2)))
        boxes = np.zeros((200, 3, 2))
        boxes[:, :2, 0], boxes[:, :2, 1] = centre - half, centre + half
        boxes[:, 2] = [-0.1, 0.1]
        outside, inside = room_verdicts(boxes, boundary)
        expected = reference_room.room_verdicts(boxes, boundary)
        np.testing.assert_array_equal(outside, expected[0])
        np.testing.assert_array_equal(inside, expected[1])
        outcomes += [outside.sum(), inside.sum(), (~outside & ~inside).sum()]
    assert (outcomes > 100).all(), outcomes


def test_paving_and_tracking_agree_with_the_references():
    """SIVIA, GOMNE (q_max 2, inner boxes on and off) and tracker epochs in ``hall`` give the
    same boxes on the kernels and on the numpy references (:func:`reference_box_tests`), with
    and without the ray test; outside the block the kernels are back."""
    hall = builtin_map("hall")
    belt = SonarBelt.from_params(PARAMS, echoes_never_lost=True)
    rng = np.random.default_rng(33)
    settings = TrackerSettings(0.5, 0.5, q_max=1)
    kernel_tracker = IntervalTracker(settings, hall.bounds)
    reference_tracker = IntervalTracker(settings, hall.bounds)
    kernel_previous = reference_previous = None
    for truth in ([2.0, 6.0, 3.1], [5.0, 3.0, -3.1], [5.2, 3.1, -2.8]):
        truth = np.array(truth)
        readings = bounded_readings(cone_ranges(truth, hall.segments), PARAMS, rng)
        readings[3] = 0.5  # an outlier
        scan = SonarScan(hall.segments, belt, readings, hall.boundary)
        prior = np.stack([truth - [0.4, 0.4, 0.2], truth + [0.4, 0.4, 0.2]], axis=-1)
        for inner in (False, True):
            a = gomne(scan, prior, 0.05, 2, inner=inner)
            with reference_box_tests():
                b = gomne(scan, prior, 0.05, 2, inner=inner)
            assert a.q == b.q and a.q_set == b.q_set
            np.testing.assert_array_equal(a.paving.inner, b.paving.inner)
            np.testing.assert_array_equal(a.paving.boundary, b.paving.boundary)
            assert a.paving.contains(truth[None])[0]
        a = localize(scan, prior, 0.05, q=0, ray_test=True)
        with reference_box_tests():
            b = localize(scan, prior, 0.05, q=0, ray_test=True)
        np.testing.assert_array_equal(a.outer, b.outer)
        kernel_step = kernel_tracker.step(kernel_previous, scan, 1.0)
        with reference_box_tests():
            reference_step = reference_tracker.step(reference_previous, scan, 1.0)
        assert reference_step.status == kernel_step.status
        np.testing.assert_array_equal(reference_step.outer, kernel_step.outer)
        kernel_previous, reference_previous = kernel_step.paving, reference_step.paving
    assert localize_module.sensor_verdicts is sensor_verdicts
    assert localize_module.room_verdicts is room_verdicts
    assert rays.piece_rejections.__module__ == "intervals.sonar.rays"


def test_the_reference_switch_replaces_every_box_test_and_restores_the_kernels():
    """Inside the block the pipeline looks up the three references (so the comparisons above
    compare two implementations); after it, even when it raised, the kernels again."""
    with pytest.raises(ZeroDivisionError), reference_box_tests():
        assert localize_module.sensor_verdicts is reference_cone.sensor_verdicts
        assert localize_module.room_verdicts is reference_room.room_verdicts
        assert rays.piece_rejections is reference_rays.piece_rejections
        _ = 1 / 0
    assert localize_module.sensor_verdicts is sensor_verdicts
    assert localize_module.room_verdicts is room_verdicts
    assert rays.piece_rejections.__module__ == "intervals.sonar.rays"


def test_bad_box_shape_is_refused():
    scan = SonarScan(
        builtin_map("hall").segments, SonarBelt.from_params(PARAMS), np.full(PARAMS.count, 1.0)
    )
    box = np.array([[1.0, 2.0], [1.0, 2.0], [0.0, 0.1]])
    with pytest.raises(IntervalError, match=r"\(N, 3, 2\)"):
        sensor_verdicts(box[:2], scan)
    with pytest.raises(IntervalError, match=r"\(N, 3, 2\)"):
        reference_cone.sensor_verdicts(box[:2], scan)
