"""The precision of a tracking epoch scaled to the previous set (``eps_cells``, issue 13:
large sets stay cheap): the formula on sets of known shape, and soundness of the coarser
epochs against sampled consistent poses in a 60 x 60 m hall, where the set is large by
nature (the sonar out of every wall's reach)."""

from __future__ import annotations

import numpy as np
import pytest

from intervals.boxes import Subpaving, area_xy, contains_points
from intervals.errors import IntervalError
from intervals.tracker import IntervalTracker, TrackerSettings
from tests.helpers import (
    BIG_HALL_SEGMENTS,
    DEFAULT_BELT,
    big_hall_scan,
    bounded_readings,
    cone_ranges,
    wrong_readings,
)


def _tracker(eps_cells: int, eps_m: float = 0.05) -> IntervalTracker:
    settings = TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=0.5, eps_m=eps_m, eps_cells=eps_cells)
    return IntervalTracker(settings, np.array([[0.0, 60.0], [0.0, 60.0]]))


def _set(*boxes) -> Subpaving:
    return Subpaving(np.zeros((0, 3, 2)), np.array(boxes, dtype=np.float64))


def test_epoch_eps_follows_the_narrowest_extent_of_the_set():
    blob = [[10.0, 30.0], [20.0, 40.0], [0.0, 0.4]]  # 20 x 20 m: 20 / 32 m
    assert _tracker(32).epoch_eps(_set(blob)) == pytest.approx(20.0 / 32.0)
    assert _tracker(16).epoch_eps(_set(blob)) == pytest.approx(20.0 / 16.0)
    assert _tracker(0).epoch_eps(_set(blob)) == 0.05
    # an L of two strips 0.4 m wide along two walls: its thickness, about twice the width
    corner = _set(
        [[50.0, 59.6], [59.2, 59.6], [0.0, 0.1]], [[59.2, 59.6], [50.0, 59.2], [0.0, 0.1]]
    )
    thickness_m = 2.0 * (9.6 * 0.4 + 0.4 * 9.2) / (9.6 + 9.6)
    assert _tracker(8).epoch_eps(corner) == pytest.approx(thickness_m / 8)
    assert _tracker(16).epoch_eps(corner) == 0.05
    # a strip 30 m long, 0.3 m wide: its width, under 8 * 0.05
    assert _tracker(8).epoch_eps(_set([[0.0, 30.0], [1.0, 1.3], [0.0, 0.1]])) == 0.05
    # two small places far apart: the hull is wide, the area small (2 x 0.25 m²: 0.7 m)
    twins = _set([[1.0, 1.5], [1.0, 1.5], [0.0, 0.1]], [[50.0, 50.5], [50.0, 50.5], [3.0, 3.1]])
    assert _tracker(32).epoch_eps(twins) == 0.05
    # the area is the volume over the heading width: the same blob in 4 boxes, 2 layers
    layered = _set(
        [[10.0, 20.0], [20.0, 40.0], [0.0, 0.2]],
        [[20.0, 30.0], [20.0, 40.0], [0.0, 0.2]],
        [[10.0, 20.0], [20.0, 40.0], [0.2, 0.4]],
        [[20.0, 30.0], [20.0, 40.0], [0.2, 0.4]],
    )
    assert _tracker(32).epoch_eps(layered) == pytest.approx(20.0 / 32.0)
    # a flat heading (volume 0): eps_m
    assert _tracker(32).epoch_eps(_set([[10.0, 30.0], [20.0, 40.0], [0.2, 0.2]])) == 0.05


def test_eps_cells_is_validated():
    with pytest.raises(IntervalError, match="eps_cells"):
        TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=0.5, eps_cells=-1)
    with pytest.raises(IntervalError, match="eps_cells"):
        TrackerSettings(v_max_m_s=0.5, omega_max_rad_s=0.5, eps_cells=2.5)  # type: ignore[arg-type]


@pytest.mark.parametrize(("lost", "cells"), [(False, 8), (True, 8), (False, 32), (True, 32)])
def test_a_coarser_epoch_from_a_large_set_keeps_every_consistent_pose(lost, cells):
    """From a previous set of 8 x 8 m around a random true pose (in the open, or near a wall
    or a corner), echoes lost at random or free space known: every sampled pose that explains
    the scan and is reachable lies in the epoch's set with ``eps_cells`` 8 (the default: an epoch
    eps of 1 m) or 32 (0.25 m), which holds about as few boxes as the same epoch at ``eps_m`` and at most a little
    more area (where the scan shrinks the set, it is paved again at ``eps_m``)."""
    rng = np.random.default_rng(29 + lost + cells)
    params, checked, boxes = DEFAULT_BELT, 0, np.zeros(2, dtype=int)
    for case in range(6):
        where = case % 3
        if where == 0:  # in the open
            truth = np.array([*rng.uniform(15, 45, 2), rng.uniform(-np.pi, np.pi)])
        elif where == 1:  # along the south wall
            truth = np.array(
                [rng.uniform(15, 45), rng.uniform(0.5, 2.5), rng.uniform(-np.pi, np.pi)]
            )
        else:  # in the north-east corner
            truth = np.array([*rng.uniform(57.5, 59.5, 2), rng.uniform(-np.pi, np.pi)])
        readings = bounded_readings(cone_ranges(truth, BIG_HALL_SEGMENTS, params), params, rng)
        if lost:
            readings[rng.random(readings.size) < 0.5] = np.inf
        scan = big_hall_scan(readings, echoes_never_lost=not lost, params=params)
        centre = np.clip(truth[:2] + rng.uniform(-3.0, 3.0, 2), 4.5, 55.5)
        previous = _set(
            [
                [centre[0] - 4, centre[0] + 4],
                [centre[1] - 4, centre[1] + 4],
                [truth[2] - 0.2, truth[2] + 0.2],
            ]
        )
        coarse = _tracker(cells).step(previous, scan, 1.0)
        fine = _tracker(0).step(previous, scan, 1.0)
        assert coarse.consistent and fine.consistent
        count = 6000
        reach = previous.outer[0] + np.array([[-0.5, 0.5], [-0.5, 0.5], [-0.5, 0.5]])
        poses = rng.uniform(reach[:, 0], reach[:, 1], (count, 3))
        poses[: count // 3] = truth + rng.normal(0.0, [0.3, 0.3, 0.05], (count // 3, 3))
        poses[:, 2] = (poses[:, 2] + np.pi) % (2 * np.pi) - np.pi
        poses = poses[contains_points(reach[None], poses)[0] | (np.arange(count) < count // 3)]
        fits = wrong_readings(poses, scan, params) <= 1  # q_max = 1
        held = contains_points(coarse.outer, poses).any(axis=0)
        assert not np.any(fits & ~held), f"case {case}: a consistent pose lost"
        assert contains_points(coarse.outer, truth[None]).any()
        checked += int(np.count_nonzero(fits))
        boxes += (coarse.outer.shape[0], fine.outer.shape[0])
        assert area_xy(coarse.outer) <= 1.5 * area_xy(fine.outer) + 1.0
    assert checked > 2000  # the check saw many consistent poses
    assert boxes[0] <= 1.25 * boxes[1], boxes  # about as few boxes
