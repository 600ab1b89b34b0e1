"""The localiser's sample appends (one compiled call a block): the grid check against its numpy
formula, non-finite readings refused with the sample and the field named, and a refused
block leaving nothing behind."""

from __future__ import annotations

import numpy as np
import pytest

from localization.compiled.samples import APPENDED, OFF_GRID, append_samples
from localization.errors import EstimationError
from scenarios.pipeline import localizer_for
from scenarios.spec import load_scenario

DT_S = 0.01


def buffers(size):
    return np.zeros(size), np.zeros((size, 2), np.int64), np.zeros(size), np.zeros((size, 2))


def test_the_grid_check_is_the_numpy_formula_and_the_rows_are_copied():
    rng = np.random.default_rng(11)
    for _ in range(200):
        count, n = int(rng.integers(0, 50)), int(rng.integers(1, 30))
        first = float(rng.uniform(-5.0, 5.0))
        grid = first + np.arange(count, count + n) * DT_S
        # jitter up to just past half a period, some samples right at the limit
        t_s = grid + rng.choice([0.0, 0.3, 0.499999, 0.5000001], n) * DT_S * rng.choice([-1, 1], n)
        ticks = rng.integers(-40, 40, (n, 2))
        gyro, accel = rng.normal(size=n), rng.normal(size=(n, 2))
        out = buffers(count + n)
        found, k = append_samples(t_s, ticks, gyro, accel, count, first, DT_S, *out)
        off = np.abs(t_s - grid) > 0.5 * DT_S
        if off.any():
            assert (found, k) == (OFF_GRID, int(np.argmax(off)))
        else:
            assert (found, k) == (APPENDED, n)
        for got, given in zip(out, (t_s, ticks, gyro, accel), strict=True):
            np.testing.assert_array_equal(got[count : count + k], given[:k])


def fresh():
    return localizer_for(load_scenario("hall"))


def block(start, n, rng):
    """``n`` good samples from sample ``start`` on the 100 Hz grid."""
    t_s = np.arange(start, start + n) * DT_S
    return t_s, rng.integers(0, 30, (n, 2)), rng.normal(0.0, 0.01, n), rng.normal(0.0, 0.1, (n, 2))


def test_non_finite_readings_are_refused_and_nothing_of_the_block_is_appended():
    rng = np.random.default_rng(5)
    good = [block(0, 3, rng), block(3, 4, rng)]
    localizer = fresh()
    localizer.push_odometry_block(*good[0])
    bad_gyro = [np.array(a) for a in good[1]]
    bad_gyro[2][2] = np.nan
    with pytest.raises(EstimationError, match=r"sample 5 at t = .* non-finite gyro reading nan"):
        localizer.push_odometry_block(*bad_gyro)
    bad_accel = [np.array(a) for a in good[1]]
    bad_accel[3][0, 1] = -np.inf
    with pytest.raises(EstimationError, match=r"sample 3 at t = .* non-finite accel reading"):
        localizer.push_odometry_block(*bad_accel)
    nan_time = [np.array(a) for a in good[1]]
    nan_time[0][1] = np.nan
    with pytest.raises(EstimationError, match=r"sample 4 at t = .*nan.* off the 100 Hz grid"):
        localizer.push_odometry_block(*nan_time)
    assert localizer.estimate().sample == 2  # still the first block's three samples
    localizer.push_odometry_block(*good[1])
    # the same estimate as a localiser that never saw the refused blocks
    clean = fresh()
    for samples in good:
        clean.push_odometry_block(*samples)
    got, expected = localizer.estimate(), clean.estimate()
    assert got.sample == expected.sample == 6
    np.testing.assert_array_equal(got.pose, expected.pose)
    np.testing.assert_array_equal(got.pose_cov, expected.pose_cov)
    np.testing.assert_array_equal(localizer.history.mean, clean.history.mean)
