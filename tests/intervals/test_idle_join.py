"""Undecided boxes joined back along their shared idle axes before SIVIA bisects them (issue
13, big_hall's tracking tail): the join against a brute-force grid, SIVIA's descent after it,
and a tracking epoch from big_hall's four-fold symmetric set (a strip along each wall) checked
against sampled consistent poses."""

from __future__ import annotations

import numpy as np

from intervals.boxes import Subpaving, contains_points
from intervals.sivia import INSIDE, OUTSIDE, UNDECIDED, _joined_idle, sivia
from intervals.tracker import IntervalTracker, TrackerSettings
from tests.helpers import (
    BIG_HALL_SEGMENTS,
    DEFAULT_BELT,
    big_hall_scan,
    bounded_readings,
    cone_ranges,
    wrong_readings,
)


def _expected_runs(present, idle, scores):
    """Brute force on a grid of unit cells ``present (nx, ny, nz)``: along x, each maximal run
    of consecutive present cells idle along x is one box (``{(x0, x1, y, z): lowest score}``);
    every other cell stays a box of its own."""
    nx, ny, nz = present.shape
    runs = {}
    for j in range(ny):
        for k in range(nz):
            i = 0
            while i < nx:
                if not present[i, j, k]:
                    i += 1
                    continue
                end = i + 1
                if idle[i, j, k]:
                    while end < nx and present[end, j, k] and idle[end, j, k]:
                        end += 1
                runs[(i, end, j, k)] = min(scores[i:end, j, k])
                i = end
    return runs


def test_joined_idle_joins_exactly_the_runs_idle_along_their_axis():
    rng = np.random.default_rng(13)
    for _ in range(20):
        shape = (9, 3, 2)
        present = rng.random(shape) < 0.8
        idle_x = rng.random(shape) < 0.6
        scores = rng.integers(0, 5, shape).astype(np.float64)
        cells = np.argwhere(present)
        rng.shuffle(cells)
        boxes = np.stack([cells, cells + 1], axis=-1).astype(np.float64)
        idle = np.zeros((cells.shape[0], 3), dtype=bool)
        idle[:, 0] = idle_x[tuple(cells.T)]
        joined, joined_idle, joined_scores = _joined_idle(boxes, idle, scores[tuple(cells.T)])
        got = {
            (int(b[0, 0]), int(b[0, 1]), int(b[1, 0]), int(b[2, 0])): s
            for b, s in zip(joined, joined_scores, strict=True)
        }
        assert got == _expected_runs(present, idle_x, scores)
        assert np.all(joined[:, 1:, 1] - joined[:, 1:, 0] == 1.0)  # never along y or z
        long = joined[:, 0, 1] - joined[:, 0, 0] > 1.0
        assert joined_idle[long, 0].all() and not joined_idle[:, 1:].any()
        # a cell no idle row meets is returned as it was, in its order
        alone = boxes[~idle[:, 0]]
        kept, kept_idle, _ = _joined_idle(alone, idle[~idle[:, 0]], np.zeros(alone.shape[0]))
        assert np.array_equal(kept, alone) and not kept_idle.any()


def test_joined_idle_keeps_the_idle_axes_every_piece_shares():
    boxes = np.array(
        [[[0.0, 1.0], [0.0, 1.0]], [[1.0, 2.0], [0.0, 1.0]], [[2.0, 3.0], [0.0, 1.0]]],
    )
    idle = np.array([[True, True], [True, False], [False, True]])
    joined, joined_idle, scores = _joined_idle(boxes, idle, np.array([3.0, 1.0, 2.0]))
    # the first two join along x (both idle there); the third is not idle along x
    assert joined.tolist() == [[[0.0, 2.0], [0.0, 1.0]], [[2.0, 3.0], [0.0, 1.0]]]
    assert joined_idle.tolist() == [[True, False], [False, True]]
    assert scores.tolist() == [1.0, 2.0]


