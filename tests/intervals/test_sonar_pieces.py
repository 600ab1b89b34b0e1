"""The cone test of pieces on their parent's pairs (intervals/sonar/pieces.py) against brute force.

Each sensor's rejection of a piece is checked with the simulator's own cone model
(``tests.helpers.cone_ranges``) and the readings' error bounds, independently of the interval
code: no sampled pose of a rejected piece (its corners, uniform draws, draws near the truth)
may explain that reading (an echo ``m``: cone distance ``d <= d_max`` and ``|m - d| <= e_abs +
e_rel d``; a no-echo reading proving free space: ``d > d_max``). The verdicts are also compared
with the full test's (:func:`intervals.sonar.cone.sensor_verdicts`), which they follow but need
not equal.
"""

from __future__ import annotations

import numpy as np
import pytest

from intervals.boxes import bisect
from intervals.localize import _test_and_counts
from intervals.sivia import OUTSIDE, UNDECIDED
from intervals.sonar.cone import sensor_verdicts
from intervals.sonar.pieces import piece_rejections
from intervals.sonar.room import room_verdicts
from intervals.sonar.scan import SonarScan
from tests.helpers import cone_ranges, random_scan_case, sample_in_boxes, with_outliers

GAMMAS_RAD = (0.05, np.deg2rad(12.5), 0.6)


def _parents(truth, rng, count):
    """Pose boxes ``(count, 3, 2)`` of random sizes near the truth (most hold it)."""
    half = rng.uniform(0.01, 0.2, (count, 3)) * np.array([1.0, 1.0, 0.7])
    centre = truth + rng.uniform(-1, 1, (count, 3)) * half * 1.5
    return np.stack([centre - half, centre + half], axis=-1)


def _explained(poses, scan, params):
    """``(N, S, k)`` bool: sample ``s`` of piece ``n`` explains reading ``i`` (module doc)."""
    d = cone_ranges(poses, scan.segments, params)
    m = scan.readings_m
    with np.errstate(invalid="ignore"):  # inf - inf: no echo
        gap = np.abs(m - d)
    bound = params.error_abs_bound_m + params.error_rel_bound * np.where(np.isfinite(d), d, 0.0)
    echo = np.isfinite(m)
    explained = ~echo | ((d <= params.d_max_m) & (gap <= bound))
    if scan.belt.echoes_never_lost:
        explained &= echo | (d > params.d_max_m)
    return explained


@pytest.mark.parametrize("gamma", GAMMAS_RAD)
def test_every_rejection_of_a_piece_is_sound(gamma):
    """Random rooms, belts, readings (with outliers), with and without free space: a sensor
    rejects a piece only when no sampled pose of it explains the reading; and the verdicts are
    nearly all the full test's."""
    rng = np.random.default_rng(int(gamma * 1e5) + 3)
    rejected = explained_seen = same = total = 0
    for case in range(6):
        scan, params, truth = random_scan_case(rng, gamma, echoes_never_lost=bool(case % 2))
        scan = with_outliers(scan, rng, case % 3)
        parents = _parents(truth, rng, 24)
        pieces = parents
        for _ in range(3):  # the tightening's order: piece n of parent n % P
            pieces = np.concatenate(bisect(pieces, None))
        reject = piece_rejections(pieces, parents, scan)
        poses = sample_in_boxes(pieces, truth, rng, 40)
        explained = _explained(poses, scan, params)
        caught = reject[:, None, :] & explained
        assert not caught.any(), f"case {case}: a sensor rejected a piece with a pose it explains"
        rejected += int(np.count_nonzero(reject))
        explained_seen += int(np.count_nonzero(explained.any(axis=1)))
        full = sensor_verdicts(pieces, scan, inner=False)[0]
        same += int(np.count_nonzero(reject == full))
        total += reject.size
    assert rejected > 100 and explained_seen > 1000  # the check saw both kinds
    assert same / total > 0.98


def test_no_pieces_and_a_piece_that_is_its_parent():
    """No pieces: an empty verdict array; a parent tested as its own piece: the full test's
    verdicts on the pairs of that same box."""
    rng = np.random.default_rng(8)
    scan, _, truth = random_scan_case(rng, np.deg2rad(12.5), echoes_never_lost=True)
    parents = _parents(truth, rng, 30)
    assert piece_rejections(parents[:0], parents, scan).shape == (0, scan.belt.count)
    full = sensor_verdicts(parents, scan, inner=False)[0]
    assert np.array_equal(piece_rejections(parents, parents, scan), full)


