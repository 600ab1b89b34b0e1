"""The segment grid (``intervals.sonar.segment_grid``) against brute force over the whole map."""

import numpy as np
import pytest

from intervals.localize import localize
from intervals.sonar import segment_grid
from intervals.sonar.cone import sensor_verdicts
from intervals.sonar.contractor import contract
from intervals.sonar.geometry import GUARD_M, segment_box_gap
from intervals.sonar.reference import cone as reference_cone
from intervals.sonar.scan import SonarBelt, SonarScan, SonarScene
from intervals.sonar.segment_grid import SegmentGrid
from robotsim.maps import point_segment_distance
from tests.helpers import DEFAULT_BELT, bounded_readings, boxes_around, cone_ranges

pytestmark = pytest.mark.slow  # brute-force soundness sweeps on random maps


def _random_segments(rng, count, extent_m, offset_m=0.0):
    """``count`` segments in a square of ``extent_m`` from ``offset_m``: mostly short walls,
    some long ones crossing many cells, some along the grid lines (integer coordinates)."""
    start = rng.uniform(0, extent_m, size=(count, 2)) + offset_m
    angle = rng.uniform(-np.pi, np.pi, size=count)
    length = np.where(rng.random(count) < 0.1, extent_m, 10.0 ** rng.uniform(-2, 0.7, count))
    end = start + length[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    segments = np.clip(np.stack([start, end], axis=1), offset_m, offset_m + extent_m)
    on_lines = rng.random(count) < 0.2
    segments[on_lines] = np.round(segments[on_lines])
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    return segments[length > 1e-3]


@pytest.mark.parametrize("cell_m", [segment_grid.CELL_M, 0.05, 7.0])
def test_near_gathers_every_segment_within_the_radius(cell_m):
    """Random maps (up to 400 m across, some far from the origin) and query discs: every
    segment with a point within the radius of the centre is gathered."""
    rng = np.random.default_rng(3)
    gathered_fraction = []
    for _ in range(60):
        extent = float(10.0 ** rng.uniform(0.5, 2.6))
        offset = float(rng.choice([0.0, -500.0, 499.0 - extent]))
        segments = _random_segments(rng, int(rng.integers(1, 300)), extent, offset)
        grid = SegmentGrid.build(segments, cell_m)
        for _ in range(20):
            centre = rng.uniform(offset - 5, offset + extent + 5, size=2)
            if rng.random() < 0.2:  # on a cell corner
                centre = grid.origin + grid.cell_m * rng.integers(0, 20, size=2)
            radius = float(10.0 ** rng.uniform(-3, 1.5))
            near = grid.near(centre, radius)
            distance = point_segment_distance(centre[None], segments[:, 0], segments[:, 1])[0]
            within = np.flatnonzero(distance <= radius)
            assert np.isin(within, near).all()
            assert np.array_equal(near, np.unique(near))
            gathered_fraction.append(near.size / segments.shape[0])
    assert np.median(gathered_fraction) < 0.5  # the grid prunes: not the whole map every time


def test_restricted_scan_keeps_the_segments_of_the_whole_map_test():
    """``restricted_to`` (grid, then the gap bound) keeps exactly the segments that the gap
    bound over the whole map keeps (the definition before the grid), in the map's order."""
    rng = np.random.default_rng(4)
    belt = SonarBelt.from_params(DEFAULT_BELT)
    radius = float(np.max(np.hypot(*belt.mount_xy.T)))
    for _ in range(150):
        segments = _random_segments(rng, int(rng.integers(1, 400)), 60.0)
        readings = np.where(rng.random(belt.count) < 0.3, np.inf, rng.uniform(0.1, 3.0, belt.count))
        scan = SonarScan(segments, belt, readings)
        lo = rng.uniform(-2, 62, size=2)
        width = 10.0 ** rng.uniform(-2, 1.5, size=2)
        boxes = np.array([[[lo[0], lo[0] + width[0]], [lo[1], lo[1] + width[1]], [-1.0, 1.0]]])
        local = scan.restricted_to(boxes)
        centre, half = lo + width / 2, width / 2
        a, e = segments[:, 0], segments[:, 1] - segments[:, 0]
        gap = segment_box_gap(a[:, 0], a[:, 1], e[:, 0], e[:, 1], *centre, *half)
        expected = np.flatnonzero(gap <= scan.reach_m + radius + GUARD_M)
        np.testing.assert_array_equal(local.segment_ids, expected)
        np.testing.assert_array_equal(local.segments, segments[expected])
        twice = local.restricted_to(boxes)  # restricting again keeps the same segments
        np.testing.assert_array_equal(twice.segment_ids, expected)


def test_compiled_verdicts_with_the_grid_equal_the_references():
    """A 60 x 60 m map of 300 segments, boxes spread over it: the compiled test (grid
    lookup) gives the numpy reference's verdicts (every segment) and those of the compiled
    test with one cell holding the whole map, bit for bit; on restricted scans too."""
    rng = np.random.default_rng(5)
    belt = SonarBelt.from_params(DEFAULT_BELT, echoes_never_lost=True)
    segments = _random_segments(rng, 300, 60.0)
    one_cell = SonarScene(segments, belt)
    object.__setattr__(one_cell, "grid", SegmentGrid.build(segments, 1e3))  # brute force
    scene = SonarScene(segments, belt)
    assert scene.grid.shape[0] > 30
    rejected = 0
    for _ in range(25):
        truth = np.array([*rng.uniform(2, 58, size=2), rng.uniform(-np.pi, np.pi)])
        readings = bounded_readings(cone_ranges(truth[None], segments)[0], DEFAULT_BELT, rng)
        boxes = boxes_around(truth, rng, 40)
        boxes[:20, :2] += rng.uniform(-20, 20, size=(20, 2, 1))  # boxes elsewhere, too
        scan, brute = scene.scan(readings), one_cell.scan(readings)
        for current in (scan, scan.restricted_to(boxes[20:])):
            compiled = sensor_verdicts(boxes, current, inner=True)
            reference = reference_cone.sensor_verdicts(boxes, current, inner=True)
            np.testing.assert_array_equal(compiled[0], reference[0])
            np.testing.assert_array_equal(compiled[1], reference[1])
        np.testing.assert_array_equal(
            sensor_verdicts(boxes, scan)[0], sensor_verdicts(boxes, brute)[0]
        )
        rejected += int(sensor_verdicts(boxes, scan)[0].sum())
        assert localize(scan, boxes[25], 0.1).contains(truth[None])[0]
    assert rejected > 0


def test_contractor_with_the_grid_equals_the_contractor_over_every_segment():
    """The contractor looks up the segments near each box in the grid: on a 60 x 60 m map of
    300 segments its boxes equal, bit for bit (NaN rows included), those of the contractor
    with one cell holding the whole map (every segment checked), on restricted scans too, and
    it contracts or empties many of them."""
    rng = np.random.default_rng(6)
    belt = SonarBelt.from_params(DEFAULT_BELT)
    segments = _random_segments(rng, 300, 60.0)
    one_cell = SonarScene(segments, belt)
    object.__setattr__(one_cell, "grid", SegmentGrid.build(segments, 1e3))  # brute force
    scene = SonarScene(segments, belt)
    assert scene.grid.shape[0] > 30
    moved = 0
    for _ in range(25):
        truth = np.array([*rng.uniform(2, 58, size=2), rng.uniform(-np.pi, np.pi)])
        readings = bounded_readings(cone_ranges(truth[None], segments)[0], DEFAULT_BELT, rng)
        boxes = boxes_around(truth, rng, 40)
        boxes[:20, :2] += rng.uniform(-20, 20, size=(20, 2, 1))  # boxes elsewhere, too
        scan, brute = scene.scan(readings), one_cell.scan(readings)
        for q in (0, 1):
            for grid_scan, brute_scan in (
                (scan, brute),
                (scan.restricted_to(boxes[20:]), brute.restricted_to(boxes[20:])),
            ):
                mine = contract(boxes, grid_scan, q)
                np.testing.assert_array_equal(mine, contract(boxes, brute_scan, q))
                moved += int(np.sum(~np.all(mine == boxes, axis=(1, 2))))
    assert moved > 500