def test_sivia_paves_a_band_cut_before_its_idle_axis_was_known_once():
    """The band ``0.3 <= y <= 0.7`` (any x: the test reports x idle): ``min_level_boxes``
    cuts the initial box across x before any test; after the first test call those slabs are
    joined, every later box spans the whole x range (the band is paved once, not once a
    slab), and the set holds every feasible point."""
    seen = []

    def band(boxes):
        seen.append(boxes.copy())
        lo, hi = boxes[:, 1, 0], boxes[:, 1, 1]
        v = np.where((hi < 0.3) | (lo > 0.7), OUTSIDE, UNDECIDED)
        v[(lo >= 0.3) & (hi <= 0.7)] = INSIDE
        idle = np.zeros(boxes.shape[:2], dtype=bool)
        idle[:, 0] = True
        return v.astype(np.int8), np.zeros(boxes.shape[0]), idle

    box = np.array([[0.0, 8.0], [0.0, 1.0]])
    paving = sivia(band, box, eps=0.01, min_level_boxes=16)
    first = seen[0]
    assert np.all(first[:, 0, 1] - first[:, 0, 0] < 8.0)  # the blind cuts crossed x
    for later in seen[1:]:
        np.testing.assert_array_equal(later[:, 0], np.broadcast_to(box[0], later[:, 0].shape))
    points = np.stack(np.meshgrid(np.linspace(0, 8, 81), np.linspace(0.3, 0.7, 41)), -1)
    assert paving.contains(points.reshape(-1, 2)).all()
    assert np.all(paving.outer[:, 1, 0] >= 0.3 - 0.01) and np.all(paving.outer[:, 1, 1] <= 0.71)


def test_a_tracking_epoch_from_four_wall_strips_keeps_every_consistent_pose():
    """big_hall's tail: the previous set is a strip along each of the four walls (the hall is
    four-fold symmetric and the sonar sees only the nearest wall); the prediction is paved
    from the whole hall, the strips' slabs joined. Every sampled pose in the strips' reach
    that explains all but ``q_max`` readings lies in the new set, which keeps the four places."""
    rng = np.random.default_rng(25)
    params = DEFAULT_BELT
    settings = TrackerSettings(v_max_m_s=0.6, omega_max_rad_s=1.5, eps_m=0.05)
    tracker = IntervalTracker(settings, np.array([[0.0, 60.0], [0.0, 60.0]]))
    checked = 0
    for case in range(3):
        along, off = rng.uniform(15.0, 45.0), rng.uniform(1.7, 2.3)
        truth = np.array([along, off, rng.uniform(-0.1, 0.1)])
        readings = bounded_readings(cone_ranges(truth, BIG_HALL_SEGMENTS, params), params, rng)
        scan = big_hall_scan(readings, echoes_never_lost=True, params=params)
        half = np.pi / 2
        strips = np.array(  # the truth's place and its images by the hall's quarter turns
            [
                [[5.0, 55.0], [off - 0.1, off + 0.1], [truth[2] - 0.1, truth[2] + 0.1]],
                [
                    [60 - off - 0.1, 60 - off + 0.1],
                    [5.0, 55.0],
                    [truth[2] + half - 0.1, truth[2] + half + 0.1],
                ],
                [
                    [5.0, 55.0],
                    [60 - off - 0.1, 60 - off + 0.1],
                    [truth[2] + 2 * half - 0.1, truth[2] + 2 * half + 0.1],
                ],
                [
                    [off - 0.1, off + 0.1],
                    [5.0, 55.0],
                    [truth[2] - half - 0.1, truth[2] - half + 0.1],
                ],
            ]
        )
        strips[2, 2] -= 2 * np.pi * (strips[2, 2, 1] > np.pi)
        result = tracker.step(Subpaving(np.zeros((0, 3, 2)), strips), scan, 1.0)
        assert result.consistent and result.components()[0] >= 4, f"case {case}"
        reach = tracker.limits(strips, 1.0)
        count = 6000
        which = rng.integers(0, 4, count)
        poses = rng.uniform(reach[which, :, 0], reach[which, :, 1])
        near = np.arange(count) < count // 2  # half near the truth's images
        turns = which[near]
        c, s = np.cos(turns * half), np.sin(turns * half)
        centred = truth[:2] - 30.0
        noise = rng.normal(0.0, [0.5, 0.05, 0.03], (turns.size, 3))  # along, across, heading
        centred = centred + noise[:, :2]
        poses[near, 0] = 30.0 + c * centred[:, 0] - s * centred[:, 1]
        poses[near, 1] = 30.0 + s * centred[:, 0] + c * centred[:, 1]
        poses[near, 2] = truth[2] + turns * half + noise[:, 2]
        poses[:, 2] = (poses[:, 2] + np.pi) % (2 * np.pi) - np.pi
        fits = wrong_readings(poses, scan, params) <= settings.q_max
        held = contains_points(result.outer, poses).any(axis=0)
        assert not np.any(fits & ~held), f"case {case}: a consistent pose lost"
        checked += int(np.count_nonzero(fits))
    assert checked > 600  # the check saw many consistent poses