@pytest.mark.parametrize("enough", (1, 2, 4))
def test_a_piece_left_at_enough_rejections_has_the_same_verdict(enough):
    """``enough``: a row holds only rejections of the complete row, exactly ``min(enough,
    full count)`` of them, and a row with fewer than ``enough`` is the complete row; so
    "more than ``q``" (``enough = q + 1``) is decided as on the complete rows."""
    rng = np.random.default_rng(40 + enough)
    short = 0
    for case in range(6):
        scan, _, truth = random_scan_case(
            rng, GAMMAS_RAD[case % 3], echoes_never_lost=bool(case % 2)
        )
        scan = with_outliers(scan, rng, case % 3)
        parents = _parents(truth, rng, 24)
        pieces = parents
        for _ in range(3):
            pieces = np.concatenate(bisect(pieces, None))
        full = piece_rejections(pieces, parents, scan)
        left = piece_rejections(pieces, parents, scan, enough)
        assert not (left & ~full).any()
        counts, full_counts = left.sum(axis=1), full.sum(axis=1)
        assert np.array_equal(counts, np.minimum(full_counts, enough))
        assert np.array_equal(left[counts < enough], full[counts < enough])
        short += int(np.count_nonzero(full_counts > enough))
    assert short > 50  # rows were cut short


def _star_boundary(rng, vertices):
    """A star-shaped polygon ``(vertices, 2)`` around (5, 5) m, radii 2 to 5 m (not convex)."""
    angle = np.sort(rng.uniform(0, 2 * np.pi, vertices))
    radius = rng.uniform(2.0, 5.0, vertices)
    return np.stack([5 + radius * np.cos(angle), 5 + radius * np.sin(angle)], axis=1)


def test_the_pieces_of_a_parent_inside_the_room_are_inside_it():
    """What the tightening's test inherits from a parent: every piece of a parent that the
    in-room test finds wholly inside a (non-convex) polygon is found wholly inside it too, never
    outside; and the tightening's test (in-room test skipped for those pieces) gives the
    verdicts of the in-room test run on every piece."""
    rng = np.random.default_rng(17)
    inherited = room_rejected = 0
    for case in range(8):
        boundary = _star_boundary(rng, int(rng.integers(5, 40)))
        half = rng.uniform(0.005, 0.6, (400, 3)) * np.array([1.0, 1.0, 0.5])
        centre = np.concatenate(
            [rng.uniform(0, 10, (400, 2)), rng.uniform(-np.pi, np.pi, (400, 1))], axis=1
        )
        parents = np.stack([centre - half, centre + half], axis=-1)
        pieces = parents
        for _ in range(3):
            pieces = np.concatenate(bisect(pieces, None))
        parent_in = room_verdicts(parents, boundary)[1]
        outside, inside = room_verdicts(pieces, boundary)
        of_inside = parent_in[np.arange(pieces.shape[0]) % parents.shape[0]]
        assert inside[of_inside].all() and not outside[of_inside].any()
        inherited += int(np.count_nonzero(of_inside))
        # the test of the tightening against the in-room test on every piece
        scan, _, truth = random_scan_case(rng, GAMMAS_RAD[case % 3], bool(case % 2))
        scan = SonarScan(scan.segments, scan.belt, scan.readings_m, boundary)
        near = _parents(truth, rng, 40)
        near_pieces = near
        for _ in range(3):
            near_pieces = np.concatenate(bisect(near_pieces, None))
        for q in (0, 1):
            verdicts = _test_and_counts(near_pieces, scan, q, False, parents=near)[0]
            rows = piece_rejections(near_pieces, near, scan, q + 1)
            by_sensors = rows.sum(axis=1) > q
            by_room = room_verdicts(near_pieces, boundary)[0]
            expected = np.where(by_sensors | by_room, OUTSIDE, UNDECIDED)
            assert np.array_equal(verdicts, expected)
            room_rejected += int(np.count_nonzero(by_room & ~by_sensors))
    assert inherited > 3000 and room_rejected > 500  # both paths seen


def test_distances_decided_on_estimates_give_the_exact_rows():
    """The comparisons decided on ``sqrt`` estimates (``DECISION_SLACK``) give the rows of the
    exact functions (a slack so large that every comparison falls back to them), bit for bit,
    complete or left at ``enough``; a slack of the wrong sign (estimates trusted 1 mm past their
    threshold) changes rows, so the comparison sees the decisions."""
    rng = np.random.default_rng(61)
    changed = 0
    for case in range(9):
        scan, _, truth = random_scan_case(
            rng, GAMMAS_RAD[case % 3], echoes_never_lost=bool(case % 2)
        )
        scan = with_outliers(scan, rng, case % 3)
        parents = _parents(truth, rng, 24)
        pieces = parents
        for _ in range(3):
            pieces = np.concatenate(bisect(pieces, None))
        for enough in (None, 2):
            exact = piece_rejections(pieces, parents, scan, enough, slack=1e6)
            assert np.array_equal(piece_rejections(pieces, parents, scan, enough), exact)
            wrong = piece_rejections(pieces, parents, scan, enough, slack=-1e-3)
            changed += int(np.count_nonzero(wrong != exact))
    assert changed > 0
